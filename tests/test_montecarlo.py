"""The Monte Carlo of missions (eqs. 38, 39): the dispersions' distributions against SciPy's,
a dispersed inertia always a rigid body's, every sample drawn again alone bit for bit, the
robot's inertial parameters and the bus's initial rate in a spec, and the command end to end:
its records kept and reused, its verdict's bound SciPy's beta quantile, a sample re-run alone
to the same bits, bad input refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import scipy.stats

from pipeline.errors import LogError, SpecError
from pipeline.montecarlo.dispersions import Dispersion, draw_inertia, draw_value
from pipeline.montecarlo.plan import draw_one, plan_montecarlo
from pipeline.montecarlo.verdict import read_table, read_verdict
from pipeline.sim.inertial import inertia_matrix, physical_problem
from pipeline.sim.robot_file import load_spec_robot
from pipeline.spec import load_spec, with_overrides
from tests.conftest import run_cli

# A short flight loop: 1 s of the seed robot's sampled-data plant at dt 3.5 ms (286 steps).
SMALL = """\
description: test Monte Carlo
mission: omega_ripple_sampled_delay_dt0035
set: {{mission.duration: 1.0}}
seed: 7
target: {{p: 0.9, confidence: 0.5}}
ripple_max: 1.0e-4
dispersions:
  body.bus.inertia: {{dist: uniform, rel: [0.0, 0.0, 0.2]}}
  controller.gains.bus.D: {{dist: uniform, {spread}}}
  mission.plant.delay_steps: {{dist: choice, values: [0, 1]}}
"""


def _write(tmp_path: Path, text: str, name: str = "mc") -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return path


def _rng(i: int = 0) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([99, i]))


def test_uniform_relative_draws_are_scipys_uniform():
    d = Dispersion(dist="uniform", rel=0.2)
    rng = _rng()
    x = np.array([draw_value(d, 2.5, rng, "k") for _ in range(4000)])
    assert x.min() >= 2.0 and x.max() <= 3.0
    assert scipy.stats.kstest(x, scipy.stats.uniform(loc=2.0, scale=1.0).cdf).pvalue > 1e-3


def test_truncated_normal_draws_are_scipys_truncnorm():
    d = Dispersion(dist="normal", sd=0.5, truncate=1.5)
    rng = _rng(1)
    x = np.array([draw_value(d, 1.0, rng, "k") for _ in range(4000)])
    assert np.all(np.abs(x - 1.0) <= 0.75)
    ref = scipy.stats.truncnorm(-1.5, 1.5, loc=1.0, scale=0.5)
    assert scipy.stats.kstest(x, ref.cdf).pvalue > 1e-3
    # and not the untruncated normal: the test can fail
    assert scipy.stats.kstest(x, scipy.stats.norm(loc=1.0, scale=0.5).cdf).pvalue < 1e-6


def test_vector_draws_per_component():
    d = Dispersion(dist="normal", sd=[0.0, 0.0, 0.01])
    v = draw_value(d, [0.0, 0.0, 0.0], _rng(2), "mission.initial_omega_b")
    assert v[0] == 0.0 and v[1] == 0.0 and v[2] != 0.0


@pytest.mark.parametrize("bad", [
    {"dist": "uniform", "sd": 0.1}, {"dist": "normal", "half_width": 0.1},
    {"dist": "uniform", "low": 2.0, "high": 1.0}, {"dist": "choice", "values": []},
    {"dist": "uniform"}, {"dist": "uniform", "rel": 0.1, "half_width": 0.1},
    {"dist": "uniform", "rel": 0.1, "truncate": 2.0}])
def test_bad_dispersions_are_refused(bad):
    with pytest.raises(ValueError):
        Dispersion(**bad)


def test_physical_inertia():
    assert physical_problem(np.diag([1.0, 2.0, 3.0])) is None
    assert physical_problem(np.diag([1.0, 1.0, 2.0])) is None  # a flat plate: equality
    assert "triangle" in physical_problem(np.diag([1.0, 1.0, 2.1]))
    assert "positive definite" in physical_problem(np.diag([1.0, -1.0, 1.0]))


def test_dispersed_inertia_is_always_a_rigid_bodys():
    """Wide factors and turned axes on a flat body (moments 1, 1, 1.9): many draws break the
    triangle inequality and are redrawn; every one kept is physical by an independent test
    (the eigenvalues of Σ = ½ tr(I)·1 − I non-negative), and keeps the factors' moments."""
    d = Dispersion(dist="uniform", rel=0.3, axes_deg=20.0)
    nominal = [1.0, 1.0, 1.9, 0.0, 0.0, 0.0]
    rng = _rng(3)
    redraws = 0
    for _ in range(300):
        got = draw_inertia(d, nominal, rng, "body.bus.inertia")
        I = inertia_matrix(got.inertia)
        sigma = 0.5 * np.trace(I) * np.eye(3) - I
        assert np.linalg.eigvalsh(sigma).min() >= -1e-12
        assert np.linalg.eigvalsh(I).min() > 0
        expected = np.sort(np.array([1.0, 1.0, 1.9]) * got.factors)
        assert np.allclose(np.linalg.eigvalsh(I), expected, rtol=1e-12, atol=0)
        redraws += got.redraws
    assert redraws > 0  # the physical limit was met, not missed


