"""Logs the pipeline did not write (issue 25): the importer (pipeline/importer/), its
consistency check (eq. 33) and the data stages of an imported log
(pipeline/analysis/imported.py).

The project's own short logs are the known answers: cut to t, q and v, written as another
tool would (CSV, Parquet, the precursor's pickled .npz, a ROS 2 bag, an MCAP file), imported
and analysed, they must give the original's data-stage numbers; written in another convention
and declared in the project's, they must be refused with the convention named.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import run_cli, run_cli_in_process
from scipy.spatial.transform import Rotation

from pipeline.analysis.schema import ImportedRecord
from pipeline.analysis.stages import analyze_log
from pipeline.errors import LogDamaged, LogError, SpecError
from pipeline.importer.conventions import Conventions
from pipeline.importer.mapping import load_mapping
from pipeline.logs import verify_log
from pipeline.paths import PROJECT_ROOT
from pipeline.spec import load_spec
from pipeline.store.door import ArtefactStore, import_log

JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
          "wrist_2_joint", "wrist_3_joint")


@pytest.fixture(scope="module")
def nominal(short_logs):
    """The short nominal log's t, q, v and its own analysis."""
    log = verify_log(short_logs["short_nominal"])
    return log.columns(["t", "q", "v"]), analyze_log(log)


def _mapping(**fields) -> object:
    return load_mapping(None, {"robot": "short_nominal", **fields})


def _analyse(path: Path, out: Path, controller: str | None = None) -> ImportedRecord:
    store = ArtefactStore(path.parents[2], out)
    ctrl = load_spec(controller) if controller else None
    return store.analysis(store.open_log(path), quiet=True, controller=ctrl).record


def _same_data_stages(imported: ImportedRecord, original) -> None:
    """Bitwise: the same q and v give the same numbers, whoever wrote them."""
    assert imported.directions == original.directions
    assert imported.dominant == original.dominant
    assert imported.velocity_jump == original.velocity_jump
    # The σ columns rebuilt on import: no provenance check to compare (issue 33, item 5).
    assert imported.provenance is None or imported.provenance == original.provenance
    assert imported.window == original.window
    for field in ("lag1", "std", "step_rms", "alternating_rms", "step_median"):
        assert getattr(imported.bus_rate, field) == getattr(original.bus_rate, field)


# -- round trips ------------------------------------------------------------------------------

def test_the_own_log_cut_to_t_q_v_reimported_from_parquet_gives_the_same_numbers(
        nominal, short_logs, tmp_path):
    cols, original = nominal
    src = tmp_path / "cut.parquet"
    pq.write_table(pa.table({"t": cols["t"], "q": list(cols["q"]), "v": list(cols["v"])}), src)
    done = import_log(src, _mapping(), "cut", tmp_path / "logs")
    assert done.rows == len(cols["t"]) and done.time.max_deviation == 0.0
    rec = _analyse(done.path, tmp_path / "rep")
    assert isinstance(rec, ImportedRecord) and rec.origin.format == "parquet"
    _same_data_stages(rec, original)
    assert rec.damping is None and rec.prediction is None and rec.integrator == "undeclared"
    # The damped J⊕'s conditioning rebuilt on import is the simulator's own at every row.
    sigma = ["s_min_J", "kappa_J"]
    rebuilt = verify_log(done.path).columns(sigma)
    flown = verify_log(short_logs["short_nominal"]).columns(sigma)
    for c in sigma:
        assert np.array_equal(rebuilt[c], flown[c]), c


def test_provenance_is_a_check_only_against_the_sources_own_sigma(nominal, short_logs,
                                                                  tmp_path):
    """Without the source's σ_min(Γ), the provenance stage is "not applicable" (the import
    rebuilt the σ columns from the same q: 0.0 would prove nothing); with it mapped, it is the
    simulated log's check, and a σ that is not this robot's Γ fails it (exit 1)."""
    cols, original = nominal
    own = verify_log(short_logs["short_nominal"]).columns(["s_min_G"])["s_min_G"]
    bare = import_log(_written(tmp_path, cols["q"], cols["v"], cols["t"]), _mapping(), "bare",
                      tmp_path / "logs")
    rec = _analyse(bare.path, tmp_path / "rep")
    stage = next(s for s in rec.stages if s.stage.startswith("1 provenance"))
    assert rec.provenance is None and not stage.ran and "not applicable" in stage.why
    src = tmp_path / "sigma.parquet"
    pq.write_table(pa.table({"t": cols["t"], "q": list(cols["q"]), "v": list(cols["v"]),
                             "sigma": own}), src)
    done = import_log(src, _mapping(s_min_G="sigma"), "sigma", tmp_path / "logs")
    assert verify_log(done.path).meta.imported["s_min_G_from"] == "source"
    rec = _analyse(done.path, tmp_path / "rep")
    assert rec.provenance == original.provenance
    assert next(s for s in rec.stages if s.stage.startswith("1 provenance")).ran
    pq.write_table(pa.table({"t": cols["t"], "q": list(cols["q"]), "v": list(cols["v"]),
                             "sigma": own * 1.01}), other := tmp_path / "other.parquet")
    done = import_log(other, _mapping(s_min_G="sigma"), "other", tmp_path / "logs")
    r = run_cli_in_process("analyze", done.path, "--out", tmp_path / "rep")
    assert r.returncode == 1 and "provenance: rebuilt σ_min(Γ) differs" in r.stderr, r.stderr


def test_a_csv_of_scalar_columns_reimported_gives_the_same_numbers(nominal, tmp_path):
    cols, original = nominal
    q_names = [f"q{i}" for i in range(13)]
    v_names = [f"v{i}" for i in range(12)]
    df = pd.DataFrame(np.c_[cols["t"], cols["q"], cols["v"]], columns=["time", *q_names,
                                                                        *v_names])
    src = tmp_path / "cut.csv"
    df.to_csv(src, index=False)  # repr floats: exact
    done = import_log(src, _mapping(time="time", q=q_names, v=v_names), "cut_csv",
                      tmp_path / "logs")
    _same_data_stages(_analyse(done.path, tmp_path / "rep"), original)


def _precursor_npz(path: Path, cols) -> Path:
    """The precursor's own layout (tonitonitonitoni/ffsm_inspection, written by its
    ``save_npz``; issue 33): one key, ``states``, a 0-d object array holding a pickled
    ``types.SimpleNamespace`` with ``t`` (N,), ``x`` (N, 25) = [q (13: bus position,
    quaternion x y z w, 6 joints) | v (12: Pinocchio's free flyer, bus frame)] and ``u``
    (N, 12) = [f_b, τ_b, τ]; no ``q`` or ``v`` attribute, no row dropped. Built here from the
    seed robot's own log (the precursor's file is not redistributed)."""
    from types import SimpleNamespace

    n = len(cols["t"])
    states = SimpleNamespace(t=cols["t"], x=np.c_[cols["q"], cols["v"]],
                             u=np.zeros((n, 12)))
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, states=np.array(states, dtype=object))
    return path


PRECURSOR_FIELDS = {"time": "states.t", "q": "states.x[:, 0:13]", "v": "states.x[:, 13:25]"}


