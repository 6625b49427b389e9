"""A command arriving within the step, and its jitter (eq. 41): the split hold against a
closed form, the simulator's own step against the map Φ(δ) by finite differences, the margins
against python-control and against the roots, the mean-square radius against a dense
Kronecker product over Gauss–Legendre nodes, and the spec's, the run's and the Monte Carlo's
handling of ``mission.plant.timing``."""

from __future__ import annotations

import itertools
import math
import subprocess
import sys

import control
import numpy as np
import pinocchio as pin
import pytest

from pipeline.analysis.linearization import simulator_map
from pipeline.errors import SpecError
from pipeline.sim import margins as mg
from pipeline.sim import stability as st
from pipeline.sim.forward_dynamics import rigid_tree
from pipeline.sim.mission import Mission
from pipeline.sim.plant import integrate_held, integrate_split
from pipeline.spec import load_spec, with_overrides

# -- the plant: a held command replaced within the step ---------------------------------------


def _spinning_body(inertia: float) -> pin.Model:
    """One free rigid body, principal inertias (inertia, 2·inertia, 3·inertia)."""
    m = pin.Model()
    j = m.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "bus")
    m.appendBodyToJoint(j, pin.Inertia(5.0, np.zeros(3),
                                       np.diag([2 * inertia, 3 * inertia, inertia])),
                        pin.SE3.Identity())
    m.gravity.setZero()
    return m


@pytest.mark.parametrize("split", [0.2, 0.5, 0.93])
def test_a_split_hold_about_a_principal_axis_is_the_closed_form(split):
    """About the principal z axis, τ_a for δ·dt then τ_b: ω(dt) = ω₀ + (δτ_a + (1 − δ)τ_b)dt/I
    and the angle the integral of that piecewise-linear rate; the excursion off the chord is
    max |θ(t_j) − t_j θ(dt)| over the path's own points."""
    inertia, dt, w0, ta, tb = 0.4, 0.03, 0.7, -0.9, 0.35
    model = _spinning_body(inertia)
    q, v = pin.neutral(model), np.zeros(6)
    v[5] = w0
    tau_a, tau_b = np.zeros(6), np.zeros(6)
    tau_a[5], tau_b[5] = ta, tb
    q1, v1, excursion = integrate_split(rigid_tree(model), q, v, tau_a, tau_b, dt, split, 8)
    a, b = ta / inertia, tb / inertia

    def angle(t: float) -> float:
        t1 = split * dt
        if t <= t1:
            return w0 * t + 0.5 * a * t * t
        return w0 * t1 + 0.5 * a * t1 * t1 + (w0 + a * t1) * (t - t1) + 0.5 * b * (t - t1)**2

    assert v1[5] == pytest.approx(w0 + (split * ta + (1 - split) * tb) * dt / inertia,
                                  abs=1e-12)
    assert 2 * math.atan2(q1[5], q1[6]) == pytest.approx(angle(dt), abs=1e-12)
    first, second = max(1, math.ceil(8 * split)), max(1, math.ceil(8 * (1 - split)))
    times = [split * k / first for k in range(1, first + 1)] + [
        split + (1 - split) * k / second for k in range(1, second + 1)]
    expected = max(abs(angle(t * dt) - t * angle(dt)) for t in times[:-1])
    assert expected > 1e-6  # the path bends
    assert excursion == pytest.approx(expected, rel=1e-8)


def test_a_split_at_the_ends_is_the_whole_hold():
    """δ → 0 is τ_b held over the step; δ → 1 is τ_a: the whole hold of eq. 29 to O(δ)."""
    model = _spinning_body(0.3)
    tree, q, v = rigid_tree(model), pin.neutral(model), np.full(6, 0.2)
    tau_a, tau_b = np.linspace(-1, 1, 6), np.linspace(0.5, -0.3, 6)
    for split, tau in ((1e-9, tau_b), (1 - 1e-9, tau_a)):
        q1, v1, _ = integrate_split(tree, q, v, tau_a, tau_b, 0.03, split, 8)
        q2, v2, _ = integrate_held(tree, q, v, tau, 0.03, 8)
        assert np.max(np.abs(v1 - v2)) < 1e-8 and np.max(np.abs(q1 - q2)) < 1e-8


