"""Checks of the analysis equations (eqs. 25–28, 30–33) against plain re-implementations
and synthetic signals of known answer."""

from __future__ import annotations

import math

import numpy as np

from pipeline.verify.checks_base import Outcome, check, fmt, maxdiff, rng
from pipeline.verify.checks_base import spec as check_spec


@check("25", "lag-1 autocorrelation vs an explicit loop over the definition; −1 for an "
       "alternating series", "pipeline.analysis.signals.lag1_autocorrelation")
def _lag1() -> Outcome:
    from pipeline.analysis.signals import lag1_autocorrelation

    g = rng(25)
    X = np.c_[g.standard_normal((500, 2)).cumsum(axis=0), (-1.0) ** np.arange(500)]
    diffs = []
    for i in range(X.shape[1]):
        x = list(X[:, i])
        mean = sum(x) / len(x)
        num = sum((x[k] - mean) * (x[k + 1] - mean) for k in range(len(x) - 1))
        den = sum((xk - mean) ** 2 for xk in x)
        diffs.append(abs(lag1_autocorrelation(X)[i] - num / den))
    return Outcome("two random walks and an alternating series, 500 samples each", max(diffs),
                   1e-12)


@check("26", "y_i = u_iᵀ Γ v from numpy's SVD vs project_chunk (up to the sign convention), "
       "σ_min", "pipeline.analysis.directions.project_chunk")
def _projection() -> Outcome:
    from pipeline.analysis.directions import project_chunk

    g = rng(26)
    G, v = g.standard_normal((8, 12, 12)), g.standard_normal((8, 12))
    part = project_chunk(G, v)
    diffs = []
    for k in range(8):
        U, s, _ = np.linalg.svd(G[k])
        y = U.T @ (G[k] @ v[k])
        diffs += [float(np.max(np.abs(np.abs(part.y[k]) - np.abs(y)))), abs(part.s_min[k] - s[-1])]
    return Outcome("8 random 12×12 Γ_k and v_k", max(diffs), 1e-10)


@check("27", "|cos| vs |a·b|/(‖a‖‖b‖) with math.fsum and math.hypot",
       "pipeline.analysis.signals.abs_cos")
def _abs_cos() -> Outcome:
    from pipeline.analysis.signals import abs_cos

    g, diffs = rng(27), []
    for _ in range(20):
        a, b = g.standard_normal(12), g.standard_normal(12)
        ref = abs(math.fsum(a * b)) / (math.hypot(*a) * math.hypot(*b))
        diffs.append(abs(abs_cos(a, b) - ref))
    return Outcome("20 random pairs of 12-vectors", max(diffs), 1e-14)


@check("28", "‖Δv_k‖ vs a loop of math.hypot over v_{k+1} − v_k",
       "pipeline.analysis.signals.velocity_jumps")
def _velocity_jumps() -> Outcome:
    from pipeline.analysis.signals import velocity_jumps

    v = rng(28).standard_normal((200, 12))
    ref = [math.hypot(*(v[k + 1] - v[k])) for k in range(len(v) - 1)]
    return Outcome("200 random 12-vectors", float(np.max(np.abs(velocity_jumps(v) - ref))),
                   1e-13)


@check("30", "period-2 amplitude of a(−1)^k on a linear trend (reads a) and of a sine at a "
       "tenth of Nyquist (reads its Δ²/4 in closed form)",
       "pipeline.analysis.harm.period2_amplitude")
def _period2_amplitude() -> Outcome:
    from pipeline.analysis.harm import period2_amplitude

    k = np.arange(402)  # Δ² has 400 samples: 20 whole periods of the sine
    a, w = 0.156, np.pi / 10
    x = np.c_[a * (-1.0) ** k + 0.01 * k - 3.0, np.sin(w * k)]
    # Δ²sin(wk) = −4 sin²(w/2) sin(w(k+1)): RMS over whole periods is 4 sin²(w/2)/√2.
    ref = [a, 4 * math.sin(w / 2) ** 2 / math.sqrt(2) / 4]
    return Outcome("402 samples: an alternating 0.156 on a ramp, a sine of period 20 steps",
                   maxdiff(period2_amplitude(x), ref), 1e-12)