def test_the_precursors_npz_imports_as_written(nominal, tmp_path):
    """The precursor's file as it writes it, read with the selection grammar: its own SHA-256
    is the origin, and the data stages are those of the same data imported as plain t, q, v
    (the original log's analysis)."""
    import hashlib

    cols, original = nominal
    src = _precursor_npz(tmp_path / "npz" / "states_ur3_1.npz", cols)
    with pytest.raises(SpecError, match=r"holds a pickled object.*--allow-pickle"):
        import_log(src, _mapping(**PRECURSOR_FIELDS), "precursor", tmp_path / "logs")
    with pytest.raises(SpecError, match=re.escape("no 'q' in key 'states' (it holds attributes "
                                                  "t (shape (1000,)), x (shape (1000, 25)), u "
                                                  "(shape (1000, 12)))")):
        import_log(src, _mapping(allow_pickle=True, time="states.t", q="states.q",
                                 v="states.v"), "precursor", tmp_path / "logs")
    done = import_log(src, _mapping(allow_pickle=True, **PRECURSOR_FIELDS), "precursor",
                      tmp_path / "logs")
    assert done.rows == len(cols["t"])
    meta = verify_log(done.path).meta
    assert meta.origin == "imported" and meta.imported["format"] == "npz"
    assert meta.imported["source_sha256"] == hashlib.sha256(src.read_bytes()).hexdigest()
    assert meta.imported["mapping"]["q"] == "states.x[:, 0:13]"
    rec = _analyse(done.path, tmp_path / "rep")
    _same_data_stages(rec, original)
    assert rec.dominant.lag1 < -0.9  # the note's period-2 ripple, from the data alone
    not_run = [s.stage for s in rec.stages if not s.ran]
    assert not_run[0].startswith("1 provenance") and not_run[1].startswith("4 damping")
    # With the controller declared, the damping theory runs and agrees with the data.
    rec = _analyse(done.path, tmp_path / "rep", controller="short_nominal")
    assert rec.damping.dt_mu_max == pytest.approx(original.theory.dt_mu_max, rel=1e-9)
    assert rec.damping.fastest_mode.name == original.theory.fastest_mode.name
    yaw = rec.prediction.modes[0]
    assert yaw.mode == "bus yaw ω_b,z" and yaw.predicted_rings and yaw.measured.rings
    assert rec.prediction.agrees


def test_selections_of_columns_in_every_format(nominal, tmp_path):
    """A Parquet list column's elements (x[13:25]), a CSV's and a Parquet file's own columns by
    position ([1:14]), a time column by position ([0]): the same numbers as the plain log."""
    cols, _ = nominal
    x = np.c_[cols["q"], cols["v"]]
    pq.write_table(pa.table({"t": cols["t"], "x": list(x)}), src := tmp_path / "x.parquet")
    a = import_log(src, _mapping(q="x[0:13]", v="x[13:25]"), "a", tmp_path / "logs")
    names = ["time", *(f"c{i}" for i in range(25))]
    frame = pd.DataFrame(np.c_[cols["t"], x], columns=names)
    frame.to_csv(csv := tmp_path / "x.csv", index=False)
    b = import_log(csv, _mapping(time="[0]", q="[1:14]", v="[14:26]"), "b", tmp_path / "logs")
    wide = tmp_path / "w.parquet"
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), wide)
    c = import_log(wide, _mapping(time="[0]", q="[1:14]", v="[-12:]"), "c", tmp_path / "logs")
    for done in (a, b, c):
        got = verify_log(done.path).columns(["q", "v"])
        np.testing.assert_array_equal(got["q"], cols["q"])
        np.testing.assert_array_equal(got["v"], cols["v"])


@pytest.mark.parametrize("text,needle", [
    ("x[0:12]", "shape (1000, 12), expected N×13"),
    ("x[::2]", "is not a selection"),
    ("x[0:13, :]", "a row selection is not a column selection"),
    ("x[", "is not a selection"),
    ("t[0:13]", "t has shape (1000,); a column selection needs rows × columns"),
    ("x[:, 40]", "column 40 of x, which has 25"),
])
def test_a_bad_selection_is_refused_naming_the_field(nominal, tmp_path, text, needle):
    cols, _ = nominal
    pq.write_table(pa.table({"t": cols["t"], "x": list(np.c_[cols["q"], cols["v"]])}),
                   src := tmp_path / "x.parquet")
    with pytest.raises(SpecError, match=re.escape(needle)):
        import_log(src, _mapping(q=text, v="x[13:25]"), "bad", tmp_path / "logs")


# -- the consistency check (eq. 33) -----------------------------------------------------------

def _written(tmp_path: Path, q: np.ndarray, v: np.ndarray, t: np.ndarray) -> Path:
    src = tmp_path / "x.parquet"
    pq.write_table(pa.table({"t": t, "q": list(q), "v": list(v)}), src)
    return src


def test_a_wrong_quaternion_order_is_refused_naming_it(nominal, tmp_path):
    cols, _ = nominal
    q = cols["q"].copy()
    q[:, 3:7] = cols["q"][:, [6, 3, 4, 5]]  # written w, x, y, z
    src = _written(tmp_path, q, cols["v"], cols["t"])
    with pytest.raises(SpecError) as err:
        import_log(src, _mapping(), "wxyz", tmp_path / "logs")
    msg = str(err.value)
    assert "with --quaternion wxyz they agree" in msg
    assert "the likely convention error is the quaternion order" in msg
    ratio = float(msg.split("the median step's residual is ")[1].split("×")[0])
    assert ratio > 1
    assert "\n" not in msg
    # Declared as written, it is taken, and is the same log.
    done = import_log(src, _mapping(quaternion="wxyz"), "wxyz", tmp_path / "logs")
    assert np.array_equal(verify_log(done.path).columns(["q"])["q"], cols["q"])


def test_world_frame_velocities_are_refused_naming_the_frame(nominal, tmp_path):
    cols, _ = nominal
    R = Rotation.from_quat(cols["q"][:, 3:7])
    v = cols["v"].copy()
    v[:, 0:3], v[:, 3:6] = R.apply(cols["v"][:, 0:3]), R.apply(cols["v"][:, 3:6])
    src = _written(tmp_path, cols["q"], v, cols["t"])
    with pytest.raises(SpecError, match=r"with --velocity-frame world they agree .*the likely "
                                        r"convention error is the velocity frame$"):
        import_log(src, _mapping(), "world", tmp_path / "logs")
    done = import_log(src, _mapping(velocity_frame="world"), "world", tmp_path / "logs")
    back = verify_log(done.path).columns(["v"])["v"]
    np.testing.assert_allclose(back, cols["v"], rtol=0, atol=1e-13)


def test_conventions_the_data_cannot_tell_apart_leave_the_declared_one(nominal, tmp_path):
    """A bus held at the world's axes: world and bus frames are the same data; either
    declaration stands (a tie is not evidence against the declared conventions)."""
    cols, _ = nominal
    q = cols["q"].copy()
    q[:, 3:7] = [0.0, 0.0, 0.0, 1.0]
    v = cols["v"].copy()
    v[:, 3:6] = 0.0  # no bus rotation
    t = cols["t"]
    for k in range(1, len(q)):  # positions integrated from the velocities (semi-implicit)
        q[k, :3] = q[k - 1, :3] + v[k, :3] * (t[k] - t[k - 1])
        q[k, 7:] = q[k - 1, 7:] + v[k, 6:] * (t[k] - t[k - 1])
    src = _written(tmp_path, q, v, t)
    for frame in ("bus", "world"):
        import_log(src, _mapping(velocity_frame=frame), f"f_{frame}", tmp_path / "logs")


def test_q_and_v_of_two_motions_are_refused(nominal, tmp_path):
    cols, _ = nominal
    v = np.roll(cols["v"], 100, axis=0)  # another part of the mission's velocities
    src = _written(tmp_path, cols["q"], v, cols["t"])
    with pytest.raises(SpecError, match="q and v disagree under the declared conventions"):
        import_log(src, _mapping(), "shifted", tmp_path / "logs")


@pytest.mark.parametrize("block,scale,factor", [
    (slice(6, 12), np.rad2deg(1.0), "the joint rates: 57.3 times"),  # rates in deg/s
    (slice(0, 3), 1000.0, "the bus's linear velocity: 1000 times"),  # mm/s
    (slice(0, 12), 2.0, "every block of v is 2 times")])