@pytest.fixture(scope="module")
def short_sampled():
    return with_overrides(load_spec("omega_ripple_sampled_delay"),
                          {"mission.duration": 0.6}, name="short_sampled")


def test_timing_that_adds_nothing_is_the_run_without_it(short_sampled):
    """delay_fraction 0 and no jitter: the log is the log without the block, bit for bit."""
    a = Mission(short_sampled).run().columns
    b = Mission(with_overrides(short_sampled, {"mission.plant.timing": {"seed": 9}})).run().columns
    assert all(np.array_equal(a[k], b[k]) for k in a)


def test_a_jittered_run_is_its_seeds_and_another_seed_differs(short_sampled):
    timing = {"delay_fraction": 0.1, "jitter": 0.6, "seed": 3}
    spec = with_overrides(short_sampled, {"mission.plant.timing": timing})
    a, b = Mission(spec).run().columns, Mission(spec).run().columns
    assert all(np.array_equal(a[k], b[k]) for k in a)
    other = Mission(with_overrides(spec, {"mission.plant.timing.seed": 4})).run().columns
    assert not np.array_equal(a["v"], other["v"])


# -- the map Φ(δ) against the simulator's own step ---------------------------------------------

@pytest.mark.parametrize("timing, delay", [
    ({"delay_fraction": 0.35}, 0), ({"delay_fraction": 0.6}, 1), ({"delay_fraction": 0.95}, 0),
    ({"delay_fraction": 0.1, "jitter": 0.5, "seed": 4}, 0)])
def test_the_split_map_is_the_simulators_linearisation(timing, delay):
    """∂w⁺/∂w of Mission.step by central differences equals Φ(δ) (eq. 41) at the arrival the
    step draws, to 1e-6 (measured 2e-9 to 3e-9)."""
    spec = with_overrides(load_spec("short_nominal"), {
        "mission.plant.model": "sampled", "mission.plant.delay_steps": delay,
        "mission.plant.timing": timing})
    lin = simulator_map(spec)
    assert lin.Phi_theory.shape[0] == 18 + 9 * (delay + 1)
    assert lin.max_abs_diff < 1e-6


def _loop_matrices(seed: int = 1):
    rng = np.random.default_rng(seed)
    A = np.eye(9) + 0.1 * rng.standard_normal((9, 9))
    M = A @ A.T
    D = np.diag(rng.uniform(0.5, 3.0, 9))
    return M, D, 0.1 * np.eye(9), np.eye(9) + 0.05 * rng.standard_normal((9, 9))


@pytest.mark.parametrize("delay", [0, 1])
def test_the_split_map_meets_the_whole_delays_at_its_ends(delay):
    """Φ(δ → 0) has the spectrum of the d-step map (plus a zero for the unused slot);
    Φ(δ = 1) has the (d + 1)-step map's."""
    M, D, K, J = _loop_matrices()

    def radius(*args):
        return st.spectrum(st.flown_map(M, D, K, J, 0.3, "explicit", "sampled", *args)
                           ).spectral_radius

    assert radius(delay, 1e-12) == pytest.approx(radius(delay), rel=1e-9)
    assert radius(delay, 1.0) == pytest.approx(radius(delay + 1), rel=1e-12)


# -- the margins with a fraction of a step ----------------------------------------------------

def _marginal_gain(g: float, delay: int, fraction: float) -> float:
    """The factor on g at which the dominant root reaches the unit circle, by bisection on
    the roots (numpy's), independent of the frequency response."""
    lo, hi = 1e-6, 100.0
    while hi - lo > 1e-13 * hi:
        mid = 0.5 * (lo + hi)
        if abs(mg.dominant_root(mid * g, delay, fraction)) < 1.0:
            lo = mid
        else:
            hi = mid
    return lo


