"""Every damping mode of M̆⁻¹D̆ and the fixes of the fastest (pipeline/sim/stability.py, eqs. 21
and 24), against closed forms, NumPy's non-symmetric eigensolver, finite differences and a
direct iteration of the delayed loop; and ``validate`` naming the mode that rings.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sim.stability import (
    DT_MU_MARGIN,
    DT_MU_STABLE,
    REDUCED_AXES,
    damping_modes,
    largest_stable_gain,
    mode_fixes,
)


def _spd(rng: np.random.Generator, n: int = 9, spread: float = 1e3) -> np.ndarray:
    """A random symmetric positive-definite matrix with eigenvalues from 1 to ``spread``."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return (Q * np.geomspace(1.0, spread, n)) @ Q.T


def _gains(bus: float, pos: float, ori: float) -> np.ndarray:
    return np.diag(np.repeat([bus, pos, ori], 3))


def _mu_max(M: np.ndarray, D: np.ndarray) -> float:
    """μ_max from NumPy's general eigensolver of M⁻¹D: another algorithm than the code's."""
    return float(np.max(np.linalg.eigvals(np.linalg.solve(M, D)).real))


def test_a_diagonal_inertia_has_the_closed_form_modes():
    """M̆ = diag(m): μ_i = d_i/m_i, each mode one axis, its share all in its block, and the
    largest stable gain of a block is min_i (bound·m_i) over its axes."""
    m = np.array([0.015625, 0.02, 0.03, 2.0, 2.5, 3.0, 0.0235, 0.03, 0.04])
    M, D = np.diag(m), _gains(2.0, 8.0, 1.0)
    modes = damping_modes(M, D)
    want = np.diag(D) / m
    assert [x.mu for x in modes] == pytest.approx(sorted(want, reverse=True), rel=1e-14)
    assert modes[0].name == "bus ω_b,x" and modes[0].mu == pytest.approx(128.0, rel=1e-14)
    for x in modes:
        assert x.shares[x.block] == pytest.approx(1.0, abs=1e-14)
        assert x.mu == pytest.approx(want[x.axis], rel=1e-14)
    bound = 2.0 / 0.03
    assert largest_stable_gain(M, D, 0, bound) == pytest.approx(bound * m[:3].min(), rel=1e-8)
    # The bus at 128 1/s is past the bound whatever the orientation gain is.
    assert largest_stable_gain(M, D, 2, bound) is None
    D_slow_bus = _gains(0.5, 8.0, 1.0)
    assert largest_stable_gain(M, D_slow_bus, 2, bound) == pytest.approx(bound * m[6:].min(),
                                                                         rel=1e-8)


@pytest.mark.parametrize("seed", range(5))
def test_coupled_modes_agree_with_numpy_and_the_shares_are_the_gain_sensitivities(seed):
    """A coupled M̆: the rates against NumPy's eigvals of M̆⁻¹D̆, each vector an eigenvector
    and M̆-normalised, and each block's share equal to ∂ln μ/∂ln d_j by central differences."""
    rng = np.random.default_rng(seed)
    M = _spd(rng)
    gains = rng.uniform(0.5, 5.0, 3)
    D = _gains(*gains)
    modes = damping_modes(M, D)
    want = np.sort(np.linalg.eigvals(np.linalg.solve(M, D)).real)[::-1]
    assert [x.mu for x in modes] == pytest.approx(want, rel=1e-10)
    h = 1e-6
    for k, x in enumerate(modes):
        e = x.vector
        assert np.linalg.norm(D @ e - x.mu * M @ e) <= 1e-10 * x.mu * np.linalg.norm(M @ e)
        assert e @ M @ e == pytest.approx(1.0, rel=1e-12)
        assert x.shares.sum() == pytest.approx(1.0, rel=1e-12)
        for j in range(3):
            up, down = gains.copy(), gains.copy()
            up[j] *= 1 + h
            down[j] *= 1 - h
            mu_up = np.sort(np.linalg.eigvals(np.linalg.solve(M, _gains(*up))).real)[::-1][k]
            mu_dn = np.sort(np.linalg.eigvals(np.linalg.solve(M, _gains(*down))).real)[::-1][k]
            sensitivity = (np.log(mu_up) - np.log(mu_dn)) / (2 * h)
            assert x.shares[j] == pytest.approx(sensitivity, abs=1e-6)


@pytest.mark.parametrize("seed", range(5))
def test_the_largest_stable_gain_puts_the_fastest_mode_on_the_bound(seed):
    rng = np.random.default_rng(100 + seed)
    M = _spd(rng, spread=50.0)
    D = _gains(*rng.uniform(0.5, 5.0, 3))
    dt = 0.03
    fixes = mode_fixes(M, D, dt)
    b = fixes.mode.block
    for g, bound in ((fixes.gain_stable, DT_MU_STABLE), (fixes.gain_margin, DT_MU_MARGIN)):
        Dg = D.copy()
        Dg[3 * b:3 * b + 3, 3 * b:3 * b + 3] = 0.0
        if g is None:  # then even without this block's damping a mode is past the bound
            assert dt * _mu_max(M, Dg) > bound
            continue
        Dg[3 * b:3 * b + 3, 3 * b:3 * b + 3] = g * np.eye(3)
        assert dt * _mu_max(M, Dg) == pytest.approx(bound, rel=1e-7)
        Dg[3 * b:3 * b + 3, 3 * b:3 * b + 3] = g * (1 + 1e-5) * np.eye(3)
        assert dt * _mu_max(M, Dg) > bound
    assert fixes.dt_stable * fixes.mode.mu == pytest.approx(2.0)
    assert fixes.dt_margin * fixes.mode.mu == pytest.approx(1.0)


@pytest.mark.parametrize("dt_mu, grows", [(0.95, False), (1.05, True), (1.9, True)])
def test_one_step_of_delay_halves_the_bound(dt_mu, grows):
    """e_{k+1} = e_k − dt·μ·e_{k−1}, iterated directly: it decays below dt·μ = 1 and grows
    above it (where the undelayed loop, stable up to 2, would still decay)."""
    e = [1.0, 1.0]
    for _ in range(400):
        e.append(e[-1] - dt_mu * e[-2])
    assert (abs(e[-1]) > 1.0) == grows
    undelayed = (1 - dt_mu) ** 400
    assert abs(undelayed) < 1.0


def test_validate_names_the_servicers_camera_roll_and_its_fixes():
    """The servicer's fastest mode is the camera roll (not the bus yaw of the closed form), set
    by the orientation damping gain; the printed step and gain that meet the requirement are
    its 1/μ and the gain with dt·μ ≤ 1."""
    from pipeline.validate import report_lines, validate_spec

    v = validate_spec("servicer_nominal")
    fast = v.fixes.mode
    assert fast.name == REDUCED_AXES[8] and v.fixes.gain_block == "cam_ori"
    assert v.fixes.dt_mu > 2 > v.dt_mu_bus
    text = "\n".join(report_lines(v))
    assert f"fastest: {REDUCED_AXES[8]}" in text
    # On the simulator's update the requirement's delay margin (one step: dt/g ≥ dt) is
    # dt·μ ≤ 1: the fix text's bisection on the margins (eq. 35) meets the stability module's
    # on μ (eq. 24), two searches of one bound.
    assert f"mission.dt ≤ {1 / fast.mu:.4g} s" in text
    assert f"cam_ori.D ≤ {v.fixes.gain_margin:.4g}" in text
