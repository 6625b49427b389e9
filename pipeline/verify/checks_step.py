"""Checks of the stability theory and of the simulator's step (eqs. 16, 21–24): damping
rates, the discrete map against the finite-difference linearisation of ``Mission.step``, the
per-mode multipliers and dt*, and one step of the compiled loop against its re-assembly.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from pipeline.verify.checks_base import Outcome, check, fmt, maxdiff, random_state, robot
from pipeline.verify.checks_base import spec as check_spec


@check("21", "μ = eig(M̆⁻¹D̆) vs sorted eigenvalues of numpy.linalg.solve(M̆, D̆)",
       "pipeline.analysis.theory.damping_rates")
def _damping_rates() -> Outcome:
    from pipeline.analysis.theory import damping_rates

    q, v = random_state(21)
    M = np.array(robot().terms(q, v).reduced_inertia)
    D = np.diag(np.repeat([2.0, 8.0, 1.0], 3))
    ref = np.sort(np.linalg.eigvals(np.linalg.solve(M, D)).real)
    mu = damping_rates(M, D)
    return Outcome(f"M̆ of a random state (seed 21), D̆ = nominal gains; μ_max = {fmt(mu[-1])}",
                   float(np.max(np.abs(mu - ref) / ref)), 1e-10, "relative difference")


@check("22", "Φ (explicit and imex) vs the finite-difference linearisation of Mission.step "
       "about a rest state", "pipeline.analysis.theory.discrete_map")
def _discrete_map() -> Outcome:
    from pipeline.analysis.linearization import simulator_map
    from pipeline.spec import with_overrides

    parts, diffs = [], []
    for integ in ("explicit", "imex"):
        lin = simulator_map(with_overrides(check_spec(), {"controller.integrator": integ}))
        d_e = maxdiff(lin.Phi_fd[9:, 9:], lin.Phi_theory[9:, 9:])
        d_x = maxdiff(lin.Phi_fd[:9], lin.Phi_theory[:9])
        d_b = maxdiff(lin.Phi_fd[9:, :9], lin.Phi_theory[9:, :9])
        parts.append(f"{integ}: A_e {fmt(d_e)}, B {fmt(d_b)}, x̃ rows {fmt(d_x)}")
        diffs.append(lin.max_abs_diff)
    return Outcome(f"spec {check_spec().name} at its start pose, static reference, 18 central "
                   "differences of one Mission.step (h = 1e-6)", max(diffs), 1e-6,
                   "; ".join(parts))


@check("23", "ρ = 1 − dt·μ (explicit), 1/(1 + dt·μ) (imex) vs the eigenvalue of the discrete "
       "map of a scalar mode; regime labels", "pipeline.analysis.theory.amplification")
def _amplification() -> Outcome:
    from pipeline.analysis import theory

    m, d, diffs = 0.5, 50.0, []
    for dt in (0.005, 0.015, 0.025, 0.03, 0.05):
        for integ in ("explicit", "imex"):
            Phi = theory.discrete_map(np.array([[m]]), np.array([[d]]), np.zeros((1, 1)),
                                      np.eye(1), dt, integ)
            # With K_x = 0 the map is [[1, dt A_e], [0, A_e]]: eigenvalues 1 and A_e = ρ.
            rho_map = Phi[1, 1]
            lam = np.linalg.eigvals(Phi)
            lam_e = lam[np.argmin(np.abs(lam - rho_map))]
            diffs.append(abs(theory.amplification(dt, np.array([d / m]), integ)[0] - lam_e))
        expect = ("monotone decay" if dt * d / m < 1 else "decaying 2-cycle"
                  if dt * d / m < 2 else "growing period-2")
        if theory.regime(dt * d / m) != expect:
            raise AssertionError(f"regime({dt * d / m:g}) = {theory.regime(dt * d / m)!r}")
    return Outcome("scalar mode m = 0.5, d = 50 (μ = 100 s⁻¹), dt·μ = 0.5, 1.5, 2.5, 3, 5, "
                   "both integrators", max(diffs), 1e-14)


@check("24", "dt* = 2/μ_max vs the root of ρ(Φ(dt)) = 1 for a scalar mode with negligible "
       "stiffness (brentq)", "pipeline.analysis.theory.critical_step")
def _critical_step() -> Outcome:
    from pipeline.analysis import theory

    m, d, k = 0.5, 50.0, 1e-9

    def excess(dt: float) -> float:
        Phi = theory.discrete_map(np.array([[m]]), np.array([[d]]), np.array([[k]]),
                                  np.eye(1), dt, "explicit")
        return float(np.max(np.abs(np.linalg.eigvals(Phi)))) - 1.0

    root = brentq(excess, 0.5 * 2 * m / d, 1.5 * 2 * m / d, xtol=1e-15)
    dt_star = theory.critical_step(d / m)
    return Outcome(f"scalar mode μ = {d / m:g} s⁻¹, stiffness k = {k:g}", abs(dt_star - root) /
                   dt_star, 1e-6, f"dt* = {dt_star:.6g} s, root {root:.6g} s (relative difference)")


@check("16", "one Mission.step (the compiled loop) vs the step computed from eqs. 1–22 in "
       "NumPy, SciPy and Pinocchio (step_from_equations), at mid-mission states with active "
       "limits", "pipeline.sim.mission.Mission.step")
def _mission_step() -> Outcome:
    from pipeline.sim.mission import Mission
    from pipeline.spec import with_overrides
    from pipeline.verify.step_from_equations import expected_step

    diffs, sat_steps = [], 0
    for integ in ("explicit", "imex"):
        mission = Mission(with_overrides(check_spec(), {"controller.integrator": integ}))
        s = mission.initial_state()
        for k in range(121):
            nxt, row = mission.step(s)
            if k % 30 == 0:
                _, ref = expected_step(mission, s)
                diffs += [maxdiff(getattr(nxt, key), ref[key])
                          for key in ("v_breve", "v_c", "v", "q")]
                sat_steps += int(any(v for key, v in row.items() if key.startswith("sat_")))
            s = nxt
    return Outcome(f"spec {check_spec().name}, explicit and imex, steps 0, 30, …, 120 "
                   f"({sat_steps} of 10 with a limit active)", max(diffs), 1e-10,
                   "largest difference over v̆, v_c, v and q")


# This module's checks, in the order the cross-check shows them: an explicit list, read by
# :func:`pipeline.verify.suite.all_checks` (no registration by import).
CHECKS = (
    _damping_rates,
    _discrete_map,
    _amplification,
    _critical_step,
    _mission_step,
)
