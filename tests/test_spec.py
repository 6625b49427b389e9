"""Mission specs: validation through the CLI (exit 2, one line), canonical hash, extends."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import run_cli

from pipeline.cli import main
from pipeline.errors import SpecError
from pipeline.paths import PROJECT_ROOT, SHIPPED_SPECS
from pipeline.spec import (
    Spec,
    canonical_hash,
    load_spec,
    with_overrides,
)

# name → (files to write {file name: text}, the file to run, substrings stderr must contain)
BAD_SPECS: dict[str, tuple[dict[str, str], str, tuple[str, ...]]] = {
    "unknown_key": ({"s.yaml": "extends: nominal\nmission: {dt: 0.03, dtt: 0.01}\n"},
                    "s.yaml", ("mission.dtt", "unknown key")),
    "unknown_top_key": ({"s.yaml": "extends: nominal\ncontroler: {integrator: imex}\n"},
                        "s.yaml", ("controler", "unknown key")),
    "wrong_type_dt": ({"s.yaml": "extends: nominal\nmission: {dt: fast}\n"},
                      "s.yaml", ("mission.dt",)),
    "bool_dt": ({"s.yaml": "extends: nominal\nmission: {dt: true}\n"},
                "s.yaml", ("mission.dt",)),
    "zero_dt": ({"s.yaml": "extends: nominal\nmission: {dt: 0}\n"},
                "s.yaml", ("mission.dt", "greater than 0")),
    "negative_dt": ({"s.yaml": "extends: nominal\nmission: {dt: -0.03}\n"},
                    "s.yaml", ("mission.dt",)),
    "nan_dt": ({"s.yaml": "extends: nominal\nmission: {dt: .nan}\n"},
               "s.yaml", ("mission.dt", "finite")),
    "inf_gain": ({"s.yaml": "extends: nominal\ncontroller: {gains: {bus: {K: .inf}}}\n"},
                 "s.yaml", ("controller.gains.bus.K", "finite")),
    "unknown_integrator": ({"s.yaml": "extends: nominal\ncontroller: {integrator: rk4}\n"},
                           "s.yaml", ("controller.integrator",)),
    "q_bar_length": ({"s.yaml": "extends: nominal\nrobot: {q_bar: [0, 1, 2]}\n"},
                     "s.yaml", ("robot.q_bar",)),
    "missing_robot": ({"s.yaml": "extends: nominal\nrobot: {file: robots/nope.urdf}\n"},
                      "s.yaml", ("robot.file", "nope.urdf")),
    "robot_unreadable": ({"s.yaml": "extends: nominal\nrobot: {file: r.urdf}\n",
                          "r.urdf": "<robot name='x'><link"}, "s.yaml", ("r.urdf",)),
    "robot_not_urdf_or_mjcf": ({"s.yaml": "extends: nominal\nrobot: {file: nominal.yaml}\n"},
                               "s.yaml", ("robot.file", "neither URDF nor MJCF")),
    "old_urdf_key": ({"s.yaml": "extends: nominal\nrobot: {urdf: robots/x.urdf}\n"},
                     "s.yaml", ("robot.urdf", "unknown key")),
    "broken_yaml": ({"broken.yaml": "extends: nominal\nmission: {dt: [0.03\n"},
                    "broken.yaml", ("broken.yaml", "YAML")),
    "not_a_mapping": ({"s.yaml": "- 1\n- 2\n"}, "s.yaml", ("s.yaml", "mapping")),
    "extends_cycle": ({"a.yaml": "extends: b\n", "b.yaml": "extends: a\n"},
                      "a.yaml", ("cycle",)),
    "self_cycle": ({"a.yaml": "extends: a\n"}, "a.yaml", ("cycle",)),
    "extends_escapes": ({"s.yaml": "extends: ../x\n"}, "s.yaml", ("../x", "not a bare name")),
    "missing_parent": ({"s.yaml": "extends: no_such_parent\n"}, "s.yaml", ("no_such_parent",)),
    "missing_file": ({}, "absent.yaml", ("absent.yaml", "not found")),
    "missing_name": ({}, "NAME:no_such_spec", ("no_such_spec",)),
    "duplicate_key": ({"s.yaml": "extends: nominal\nmission: {dt: 0.03}\nmission: {dt: 0.01}\n"},
                      "s.yaml", ("s.yaml", "duplicate key 'mission'", "line")),
    "duplicate_nested_key": ({"s.yaml": "extends: nominal\nmission:\n  dt: 0.03\n  dt: 0.01\n"},
                             "s.yaml", ("duplicate key 'dt'",)),
    "empty_spec": ({"s.yaml": ""}, "s.yaml", ("s.yaml", "empty")),
    "comment_only_spec": ({"s.yaml": "# nothing here\n"}, "s.yaml", ("s.yaml", "empty")),
    "binary_spec": ({"s.yaml": b"\xff\xfe\x00\x01PK"}, "s.yaml", ("s.yaml", "not UTF-8")),
}


# The cases the brief requires end to end in a fresh interpreter (≈1 s each, started in
# parallel); every case also runs in-process through ``cli.main`` (milliseconds).
SUBPROCESS_CASES = ("unknown_key", "wrong_type_dt", "zero_dt", "nan_dt", "inf_gain",
                    "unknown_integrator", "missing_robot", "broken_yaml", "extends_cycle",
                    "extends_escapes", "missing_file")


def _write_case(case: str, d: Path) -> tuple[str, Path]:
    files, target, _ = BAD_SPECS[case]
    for fname, text in files.items():
        if isinstance(text, bytes):
            (d / fname).write_bytes(text)
        else:
            (d / fname).write_text(text)
    arg = target.removeprefix("NAME:") if target.startswith("NAME:") else str(d / target)
    return arg, d / "out"


@pytest.fixture(scope="module")
def bad_runs(tmp_path_factory) -> dict[str, tuple[subprocess.CompletedProcess, Path]]:
    """Start the subprocess cases at once (they are independent), then collect them."""
    procs = {}
    for case in SUBPROCESS_CASES:
        arg, out = _write_case(case, tmp_path_factory.mktemp(case))
        p = subprocess.Popen([sys.executable, "-m", "pipeline", "run", arg, "--out", str(out)],
                             cwd=PROJECT_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
        procs[case] = (p, out)
    results = {}
    for case, (p, out) in procs.items():
        stdout, stderr = p.communicate(timeout=120)
        results[case] = (subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr), out)
    return results


def _check_bad_input(case: str, code: int, stdout: str, stderr: str, out: Path) -> None:
    _, _, needles = BAD_SPECS[case]
    assert code == 2, (code, stderr)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ")
    assert "Traceback" not in stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert stdout == ""
    assert not out.exists() or not any(out.rglob("*")), "bad input wrote into the out dir"


@pytest.mark.parametrize("case", SUBPROCESS_CASES)
def test_bad_spec_cli_subprocess(case, bad_runs):
    res, out = bad_runs[case]
    _check_bad_input(case, res.returncode, res.stdout, res.stderr, out)


@pytest.mark.parametrize("case", list(BAD_SPECS))
def test_bad_spec_cli_in_process(case, tmp_path, capsys):
    arg, out = _write_case(case, tmp_path)
    code = main(["run", arg, "--out", str(out)])
    cap = capsys.readouterr()
    _check_bad_input(case, code, cap.out, cap.err, out)


def test_bad_spec_in_process_raises_spec_error(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("extends: nominal\nmission: {dt: -1}\n")
    with pytest.raises(SpecError, match=r"mission\.dt"):
        load_spec(p)


def test_good_spec_file_runs_via_cli(tmp_path):
    """The positive control of the cases above: a valid file in tmp_path runs (exit 0)."""
    (tmp_path / "tiny.yaml").write_text("extends: short_nominal\nmission: {duration: 0.3}\n")
    res = run_cli("run", str(tmp_path / "tiny.yaml"), "--out", str(tmp_path / "out"))
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "out" / "tiny" / "run.parquet").is_file()


SHORT_SPECS = ("short_nominal", "short_omega_ripple_dt010", "short_omega_ripple_imex")


# -- canonical hash ----------------------------------------------------------------------------

def _reverse_keys(obj):
    if isinstance(obj, dict):
        return {k: _reverse_keys(obj[k]) for k in reversed(list(obj))}
    return obj


def test_hash_ignores_key_order_and_file(tmp_path):
    a = tmp_path / "a.yaml"
    b = tmp_path / "b.yaml"
    a.write_text("extends: nominal\nmission: {dt: 0.02, duration: 5.0}\n"
                 "controller: {integrator: imex, gains: {bus: {K: 3.0, D: 2.5}}}\n")
    b.write_text("controller:\n  gains:\n    bus: {D: 2.5, K: 3.0}\n  integrator: imex\n"
                 "mission:\n  duration: 5.0\n  dt: 2.0e-2\nextends: nominal\n")
    sa, sb = load_spec(a), load_spec(b)
    assert sa.name != sb.name
    assert sa.spec_hash == sb.spec_hash
    assert sa.content() == sb.content()


def test_hash_of_fully_written_spec_in_reverse_order_equals_nominal(tmp_path):
    nominal = load_spec("nominal")
    full = _reverse_keys(nominal.content())
    full["description"] = "a different description is not content"
    p = tmp_path / "copy.yaml"
    p.write_text(yaml.safe_dump(full, sort_keys=False))
    assert next(iter(yaml.safe_load(p.read_text()))) != "robot"  # really reordered
    assert load_spec(p).spec_hash == nominal.spec_hash


def test_canonical_hash_of_plain_mappings():
    """canonical_hash itself sorts keys at every level (the Spec model already orders its
    fields, so this is the only place a key-order dependence could hide)."""
    a = {"b": 1.5, "a": {"y": [1, 2], "x": "s"}}
    b = {"a": {"x": "s", "y": [1, 2]}, "b": 1.5}
    assert canonical_hash(a) == canonical_hash(b)
    assert canonical_hash(a) != canonical_hash({**a, "b": 1.25})
    assert canonical_hash({"y": [1, 2]}) != canonical_hash({"y": [2, 1]})  # lists keep order
    with pytest.raises(ValueError):
        canonical_hash({"x": float("nan")})


def test_exponent_numbers_are_floats_as_yaml_1_2_reads_them(tmp_path):
    """`dt: 1e-2` was a string to PyYAML (YAML 1.1) and refused; YAML 1.2 reads a float,
    the same value `--set mission.dt=1e-2` gives."""
    (tmp_path / "e.yaml").write_text("extends: nominal\nmission: {dt: 1e-2}\n")
    spec = load_spec(tmp_path / "e.yaml")
    assert spec.mission.dt == 0.01
    assert spec.spec_hash == with_overrides(load_spec("nominal"), {"mission.dt": 0.01}).spec_hash


def test_hash_int_and_float_spelling_agree():
    base = load_spec("short_nominal")
    assert with_overrides(base, {"mission.duration": 30}).spec_hash == base.spec_hash
    assert with_overrides(base, {"controller.gains.bus.K": 2}).spec_hash == base.spec_hash


@pytest.mark.parametrize("key,value", [
    ("mission.dt", 0.0300001), ("controller.integrator", "imex"), ("target.seed", 8),
    ("config_sampling.seed", 1), ("robot.q_bar", [0.0, -1.6, 1.0, -0.95, 1.5708, 1e-9]),
    ("controller.base.derate.gain", True),
])
def test_hash_changes_with_content(key, value):
    base = load_spec("nominal")
    assert with_overrides(base, {key: value}).spec_hash != base.spec_hash


def test_hash_is_distinct_across_shipped_specs():
    # Every mission spec shipped loads and is distinct (claims registers share the folder).
    names = [p.stem for p in SHIPPED_SPECS.glob("*.yaml")
             if not p.stem.startswith("claims") and p.stem != "seed_note"]
    assert {"nominal", "omega_ripple_dt010", "omega_ripple_imex", *SHORT_SPECS} <= set(names)
    # Deliberate twins: the reach flight under a name of its own, so that its record at the
    # seed note's step stays apart from the reach run's own (issue 50).
    twins = {"omega_ripple_reach_note": "omega_ripple_reach",
             "short_omega_ripple_reach_note": "short_omega_ripple_reach"}
    for twin, of in twins.items():
        assert load_spec(twin).spec_hash == load_spec(of).spec_hash
    hashes = {load_spec(n).spec_hash for n in names if n not in twins}
    assert len(hashes) == len(names) - len(twins)
    h = load_spec("nominal").spec_hash
    assert len(h) == 64 and int(h, 16) >= 0


# -- extends -----------------------------------------------------------------------------------

def test_extends_merges_recursively(tmp_path):
    (tmp_path / "parent.yaml").write_text(
        "extends: nominal\ncontroller: {gains: {bus: {K: 3.0}}, integrator: imex}\n")
    (tmp_path / "child.yaml").write_text(
        "extends: parent\ncontroller: {gains: {cam_pos: {D: 9.0}}}\nmission: {duration: 7.0}\n")
    s = load_spec(tmp_path / "child.yaml")
    nominal = load_spec("nominal")
    g = s.controller.gains
    assert (g.bus.K, g.bus.D) == (3.0, nominal.controller.gains.bus.D)
    assert (g.cam_pos.K, g.cam_pos.D) == (nominal.controller.gains.cam_pos.K, 9.0)
    assert g.cam_ori == nominal.controller.gains.cam_ori
    assert s.controller.integrator == "imex"  # from the parent
    assert s.controller.limits == nominal.controller.limits  # from the grandparent
    assert (s.mission.dt, s.mission.duration) == (nominal.mission.dt, 7.0)
    assert s.name == "child"


def test_shipped_short_specs_merge_their_chain():
    imex = load_spec("short_omega_ripple_imex")
    assert imex.controller.integrator == "imex"
    assert (imex.mission.dt, imex.mission.duration) == (0.03, 30.0)
    dt010 = load_spec("short_omega_ripple_dt010")
    assert (dt010.mission.dt, dt010.mission.duration, dt010.controller.integrator) == (
        0.01, 30.0, "explicit")
    assert dt010.n_steps == 3000 and imex.n_steps == 1000
    # Only what the chain changes differs from nominal.
    nominal = load_spec("nominal").content()
    c = imex.content()
    assert c["controller"].pop("integrator") == "imex"
    assert c["mission"].pop("duration") == 30.0
    nominal["controller"].pop("integrator")
    nominal["mission"].pop("duration")
    assert c == nominal


def test_extends_prefers_a_parent_beside_the_child(tmp_path):
    (tmp_path / "short_nominal.yaml").write_text("extends: nominal\nmission: {duration: 2.0}\n")
    (tmp_path / "child.yaml").write_text("extends: short_nominal\n")
    assert load_spec(tmp_path / "child.yaml").mission.duration == 2.0


def test_spec_defaults_equal_nominal_file():
    """nominal.yaml writes every block out; the model defaults must agree with it."""
    assert Spec(name="nominal").content() == load_spec("nominal").content()


# -- overrides ---------------------------------------------------------------------------------

def test_with_overrides_validates_and_names_the_key():
    base = load_spec("nominal")
    s = with_overrides(base, {"mission.dt": 0.01, "controller.limits.v_max": 10.0})
    assert (s.mission.dt, s.controller.limits.v_max, s.name) == (0.01, 10.0, "nominal")
    with pytest.raises(SpecError, match="nope"):
        with_overrides(base, {"mission.nope": 1.0})
    with pytest.raises(SpecError, match="nope"):
        with_overrides(base, {"nope.dt": 1.0})
    with pytest.raises(SpecError, match=r"mission\.dt"):
        with_overrides(base, {"mission.dt": -1.0})
    with pytest.raises(SpecError, match=r"controller\.integrator"):
        with_overrides(base, {"controller.integrator": "rk4"})
    # The original is untouched (frozen model, copied data).
    assert base.mission.dt == 0.03


def test_spec_is_immutable():
    s = load_spec("nominal")
    with pytest.raises(Exception, match="frozen"):
        s.mission.dt = 0.5  # type: ignore[misc]


def test_shipped_specs_live_at_the_top_of_the_repository():
    """specs/ at the checkout's root, as the design card says (an installed package carries
    them inside it, tests/test_install.py)."""
    assert SHIPPED_SPECS == PROJECT_ROOT / "specs"
    assert not (PROJECT_ROOT / "pipeline" / "specs").exists()
    assert load_spec("nominal").robot_path == SHIPPED_SPECS / "robots" / "seed_ur3_box.xml"


def test_spec_files_resolve_beside_the_spec_then_on_the_search_path(tmp_path, monkeypatch):
    """A user's folder outside the package: its own robot beside its spec wins over the
    shipped one of the same name; BREVE_SPEC_PATH makes its specs usable by name; an
    ``extends`` of a shipped spec still finds the shipped spec."""
    user = tmp_path / "my_specs"
    (user / "robots").mkdir(parents=True)
    robot = user / "robots" / "seed_ur3_box.xml"
    robot.write_bytes((SHIPPED_SPECS / "robots" / "seed_ur3_box.xml").read_bytes())
    (user / "mine.yaml").write_text("extends: nominal\nmission: {duration: 1.0}\n")
    spec = load_spec(user / "mine.yaml")
    assert spec.robot_path == robot.resolve()
    robot.unlink()  # now only the shipped robot of that name is left
    assert load_spec(user / "mine.yaml").robot_path == SHIPPED_SPECS / "robots" / robot.name
    with pytest.raises(SpecError, match="spec 'mine' not found"):
        load_spec("mine")
    monkeypatch.setenv("BREVE_SPEC_PATH", str(user))
    assert load_spec("mine").mission.duration == 1.0


def test_a_yaml_text_read_twice_gives_two_independent_documents_and_errors_twice():
    """The parser keeps each text's document for the process (pipeline/yamlfile.py): the second
    read must equal the first yet be a new object, so a caller that changes its copy cannot
    change the next caller's, and a broken text is refused every time, not once."""
    from pipeline.errors import SpecError
    from pipeline.yamlfile import load_text

    text = "mission: {dt: 1e-2, tags: [a, b]}\n"
    first = load_text(text, "a.yaml")
    first["mission"]["tags"].append("c")
    first["mission"]["dt"] = 5
    assert load_text(text, "b.yaml") == {"mission": {"dt": 0.01, "tags": ["a", "b"]}}
    for source in ("c.yaml", "d.yaml"):
        with pytest.raises(SpecError, match=f"{source}: duplicate key 'x'"):
            load_text("x: 1\nx: 2\n", source)