@check("30", "short-period peak to peak (30b) of a(−1)^k on a ramp (reads 2a) and of a sine of "
       "period 6 steps on a ramp (reads √3 A in closed form), whose period-2 amplitude is a "
       "fraction of it", "pipeline.analysis.harm.short_period_peak_to_peak")
def _short_period_peak_to_peak() -> Outcome:
    from pipeline.analysis.harm import period2_amplitude, short_period_peak_to_peak

    k = np.arange(600)
    a, A = 0.156, 0.3
    x = np.c_[a * (-1.0) ** k + 0.01 * k - 3.0, A * np.sin(2 * np.pi * k / 6) + 0.002 * k]
    ref = np.array([2 * a, math.sqrt(3) * A])
    p2 = period2_amplitude(x)[1]
    return Outcome(f"600 samples: an alternating {a} and a sine of amplitude {A} over 6 steps, "
                   f"each on a ramp; the sine's period-2 amplitude reads {fmt(p2)}",
                   float(np.max(np.abs(short_period_peak_to_peak(x) - ref) / ref)), 1e-3,
                   "relative difference")


@check("31", "reversal share vs a loop counting sign changes; 1 for an alternating series, "
       "0 for one of one sign, an exact zero counted as no reversal",
       "pipeline.analysis.harm.reversal_share")
def _reversal_share() -> Outcome:
    from pipeline.analysis.harm import reversal_share

    g = rng(31)
    x = np.c_[g.standard_normal(300), (-1.0) ** np.arange(300), 1.0 + g.random(300)]
    x[10, 0] = 0.0
    ref = [sum(1 for k in range(299) if x[k, i] * x[k + 1, i] < 0) / 299 for i in range(3)]
    diffs = [maxdiff(reversal_share(x), ref), abs(ref[1] - 1.0), abs(ref[2])]
    return Outcome("300 samples: random signs with one exact zero, alternating, positive",
                   max(diffs), 0.0)


@check("32", "attitude jitter at the instants of θ_k = ωk dt + A(−1)^k about a random fixed "
       "axis on top of a random attitude (reads A), and of a constant rate (reads 0)",
       "pipeline.analysis.harm.attitude_jitter")
def _attitude_jitter() -> Outcome:
    from scipy.spatial.transform import Rotation

    from pipeline.analysis.harm import attitude_jitter

    g = rng(32)
    axis = g.standard_normal(3)
    axis /= np.linalg.norm(axis)
    R0 = Rotation.from_rotvec(g.standard_normal(3))
    k = np.arange(200)
    diffs = []
    for A in (0.00225, 0.0):
        theta = 0.0045 * k + A * (-1.0) ** k
        quat = (R0 * Rotation.from_rotvec(theta[:, None] * axis)).as_quat()
        diffs.append(maxdiff(attitude_jitter(quat), A))
    return Outcome("200 steps at 0.0045 rad per step, A = 0.00225 rad and 0", max(diffs), 1e-12,
                   "rad")


@check("32", "the camera roll's smear of a roll rate ±w alternating on a slow one: the angle "
       "zigzags by w·dt, so it reads w·dt·resolution/√2 px", "pipeline.analysis.harm.roll_smear")
def _roll_smear() -> Outcome:
    from pipeline.analysis.harm import roll_smear

    w, dt, px = 0.3, 0.03, 1024
    n = np.arange(1000)
    smear = roll_smear(0.05 * np.sin(2 * np.pi * n / 900) + w * (-1.0) ** n, dt, px, 40.0)
    expected = w * dt * px / np.sqrt(2)
    return Outcome(f"1000 steps of ±{w:g} rad/s at dt {dt:g} s on a 900-step sine, {px} px: "
                   f"{smear.smear_px:.4g} px against {expected:.4g}",
                   abs(smear.smear_px / expected - 1.0), 1e-4, "relative difference")


def _seed_model():
    from pipeline.sim.robot import GiordanoRobot
    from pipeline.spec import load_spec

    return GiordanoRobot(load_spec("nominal")).model


@check("33", "the step twist of a motion integrated finely under a linearly varying twist vs "
       "its mean plus (dt/12)[ξ_k, ξ_k+1] (the BCH term of the bound), and a constant twist's "
       "residual vs 0", "pipeline.importer.consistency.residuals",
       "pipeline.importer.consistency.step_twists")