CASES = [(1.2, 0, 0.3), (0.5, 1, 0.4), (1.5, 0, 0.7), (0.3, 1, 0.9), (1.9, 0, 0.1),
         (0.8, 0, 0.35), (0.45, 1, 0.75)]


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # python-control at a pole, z = 1
@pytest.mark.parametrize("g, delay, fraction", CASES)
def test_fractional_margins_against_the_roots_and_python_control(g, delay, fraction):
    """GM is the factor at which a root crosses the unit circle (bisection on the roots);
    GM and PM equal python-control's ``stability_margins`` of L(z) = g((1 − δ)z + δ)/
    (z^{n+1}(z − 1)) where it reports one (it misses a crossover at ω = π exactly)."""
    gm, _ = mg.gain_margin(g, delay, fraction)
    pm, wc = mg.phase_margin(g, delay, fraction)
    assert gm == pytest.approx(_marginal_gain(g, delay, fraction), rel=1e-9)
    den = np.r_[1.0, -1.0, np.zeros(delay + 1)]
    L = control.tf([g * (1 - fraction), g * fraction], den, 1.0)
    cgm, cpm, _, _, cwc, _ = control.stability_margins(L)
    if math.isfinite(cgm):
        assert gm == pytest.approx(cgm, rel=1e-9)
    assert math.degrees(pm) == pytest.approx((cpm + 180) % 360 - 180, abs=1e-7)
    assert wc == pytest.approx(cwc, rel=1e-9)


@pytest.mark.parametrize("g, delay", [(1.28, 0), (0.5, 1), (1.9, 0)])
def test_fractional_margins_tend_to_the_closed_forms(g, delay):
    gm0, pm0 = mg.gain_margin(g, delay)[0], mg.phase_margin(g, delay)[0]
    assert mg.gain_margin(g, delay, 1e-10)[0] == pytest.approx(gm0, rel=1e-8)
    assert mg.phase_margin(g, delay, 1e-10)[0] == pytest.approx(pm0, abs=1e-8)
    gm1 = mg.gain_margin(g, delay + 1)[0]
    assert mg.gain_margin(g, delay, 1 - 1e-10)[0] == pytest.approx(gm1, rel=1e-8)


def test_the_delay_margin_counts_from_the_flown_fraction():
    """A loop flown 1.3 steps late has the margin of the 1-step loop less 0.3 step."""
    g, dt = 0.6, 0.01
    whole, _ = mg.delay_margin(g, 1, dt)
    part, _ = mg.delay_margin(g, 1.3, dt)
    assert part == pytest.approx(whole - 0.3 * dt, abs=1e-9 * dt)


# -- the jittered loop in mean square ----------------------------------------------------------

@pytest.mark.parametrize("delay, low, high", [(0, 0.1, 0.7), (1, 0.0, 0.5), (0, 0.4, 0.4)])
def test_the_mean_square_radius_is_the_dense_kronecker_over_gauss_nodes(delay, low, high):
    """√ρ(E[Φ(δ) ⊗ Φ(δ)]) from the moments on the symmetric matrices equals the same on every
    matrix from np.kron of Φ at 8 Gauss–Legendre nodes on [low, high] (exact: the integrand
    is a quartic in δ), and with no jitter the map's own radius."""
    M, D, K, J = _loop_matrices(2)
    dt = 0.3
    terms = st.split_map_terms(M, D, K, J, dt, "explicit", delay)
    ms = st.mean_square_radius(terms, low, high)
    if high == low:
        own = st.flown_map(M, D, K, J, dt, "explicit", "sampled", delay, low)
        assert ms == pytest.approx(st.spectrum(own).spectral_radius, rel=1e-9)
        return
    x, w = np.polynomial.legendre.leggauss(8)
    nodes, weights = low + (high - low) * (x + 1) / 2, w / 2
    S = sum(wi * np.kron(Phi, Phi) for Phi, wi in
            ((st.flown_map(M, D, K, J, dt, "explicit", "sampled", delay, d), wi)
             for d, wi in zip(nodes, weights, strict=True)))
    assert ms == pytest.approx(math.sqrt(np.max(np.abs(np.linalg.eigvals(S)))), rel=1e-9)


