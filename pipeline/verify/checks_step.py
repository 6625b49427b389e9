"""Checks of the stability theory and of the simulator's step (eqs. 16, 21–24): damping
rates, the discrete map against the finite-difference linearisation of ``Mission.step``, the
per-mode multipliers and dt*, and one step of the compiled loop against its re-assembly.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from pipeline.verify.checks_base import Outcome, check, fmt, maxdiff, random_state, rng, robot
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


@check("34", "Φ of the loop as flown (the sampled-data plant, 0 and 1 step of delay, explicit "
       "and imex) vs the finite-difference linearisation of Mission.step about a rest state, "
       "the held command perturbed with the state", "pipeline.sim.stability.flown_map")
def _flown_map() -> Outcome:
    from pipeline.analysis.linearization import simulator_map
    from pipeline.spec import with_overrides

    parts, diffs = [], []
    for delay in (0, 1):
        for integ in ("explicit", "imex"):
            lin = simulator_map(with_overrides(check_spec(), {
                "controller.integrator": integ, "mission.plant.model": "sampled",
                "mission.plant.delay_steps": delay}))
            rho = float(np.max(np.abs(np.linalg.eigvals(lin.Phi_theory))))
            parts.append(f"{integ}, delay {delay}: {fmt(lin.max_abs_diff)} (ρ {rho:.4g})")
            diffs.append(lin.max_abs_diff)
    return Outcome(f"spec {check_spec().name} at its start pose, static reference, one central "
                   "difference per state coordinate (h = 1e-6)", max(diffs), 1e-6,
                   "; ".join(parts))


def _held_loop_grows(g: float, total_delay: float, steps: int = 3000) -> float:
    """|e| over the last 100 steps against the 100 before the last 1000, of the scalar loop
    ė(t) = u(t − τ)/dt with u_k = −g e_k held over each step, simulated in the time domain:
    the input over step k is the commands whose held intervals, shifted by τ = total_delay
    steps, overlap it (eq. 35's plant, without its polynomial)."""
    e = np.zeros(steps + 1)
    e[0] = 1.0
    u = np.zeros(steps + 1)
    n, frac = int(np.floor(total_delay)), total_delay - np.floor(total_delay)
    for k in range(steps):
        u[k] = -g * e[k]
        # Over [k, k + 1) the shifted holds of commands k − n (its last 1 − frac) and
        # k − n − 1 (its first frac... of the step) overlap it.
        a = u[k - n] if k - n >= 0 else 0.0
        b = u[k - n - 1] if k - n - 1 >= 0 else 0.0
        e[k + 1] = e[k] + (1.0 - frac) * a + frac * b
    late, early = np.abs(e[-100:]).max(), np.abs(e[-1100:-1000]).max()
    return float(late / early)


@check("35", "gain, phase and delay margins of a mode's loop L(z) = g z^−d/(z − 1) vs "
       "independent computations: the closed loop at g·GM on the unit circle (eigenvalues of "
       "its companion matrix), |L| and ∠L at ω_c by complex arithmetic, the delay margin by "
       "a time-domain simulation of the held loop 5 % either side of it",
       "pipeline.sim.margins.margins")
def _margins() -> Outcome:
    from pipeline.sim import margins as mg

    req = mg.Requirement(6.0, 30.0, 1.0)
    diffs, parts = [], []
    for g, d in ((1.28, 0), (0.5, 0), (0.427, 1), (0.793, 1), (1.2, 1)):
        m = mg.margins(g, d, 1.0, req)
        gm = 10 ** (m.gain_margin_db / 20)
        poly = np.r_[1.0, -1.0, np.zeros(d)]
        poly[-1] += g * gm
        companion = np.diag(np.ones(d), -1) if d else np.zeros((1, 1))
        companion[0, :] = -poly[1:]
        diffs.append(abs(np.max(np.abs(np.linalg.eigvals(companion))) - 1.0))
        if m.phase_margin_deg is not None and m.phase_margin_deg > 0:
            z = np.exp(1j * m.gain_crossover)
            L = g * z ** (-d) / (z - 1.0)
            diffs += [abs(abs(L) - 1.0),
                      abs(np.degrees(np.angle(L)) + 180.0 - m.phase_margin_deg)]
            dm = m.delay_margin_s  # dt = 1: in steps
            below, above = (_held_loop_grows(g, d + 0.95 * dm), _held_loop_grows(g, d + 1.05 * dm))
            if not below < 1.0 < above:
                raise AssertionError(f"g {g}, d {d}: the held loop's growth at 0.95 and 1.05 × "
                                     f"the delay margin {dm:.4g} steps: {below:.3g}, {above:.3g}")
            parts.append(f"g {g:g}, d {d}: GM {m.gain_margin_db:.3g} dB, PM "
                         f"{m.phase_margin_deg:.3g}°, DM {dm:.4g} steps")
        else:
            parts.append(f"g {g:g}, d {d}: GM {m.gain_margin_db:.3g} dB, no phase margin")
    return Outcome("five loops (g, d); the simulation decays at 0.95 × DM and grows at 1.05 × "
                   "DM for each with a phase margin", max(diffs), 1e-10, "; ".join(parts))


@check("41", "margins of a mode's loop with its command arriving a fraction δ of a step late, "
       "L(z) = g((1 − δ)z + δ)/(z^{n+1}(z − 1)), vs independent computations: a time-domain "
       "simulation of the held loop growing at 1.01 × GM and decaying at 0.99 × GM, |L| and ∠L "
       "at ω_c by complex arithmetic", "pipeline.sim.margins.margins")
def _fractional_margins() -> Outcome:
    from pipeline.sim import margins as mg

    req = mg.Requirement(6.0, 30.0, 1.0)
    diffs, parts = [], []
    for g, n, frac in ((1.2, 0, 0.3), (0.5, 1, 0.4), (0.8, 0, 0.7), (0.3, 1, 0.9)):
        m = mg.margins(g, n, 1.0, req, frac)
        gm = 10 ** (m.gain_margin_db / 20)
        below, above = (_held_loop_grows(0.99 * gm * g, n + frac),
                        _held_loop_grows(1.01 * gm * g, n + frac))
        if not below < 1.0 < above:
            raise AssertionError(f"g {g}, delay {n + frac}: the held loop's growth at 0.99 and "
                                 f"1.01 × GM {gm:.4g}: {below:.3g}, {above:.3g}")
        z = np.exp(1j * m.gain_crossover)
        L = g * ((1 - frac) * z + frac) / (z ** (n + 1) * (z - 1.0))
        diffs += [abs(abs(L) - 1.0),
                  abs((np.degrees(np.angle(L)) + 180.0) % 360.0 - m.phase_margin_deg)]
        parts.append(f"g {g:g}, delay {n + frac:g}: GM {m.gain_margin_db:.3g} dB, PM "
                     f"{m.phase_margin_deg:.3g}°")
    return Outcome("four loops (g, n + δ); the simulation decays at 0.99 × GM and grows at "
                   "1.01 × GM for each", max(diffs), 1e-9, "; ".join(parts))


@check("41c", "mean-square radius of a loop whose arrival δ is drawn afresh each step, uniform, "
       "vs √ρ of E[Φ ⊗ Φ] formed densely with numpy's kron at Gauss–Legendre nodes; without "
       "jitter vs the map's own spectral radius", "pipeline.sim.stability.mean_square_radius")
def _mean_square() -> Outcome:
    from pipeline.sim import stability as st

    diffs = []
    for g, low, high in ((1.1, 0.0, 0.9), (0.6, 0.2, 0.5), (1.5, 0.3, 0.3)):
        # The scalar mode loop, n = 0: w = [e; p_{k−1}], e⁺ = (1 − g)e + δ(p_old + g e).
        A0, A1 = np.array([[1.0 - g, 0.0], [-g, 0.0]]), np.array([[g, 1.0], [0.0, 0.0]])
        ms = st.mean_square_radius((A0, A1, np.zeros((2, 2))), low, high)
        x, w = np.polynomial.legendre.leggauss(6)
        S = sum(wi / 2 * np.kron(A0 + d * A1, A0 + d * A1)
                for d, wi in zip(low + (high - low) * (x + 1) / 2, w, strict=True))
        diffs.append(abs(ms - np.sqrt(np.max(np.abs(np.linalg.eigvals(S))))))
    return Outcome("scalar mode loops g = 1.1, 0.6, 1.5 with δ on [0, 0.9], [0.2, 0.5] and "
                   "0.3 (no jitter)", max(diffs), 1e-10)


@check("36", "ring() on synthetic series with known answers: oscillations of period 6 and 2 on "
       "a slow trend (their period and peak to peak), a small one under a slew a thousand "
       "times larger (rings), white noise and a smooth series (no ring), a stable mode's "
       "decaying ring (decaying)", "pipeline.analysis.ringing.ring")
def _ring() -> Outcome:
    from pipeline.analysis.ringing import ring

    k = np.arange(1000, dtype=float)
    slow = 0.3 * np.sin(2 * np.pi * k / 1333) + 1e-4 * k
    diffs = []
    for period, amp in ((6.0, 0.45), (2.0, 0.15)):
        r = ring(slow + amp * np.cos(2 * np.pi * k / period), "x", "1")
        if not r.rings:
            raise AssertionError(f"a period-{period:g} oscillation does not ring: {r}")
        diffs += [abs(r.period_steps - period) / period, abs(r.peak_to_peak - 2 * amp) / (2 * amp)]
    slew = 300.0 * np.sin(2 * np.pi * k / 500) + 0.15 * np.cos(np.pi * k)
    r = ring(slew, "slew", "1")
    if not r.rings:
        raise AssertionError(f"a period-2 ring under a slew does not ring: {r}")
    diffs.append(abs(r.peak_to_peak - 0.3) / 0.3)
    for name, x in (("white noise", rng(36).standard_normal(1000)), ("smooth", slow)):
        if ring(x, name, "1").rings:
            raise AssertionError(f"{name} rings")
    fading = ring(slow + 0.995 ** k * np.cos(np.pi * k), "fading", "1")
    if fading.trend != "decaying":
        raise AssertionError(f"a ring decaying ×0.995 per step reads {fading.trend}")
    return Outcome("1000 steps; a 1333-step sine and a trend under each", max(diffs), 2e-3,
                   "largest relative error of period and peak to peak")


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
    _flown_map,
    _margins,
    _fractional_margins,
    _mean_square,
    _ring,
    _amplification,
    _critical_step,
    _mission_step,
)