def test_principal_moment_of_a_diagonal_tensor_is_dispersed_alone():
    d = Dispersion(dist="uniform", rel=[0.0, 0.0, 0.2])
    got = draw_inertia(d, [0.3, 0.4, 0.5, 0.0, 0.0, 0.0], _rng(4), "body.bus.inertia")
    assert got.inertia[:2] == [0.3, 0.4] and got.inertia[3:] == [0.0, 0.0, 0.0]
    assert 0.4 <= got.inertia[2] <= 0.6


def test_inertial_override_reaches_the_model():
    base = load_spec("nominal")
    spec = with_overrides(base, {"robot.inertial": {"bus": {
        "mass": 9.0, "com": [0.0, 0.01, 0.02], "inertia": [0.02, 0.03, 0.04, 0.001, 0.0, 0.0]}}})
    model = load_spec_robot(spec)
    assert model.inertias[1].mass == 9.0
    assert np.array_equal(model.inertias[1].lever, [0.0, 0.01, 0.02])
    assert np.array_equal(model.inertias[1].inertia,
                          inertia_matrix([0.02, 0.03, 0.04, 0.001, 0.0, 0.0]))
    assert spec.spec_hash != base.spec_hash
    # the payload is the body the camera frame is on
    spec = with_overrides(base, {"robot.inertial": {"payload": {
        "mass": 1.5, "com": [0.0, 0.0, 0.0], "inertia": [0.01, 0.01, 0.01, 0.0, 0.0, 0.0]}}})
    model = load_spec_robot(spec)
    frame = next(f for f in model.frames if f.name == "camera")
    assert model.inertias[frame.parentJoint].mass == 1.5


def test_unphysical_inertial_override_is_refused_naming_the_field():
    spec = with_overrides(load_spec("nominal"), {"robot.inertial": {"bus": {
        "mass": 9.0, "com": [0.0, 0.0, 0.0], "inertia": [0.01, 0.01, 0.05, 0.0, 0.0, 0.0]}}})
    with pytest.raises(SpecError, match=r"robot\.inertial\.bus\.inertia: .*triangle"):
        load_spec_robot(spec)
    with pytest.raises(SpecError, match="unknown body 'arm'"):
        with_overrides(load_spec("nominal"), {"robot.inertial": {"arm": {
            "mass": 1.0, "com": [0.0, 0.0, 0.0], "inertia": [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]}}})


def test_unset_fields_leave_every_shipped_hash():
    spec = load_spec("nominal")
    assert "inertial" not in json.dumps(spec.content()) or spec.robot.inertial == {}
    explicit = with_overrides(spec, {"robot.inertial": {},
                                     "mission.initial_omega_b": [0.0, 0.0, 0.0]})
    assert explicit.spec_hash == spec.spec_hash


