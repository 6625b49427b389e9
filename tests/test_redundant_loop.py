"""The loop of a redundant arm (issue 34 items 2 and 4): the shipped 7-DoF servicer (the
collection's Panda on the servicer's bus, ``specs/panda_nominal.yaml``) through validate and
run, its damping modes with the null-space one named as such, the period-2 prediction of the
flown map (eq. 34) against the run itself (a causal dt test), and the refusals.

The causal test takes nothing from the pipeline's analysis: the ripple is read from the log's
own v̆ columns (the lag-1 autocorrelation of step differences is −1 for a pure period-2 ripple
and near +1 for smooth motion, seed note 000), and the prediction from the map of the loop as
flown at the start state.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli_in_process

from pipeline.errors import SpecError
from pipeline.sim.mission import Mission
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.stability import damping_modes, flown_map, spectrum
from pipeline.spec import load_spec, with_overrides
from pipeline.store.table import read_log_table

SPEC = "short_panda_nominal"


def _lag1_of_differences(x: np.ndarray) -> float:
    d = np.diff(x)
    return float(np.corrcoef(d[:-1], d[1:])[0, 1])


def test_validate_names_the_null_space_mode():
    r = run_cli_in_process("validate", SPEC)
    assert r.returncode == 0, r.stderr
    modes = next(ln for ln in r.stdout.splitlines() if "damping modes at the start" in ln)
    listed = modes.split("fastest first: ")[1]
    assert len(listed.split("), ")) == 10  # nine task modes and one null-space mode
    assert "null-space ν_n,1" in modes
    assert "rows of 108 numbers" in r.stdout  # q 14, v 13, v̆ 10, u 13, and two more flags


def test_the_null_space_mode_is_eig_of_lambda_n_inverse_d_n():
    """The null-space damping mode's rate is D_n/Λ_n with Λ_n = Z̃ᵀH_qqZ̃ (eq. 37c), computed
    here from Pinocchio's M by the kinetic energy at a still CoM (not eq. 37b's Schur
    complement) and the null space of J⊕ from SciPy."""
    import pinocchio as pin
    import scipy.linalg

    spec = load_spec(SPEC)
    m = Mission(spec)
    s0 = m.initial_state()
    M_breve, D, _, _ = m.linearised_loop(s0)
    null = [md for md in damping_modes(M_breve, D) if md.null_space]
    assert len(null) == 1 and null[0].name == "null-space ν_n,1"
    robot = GiordanoRobot(spec)
    model, data = robot.model, robot.model.createData()
    M = pin.crba(model, data, s0.q)
    M = np.triu(M) + np.triu(M, 1).T
    A = pin.computeCentroidalMap(model, data, s0.q)[0:3]  # m·v_c per v
    W = np.vstack([-np.linalg.solve(A[:, 0:3], A[:, 3:]), np.eye(model.nv - 3)])
    H = W.T @ M @ W  # inertia of [ω_b; q̇] with the CoM still
    T = robot.terms(s0.q, s0.v)
    z = scipy.linalg.null_space(T.J_oplus)[:, 0]
    lam = float(z @ H[3:, 3:] @ z)
    assert abs(null[0].mu / (spec.controller.null_space.D / lam) - 1) < 1e-9


@pytest.mark.parametrize(("overrides", "axis", "ripples"), [
    ({"mission.dt": 0.012}, 8, False),  # camera roll: dt·μ 1.8, below Euler's 2
    ({"mission.dt": 0.015}, 8, True),  # camera roll: dt·μ 2.3
    ({"mission.dt": 0.005, "controller.null_space.D": 300.0}, 9, True),  # ν_n: dt·μ 8.9
])
def test_the_flown_map_predicts_the_ripple_and_its_mode(tmp_path, overrides, axis, ripples):
    """The map of the loop as flown at the start (eq. 34) is unstable exactly when the run
    rings period-2, and its fastest damping mode names the reduced coordinate that rings:
    the camera roll when the step grows, the null-space velocity when its damping does."""
    spec = with_overrides(load_spec(SPEC), overrides, name="causal")
    m = Mission(spec)
    M_breve, D, K_x, J_x = m.linearised_loop(m.initial_state())
    rho = spectrum(flown_map(M_breve, D, K_x, J_x, spec.mission.dt, "explicit")).spectral_radius
    fastest = damping_modes(M_breve, D)[0]
    assert fastest.axis == axis
    assert (rho > 1.0) is ripples
    result = m.run()
    assert result.status == "complete"
    x = result.columns["v_breve"][len(result.columns["v_breve"]) // 2:, axis]
    lag = _lag1_of_differences(x)
    if ripples:
        assert lag < -0.9, lag
        assert any("unstable" in w for w in result.warnings)  # the guard said so, at step 0
    else:
        assert lag > 0.5, lag
        assert not result.warnings


def test_a_redundant_arms_log_reads_by_joint_name_and_analyzes_with_its_null_space_mode(
        tmp_path):
    r = run_cli_in_process("run", SPEC, "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    path = tmp_path / SPEC / "run.parquet"
    t = read_log_table(path)
    assert [c for c in t.columns if c.startswith("q.panda")] == [
        f"q.panda_joint{i}" for i in range(1, 8)]
    assert {"v_breve.null_space.0", "sat_null_space_acc", "sat_null_space_rate"} <= set(t.columns)
    a = run_cli_in_process("analyze", str(path), "--out", str(tmp_path / "out"))
    assert a.returncode == 0, a.stderr
    record = json.loads((tmp_path / "out" / SPEC / "analysis.json").read_text())
    th = record["theory"]
    assert len(th["M_breve"]) == 10 and len(th["mu"]) == 10
    null = [m for m in th["modes"] if m["gain_block"] == "null_space"]
    assert [m["symbol"] for m in null] == ["ν_n,1"]
    # The null-space mode's undamped frequency is K_n's on Λ_n: √(K_n/Λ_n) = √(μ K_n/D_n).
    spec = load_spec(SPEC)
    n = spec.controller.null_space
    assert null[0]["omega_n"] == pytest.approx(np.sqrt(null[0]["mu"] * n.K / n.D), rel=1e-9)
    assert {"sat_null_space_acc", "sat_null_space_rate"} <= set(record["metrics"]["limit_share"])


def test_the_null_space_impedance_is_required_for_seven_joints_and_refused_for_six():
    spec = load_spec(SPEC)
    no_null = spec.model_copy(update={"controller": spec.controller.model_copy(
        update={"null_space": None})})
    with pytest.raises(SpecError, match=r"field controller\.null_space: 7 arm joints .* leave "
                                        r"1 null-space velocity"):
        Mission(no_null)
    six = with_overrides(load_spec("nominal"), {"controller.null_space": {"D": 1.0}})
    with pytest.raises(SpecError, match=r"field controller\.null_space: the 6 arm joints .* "
                                        r"leave no null space"):
        Mission(six)


def test_the_analysis_verdict_on_the_rippling_panda(tmp_path):
    """analyze on the Panda past the camera roll's bound (short_panda_dt015): the verdict
    predicts the camera roll's period-2 ring from the map of that run and finds it in the
    data, the null-space mode predicted and measured quiet, theory and data agreeing."""
    r = run_cli_in_process("run", "short_panda_dt015", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    path = tmp_path / "short_panda_dt015" / "run.parquet"
    a = run_cli_in_process("analyze", str(path), "--out", str(tmp_path / "out"))
    assert a.returncode == 0, a.stderr
    record = json.loads((tmp_path / "out" / "short_panda_dt015" / "analysis.json").read_text())
    assert record["theory"]["spectral_radius"] > 1.0
    judged = {j["mode"]: j for j in record["prediction"]["modes"]}
    roll = judged["camera roll ω_e,z (about the boresight)"]
    assert roll["predicted_rings"] and roll["measured"]["rings"] and roll["agrees"]
    assert roll["measured"]["period_steps"] == pytest.approx(2.0, abs=0.05)
    null = judged["null-space ν_n,1"]
    assert not null["predicted_rings"] and null["agrees"]
    assert record["prediction"]["agrees"]


def test_a_redundant_arms_log_imported_from_t_q_v_gives_the_same_data_stages(tmp_path):
    """The importer at n = 7: the Panda's own log cut to t, q (14 wide) and v (13), written as
    another tool would, imported against the robot, analysed with the spec as its declared
    controller: the same data-stage numbers as the simulated log's, bitwise, and the damping
    theory with the null-space mode."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.analysis.stages import analyze_log
    from pipeline.importer.mapping import load_mapping
    from pipeline.logs import verify_log
    from pipeline.store.door import ArtefactStore, import_log

    r = run_cli_in_process("run", SPEC, "--out", str(tmp_path / "sim"))
    assert r.returncode == 0, r.stderr
    log = verify_log(tmp_path / "sim" / SPEC / "run.parquet")
    original = analyze_log(log)
    cols = log.columns(["t", "q", "v"])
    src = tmp_path / "cut.parquet"
    pq.write_table(pa.table({"t": cols["t"], "q": list(cols["q"]), "v": list(cols["v"])}), src)
    done = import_log(src, load_mapping(None, {"robot": SPEC}), "cut", tmp_path / "logs")
    assert done.rows == len(cols["t"])
    store = ArtefactStore(done.path.parents[2], tmp_path / "rep")
    rec = store.analysis(store.open_log(done.path), quiet=True,
                         controller=load_spec(SPEC)).record
    assert rec.directions == original.directions and rec.dominant == original.dominant
    assert len(rec.directions) == 13
    names = [m.name for m in rec.damping.modes]
    assert "null-space ν_n,1" in names and len(names) == 10