def test_the_second_moment_is_an_ensembles():
    """A scalar mode loop (eq. 41 with n = 0: w = [e; p_{k−1}]) with δ_k drawn afresh each
    step: E‖w_k‖² over 200 000 simulated runs equals the second-moment map's k-th power (whose
    radius is ρ_ms²) within 1 % at k = 8, and decays as ρ_ms² per step there."""
    g, low, high = 1.1, 0.0, 0.9
    # e⁺ = (1 − g) e + δ (p_old + g e), p_new = −g e; the slot takes p_new.
    A0 = np.array([[1.0 - g, 0.0], [-g, 0.0]])
    A1 = np.array([[g, 1.0], [0.0, 0.0]])
    terms = (A0, A1, np.zeros((2, 2)))
    ms = st.mean_square_radius(terms, low, high)
    x, w = np.polynomial.legendre.leggauss(6)
    nodes, weights = low + (high - low) * (x + 1) / 2, w / 2
    S = sum(wi * np.kron(A0 + d * A1, A0 + d * A1) for d, wi in zip(nodes, weights, strict=True))
    rng = np.random.default_rng(41)
    runs = 200_000
    state = np.tile([1.0, 0.0], (runs, 1))
    P = np.outer([1.0, 0.0], [1.0, 0.0]).ravel()
    for _ in range(8):
        d = rng.uniform(low, high, runs)[:, None]
        state = state @ A0.T + d * (state @ A1.T)
        P = S @ P
    assert np.mean(np.sum(state**2, axis=1)) == pytest.approx(P[0] + P[3], rel=0.01)
    for _ in range(200):  # the dominant mode alone
        P = S @ P
        P /= np.linalg.norm(P)
    assert np.linalg.norm(S @ P) == pytest.approx(ms**2, rel=1e-9)


# -- the spec, the analysis and the Monte Carlo ------------------------------------------------