def test_a_velocity_in_the_wrong_unit_is_refused_with_its_factor(nominal, tmp_path, block,
                                                                 scale, factor):
    """A scaled block stays on its chord's line, which a ripple's long chords could hold: the
    weights of the step name it (eq. 33)."""
    cols, _ = nominal
    v = cols["v"].copy()
    v[:, block] *= scale
    src = _written(tmp_path, cols["q"], v, cols["t"])
    with pytest.raises(SpecError, match=f"{factor} what q's motion says"):
        import_log(src, _mapping(), "scaled", tmp_path / "logs")



def test_a_log_in_degrees_declared_so_is_the_same_log(nominal, tmp_path):
    cols, _ = nominal
    q, v = cols["q"].copy(), cols["v"].copy()
    q[:, 7:], v[:, 3:] = np.rad2deg(q[:, 7:]), np.rad2deg(v[:, 3:])
    src = _written(tmp_path, q, v, cols["t"])
    # The joints' limits name it first (issue 36, item 7): the shoulder pan at 449° read as rad.
    with pytest.raises(SpecError, match=r"joint shoulder_pan_joint .*degrees declared as "
                                        r"radians\? --angle-unit deg"):
        import_log(src, _mapping(), "deg", tmp_path / "logs")
    done = import_log(src, _mapping(angle_unit="deg"), "deg", tmp_path / "logs")
    got = verify_log(done.path).columns(["q", "v"])
    np.testing.assert_allclose(got["q"], cols["q"], rtol=1e-15, atol=0)
    np.testing.assert_allclose(got["v"], cols["v"], rtol=1e-15, atol=0)


# -- the time base ------------------------------------------------------------------------------

def test_an_uneven_time_base_is_refused_or_resampled_on_request(nominal, tmp_path):
    cols, _ = nominal
    keep = np.r_[0:200, 201:len(cols["t"])]  # one row dropped: a gap of two steps
    src = _written(tmp_path, cols["q"][keep], cols["v"][keep], cols["t"][keep])
    with pytest.raises(SpecError, match=r"uneven time base: a gap of 2 steps before row 200 .*"
                                        r"--resample DT"):
        import_log(src, _mapping(), "gappy", tmp_path / "logs")
    done = import_log(src, _mapping(), "gappy", tmp_path / "logs", resample_dt=0.03)
    rec = verify_log(done.path).meta.imported
    assert rec["time"]["resampled_from"] == len(keep) and rec["time"]["dt"] == 0.03
    assert done.rows == len(cols["t"])


def test_stamps_jittered_beyond_their_resolution_are_refused(nominal, tmp_path):
    cols, _ = nominal
    t = cols["t"] + np.where(np.arange(len(cols["t"])) == 50, 1e-6, 0.0)
    src = _written(tmp_path, cols["q"], cols["v"], t)
    with pytest.raises(SpecError, match=r"x\.parquet: uneven time base: jitter: row 50 is "
                                        r"\+1e-06 s off t0 \+ k·dt, beyond the stamps'"):
        import_log(src, _mapping(), "jitter", tmp_path / "logs")


def test_a_csv_written_by_pandas_with_a_dropped_row_is_refused(nominal, tmp_path):
    """pandas prints the shortest text of each float (t0 as ``0.0``): the rows are exact, so
    the resolution is the float's, and a dropped row is a gap whatever the resolution."""
    cols, _ = nominal
    keep = np.r_[0:50, 51:len(cols["t"])]
    q_names, v_names = [f"q{i}" for i in range(13)], [f"v{i}" for i in range(12)]
    df = pd.DataFrame(np.c_[cols["t"][keep], cols["q"][keep], cols["v"][keep]],
                      columns=["t", *q_names, *v_names])
    src = tmp_path / "gap.csv"
    df.to_csv(src, index=False)
    with pytest.raises(SpecError, match="uneven time base: a gap of 2 steps before row 50"):
        import_log(src, _mapping(q=q_names, v=v_names), "gap", tmp_path / "logs")


def test_stamps_printed_to_fixed_decimals_or_accumulated_are_even(nominal, tmp_path):
    cols, _ = nominal
    n = len(cols["t"])
    t = np.cumsum(np.full(n, 0.03)) - 0.03  # t += dt: up to 4e-13 s off k·dt
    import_log(_written(tmp_path, cols["q"], cols["v"], t), _mapping(), "acc", tmp_path / "l")
    q_names, v_names = [f"q{i}" for i in range(13)], [f"v{i}" for i in range(12)]
    df = pd.DataFrame(np.c_[cols["q"], cols["v"]], columns=[*q_names, *v_names])
    df.insert(0, "t", [f"{x:.3f}" for x in cols["t"]])  # written to the millisecond
    src = tmp_path / "ms.csv"
    df.to_csv(src, index=False)
    done = import_log(src, _mapping(q=q_names, v=v_names), "ms", tmp_path / "l")
    assert done.time.resolution == pytest.approx(5e-4, rel=1e-6)


@pytest.mark.parametrize("damage,needle", [
    ("nan_time", "time (t): row 3 is not a finite time"),
    ("empty_time", "column 't' holds something that is not a number"),
])
def test_a_damaged_csv_time_column_is_one_line(nominal, tmp_path, damage, needle):
    cols, _ = nominal
    q_names, v_names = [f"q{i}" for i in range(13)], [f"v{i}" for i in range(12)]
    df = pd.DataFrame(np.c_[cols["q"][:10], cols["v"][:10]], columns=[*q_names, *v_names])
    t = [repr(float(x)) for x in cols["t"][:10]]
    t[3] = "nan" if damage == "nan_time" else ""
    df.insert(0, "t", t)
    src = tmp_path / "bad.csv"
    df.to_csv(src, index=False)
    with pytest.raises(SpecError, match=re.escape(needle)):
        import_log(src, _mapping(q=q_names, v=v_names), "bad", tmp_path / "logs")


def test_bad_inputs_are_one_line_errors(nominal, tmp_path):
    cols, _ = nominal
    rows = [list(r) for r in cols["q"][:5]]
    rows[2] = rows[2][:12]  # one row a component short
    src = tmp_path / "ragged.parquet"
    pq.write_table(pa.table({"t": cols["t"][:5], "q": rows, "v": list(cols["v"][:5])}), src)
    with pytest.raises(SpecError, match="column 'q': rows of different lengths or nulls"):
        import_log(src, _mapping(), "ragged", tmp_path / "logs")
    good = _written(tmp_path, cols["q"], cols["v"], cols["t"])
    for name in ("../x", "a/b", ".hidden", ""):
        with pytest.raises(SpecError, match="a log's name is letters"):
            import_log(good, _mapping(), name, tmp_path / "logs")
    assert not (tmp_path / "x").exists()
    with pytest.raises(SpecError, match="300 characters, a log's name is at most 100"):
        import_log(good, _mapping(), "a" * 300, tmp_path / "logs")
    (not_a_folder := tmp_path / "a_file").write_text("")
    r = run_cli("import", good, "--robot", "short_nominal", "--out", not_a_folder)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Not a directory" in r.stderr
    with pytest.raises(SpecError, match="no time stamps to resample"):
        import_log(good, _mapping(time=None, dt=0.03), "x", tmp_path / "logs", resample_dt=0.01)