def _consistency() -> Outcome:
    import pinocchio as pin

    from pipeline.importer.consistency import residuals, step_twists

    model = _seed_model()
    g = rng(33)
    q0 = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    xi0, slope = g.standard_normal(12), g.standard_normal(12)
    dt, n = 0.01, 2000
    q = q0.copy()
    for i in range(n):  # the midpoint rule on each substep: exact for the joints
        q = pin.integrate(model, q, (xi0 + (i + 0.5) / n * slope) * (dt / n))
    d = step_twists(model, np.array([q0, q]), dt)[0]
    w0, v0, w1, v1 = xi0[3:6], xi0[0:3], (xi0 + slope)[3:6], (xi0 + slope)[0:3]
    bracket = np.r_[np.cross(w0, v1) - np.cross(w1, v0), np.cross(w0, w1)]
    expected = xi0 + slope / 2 + np.r_[dt / 12 * bracket, np.zeros(6)]
    # Each BCH term is smaller than the one before by a factor of order dt‖ξ‖ (the bus
    # twist's): the tolerance is the bracket's term times that; a wrong sign or factor, or no
    # bracket at all, misses by the term itself, here some 30 times the tolerance.
    term = dt / 12 * np.abs(bracket).max()
    tol = term * dt * max(np.linalg.norm(xi0[:6]), np.linalg.norm((xi0 + slope)[:6]))
    qs = [q0]
    for _ in range(50):
        qs.append(pin.integrate(model, qs[-1], xi0 * dt))
    const = residuals(model, np.array(qs), np.tile(xi0, (51, 1)), dt)
    return Outcome(f"seed robot, random q and twists, dt {dt} s, {n} substeps; 50 steps of a "
                   f"constant twist (its residual within the rounding term: "
                   f"{bool(np.all(const.residual <= const.bound))})",
                   max(maxdiff(d, expected), 0.0 if np.all(const.residual <= const.bound)
                       else float("inf")), tol)


@check("38", "one-sided Clopper–Pearson bound vs the binomial tail it defines "
       "(P(X ≥ k | N, p_L) = 1 − C, SciPy's binomial); the zero-failure N vs the least N "
       "with p^N ≤ 1 − C found by counting",
       "pipeline.analysis.confidence.lower_bound",
       "pipeline.analysis.confidence.samples_needed")
def _confidence() -> Outcome:
    import scipy.stats

    from pipeline.analysis.confidence import lower_bound, samples_needed

    cases = [(852, 852, 0.9), (851, 852, 0.9), (40, 50, 0.95), (3, 7, 0.99)]
    tails = [abs(scipy.stats.binom.sf(k - 1, n, lower_bound(k, n, c)) / (1 - c) - 1)
             for k, n, c in cases]
    counted = []
    for p, c in ((0.9973, 0.9), (0.9973, 0.95), (0.5, 0.75)):
        n = 1
        while p**n > 1 - c:
            n += 1
        counted.append(abs(samples_needed(p, c) - n))
    return Outcome("4 (k, N, C) cases; p = 0.9973 at C = 90 % and 95 %, 0.5 at 75 %",
                   max(*tails, *counted), 1e-9,
                   f"tail relative error {max(tails):.1e}; N for 0.9973: "
                   f"{samples_needed(0.9973, 0.9)} at 90 %, {samples_needed(0.9973, 0.95)} "
                   "at 95 %")


@check("39", "a dispersed inertia's principal moments vs the nominal's times the drawn factors "
       "(NumPy's eigvalsh), every kept draw physical by Σ = ½ tr(I)·1 − I ⪰ 0, and the loaded "
       "model's tensor the spec's",
       "pipeline.montecarlo.dispersions.draw_inertia",
       "pipeline.sim.inertial.physical_problem", "pipeline.sim.inertial.set_inertial")