def test_initial_bus_rate_is_the_first_rows():
    from pipeline.sim.mission import Mission

    spec = with_overrides(load_spec("short_nominal"), {
        "mission.initial_omega_b": [0.0, 0.0, 0.02], "mission.duration": 0.09})
    cols = Mission(spec).run().columns
    assert np.array_equal(cols["v_breve"][0, :3], [0.0, 0.0, 0.02])
    # ω_b in the bus frame is v's angular block (eq. 13's ν: ω_b is its own coordinate)
    assert np.allclose(cols["v"][0, 3:6], [0.0, 0.0, 0.02], rtol=0, atol=1e-15)


def test_a_sample_is_drawn_again_alone(tmp_path):
    path = _write(tmp_path, SMALL.format(spread="rel: 0.1"))
    mc = plan_montecarlo(path, samples=5)
    for i in (0, 3):
        _, alone = draw_one(path, i)
        assert alone.draws == mc.samples[i].draws
        assert alone.spec.spec_hash == mc.samples[i].spec.spec_hash
    assert len({s.spec.spec_hash for s in mc.samples}) == 5
    delays = {s.spec.mission.plant.delay_steps for s in plan_montecarlo(path, 40).samples}
    assert delays == {0, 1}


@pytest.mark.parametrize("text, field", [
    (SMALL.format(spread="rel: 0.1").replace("ripple_max: 1.0e-4\n", ""), "ripple_max"),
    (SMALL.format(spread="rel: 0.1") + "  controller.gains.nope.D: {dist: uniform, rel: 0.1}\n",
     "dispersions.controller.gains.nope.D"),
    (SMALL.format(spread="rel: 0.1") + "  body.arm.mass: {dist: uniform, rel: 0.1}\n",
     "dispersions.body.arm"),
    (SMALL.format(spread="rel: 0.1") + "  controller.integrator: {dist: uniform, rel: 0.1}\n",
     "dispersions.controller.integrator"),
    (SMALL.format(spread="rel: 0.1").replace("values: [0, 1]", "values: [0.5]"), "sample 0"),
    (SMALL.format(spread="rel: 0.1").replace("dist: choice", "dist: chance"),
     "dispersions.mission.plant.delay_steps.dist")])
def test_bad_files_are_refused_in_one_line(tmp_path, text, field):
    path = _write(tmp_path, text)
    r = run_cli("montecarlo", path, "--samples", "2", "--logs", tmp_path / "l",
                "--out", tmp_path / "o")
    assert r.returncode == 2, r.stderr
    assert field in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "o").exists() and not (tmp_path / "l").exists()