def _damaged(kind: str, cols: dict, d: Path) -> Path:
    """A file of one class of damage, written by the libraries that write such files."""
    import io
    import zipfile

    t, q, v = cols["t"][:20], cols["q"][:20], cols["v"][:20]
    if kind == "empty_csv":
        (p := d / "empty.csv").write_bytes(b"")
    elif kind == "header_only_csv":
        (p := d / "header.csv").write_text("t,q0,q1\n")
    elif kind == "empty_npz":
        (p := d / "empty.npz").write_bytes(b"")
    elif kind == "random_npz":
        (p := d / "random.npz").write_bytes(np.random.default_rng(0).bytes(300))
    elif kind == "truncated_npz":
        np.savez(full := d / "full.npz", t=t, q=q, v=v)
        (p := d / "truncated.npz").write_bytes(full.read_bytes()[:full.stat().st_size // 2])
    elif kind == "no_arrays_npz":
        np.savez(p := d / "none.npz")
    elif kind == "lying_header_npz":  # a header claiming 10^11 rows over 64 bytes
        head = io.BytesIO()
        np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False,
                                                    "shape": (10**11, 13)})
        with zipfile.ZipFile(p := d / "lying.npz", "w") as z:
            for key in ("t", "q", "v"):
                z.writestr(f"{key}.npy", head.getvalue() + bytes(64))
    elif kind == "empty_parquet":
        pq.write_table(pa.table({"t": pa.array([], pa.float64()),
                                 "q": pa.array([], pa.list_(pa.float64())),
                                 "v": pa.array([], pa.list_(pa.float64()))}),
                       p := d / "empty.parquet")
    return p


@pytest.mark.parametrize("kind,needle", [
    ("empty_csv", "empty: no header and no rows"),
    ("header_only_csv", "no rows (a header of 3 columns only)"),
    ("empty_npz", "not a .npz file (not a zip archive"),
    ("random_npz", "not a .npz file (not a zip archive"),
    ("truncated_npz", "not a .npz file (not a zip archive"),
    ("no_arrays_npz", "the archive holds no arrays"),
    ("lying_header_npz", "its header claims shape (100000000000, 13)"),
    ("empty_parquet", "empty.parquet: no rows"),
])
def test_an_empty_or_damaged_file_is_refused_as_such(nominal, tmp_path, kind, needle):
    cols, _ = nominal
    src = _damaged(kind, cols, tmp_path)
    with pytest.raises(SpecError, match=re.escape(needle)):
        import_log(src, _mapping(), "x", tmp_path / "logs")
    assert not (tmp_path / "logs").exists()


def test_a_damaged_file_is_one_line_exit_2_from_the_command(nominal, tmp_path):
    cols, _ = nominal
    r = run_cli_in_process("import", _damaged("truncated_npz", cols, tmp_path), "--robot",
                           "short_nominal", "--out", tmp_path / "logs")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "Traceback" not in r.stderr and "truncated.npz" in r.stderr


def test_a_file_over_the_memory_budget_is_refused_before_it_is_read(nominal, tmp_path,
                                                                      monkeypatch):
    cols, _ = nominal
    from pipeline.importer.readers import parquet_decoded_size

    src = _written(tmp_path, cols["q"], cols["v"], cols["t"])
    data = parquet_decoded_size(pq.ParquetFile(src).metadata)
    assert data >= 8 * 26 * len(cols["t"])  # t, 13 + 12 doubles a row, and list offsets
    # A budget of 5 copies of the data: under the 12 the import needs at its peak.
    monkeypatch.setenv("BREVE_MEMORY_BUDGET_GB", repr(5 * data / 2**30))
    with pytest.raises(SpecError, match=r"importing it needs about 12× that, over the memory "
                                        r"budget .*BREVE_MEMORY_BUDGET_GB"):
        import_log(src, _mapping(), "x", tmp_path / "logs")
    monkeypatch.setenv("BREVE_MEMORY_BUDGET_GB", repr(13 * data / 2**30))
    import_log(src, _mapping(), "x", tmp_path / "logs")


def test_a_parquet_file_is_bounded_by_its_decoded_size_not_its_encoded_one(nominal, tmp_path,
                                                                             monkeypatch):
    """A robot at rest for 20 000 rows: run-length encoding makes the footer's total_byte_size
    a small fraction of the data (10⁷ such rows: 158 MB against 2.1 GB, and an import that grew
    past 12 GB before this bound). A budget between 12× the encoded and 12× the decoded size
    refuses it, before a row is read."""
    from pipeline.importer.readers import parquet_decoded_size

    cols, _ = nominal
    n = 20_000
    q = np.repeat(cols["q"][:1], n, axis=0)
    src = tmp_path / "rest.parquet"
    pq.write_table(pa.table({"t": np.arange(n) * 0.03, "q": list(q), "v": list(np.zeros((n, 12)))}),
                   src)
    meta = pq.ParquetFile(src).metadata
    encoded = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
    decoded = parquet_decoded_size(meta)
    assert decoded > 5 * encoded
    monkeypatch.setenv("BREVE_MEMORY_BUDGET_GB", repr(12 * (encoded + decoded) / 2 / 2**30))
    with pytest.raises(SpecError, match="MiB decoded of data"):
        import_log(src, _mapping(), "rest", tmp_path / "logs")


def test_a_missing_attribute_is_named_with_what_the_object_holds(nominal, tmp_path):
    from types import SimpleNamespace

    cols, _ = nominal
    src = tmp_path / "ns.npz"
    ns = SimpleNamespace(t=cols["t"][:20], x=np.c_[cols["q"][:20], cols["v"][:20]])
    np.savez(src, states=np.array(ns, dtype=object))
    with pytest.raises(SpecError, match=re.escape("no 'q' in key 'states' (it holds attributes "
                                                  "t (shape (20,)), x (shape (20, 25)))")):
        import_log(src, _mapping(allow_pickle=True, q="states.q", v="states.v",
                                 time="states.t"), "x", tmp_path / "logs")


def test_a_log_without_motion_is_undetermined_and_its_record_strict_json(nominal, tmp_path):
    """The robot held at rest for 200 steps: no statistic of shape is a verdict. The lag-1s
    are null (undetermined), the record parses as strict JSON (no NaN token), the summary
    says so, and a claim on the lag-1 does not hold."""
    from pipeline.analysis.summary import imported_lines
    from pipeline.claims.evaluate import compare_values

    cols, _ = nominal
    q = np.tile(cols["q"][0], (200, 1))
    src = _written(tmp_path, q, np.zeros((200, 12)), 0.03 * np.arange(200))
    done = import_log(src, _mapping(), "still", tmp_path / "logs")
    rec = _analyse(done.path, tmp_path / "rep", controller="short_nominal")
    assert rec.dominant.lag1 is None and rec.bus_rate.lag1 is None
    assert rec.dominant.step_energy_share is None
    assert all(d.lag1 is None for d in rec.directions)
    text = (tmp_path / "rep" / "imported" / "still" / "analysis.json").read_text()

    def no_constant(name: str):
        raise AssertionError(f"{name} in analysis.json")

    assert json.loads(text, parse_constant=no_constant)["dominant"]["lag1"] is None
    assert "lag-1 undetermined (no motion)" in imported_lines(rec, Path("x"))[0]
    assert not compare_values("lt", rec.dominant.lag1, -0.5)
    assert not compare_values("gt", rec.dominant.lag1, -0.5)
    assert all(m.agrees is None for m in rec.prediction.modes)
    assert rec.prediction.undetermined == len(rec.prediction.modes) and not rec.prediction.agrees


def test_an_imported_log_whose_import_record_is_damaged_is_refused(nominal, tmp_path):
    cols, _ = nominal
    done = import_log(_written(tmp_path, cols["q"], cols["v"], cols["t"]), _mapping(), "x",
                      tmp_path / "logs")
    table = pq.read_table(done.path)
    md = dict(table.schema.metadata)
    md[b"pipeline.import"] = b"{}"
    pq.write_table(table.replace_schema_metadata(md), done.path)
    with pytest.raises(LogError, match=r"metadata key pipeline\.import: no 'source'"):
        verify_log(done.path)