def _dispersed_inertia() -> Outcome:
    from pipeline.montecarlo.dispersions import Dispersion, draw_inertia
    from pipeline.sim.inertial import inertia_matrix
    from pipeline.sim.robot_file import load_spec_robot
    from pipeline.spec import with_overrides

    d = Dispersion(dist="uniform", rel=0.3, axes_deg=20.0)
    nominal = [1.0, 1.0, 1.9, 0.0, 0.0, 0.0]
    g = rng(39)
    moments, sigma_min, redraws = [], [], 0
    for _ in range(200):
        got = draw_inertia(d, nominal, g, "body.bus.inertia")
        I = inertia_matrix(got.inertia)
        expected = np.sort(np.array([1.0, 1.0, 1.9]) * got.factors)
        moments.append(maxdiff(np.linalg.eigvalsh(I), expected) / expected[-1])
        sigma_min.append(float(np.linalg.eigvalsh(0.5 * np.trace(I) * np.eye(3) - I)[0]))
        redraws += got.redraws
    six = [0.02, 0.03, 0.04, 0.001, -0.002, 0.0005]
    spec = with_overrides(check_spec(), {"robot.inertial": {"bus": {
        "mass": 9.0, "com": [0.0, 0.01, 0.02], "inertia": six}}})
    loaded = maxdiff(load_spec_robot(spec).inertias[1].inertia, inertia_matrix(six))
    physical = min(sigma_min) >= -1e-12
    return Outcome(f"200 draws of a flat body (moments 1, 1, 1.9), ±30 % and 20° turns "
                   f"({redraws} unphysical draws redrawn); one spec's bus tensor",
                   max(*moments, loaded, 0.0 if physical else float("inf")), 1e-12,
                   f"least eigenvalue of Σ over the kept draws {min(sigma_min):.3g}")


@check("40", "the gyro's measured-minus-true rate: variance vs N²/dt, lag-1 vs 0, the bias "
       "constant within a run; a quantised reading within half an lsb of the truth; both "
       "detectors on a period-2 tone in white noise (seen) and on the noise alone (not)",
       "pipeline.sim.sensors.Measurement", "pipeline.sim.sensors.quantise",
       "pipeline.analysis.detection.detect_ripple")
def _sensors() -> Outcome:
    import math

    from pipeline.analysis.detection import detect_ripple
    from pipeline.sim.sensors import Measurement
    from pipeline.spec import Sensors

    dt, arw = 0.01, 2e-3
    q = np.r_[np.zeros(3), [0.0, 0.0, 0.0, 1.0], np.full(6, 0.123456)]
    v = np.linspace(-0.3, 0.3, 12)
    m = Measurement(Sensors(seed=4, gyro_arw=arw, gyro_bias=1e-3, encoder_lsb=1e-3), dt)
    first = m.measure(q, v)
    err = np.array([m.measure(q, v)[1][3:6] - v[3:6] for _ in range(20000)])
    bias = err.mean(axis=0)
    variance = abs(err.var() / (arw**2 / dt) - 1)  # 60000 normals: standard error 0.6 %
    lag1 = abs(np.corrcoef(err[:-1, 0], err[1:, 0])[0, 1])
    quantised = float(np.max(np.abs(first[0][7:] - q[7:]))) / 0.5e-3
    g = np.random.default_rng(40)
    tone = np.outer((-1.0) ** np.arange(1000), [0.0, 0.0, 0.01]) + 1e-3 * g.standard_normal(
        (1000, 3))
    seen, noise = detect_ripple(tone), detect_ripple(g.standard_normal((1000, 3)))
    right = (seen.lag1_detects and seen.spectral_detects and not noise.lag1_detects
             and not noise.spectral_detects)
    bad = max(variance - 0.03, lag1 - 0.03, quantised - 1.0, 0.0) + (0.0 if right else 1.0)
    return Outcome("20000 steps of a seeded gyro (N = 2e-3 rad/√s, dt 0.01 s), encoders of 1e-3 "
                   "rad; 1000 steps of a 0.01 rad/s period-2 tone in 1e-3 rad/s noise, and of "
                   "noise alone", bad, 1e-12,
                   f"variance ratio − 1: {variance:.2e} (allowed 0.03); lag-1 {lag1:.2e}; bias "
                   f"{float(np.abs(bias).max()):.2e} rad/s; quantisation/half-lsb {quantised:.3f};"
                   f" tone lag-1 {seen.lag1:.3f}, noise lag-1 {noise.lag1:.3f}; "
                   f"σ = {arw / math.sqrt(dt):.3g} rad/s")


@check("42", "each joint's excess beyond its range vs an element-by-element loop over the "
       "ranges MuJoCo reads from the same robot file (a second parser); the flag vs any",
       "pipeline.joint_ranges.JointRanges.excess")