def test_timing_reaching_past_the_step_is_refused_by_name(tmp_path):
    spec = tmp_path / "late.yaml"
    spec.write_text("extends: omega_ripple_sampled_delay\n"
                    "mission: {plant: {timing: {delay_fraction: 0.7, jitter: 0.5}}}\n")
    r = subprocess.run([sys.executable, "-m", "pipeline", "validate", str(spec)],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert "mission.plant.timing" in r.stderr and "jitter" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_timing_on_the_reduced_plant_is_refused():
    with pytest.raises(SpecError, match="timing"):
        with_overrides(load_spec("nominal"), {"mission.plant.timing": {"delay_fraction": 0.2}})


def test_the_analysis_judges_the_longest_delay_and_the_mean_square():
    """A run 1 + [0.2, 0.5) steps late at dt 3.5 ms: its modes' margins are eq. 41's at 1.5
    steps, below the 1-step loop's, and its record carries the mean-square radius (eq. 41c)
    of a loop stable in mean square."""
    from pipeline.analysis.stages import theory_at_step
    from pipeline.montecarlo.sample import ColumnsLog
    from pipeline.sim.robot import GiordanoRobot

    spec = with_overrides(load_spec("omega_ripple_sampled_delay_dt0035"), {
        "mission.duration": 0.1,
        "mission.plant.timing": {"delay_fraction": 0.2, "jitter": 0.3, "seed": 1}})
    cols = Mission(spec).run().columns
    th = theory_at_step(GiordanoRobot(spec), spec, ColumnsLog(cols), 10).record
    assert th.latency is not None and th.latency.judged_delay_steps == pytest.approx(1.5)
    fast = th.modes[0]
    gm, _ = mg.gain_margin(fast.loop_gain, 1, 0.5)
    assert fast.margins.gain_margin_db == pytest.approx(20 * math.log10(gm), rel=1e-12)
    assert fast.margins.gain_margin_db < mg.margins(fast.loop_gain, 1, spec.mission.dt,
                                                    mg.Requirement(6, 30, 0.5)).gain_margin_db
    assert th.latency.mean_square_radius < 1.0 and "stable in mean square" in th.latency.verdict
    # The margins fall as the delay grows; the map's radius need not: near 1 it is a slow
    # stiffness mode's, which the delay moves by 1e-7 either way. The loop is stable at both
    # ends of the arrival's range, and judged in mean square over all of it (above).
    assert max(th.latency.earliest_radius, th.spectral_radius) < 1.0
    assert "arriving with 1.2 to 1.5" in th.update_order


def test_a_monte_carlo_disperses_the_arrival_and_seeds_each_samples_jitter(tmp_path):
    from pipeline.montecarlo.plan import plan_montecarlo

    f = tmp_path / "late.yaml"
    f.write_text("mission: omega_ripple_sampled_delay_dt0035\nseed: 3\nsamples: 4\n"
                 "ripple_max: 1.0e-4\n"
                 "set: {mission.duration: 1.0, mission.plant.timing: {jitter: 0.1}}\n"
                 "dispersions:\n"
                 "  mission.plant.timing.delay_fraction: {dist: uniform, low: 0.0, high: 0.5}\n"
                 "  mission.plant.timing.seed: {dist: seed}\n")
    mc = plan_montecarlo(f)
    timings = [s.spec.mission.plant.timing for s in mc.samples]
    assert all(t.jitter == 0.1 and 0.0 <= t.delay_fraction < 0.5 for t in timings)
    assert len({t.seed for t in timings}) == 4
    assert all(isinstance(t.seed, int) for t in timings)


def test_a_monte_carlo_disperses_the_arms_start_configuration(tmp_path):
    """The arm's start is the best-conditioned of config_sampling's draws near q̄: a seed per
    sample starts each sample's arm elsewhere, q̄ (the posture spring's rest) dispersed with
    ``robot.q_bar`` moves the neighbourhood itself."""
    from pipeline.montecarlo.plan import plan_montecarlo

    f = tmp_path / "start.yaml"
    f.write_text("mission: omega_ripple_sampled_delay_dt0035\nseed: 5\nsamples: 3\n"
                 "ripple_max: 1.0e-4\nset: {mission.duration: 1.0}\ndispersions:\n"
                 "  config_sampling.seed: {dist: seed}\n"
                 "  robot.q_bar: {dist: normal, sd: 0.02, truncate: 3}\n")
    mc = plan_montecarlo(f)
    starts = [Mission(s.spec).q0[7:] for s in mc.samples]
    bars = [np.asarray(s.spec.robot.q_bar) for s in mc.samples]
    assert len({s.spec.config_sampling.seed for s in mc.samples}) == 3
    assert all(np.max(np.abs(a - b)) > 1e-6 for a, b in itertools.pairwise(starts))
    nominal = np.asarray(load_spec("omega_ripple_sampled_delay_dt0035").robot.q_bar)
    assert all(0 < np.max(np.abs(b - nominal)) <= 0.06 for b in bars)


# -- the stability test without roots (eq. 35) -------------------------------------------------

def test_the_schur_cohn_test_is_the_roots_verdict():
    """schur_stable against NumPy's roots on random real polynomials of degree 1 to 20 (some
    scaled to put roots near the unit circle) and on the loop's own characteristic polynomials
    around their marginal gain; a polynomial with a root on or outside the circle is refused."""
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(3000):
        c = rng.standard_normal(int(rng.integers(2, 22)))
        c *= rng.uniform(0.2, 2.0) ** np.arange(c.size)  # spread the roots' moduli
        peak = np.abs(np.roots(c)).max()
        if abs(peak - 1.0) < 1e-9:  # too near the circle for either to decide
            continue
        assert mg.schur_stable(c) == (peak < 1.0), c
        checked += 1
    assert checked > 2900
    for delay, fraction in [(0, 0.25), (1, 0.5), (3, 0.9), (12, 0.1)]:
        gm, _ = mg.gain_margin(1.0, delay, fraction)  # the marginal gain
        for g, stable in ((gm * (1 - 1e-6), True), (gm * (1 + 1e-6), False)):
            c = mg.characteristic(g, delay, fraction)
            assert (np.abs(np.roots(c)).max() < 1.0) == stable
            assert mg.schur_stable(c) == stable
    assert not mg.schur_stable(np.array([1.0, -1.0]))  # z = 1: marginal, not stable
    assert not mg.schur_stable(np.array([1.0, 0.0, 1.0]))  # z = ±j


@pytest.mark.parametrize("delay", [0, 1, 2, 5, 16])
def test_a_whole_delays_stability_is_its_closed_form(delay):
    """_stable at a whole number of steps (the closed form g < 2 sin(π/(2(2n + 1)))) against
    the roots, on a grid through the bound, and g = 0 (a root at z = 1) not stable."""
    bound = 2.0 * math.sin(math.pi / (2.0 * (2 * delay + 1)))
    for g in np.r_[np.linspace(0.01, 2.5, 60), bound * (1 - 1e-7), bound * (1 + 1e-7)]:
        by_roots = np.abs(np.roots(mg.characteristic(g, delay))).max() < 1.0
        assert mg._stable(float(g), float(delay)) == by_roots
    assert not mg._stable(0.0, float(delay))