@pytest.mark.parametrize("edit", ["a velocity", "the time resolution", "the hashes removed"])
def test_an_imported_log_changed_after_the_import_is_refused(nominal, tmp_path, edit):
    """The values and the import record are hashed at the import and checked on every read;
    the same values rewritten in other row groups are the same log."""
    cols, _ = nominal
    done = import_log(_written(tmp_path, cols["q"], cols["v"], cols["t"]), _mapping(), "x",
                      tmp_path / "logs")
    table = pq.read_table(done.path)
    md = dict(table.schema.metadata)
    pq.write_table(table, regrouped := tmp_path / "regrouped.parquet", row_group_size=37)
    verify_log(regrouped)
    if edit == "a velocity":
        v = table.column("v").to_pylist()
        v[5][0] += 1e-9
        table = table.set_column(table.column_names.index("v"), "v",
                                 pa.array(v, table.schema.field("v").type))
        needle = "the columns' values are not the ones the import wrote"
    elif edit == "the time resolution":
        record = json.loads(md[b"pipeline.import"])
        record["time"]["resolution"] = 0.5
        md[b"pipeline.import"] = json.dumps(record, sort_keys=True).encode()
        needle = "the import record is not the one the import wrote"
    else:
        del md[b"pipeline.import_sha256"]
        needle = "an imported log without its own hashes"
    pq.write_table(table.replace_schema_metadata(md), done.path)
    with pytest.raises(LogDamaged, match=re.escape(needle)):
        verify_log(done.path)


# -- ROS 2 bags and MCAP --------------------------------------------------------------------------