@pytest.mark.parametrize("plant", [{}, {"mission.plant.model": "sampled"},
                                   {"mission.plant.model": "sampled",
                                    "mission.plant.delay_steps": 1}])
def test_the_flown_map_of_a_redundant_arm_is_the_simulators_step(plant):
    """Eq. 37f's map against finite differences of the simulator's own step (and of the
    sampled-data plant, without and with one step of delay, eq. 34): z = [x̃; η; e], η the
    self-motion coordinate, at the Panda's rest state."""
    from pipeline.analysis.linearization import simulator_map

    lin = simulator_map(with_overrides(load_spec(SPEC), plant, name="fd"))
    n = 10 * (3 if plant.get("mission.plant.delay_steps") else 2)
    assert lin.Phi_fd.shape == lin.Phi_theory.shape == (n, n)
    scale = np.max(np.abs(lin.Phi_theory))
    assert lin.max_abs_diff <= 1e-5 * scale, (lin.max_abs_diff, scale)
    # The null-space spring is in the map: η feeds ν_n's command (the row of e_n, or with a
    # delay the newest increment's slot), in the simulator's step as in the theory.
    row = n - 1
    assert abs(lin.Phi_theory[row, 9]) > 1e-3 * scale
    assert abs(lin.Phi_fd[row, 9] / lin.Phi_theory[row, 9] - 1) < 1e-4


@pytest.mark.slow
def test_a_sweep_of_the_null_space_damping(tmp_path):
    """The sweep at n = 7 (embedded Dask): the null-space damping swept across forward
    Euler's bound at dt 0.005 s; each point's analysis sees its own fastest mode and map."""
    from sweep_helpers import sweep, table

    r = sweep(tmp_path, "short_panda_nominal", "--set", "controller.null_space.D=0.5,300",
              "--set", "mission.dt=0.005", "--set", "mission.duration=5", "--workers", "1")
    assert r.returncode == 0, r.stderr
    t = table(tmp_path).set_index("controller.null_space.D").sort_index()
    assert list(t["status"]) == ["complete", "complete"]
    assert t.loc[0.5, "spectral_radius"] < 1.0 < t.loc[300.0, "spectral_radius"]
    assert t.loc[300.0, "dt_mu_max"] > 2.0 > t.loc[0.5, "dt_mu_max"]