def _joint_excess() -> Outcome:
    import mujoco

    from pipeline.joint_ranges import JointRanges, outside
    from pipeline.verify.checks_base import robot

    r = robot()
    mj = mujoco.MjModel.from_xml_path(str(check_spec().robot_path))
    ranges = {mj.joint(j).name: tuple(mj.jnt_range[j]) for j in range(mj.njnt)
              if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and mj.jnt_limited[j]}
    names = list(r.model.names)[2:]
    g = rng(42)
    q = np.tile(r.full_configuration(r.q_bar), (200, 1))
    q[:, 7:] = g.uniform(-7.0, 7.0, (200, len(names)))  # either side of each range
    got = JointRanges.of(r.model).excess(q)
    diffs, flags = [], 0
    for k in range(len(q)):
        any_out = False
        for j, name in enumerate(names):
            lo, hi = ranges.get(name, (-math.inf, math.inf))
            x = q[k, 7 + j]
            want = x - hi if x > hi else x - lo if x < lo else 0.0
            any_out = any_out or want != 0.0
            diffs.append(abs(got[k, j] - want))
        flags += int(any_out != bool(outside(got[k:k + 1])[0]))
    return Outcome("200 configurations of the check robot, each joint uniform on [−7, 7] rad",
                   max(diffs) + flags, 0.0, f"{flags} flags differ")


@check("43", "the least change of a knob on 400 synthetic samples of known critical values "
       "vs their minimum (43a); the bound (1 − ε)^N vs the violation probability of the "
       "minimum of N uniform critical values counted over 20,000 trials (43b); the prediction "
       "vs the step at which eq. 35's gain margin of the loop gain k·μ with one step of delay "
       "is the required 6 dB (43c)",
       "pipeline.montecarlo.search.least_change", "pipeline.montecarlo.search.LeastChange.risk",
       "pipeline.montecarlo.search.predicted")
def _least_change() -> Outcome:
    from pipeline.montecarlo.search import RTOL, LeastChange, least_change, predicted
    from pipeline.montecarlo.search import Outcome as Flown
    from pipeline.sim.margins import gain_margin

    g = rng(43)
    critical = g.uniform(0.5, 3.0, 400)

    def fly(value, which):
        return {i: Flown(bool(value <= critical[i]),
                         6.0 + 20 * math.log10(critical[i] / value)) for i in which}

    found = least_change(1.0, list(range(400)), 6.0, fly)
    # (43a): within the bisection's width below the least critical value, else its miss
    miss = max(0.0, found.chosen - critical.min(), critical.min() * (1 - RTOL) - found.chosen)
    # (43b): the minimum of N uniform critical values fails a fraction V = k* of the cases
    n, eps, trials = 20, 0.1, 20_000
    k_star = g.uniform(0.0, 1.0, (trials, n)).min(axis=1)
    counted = float(np.mean(k_star > eps))
    bound = LeastChange("k", 1.0, None, n, 0, None, [], [], []).risk(1 - eps)
    se = math.sqrt(bound * (1 - bound) / trials)
    # (43c): the gain margin at the predicted step, one step of delay, μ = 40 1/s
    mu, k0 = 40.0, 0.0025
    gm0 = 20 * math.log10(gain_margin(k0 * mu, 1)[0])
    at = 20 * math.log10(gain_margin(predicted(k0, gm0, 6.0) * mu, 1)[0])
    return Outcome(f"400 critical values uniform on [0.5, 3], nominal 1; N = {n}, ε = {eps}, "
                   f"{trials} trials; μ = {mu} 1/s at dt {k0} s",
                   max(miss, abs(counted - bound) - 4 * se, abs(at - 6.0)), 1e-9,
                   f"{found.flights} flights for 400 samples; P(V > ε) counted {counted:.4f} "
                   f"against (1 − ε)^N = {bound:.4f} (4 standard errors {4 * se:.4f} allowed); "
                   f"the predicted step's margin {at:.12f} dB")


# This module's checks, in the order the cross-check shows them: an explicit list, read by
# :func:`pipeline.verify.suite.all_checks` (no registration by import).
CHECKS = (
    _lag1,
    _projection,
    _abs_cos,
    _velocity_jumps,
    _period2_amplitude,
    _short_period_peak_to_peak,
    _reversal_share,
    _attitude_jitter,
    _roll_smear,
    _consistency,
    _confidence,
    _dispersed_inertia,
    _sensors,
    _joint_excess,
    _least_change,
)