def _write_bag(path: Path, cols: dict, storage: str, joint_order: list[int],
               drop_joint_row: int | None = None, reorder_from: int | None = None,
               no_velocity: bool = False, jitter: np.ndarray | None = None,
               imu_tf: bool = False) -> None:
    """A bag of nav_msgs/Odometry (/bus/odom) and sensor_msgs/JointState (/arm/joint_states,
    joints in ``joint_order``), stamped at an epoch time in nanoseconds (each row ``jitter``
    seconds late), written with rosbags. ``imu_tf``: the bus's angular rate on a
    sensor_msgs/Imu topic (/imu) and its pose on /tf (world → bus, among another transform),
    as a ROS 2 robot publishes them, the odometry's pose and angular rate left at zero."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    vec = T["geometry_msgs/msg/Vector3"]
    with Writer(path, version=9, storage_plugin=plugin) as w:
        odom = w.add_connection("/bus/odom", "nav_msgs/msg/Odometry", typestore=ts)
        joints = w.add_connection("/arm/joint_states", "sensor_msgs/msg/JointState",
                                  typestore=ts)
        if imu_tf:
            imu = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
            tf = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        for row, (t, q, v) in enumerate(zip(cols["t"], cols["q"], cols["v"], strict=True)):
            late = 0.0 if jitter is None else float(jitter[row])
            ns = 1_764_000_000 * 10**9 + round((t + late) * 1e9)
            header = T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                frame_id="world")
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](*q[:3]),
                orientation=T["geometry_msgs/msg/Quaternion"](x=q[3], y=q[4], z=q[5], w=q[6]))
            twist = T["geometry_msgs/msg/Twist"](linear=vec(*v[:3]), angular=vec(*v[3:6]))
            if imu_tf:
                quat = T["geometry_msgs/msg/Quaternion"]
                stamped = [T["geometry_msgs/msg/TransformStamped"](
                    header=T["std_msgs/msg/Header"](stamp=header.stamp, frame_id=parent),
                    child_frame_id=child, transform=T["geometry_msgs/msg/Transform"](
                        translation=vec(*xyz), rotation=quat(x=r[0], y=r[1], z=r[2], w=r[3])))
                    for parent, child, xyz, r in (("bus", "camera_mount", (0, 0, 0.3),
                                                   (0, 0, 0, 1)),
                                                  ("world", "bus", q[:3], q[3:7]))]
                w.write(tf, ns, ts.serialize_cdr(T["tf2_msgs/msg/TFMessage"](
                    transforms=stamped), "tf2_msgs/msg/TFMessage"))
                w.write(imu, ns, ts.serialize_cdr(T["sensor_msgs/msg/Imu"](
                    header=T["std_msgs/msg/Header"](stamp=header.stamp, frame_id="bus"),
                    orientation=quat(x=0, y=0, z=0, w=1), orientation_covariance=np.zeros(9),
                    angular_velocity=vec(*v[3:6]), angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=vec(0, 0, 0),
                    linear_acceleration_covariance=np.zeros(9)), "sensor_msgs/msg/Imu"))
                pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](0, 0, 0),
                                                   orientation=quat(x=0, y=0, z=0, w=1))
                twist = T["geometry_msgs/msg/Twist"](linear=vec(*v[:3]), angular=vec(0, 0, 0))
            msg = T["nav_msgs/msg/Odometry"](
                header=header, child_frame_id="bus",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose,
                                                               covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist,
                                                                 covariance=np.zeros(36)))
            order = joint_order if reorder_from is None or row < reorder_from else \
                joint_order[::-1]  # a publisher that changes its order mid-log
            js = T["sensor_msgs/msg/JointState"](
                header=header, name=[JOINTS[i] for i in order],
                position=q[7:][order].copy(),
                velocity=np.zeros(0) if no_velocity else v[6:][order].copy(),
                effort=np.zeros(0))
            w.write(odom, ns, ts.serialize_cdr(msg, "nav_msgs/msg/Odometry"))
            if row != drop_joint_row:
                w.write(joints, ns, ts.serialize_cdr(js, "sensor_msgs/msg/JointState"))


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_ros2_bag_written_here_is_imported_and_analysed(nominal, tmp_path, storage):
    cols, original = nominal
    bag = tmp_path / f"bag_{storage}"
    # Joints by name, not by position, and by each message's own order.
    _write_bag(bag, cols, storage, [3, 0, 5, 1, 4, 2], reorder_from=300)
    topics = {"odometry": "/bus/odom", "joints": "/arm/joint_states"}
    src = bag if storage == "sqlite3" else next(bag.glob("*.mcap"))  # a bare MCAP file too
    done = import_log(src, _mapping(topics=topics), f"bag_{storage}", tmp_path / "logs")
    rec = _analyse(done.path, tmp_path / "rep", controller="short_nominal")
    assert rec.origin.format == ("rosbag" if storage == "sqlite3" else "mcap")
    _same_data_stages(rec, original)
    assert rec.prediction.agrees and rec.prediction.modes[0].measured.rings


def test_a_bag_of_jittered_imu_and_tf_topics_is_analysed_at_its_own_instants(nominal, tmp_path):
    """As a ROS 2 robot publishes (issue 33, item 8): the bus pose on /tf (world → bus, beside
    another transform), its angular rate on /imu, the odometry's pose and angular rate left at
    zero, every row stamped as published, up to 0.1·dt late or early. Read from TF and the IMU
    at its own instants (--max-jitter 0.15), the data stages are the original log's; read from
    the odometry alone, the same bag has a bus at rest and no ripple: the topics named are the
    ones read."""
    cols, original = nominal
    jitter = np.random.default_rng(8).uniform(-0.1, 0.1, len(cols["t"])) * 0.03
    bag = tmp_path / "bag"
    _write_bag(bag, cols, "mcap", list(range(6)), jitter=jitter, imu_tf=True)
    topics = {"odometry": "/bus/odom", "joints": "/arm/joint_states", "imu": "/imu",
              "tf": "/tf", "tf_parent": "world", "tf_child": "bus"}
    with pytest.raises(SpecError, match="uneven time base: jitter"):
        import_log(bag, _mapping(topics=topics), "imu", tmp_path / "logs")
    done = import_log(bag, _mapping(topics=topics, max_jitter=0.15), "imu", tmp_path / "logs")
    time = verify_log(done.path).meta.imported["time"]
    assert time["jitter_bound"] == 0.15 and time["max_deviation"] > 0.05 * 0.03
    _same_data_stages(_analyse(done.path, tmp_path / "rep"), original)
    odometry_only = {"odometry": "/bus/odom", "joints": "/arm/joint_states"}
    odom = import_log(bag, _mapping(topics=odometry_only, max_jitter=0.15), "odom",
                      tmp_path / "logs")
    assert _analyse(odom.path, tmp_path / "rep").bus_rate.alternating_rms == 0.0
    assert original.bus_rate.alternating_rms > 0.1
    with pytest.raises(SpecError, match="tf needs tf_parent and tf_child"):
        _mapping(topics={**odometry_only, "tf": "/tf"})


def test_bag_topics_stamped_apart_are_refused(nominal, tmp_path):
    cols, _ = nominal
    bag = tmp_path / "bag"
    _write_bag(bag, {k: v[:50] for k, v in cols.items()}, "sqlite3", list(range(6)))
    with pytest.raises(SpecError, match="field topics: no topic '/nope'"):
        import_log(bag, _mapping(topics={"odometry": "/nope", "joints": "/arm/joint_states"}),
                   "b", tmp_path / "logs")
    with pytest.raises(SpecError, match="/arm/joint_states holds sensor_msgs/msg/JointState, "
                                        "not nav_msgs/msg/Odometry"):
        import_log(bag, _mapping(topics={"odometry": "/arm/joint_states",
                                         "joints": "/bus/odom"}), "b", tmp_path / "logs")
    apart = tmp_path / "apart"
    _write_bag(apart, {k: v[:50] for k, v in cols.items()}, "sqlite3", list(range(6)),
               drop_joint_row=20)
    topics = {"odometry": "/bus/odom", "joints": "/arm/joint_states"}
    with pytest.raises(SpecError, match=r"not stamped at the same instants \(50 and 49 "
                                        r"messages; first unmatched stamp \d+ ns\)"):
        import_log(apart, _mapping(topics=topics), "b", tmp_path / "logs")
    rates = tmp_path / "no_rates"
    _write_bag(rates, {k: v[:50] for k, v in cols.items()}, "sqlite3", list(range(6)),
               no_velocity=True)
    with pytest.raises(SpecError, match="has 6 names, 6 positions and 0 velocities"):
        import_log(rates, _mapping(topics=topics), "b", tmp_path / "logs")


# -- the analysis of an imported log --------------------------------------------------------------

def test_the_controller_is_declared_for_imported_logs_only_and_at_their_step(
        nominal, short_logs, tmp_path):
    cols, _ = nominal
    src = _written(tmp_path, cols["q"], cols["v"], cols["t"])
    done = import_log(src, _mapping(), "x", tmp_path / "logs")
    with pytest.raises(SpecError, match=r"field mission\.dt: 0\.01 s is not the log's step"):
        _analyse(done.path, tmp_path / "rep", controller="short_omega_ripple_dt010")
    with pytest.raises(SpecError, match=r"field robot: the spec's robot .* is not the log's"):
        _analyse(done.path, tmp_path / "rep", controller="short_servicer_nominal")
    store = ArtefactStore(tmp_path / "logs", tmp_path / "rep")
    own = store.open_log(short_logs["short_nominal"])
    with pytest.raises(SpecError, match="is a simulated log, its controller is its spec's"):
        store.analysis(own, controller=load_spec("short_nominal"), quiet=True)
    imported = store.open_log(done.path)
    with pytest.raises(LogError, match="an imported log is analysed alone"):
        store.analysis(imported, own, quiet=True)
    with pytest.raises(LogError, match="data stages are analyze_imported's"):
        analyze_log(imported)
    # The record is reused for the same controller only.
    first = store.analysis(imported, quiet=True, controller=load_spec("short_nominal"))
    assert not first.reused and first.path.parent.parent.name == "imported"
    assert store.analysis(imported, quiet=True, controller=load_spec("short_nominal")).reused
    bare = store.analysis(imported, quiet=True)
    assert not bare.reused and bare.record.damping is None


def test_the_import_and_analyze_commands(nominal, tmp_path):
    cols, _ = nominal
    src = _precursor_npz(tmp_path / "states_ur3_1.npz", cols)
    args = ["import", src, "--robot", "short_nominal", "--q", "states.x[:, 0:13]", "--v",
            "states.x[:, 13:25]", "--time", "states.t", "--out", tmp_path / "logs"]
    r = run_cli_in_process(*args)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--allow-pickle" in r.stderr
    r = run_cli_in_process(*args, "--allow-pickle")
    assert r.returncode == 0, r.stderr
    assert "q and v agree" in r.stdout
    log = tmp_path / "logs" / "imported" / "states_ur3_1" / "run.parquet"
    r = run_cli_in_process("analyze", log, "--out", tmp_path / "rep")
    assert r.returncode == 0, r.stderr
    assert "imported npz" in r.stdout and "not run: 4 damping modes" in r.stdout
    rec = json.loads((tmp_path / "rep" / "imported" / "states_ur3_1" /
                      "analysis.json").read_text())
    assert rec["origin"]["format"] == "npz" and rec["damping"] is None
    r = run_cli_in_process("import", src, "--allow-pickle", "--q", "states.x[:, 0:13]", "--v",
                "states.x[:, 13:25]", "--time", "states.t", "--out", tmp_path / "logs")
    assert r.returncode == 2 and "field robot" in r.stderr
    # A log without stamps: --time none and its step.
    bare = tmp_path / "bare.parquet"
    pq.write_table(pa.table({"q": list(cols["q"]), "v": list(cols["v"])}), bare)
    r = run_cli_in_process("import", bare, "--robot", "short_nominal", "--time", "none",
                           "--dt", "0.03", "--out", tmp_path / "logs")
    assert r.returncode == 0, r.stderr


def test_conventions_list_the_alternatives_a_check_can_tell_apart():
    c = Conventions()
    assert len(c.alternatives(0.0)) == 3 and len(c.alternatives(0.01)) == 7
    assert c.differences(Conventions(quaternion="wxyz", velocity_frame="world")) == (
        "the quaternion order and the velocity frame", "--quaternion wxyz --velocity-frame world")


# -- claims and reports by name ---------------------------------------------------------------

@pytest.mark.slow
def test_claims_and_reports_accept_an_imported_log_by_name(nominal, tmp_path):
    cols, _ = nominal
    src = _written(tmp_path, cols["q"], cols["v"], cols["t"])
    logs, out = tmp_path / "logs", tmp_path / "rep"
    import_log(src, _mapping(), "flight", logs)
    register = {"logs": str(logs),
                "runs": {"flight": {"imported": "flight", "controller": "short_nominal"}},
                "claims": [{"id": "I1", "statement": "The imported log rings at period 2, as "
                            "its declared controller predicts.", "expect": "hold",
                            "checks": [{"metric": "flight:dominant.lag1", "op": "lt",
                                        "threshold": -0.5},
                                       {"metric": "flight:prediction.agrees", "op": "eq",
                                        "threshold": True}]}]}
    path = tmp_path / "claims.yaml"
    path.write_text(json.dumps(register))  # YAML 1.2 reads JSON
    r = run_cli_in_process("claims", "--claims", path, "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    data = json.loads((out / "claims.json").read_text())
    assert data["claims"][0]["status"] == "PASS"
    assert data["claims"][0]["provenance"][0]["origin"].startswith("imported parquet")
    assert "**imported parquet" in (out / "CLAIMS.md").read_text()
    r = run_cli_in_process("report", "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    index = (out / "index.html").read_text()
    assert "Imported logs" in index and "imported parquet" in index
    page = (out / "imported" / "flight" / "imported.md").read_text()
    assert "**Origin: imported** from" in page and "| 4 the discrete map Φ (eq. 22) | no |" in page
    assert "log is gone" not in page
    # The robot and the declared controller, on the page and in the index (issue 33, item 7).
    meta = verify_log(logs / "imported" / "flight" / "run.parquet").meta
    assert f"Robot: `{meta.robot_file}` (SHA-256 `{meta.robot_hash[:12]}…`" in page
    assert "Declared controller: short_nominal (spec hash" in page
    assert f"<code>{meta.robot_file}</code> ({meta.robot_hash[:8]}…)" in index
    # The log deleted: the report is not "up to date"; the page and the index flag it.
    (logs / "imported" / "flight" / "run.parquet").unlink()
    r = run_cli_in_process("report", "--out", out, timeout=600)
    assert r.returncode == 0 and "up to date" not in r.stderr, r.stderr
    page = (out / "imported" / "flight" / "imported.md").read_text()
    assert "**Its log is gone, damaged or not the one analysed**" in page
    assert "(its log is gone or changed)" in (out / "index.html").read_text()
    # A spec or log path of an imported run is refused when the register is loaded.
    register["claims"][0]["checks"][0]["metric"] = "flight:spec.mission.dt"
    path.write_text(json.dumps(register))
    r = run_cli_in_process("claims", "--claims", path, "--out", out)
    assert r.returncode == 2 and "flight is an imported log" in r.stderr
    register["runs"]["flight"]["against"] = "flight"
    path.write_text(json.dumps(register))
    r = run_cli_in_process("claims", "--claims", path, "--out", out)
    assert r.returncode == 2 and "an imported log is analysed alone" in r.stderr


def test_the_docs_example_register_runs_as_written(nominal, tmp_path):
    """docs/importing.md's register, taken from the page as it is, evaluated on a log imported
    under the name it uses (issue 36, item 8: it was refused as written, no ``expect:``)."""
    cols, _ = nominal
    page = (PROJECT_ROOT / "docs" / "importing.md").read_text()
    section = page[page.index("## In the claims and the reports"):]
    block = re.search(r"```yaml\n(.*?)```", section, re.S).group(1)
    (tmp_path / "claims.yaml").write_text(block)
    import_log(_written(tmp_path, cols["q"], cols["v"], cols["t"]), _mapping(), "flight",
               tmp_path / "logs")
    r = run_cli_in_process("claims", "--claims", "claims.yaml", cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr
    assert re.search(r"F1 PASS", r.stdout), r.stdout


def test_exact_stamps_keep_their_own_resolution_and_rounded_ones_theirs(nominal, tmp_path):
    """Integer epoch nanoseconds are exact: 0.3 ms of jitter is refused, not absorbed by an
    accumulation allowance; a 60 Hz log printed to 10 ms (%.2f) is even, its short and long
    steps the rounding's."""
    cols, _ = nominal
    ns = 1_764_000_000 * 10**9 + np.round(cols["t"] * 1e9).astype(np.int64)
    ns[500] += 300_000
    src = tmp_path / "epoch.parquet"
    pq.write_table(pa.table({"t": ns, "q": list(cols["q"]), "v": list(cols["v"])}), src)
    with pytest.raises(SpecError, match=r"row 500 is \+0\.0003 s off"):
        import_log(src, _mapping(time_unit="ns"), "epoch", tmp_path / "logs")
    t = np.arange(len(cols["t"])) / 60.0
    q_names, v_names = [f"q{i}" for i in range(13)], [f"v{i}" for i in range(12)]
    from pipeline.importer.readers import printed_resolution
    from pipeline.importer.timebase import even_time_base

    text = np.array([f"{x:.2f}" for x in t])
    tb = even_time_base(np.array([float(s) for s in text]), printed_resolution(text), "60 Hz")
    assert tb.dt == pytest.approx(1 / 60, rel=1e-4) and q_names and v_names


