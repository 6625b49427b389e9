"""Every computed field of a log row, and the state the step hands on, against an independent
computation written from docs/equations.md with NumPy, SciPy and Pinocchio
(:mod:`pipeline.verify.step_from_equations`).

The step under test is the simulator's own (``Mission.step``: Pinocchio, the guidance, one call
of the compiled step kernel, Pinocchio's integrate) on the seed robot, mid-mission.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sim.mission import LoopState, Mission
from pipeline.spec import load_spec, with_overrides
from pipeline.verify.step_from_equations import expected_step

# Tolerances, relative to the largest entry of the expected value: the row's fields agree to
# rounding; the next state carries the central difference's error in Γ̇ through Ĉ (about 1e-11
# here). A swapped gain or field moves them by far more (test_control_step's swap tests).
EXACT = {"tau", "q", "v", "v_c", "v_breve"}  # the state at the start of the step, copied
ROW_TOL = 1e-10
# The commanded force (eq. 29) is M Γ⁻¹((ν⁺ − ν)/dt − Γ̇ v) + C v: it carries the next state's
# error (1e-9 in v̆⁺, above) divided by dt (measured 4.4e-9 on the nominal scenario).
FORCE_TOL = 1e-8
# An angle from acos of a cosine near 1 (eq. 18's pointing errors) is ill-conditioned: a
# rounding δ of the cosine moves θ by δ/sin θ. The simulator's placements are its own
# rigid-body terms', the reference's Pinocchio's, equal to a few ulps, so at θ = 1.5 mrad (the
# boresight error of the nominal scenario) the angles differ by about 1e-13 rad, 1e-10
# relative; allowed: ROW_TOL relative plus 16 ulps of the cosine carried through acos.
ANGLES = {"pointing_err_deg", "boresight_err_deg"}
# Likewise the CoM error |p_c − p_c,des|, 2e-5 m between two positions some 6 m from the
# target: a few ulps of the positions (1e-15 m) are 1e-10 of it. Allowed: ROW_TOL relative
# plus 16 ulps of a position as far out as the bus, |p_b| + 1 m.
POSITION_DIFFERENCES = {"com_err"}
NEXT_TOL = {"q": 1e-12, "v": 1e-9, "v_c": 1e-12, "v_breve": 1e-9, "tau": 1e-15,
            "integral": 1e-12, "v_breve_des_prev": 1e-12}


def _assert_close(got, want, tol: float, what: str) -> None:
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    err = float(np.max(np.abs(got - want)))
    assert err <= tol * float(np.max(np.abs(want))), f"{what}: {got} vs {want} (|Δ| = {err:.3g})"


def _assert_angle_close(got: float, want: float, what: str) -> None:
    """Degrees from acos: ROW_TOL relative plus 16 ε of the cosine through acos (ANGLES)."""
    theta = np.radians(want)
    slack = np.degrees(16 * np.finfo(float).eps / max(np.sin(theta), 1e-8))
    err = abs(got - want)
    assert err <= ROW_TOL * abs(want) + slack, f"{what}: {got} vs {want} (|Δ| = {err:.3g})"


SCENARIOS = {
    # The nominal mission as it runs (explicit, γ = 1; the period-2 ripple already drives the
    # bus-rate acceleration into its limit, as over the whole mission (claim C16)).
    "nominal": {},
    # imex, the bus gains derated, γ on the ramp, and every kind of limit close enough to bind
    # somewhere (the flags are checked either way).
    "imex_derated_limited": {
        "controller.integrator": "imex", "controller.base.derate.gain": True,
        "controller.base.conditioning.low": 0.01, "controller.base.conditioning.high": 5.0,
        "controller.base.conditioning.floor": 0.25,
        "controller.limits.omega_b_acc": 1e-3, "controller.limits.nu_e_lin_rate": 1e-3,
        "controller.limits.nu_e_ang_acc": 2e-3, "controller.limits.v_c_acc": 1e-4,
        "controller.limits.v_c_rate": 0.01, "controller.limits.v_max": 0.02},
    # explicit with the posture spring and the CoM integral bound active, and the bus-rate
    # acceleration limit far above anything the step commands (its flag clear).
    "explicit_posture_integral": {
        "controller.gains.posture": 2.0, "controller.com.i_max": 1e-6,
        "controller.limits.omega_b_acc": 1e3,
        "controller.limits.omega_b_rate": 2e-3, "controller.limits.nu_e_lin_acc": 1e-3,
        "controller.limits.nu_e_ang_rate": 1e-3},
}


@pytest.fixture(scope="module")
def mid_mission_state() -> LoopState:
    """The nominal mission's state after 80 steps (t = 2.4 s: past the start, the camera
    turning onto its aim with coverage begun, a v̆_des history)."""
    mission = Mission(with_overrides(load_spec("short_nominal"), {"mission.duration": 2.0}))
    s = mission.initial_state()
    s.integral = np.array([2e-4, -3e-4, 1e-4])  # a CoM integral to bound
    for _ in range(80):
        s, _ = mission.step(s)
    return s


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_log_row_against_the_equations(mid_mission_state, scenario):
    spec = with_overrides(load_spec("short_nominal"),
                          {"mission.duration": 2.0, **SCENARIOS[scenario]})
    mission = Mission(spec)
    s = mid_mission_state
    nxt, row = mission.step(s)
    want, want_next = expected_step(mission, s)
    assert set(want) == set(row)
    for name in sorted(row):
        if name in EXACT or name.startswith("sat_"):
            np.testing.assert_array_equal(np.asarray(row[name], dtype=float),
                                          np.asarray(want[name], dtype=float), err_msg=name)
        elif name in ANGLES:
            _assert_angle_close(float(row[name]), float(want[name]), name)
        elif name in POSITION_DIFFERENCES:
            slack = 16 * np.finfo(float).eps * (np.linalg.norm(s.q[0:3]) + 1.0)
            err = abs(float(row[name]) - float(want[name]))
            assert err <= ROW_TOL * abs(float(want[name])) + slack, (name, err)
        else:
            tol = FORCE_TOL if name in ("u_cmd", "u_applied") else ROW_TOL
            _assert_close(row[name], want[name], tol, name)
    for name, tol in NEXT_TOL.items():
        _assert_close(getattr(nxt, name), want_next[name], tol, f"next {name}")


def test_scenarios_exercise_every_branch(mid_mission_state):
    """The scenarios above cover what the row records: both integrators, γ on the ramp and at
    1, every limit flag both set and clear, the damped inverse exact, coverage above 0."""
    rows = {name: Mission(with_overrides(load_spec("short_nominal"),
                                         {"mission.duration": 2.0, **over})).step(
                                             mid_mission_state)[1]
            for name, over in SCENARIOS.items()}
    flags = [f for f in rows["nominal"] if f.startswith("sat_")]
    for f in flags:
        assert {bool(r[f]) for r in rows.values()} == {False, True}, f
    assert {r["gamma"] == 1.0 for r in rows.values()} == {False, True}
    assert all(r["coverage"] > 0 for r in rows.values())
    spec = load_spec("short_nominal")
    assert rows["nominal"]["s_min_J"] >= spec.robot.damped_inverse.floor