@pytest.mark.slow
def test_montecarlo_end_to_end(tmp_path):
    """Eight samples on the embedded Dask cluster: the bus damping from 1 to 5 N·m·s/rad puts
    the bus yaw's gain margin below 6 dB above 2.2 with one step of delay (4.5 without). The
    table, the verdict and its bound (SciPy's beta quantile, computed here); the records
    reused by a second run; a sample re-run alone to the same bits, and a kept record altered
    caught."""
    path = _write(tmp_path, SMALL.format(spread="low: 1.0, high: 5.0"))
    args = ("--samples", "8", "--logs", tmp_path / "l", "--out", tmp_path / "o")
    r = run_cli("montecarlo", path, *args, timeout=300)
    assert r.returncode == 0, r.stderr
    table = read_table(tmp_path / "o" / "mc" / "montecarlo.parquet")
    v = read_verdict(tmp_path / "o" / "mc" / "verdict.json")
    assert len(table) == 8 and table["ran"].all()
    k = int(table["passes"].sum())
    assert 0 < k < 8, table[["gain_margin_db", "fails"]]
    assert v.passes == k and v.samples == 8
    assert v.lower_bound == pytest.approx(scipy.stats.beta.ppf(0.5, k, 8 - k + 1), rel=1e-12)
    assert v.shown is (v.lower_bound >= 0.9)
    failing = table[~table["passes"]]
    assert (failing["gain_margin_db"] < 6.0).all() or failing["fails"].str.contains("ripple").any()
    assert v.worst[0].passes is False and "controller.gains.bus.D" in v.worst[0].draws
    assert "NOT shown" in r.stdout or "shown" in r.stdout

    again = run_cli("montecarlo", path, *args, timeout=300)
    assert again.returncode == 0, again.stderr
    assert not read_table(tmp_path / "o" / "mc" / "montecarlo.parquet")["ran"].any()

    worst = v.worst[0].index
    alone = run_cli("montecarlo", path, "--sample", str(worst), "--logs", tmp_path / "l")
    assert alone.returncode == 0, alone.stderr
    assert "the same bits" in alone.stdout
    assert (tmp_path / "l" / "mc" / f"mc__{worst:05d}" / "run.parquet").is_file()

    kept = tmp_path / "l" / "mc" / f"mc__{worst:05d}.json"
    data = json.loads(kept.read_text())
    data["record"]["log_digest"] = "0" * 64
    kept.write_text(json.dumps(data))
    altered = run_cli("montecarlo", path, "--sample", str(worst), "--logs", tmp_path / "l")
    assert altered.returncode == 1 and "altered or damaged" in altered.stderr
    assert len(altered.stderr.strip().splitlines()) == 1

    # A failing record turned passing, its seal left as it was: not counted; the sample runs
    # again and its record is the judgement's again.
    data = json.loads(kept.read_text())
    data["record"]["passes"], data["record"]["fails"] = True, []
    kept.write_text(json.dumps(data))
    rerun = run_cli("montecarlo", path, *args, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    table = read_table(tmp_path / "o" / "mc" / "montecarlo.parquet")
    assert table["ran"].sum() == 1 and bool(table.loc[table["index"] == worst, "ran"].iloc[0])
    assert read_verdict(tmp_path / "o" / "mc" / "verdict.json").passes == k

    # A verdict edited after it was written is refused by its readers, naming the file.
    verdict = tmp_path / "o" / "mc" / "verdict.json"
    edited = json.loads(verdict.read_text())
    edited["shown"] = True
    verdict.write_text(json.dumps(edited))
    with pytest.raises(LogError, match=r"verdict\.json.*altered or damaged"):
        read_verdict(verdict)


def test_the_seed_montecarlo_file_is_valid():
    mc = plan_montecarlo("seed_dispersions", samples=3)
    assert mc.base.name == "omega_ripple_sampled_delay_dt0035"
    assert plan_montecarlo.__doc__
    full_n = __import__("pipeline.analysis.confidence", fromlist=["x"]).samples_needed(0.9973, 0.9)
    assert full_n == 852
    assert pin  # the dispersed body is Pinocchio's (imported for the fixture's robots)


def test_a_study_and_a_run_of_the_same_loop_share_its_key():
    """loop_key: C41's study (seed_dispersions: the dt 3.5 ms mission for 10 s) flies the
    dt 3.5 ms run's loop; C44's (dt 2.5 ms, the command's arrival dispersed about none) flies
    that mission's loop at 2.5 ms, not at 3.5 ms; and a change of gain, step, integrator, delay
    or arrival is another loop, while the mission's length and the jitter stream's seed are
    not."""
    from pipeline.montecarlo.plan import nominal_spec, read_montecarlo, resolve_montecarlo
    from pipeline.montecarlo.verdict import loop_key

    def study(name: str) -> str:
        path = resolve_montecarlo(name)
        config = read_montecarlo(path)
        return loop_key(nominal_spec(load_spec(config.mission, path.parent),
                                     config).model_dump(mode="json"))

    def run(changes: dict) -> str:
        spec = with_overrides(load_spec("omega_ripple_sampled_delay_dt0035"), changes)
        return loop_key(spec.model_dump(mode="json"))

    assert study("seed_dispersions") == run({}) == run({"mission.duration": 3.0})
    assert study("seed_latency_dt0025") == run({"mission.dt": 0.0025})
    assert study("seed_latency_dt0025") != study("seed_dispersions")
    timed = {"mission.plant.timing": {"delay_fraction": 0.25, "jitter": 0.5, "seed": 1}}
    assert run(timed) == run({**timed, "mission.plant.timing": {**timed[
        "mission.plant.timing"], "seed": 2}})
    others = [run(c) for c in ({"controller.gains.bus.D": 1.0}, {"mission.dt": 0.003},
                               {"controller.integrator": "imex"},
                               {"mission.plant.delay_steps": 0}, timed)]
    assert len({run({}), *others}) == 1 + len(others)


def test_a_fix_draws_what_the_montecarlo_drew():
    """Common random numbers (issue 52): sample i of a fix sees sample i's inertia, the ε of
    each dispersed gain, its arrival, jitter and their stream's seed, bitwise. The step's fix
    holds the arrival and jitter in seconds (the file's latency_step) and the whole step of
    delay in steps; the gain's fix moves the nominal the ε multiplies."""
    from pipeline.montecarlo.plan import derive

    mc = plan_montecarlo("seed_latency_dt0025", samples=6)
    dt = derive(mc, {"mission.dt": 0.002}, "fix_dt")
    gain = derive(mc, {"controller.gains.bus.D": 1.5}, "fix_gain")
    nominal_d = 2.0  # the mission's bus D (specs/omega_ripple_sampled_delay_dt0035.yaml)
    assert with_overrides(load_spec("omega_ripple_sampled_delay_dt0035"), {}).controller.gains \
        .bus.D == nominal_d
    for base, a, b in zip(mc.samples, dt.samples, gain.samples, strict=True):
        assert a.seed == b.seed == base.seed and a.index == base.index
        assert a.draws == base.draws  # every draw, bitwise
        assert {k: x for k, x in b.draws.items() if k != "controller.gains.bus.D"} == {
            k: x for k, x in base.draws.items() if k != "controller.gains.bus.D"}
        # the same ε on the new nominal: D = nominal·(1 + ε)
        eps = base.draws["controller.gains.bus.D"] / nominal_d - 1
        assert b.draws["controller.gains.bus.D"] == pytest.approx(1.5 * (1 + eps), rel=1e-15)
        sa, sb, s0 = a.spec, b.spec, base.spec
        assert sa.robot.inertial == sb.robot.inertial == s0.robot.inertial
        assert sa.mission.plant.delay_steps == s0.mission.plant.delay_steps == 1
        t0, ta = s0.mission.plant.timing, sa.mission.plant.timing
        assert ta.seed == sb.mission.plant.timing.seed == t0.seed
        assert sb.mission.plant.timing == t0  # the gain's fix keeps the step and the latency
        # the same seconds: 2.5 ms steps' fraction at 2 ms steps
        assert ta.delay_fraction * 0.002 == pytest.approx(t0.delay_fraction * 0.0025, rel=1e-15)
        assert ta.jitter * 0.002 == pytest.approx(t0.jitter * 0.0025, rel=1e-15)
        assert sa.controller == s0.controller and sa.mission.dt == 0.002
    # C41's file holds its whole-step delay in steps and has no latency in seconds: a step's
    # fix changes nothing else.
    c41 = plan_montecarlo("seed_dispersions", samples=4)
    for base, a in zip(c41.samples, derive(c41, {"mission.dt": 0.002}, "x").samples,
                       strict=True):
        assert a.draws == base.draws
        assert a.spec.mission.plant == base.spec.mission.plant
    # A step the latency does not fit in is refused, naming the field and the least step.
    with pytest.raises(SpecError, match=r"latency_step.*fly a step of at least"):
        derive(mc, {"mission.dt": 0.0012}, "too_small")


HOT = """\
description: test search
mission: omega_ripple_sampled_delay_dt0035
set:
  mission.duration: 3.0
  mission.dt: 0.0025
  mission.plant.timing: {delay_fraction: 0.0, jitter: 0.0}
  controller.gains.bus.D: 2.4
seed: 35
samples: 10
target: {p: 0.9973, confidence: 0.90}
ripple_max: 1.0e-4
latency_step: 0.0025
dispersions:
  body.bus.inertia: {dist: uniform, rel: [0.0, 0.0, 0.2]}
  controller.gains.bus.D: {dist: uniform, rel: 0.1}
  mission.plant.timing.delay_fraction: {dist: uniform, low: 0.0, high: 0.5}
  mission.plant.timing.jitter: {dist: uniform, low: 0.0, high: 0.25}
  mission.plant.timing.seed: {dist: seed}
"""


@pytest.mark.slow
def test_the_least_step_and_its_fixes_fly_on_the_same_draws(tmp_path):
    """Ten samples of the seed robot at dt 2.5 ms with the bus damping raised to 2.4 and the
    latency in seconds, two failing on the bus yaw's gain margin: the search finds the least
    step every sample meets (each sample flown at the nominal reused from the Monte Carlo's
    records); the fixes fly imex and that step through the same samples, all of which meet it
    (the worst at the required margin: the sample that set it); a fix's sample re-run alone is
    the bits its record holds."""
    from pipeline.montecarlo.fixes import judged, read_fixes
    from pipeline.montecarlo.sealed import unseal

    path = _write(tmp_path, HOT, "hot")
    out = tmp_path / "rep" / "montecarlo"  # a report folder's Monte Carlos
    args = ("--logs", tmp_path / "l", "--out", out)
    assert run_cli("montecarlo", path, *args, timeout=300).returncode == 0
    v = read_verdict(out / "hot" / "verdict.json")
    assert v.failures == 2 and not v.shown
    r = run_cli("search", path, "--knob", "mission.dt", *args, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "mission.dt = 0.0025: 10 samples, 2 failing" in r.stderr  # the kept records
    s = unseal((out / "hot" / "search-mission.dt.json").read_text())
    chosen, set_by = s["search"]["chosen"], s["search"]["set_by"]
    assert 0.0015 < chosen < 0.0025 and s["search"]["violations"] == []
    assert set_by == v.worst[0].index  # the least margin sets the least step
    r = run_cli("fixes", path, *args, timeout=300)
    assert r.returncode == 0, r.stderr
    records = {r.change.slug: r for r in read_fixes(out / "hot" / "fixes.json").fixes}
    assert set(records) == {"imex", "dt"}
    fixes = {k: judged(r, read_verdict(out / r.montecarlo / "verdict.json"))
             for k, r in records.items()}
    assert fixes["dt"].passes == fixes["dt"].samples == 10
    assert fixes["dt"].worst_gain_margin_db == pytest.approx(6.0, abs=0.05)
    assert fixes["dt"].steps_per_s == pytest.approx(1 / chosen)
    assert "in seconds (a transport latency" in fixes["dt"].delay_held
    # Chosen from these ten samples: every one meets it as flown, yet ten cannot certify it
    # (eq. 43b: 0.9973^10); imex, chosen beforehand, is judged by its own verdict (eq. 38).
    assert fixes["dt"].shown is False and "rests on the search" in fixes["dt"].statement
    assert fixes["imex"].shown is False and fixes["imex"].statement.startswith("10 of 10")
    alone = run_cli("montecarlo", records["dt"].file, "--sample", str(set_by), "--logs",
                    tmp_path / "l", timeout=300)
    assert alone.returncode == 0 and "the same bits" in alone.stdout, alone.stderr
    # The Monte Carlo's page: no fix shows the target at ten samples, each fix's row, the
    # search's statement and its figure.
    assert run_cli("report", "--out", tmp_path / "rep", timeout=300).returncode == 0
    page = (out / "hot" / "montecarlo.md").read_text()
    assert ("**Recommended change:** none: no fix flown through these samples, judged by its "
            "current verdict, shows the target") in page
    assert "## Each fix through the same samples" in page
    assert "[the implicit damping (imex) at the same step](../hot+imex/montecarlo.md)" in page
    assert f"mission.dt ≤ {chosen:.6g} (nominal 0.0025" in page
    assert (tmp_path / "rep" / "figures" / "mc_hot_search-mission.dt.png").is_file()