def test_a_run_of_a_register_that_extends_another_merges_into_it(tmp_path):
    """JSON Merge Patch (RFC 7386, issue 51): a child's run merges key by key into the
    parent's; null deletes an inherited key."""
    from pipeline.claims.register import load_claims

    claim = {"id": "X1", "statement": "s", "expect": "hold",
             "checks": [{"metric": "flight:dominant.lag1", "op": "lt", "threshold": 0}]}
    parent = {"runs": {"flight": {"imported": "a", "controller": "short_nominal"}},
              "claims": [claim]}
    (tmp_path / "parent.yaml").write_text(json.dumps(parent))
    (tmp_path / "child.yaml").write_text(json.dumps(
        {"extends": "parent.yaml", "runs": {"flight": {"imported": "b"}}}))
    cf = load_claims(tmp_path / "child.yaml")
    assert cf.runs["flight"].imported == "b"
    assert cf.runs["flight"].controller == "short_nominal"  # inherited
    (tmp_path / "bare.yaml").write_text(json.dumps(
        {"extends": "parent.yaml", "runs": {"flight": {"imported": "b", "controller": None}}}))
    cf = load_claims(tmp_path / "bare.yaml")
    assert cf.runs["flight"].imported == "b" and cf.runs["flight"].controller is None


# -- what the robot file and the numbers allow (issue 36, item 7) -----------------------------

def test_one_joint_in_degrees_in_q_and_v_is_refused_naming_the_joint_and_unit(nominal,
                                                                               tmp_path):
    """The elbow logged in degrees in both q and v: still one motion (eq. 33 cannot tell),
    but −98.8 "rad" is far outside the file's [−2.44, 2.09]: refused, naming the unit."""
    cols, _ = nominal
    q, v = cols["q"].copy(), cols["v"].copy()
    q[:, 9], v[:, 8] = np.rad2deg(q[:, 9]), np.rad2deg(v[:, 8])  # elbow_joint
    with pytest.raises(SpecError, match=r"q: joint elbow_joint is -?\d+\.?\d* rad on row 0, "
                                        r"outside the robot file's limits \[-2\.44, 2\.09\] "
                                        r"rad by more than 1 rad \(degrees declared as radians"):
        import_log(_written(tmp_path, q, v, cols["t"]), _mapping(), "deg1", tmp_path / "logs")
    assert not (tmp_path / "logs" / "imported" / "deg1").exists()


@pytest.mark.parametrize("kind,needle", [
    ("complex", "q (q): complex numbers (complex128)"),
    ("bool", "v (v): booleans, not numbers"),
    ("strings", "q (q): not numbers"),
    ("complex_t", "time (t): complex numbers"),
])
def test_complex_boolean_or_text_arrays_are_refused(nominal, tmp_path, kind, needle):
    cols, _ = nominal
    arrays = {"t": cols["t"], "q": cols["q"], "v": cols["v"]}
    if kind == "complex":
        arrays["q"] = cols["q"] + 1e-3j
    elif kind == "bool":
        arrays["v"] = cols["v"] > 0
    elif kind == "strings":
        arrays["q"] = cols["q"].astype(str)
    else:
        arrays["t"] = cols["t"] + 0j
    src = tmp_path / f"{kind}.npz"
    np.savez(src, **arrays)
    with pytest.raises(SpecError, match=re.escape(needle)):
        import_log(src, _mapping(), "x", tmp_path / "logs")


@pytest.mark.parametrize("dtype,start", [("uint64", 2**63 + 12_345), ("uint64", 2**63 - 10**10),
                                         ("uint64", 2**64 - 10**12),
                                         ("int64", -(10**18)), ("uint32", 7), ("int16", -3)])