def test_the_inert_fields_change_no_run_and_no_hash(tmp_path):
    """config_sampling.low/high/floor and robot.package_dirs stay out of the spec hash because
    a run does not read them: a mission with other values writes the same log, bit for bit; a
    field a run does read (config_sampling.seed) changes the hash."""
    import pyarrow.parquet as pq

    from pipeline.sim.run import run_spec
    from pipeline.spec import INERT_FIELDS

    base = with_overrides(load_spec("short_nominal"), {"mission.duration": 0.6}, name="a")
    other = with_overrides(base, {f"{b}.{k}": v for (b, k), v in
                                  zip(INERT_FIELDS, (0.2, 0.4, 0.9, ["pkgs"]), strict=True)},
                          name="a")
    assert other.config_sampling.floor == 0.9 and other.robot.package_dirs == ["pkgs"]
    assert other.spec_hash == base.spec_hash
    assert with_overrides(base, {"config_sampling.seed": 3}).spec_hash != base.spec_hash
    logs = [pq.read_table(run_spec(s, tmp_path / d).path) for s, d in ((base, "x"), (other, "y"))]
    assert all(logs[0].column(c).equals(logs[1].column(c)) for c in logs[0].column_names)


def test_a_posture_outside_a_joints_range_is_refused_naming_it(tmp_path):
    """Issue 50: robot.q_bar must be a posture the arm can take. The seed robot's wrist_1 is
    limited to [-3.67, 0.524] rad in its file (the precursor's range);
    1.0 rad is outside it."""
    from conftest import run_cli_in_process

    path = tmp_path / "outside.yaml"
    path.write_text("extends: nominal\nrobot: {q_bar: [0.0, -0.367, -1.763, 1.0, -5.95, 0.0]}\n")
    r = run_cli_in_process("validate", path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "field robot.q_bar: wrist_1_joint at 1 rad is outside its " \
        "range" in lines[0], lines


def test_spec_differences_read_the_specs_as_their_hash_does():
    """Dotted keys, sorted; a name, a description, an inert field or an unset one at its
    unset value is no difference (the spec hash ignores them)."""
    from pipeline.spec import spec_differences

    a = {"name": "a", "description": "x", "mission": {"dt": 0.03, "duration": 60.0,
                                                      "initial_omega_b": [0.0, 0.0, 0.0]},
         "robot": {"q_bar": [0.0, 1.0]}, "config_sampling": {"low": 1.0}}
    b = {"name": "b", "description": "y", "mission": {"dt": 0.01, "duration": 60.0},
         "robot": {"q_bar": [0.0, 1.5]}, "config_sampling": {"low": 2.0}, "extra": 1}
    assert spec_differences(a, b) == ["extra", "mission.dt", "robot.q_bar"]
    assert spec_differences(a, a) == []
    assert spec_differences(a, {**a, "mission": {**a["mission"], "initial_omega_b": [0, 0, 1]}}
                            ) == ["mission.initial_omega_b"]