def test_integer_stamps_of_any_width_are_read_exactly(nominal, tmp_path, dtype, start):
    """Integer stamps from their type's top to its bottom: the step, the rows and the data
    stages are those of the same log stamped in seconds (a uint64 at or above 2⁶³ used to wrap
    to a negative time)."""
    cols, original = nominal
    n = len(cols["t"])
    tick = {"uint64": 30_000_000, "int64": 30_000_000, "uint32": 30, "int16": 30}[dtype]
    unit = {"uint64": "ns", "int64": "ns", "uint32": "ms", "int16": "ms"}[dtype]
    if dtype == "int16":
        n = 300  # int16 holds −3 + 299·30 = 8967
    stamps = np.array([start + k * tick for k in range(n)], dtype=object).astype(dtype)
    assert int(stamps[-1]) - int(stamps[0]) == (n - 1) * tick  # no wrap in the fixture
    src = tmp_path / "ints.parquet"
    pq.write_table(pa.table({"t": pa.array(stamps), "q": list(cols["q"][:n]),
                             "v": list(cols["v"][:n])}), src)
    done = import_log(src, _mapping(time_unit=unit), "ints", tmp_path / "logs")
    assert done.rows == n and done.time.dt == pytest.approx(0.03, rel=1e-9)
    if n == len(cols["t"]):
        _same_data_stages(_analyse(done.path, tmp_path / "rep"), original)


# -- messages (issue 36, item 8) --------------------------------------------------------------

def test_a_scale_error_below_four_digits_is_printed_with_the_digits_that_show_it(nominal,
                                                                                 tmp_path):
    """Joint rates 1.00001 times too large: refused, and the message says 1.00001 and
    0.99999, not "1 times … sum to 1, not 1"."""
    cols, _ = nominal
    v = cols["v"].copy()
    v[:, 6:] *= 1.00001
    with pytest.raises(SpecError, match=r"the joint rates: 1\.00001 times what q's motion says "
                                        r"\(the weights in the step sum to 0\.99999, not 1, by "
                                        r"1e-05 where the fit explains"):
        import_log(_written(tmp_path, cols["q"], v, cols["t"]), _mapping(), "s",
                   tmp_path / "logs")


@pytest.mark.parametrize("dt,needle", [
    (1e-9, "GiB, over the memory budget"),  # 3e10 rows: 223 GiB were allocated before
    (1e3, "--resample 1000: the log's 29.97 s give 1 row(s) at that step; an analysis needs "
          "at least 3"),
])
def test_resampling_to_an_extreme_step_is_refused_before_anything_is_allocated(nominal, tmp_path,
                                                                               dt, needle):
    cols, _ = nominal
    keep = np.r_[0:200, 201:len(cols["t"])]
    src = _written(tmp_path, cols["q"][keep], cols["v"][keep], cols["t"][keep])
    with pytest.raises(SpecError, match=re.escape(needle)):
        import_log(src, _mapping(), "r", tmp_path / "logs", resample_dt=dt)
    assert not (tmp_path / "logs" / "imported" / "r").exists()


def test_a_bad_robot_is_refused_before_the_log_is_read_in_one_line(tmp_path):
    """The robot is checked first (issue 33, item 6): a source that is not even there is not
    what the refusal names; and the URDF parser's own complaint (written by C++ to the
    process's stderr) is inside that one line, not around it."""
    (tmp_path / "broken.urdf").write_text('<robot name="x"><link name="a"/>\n')
    (tmp_path / "bad.yaml").write_text("extends: short_nominal\nrobot: {file: broken.urdf}\n")
    r = run_cli_in_process("import", tmp_path / "missing.parquet", "--robot", tmp_path / "bad.yaml",
                "--out", tmp_path / "logs")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "broken.urdf: not a loadable robot file" in r.stderr
    assert "the parser said: Error: Error=XML_ERROR_PARSING" in r.stderr
    assert not (tmp_path / "logs").exists()


# -- telemetry stamped as published (issue 33, item 8) -----------------------------------------

def test_jittered_stamps_are_analysed_at_their_own_instants_within_a_stated_bound(nominal,
                                                                                  tmp_path):
    """The seed's own log with its stamps jittered by up to 0.1·dt (uniform, seeded), as a
    telemetry stamps rows when it publishes them: refused as uneven by default (naming
    --max-jitter), accepted with --max-jitter 0.15, the bound and the measured deviation
    recorded, and every data-stage number that of the unjittered log (the rows are the same
    samples; nothing was resampled). Resampling the same log instead changes the ripple."""
    cols, original = nominal
    rng = np.random.default_rng(33)
    dt = 0.03
    t = cols["t"] + rng.uniform(-0.1, 0.1, len(cols["t"])) * dt
    src = _written(tmp_path, cols["q"], cols["v"], t)
    with pytest.raises(SpecError, match=r"uneven time base: jitter: .*--max-jitter FRACTION"):
        import_log(src, _mapping(), "j", tmp_path / "logs")
    with pytest.raises(SpecError, match=r"uneven time base: jitter: .*jitter allowed \(0\.05"):
        import_log(src, _mapping(max_jitter=0.05), "j", tmp_path / "logs")
    done = import_log(src, _mapping(max_jitter=0.15), "j", tmp_path / "logs")
    time = verify_log(done.path).meta.imported["time"]
    assert time["jitter_bound"] == 0.15 and 0.05 * dt < time["max_deviation"] <= 0.2 * dt
    assert time["resampled_from"] is None
    _same_data_stages(_analyse(done.path, tmp_path / "rep"), original)
    resampled = import_log(src, _mapping(), "r", tmp_path / "logs", resample_dt=dt)
    rec = _analyse(resampled.path, tmp_path / "rep")
    assert rec.bus_rate.alternating_rms < 0.99 * original.bus_rate.alternating_rms
    with pytest.raises(SpecError, match="max_jitter"):
        _mapping(max_jitter=0.25)


def test_the_jitter_bound_holds_a_row_against_the_jittered_end_stamps():
    """Row 1 published J·dt late, t_0 J·dt early: it lies 2·J·dt (less the end stamps' line's
    share) off t_0 + k·dt, within a jitter of J, not of 0.9·J (a bound of J alone would refuse
    stamps each within J of their instant)."""
    from pipeline.importer.timebase import even_time_base

    dt, J, n = 0.03, 0.1, 1000
    t = np.arange(n) * dt
    t[0] -= J * dt
    t[1] += J * dt
    tb = even_time_base(t, 0.0, "x", jitter=J)
    assert tb.max_deviation == pytest.approx(2 * J * dt, rel=2e-3) and tb.jitter_bound == J
    with pytest.raises(SpecError, match="jitter allowed"):
        even_time_base(t, 0.0, "x", jitter=0.9 * J)


def test_a_jitter_bound_above_a_sixth_accepts_every_step_within_it():
    """Issue 49: with J between 1/6 and 1/4 a genuine step can be as short as (1 − 2J)·dt,
    below the dt/1.5 a row too many is judged by: such stamps (row 5 J·dt late, row 6 J·dt
    early: a step of (1 − 2J)·dt) are within the bound and must be taken; a row too many (a
    step of half a dt) is still refused."""
    from pipeline.importer.timebase import even_time_base

    dt, J = 0.03, 0.2
    t = np.arange(40) * dt
    t[5] += J * dt * 0.999
    t[6] -= J * dt * 0.999
    tb = even_time_base(t, 0.0, "jittered", J)
    assert tb.max_deviation <= 2 * J * dt
    extra = np.sort(np.append(np.arange(40) * dt, 10.5 * dt))
    with pytest.raises(SpecError, match="uneven time base"):
        even_time_base(extra, 0.0, "extra", J)


def test_a_log_imported_with_jitter_is_analysed_with_its_controller(nominal, tmp_path):
    """The step the import draws from jittered end stamps is known to 2(J·dt + r)/(N − 1),
    not exactly: the controller's nominal step is this log's step within that."""
    cols, _ = nominal
    rng = np.random.default_rng(49)
    dt = 0.03
    t = cols["t"] + rng.uniform(-0.1, 0.1, len(cols["t"])) * dt
    src = _written(tmp_path, cols["q"], cols["v"], t)
    done = import_log(src, _mapping(max_jitter=0.15), "jc", tmp_path / "logs")
    assert verify_log(done.path).spec.mission.dt != dt  # drawn from the end stamps
    rec = _analyse(done.path, tmp_path / "rep", controller="short_nominal")
    assert rec.damping is not None
