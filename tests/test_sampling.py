"""The γ ramp, σ_min readouts and the startup configuration sampler."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SEEDS

from pipeline.errors import SpecError
from pipeline.sim.base_controller import conditioning_scale
from pipeline.sim.mission import Mission
from pipeline.sim.sampling import Sampling, scale_by_svd, sigma_min, sigma_min_and_cond
from pipeline.spec import ConfigSampling, Ramp, load_spec, with_overrides


def _ramp(sigma, low, high, floor):
    """DESIGN §2, written out: σ <= low → floor; σ >= high → 1; linear in between."""
    if sigma <= low:
        return floor
    if sigma >= high:
        return 1.0
    return floor + (1.0 - floor) * (sigma - low) / (high - low)


# -- scale_by_svd ------------------------------------------------------------------------------

def test_scale_by_svd_is_monotone_and_bounded(rng):
    low, high, floor = 0.01, 0.05, 0.3
    sig = np.sort(rng.uniform(0, 0.1, 500))
    g = np.array([scale_by_svd(s, low, high, floor) for s in sig])
    assert np.all(np.diff(g) >= 0)
    assert g.min() >= floor and g.max() <= 1.0


def test_method_and_conditioning_scale_use_the_same_ramp(rng):
    cfg = ConfigSampling(low=0.02, high=0.08, floor=0.4)
    samp = Sampling(cfg)
    ramp = Ramp(low=0.005, high=0.03, floor=0.2)
    ctrl = with_overrides(load_spec("nominal"), {"controller.base.conditioning.low": 0.005,
                                                 "controller.base.conditioning.high": 0.03,
                                                 "controller.base.conditioning.floor": 0.2})
    for sigma in rng.uniform(0, 0.1, 50):
        assert samp.scale_by_svd(sigma) == pytest.approx(_ramp(sigma, 0.02, 0.08, 0.4))
        assert samp.scale_by_svd(sigma, ramp) == pytest.approx(_ramp(sigma, 0.005, 0.03, 0.2))
        assert conditioning_scale(sigma, ctrl.controller) == pytest.approx(
            _ramp(sigma, 0.005, 0.03, 0.2))


def test_opts_as_the_seed_note_writes_them(rng):
    """``scale_by_svd(σ, opts)`` with opts a mapping {low, high, floor}, as the note's
    pseudocode writes it, gives the typed block's ramp."""
    samp = Sampling(ConfigSampling())
    for sigma in rng.uniform(0, 0.1, 50):
        assert samp.scale_by_svd(sigma, {"low": 0.005, "high": 0.03, "floor": 0.2}) == \
            pytest.approx(_ramp(sigma, 0.005, 0.03, 0.2))
    assert samp.scale_by_svd(0.0, {"low": 0, "high": 1, "floor": 1}) == 1.0  # ints are fine


@pytest.mark.parametrize("opts,needle", [
    ({"low": 0.01, "high": 0.05}, "key 'floor' missing"),
    ({"low": 0.05, "high": 0.01, "floor": 0.3}, "must be below high"),
    ({"low": 0.01, "high": 0.05, "floor": 0.3, "gain": 1}, "gain: unknown key"),
    ({"low": 0.01, "high": 0.05, "floor": float("nan")}, "floor"),
    ({"low": 0.01, "high": "x", "floor": 0.3}, "high"),
])
def test_bad_opts_mappings_are_spec_errors(opts, needle):
    with pytest.raises(SpecError, match=needle):
        Sampling(ConfigSampling()).scale_by_svd(0.02, opts)


# -- sigma_min, sigma_min_and_cond -------------------------------------------------------------

def test_sigma_min_and_cond_of_singular_matrix():
    A = np.diag([2.0, 1.0, 0.0])
    smin, kappa = sigma_min_and_cond(A)
    assert smin == 0.0
    assert kappa == float("inf")


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_sigma_min_of_non_finite_matrix_is_none(bad):
    A = np.eye(4)
    A[1, 2] = bad
    assert sigma_min(A) is None


# -- Sampling ----------------------------------------------------------------------------------

def _sampler(seed=0, step=0.05, num=32):
    return Sampling(ConfigSampling(seed=seed, default={"step_size": step, "num": num}))


def test_generate_samples_are_uniform_within_step_of_q_bar(rng):
    q_bar = rng.uniform(-2, 2, 6)
    X = _sampler(seed=3, step=0.1, num=4000).generate_samples(q_bar)
    assert X.shape == (4000, 6)
    d = X - q_bar
    assert np.all(np.abs(d) <= 0.1)
    # Uniform on [−h, h]: mean 0 (sd h/√(3N) ≈ 9e-4), variance h²/3 (≈ 3.3e-3).
    assert np.all(np.abs(d.mean(axis=0)) < 5e-3)
    np.testing.assert_allclose(d.var(axis=0), 0.1**2 / 3, rtol=0.1)
    # Seeded: the same draws again, other seeds differ.
    np.testing.assert_array_equal(X, _sampler(seed=3, step=0.1, num=4000).generate_samples(q_bar))
    assert not np.array_equal(X, _sampler(seed=4, step=0.1, num=4000).generate_samples(q_bar))


def _score(rng_seed):
    """A scoring function with a known σ_min per sample: a random matrix depending on q."""
    def func(q_joint):
        A = np.diag(np.abs(q_joint) + 0.01) + 0.1 * np.outer(np.sin(q_joint), np.cos(q_joint))
        return np.concatenate([[rng_seed], q_joint]), A
    return func


@pytest.mark.parametrize("seed", SEEDS)
def test_best_sample_is_brute_force_argmax(seed):
    samp = _sampler(seed=seed, step=0.5, num=40)
    q_bar = np.array([0.0, -1.6, 1.0, -0.95, 1.5708, 0.0])
    func = _score(seed)
    X = samp.generate_samples(q_bar)
    scores = [np.linalg.svd(func(x)[1], compute_uv=False).min() for x in X]
    i = int(np.argmax(scores))
    best = samp.best_sample(q_bar, func)
    np.testing.assert_array_equal(best.q_joint, X[i])
    np.testing.assert_array_equal(best.sample, X[i] - q_bar)
    np.testing.assert_array_equal(best.q_full[1:], X[i])
    assert best.sigma_min == pytest.approx(max(scores), rel=1e-12)
    ranked = samp.sorted_samples(q_bar, func)
    got = [r.sigma_min for r in ranked]
    np.testing.assert_allclose(got, np.sort(scores), rtol=1e-12)
    # Reproducible from its seed: a fresh sampler with the same block picks the same sample.
    again = _sampler(seed=seed, step=0.5, num=40).best_sample(q_bar, func)
    np.testing.assert_array_equal(again.q_joint, best.q_joint)


def test_non_finite_scores_rank_first_and_all_non_finite_gives_none():
    samp = _sampler(seed=1, num=10)
    q_bar = np.zeros(3)

    def some_nan(q):
        A = np.diag(np.abs(q) + 1.0)
        if q[0] > 0:
            A[0, 0] = np.nan
        return q, A

    ranked = samp.sorted_samples(q_bar, some_nan)
    flags = [r.sigma_min is None for r in ranked]
    n_nan = sum(flags)
    assert 0 < n_nan < 10
    assert flags == [True] * n_nan + [False] * (10 - n_nan)
    assert samp.best_sample(q_bar, some_nan).sigma_min is not None
    assert samp.best_sample(q_bar, lambda q: (q, np.full((3, 3), np.nan))) is None


def test_robot_start_is_best_sample_on_gamma(robot):
    """The start configuration maximises σ_min(Γ) over the seeded samples (brute force)."""
    X = robot.sampling.generate_samples(robot.q_bar)
    scores = []
    for x in X:
        _, G = robot.gamma_of_joints(x)
        scores.append(np.linalg.svd(G, compute_uv=False).min())
    q0 = robot.start_configuration()
    np.testing.assert_array_equal(q0[7:], X[int(np.argmax(scores))])
    np.testing.assert_array_equal(q0[:7], [0, 0, 0, 0, 0, 0, 1])


def test_robot_falls_back_to_q_bar_when_no_sample_scores(robot, monkeypatch):
    monkeypatch.setattr(robot, "gamma_of_joints", lambda q: (q, np.full((12, 12), np.nan)))
    np.testing.assert_array_equal(robot.start_configuration()[7:], robot.q_bar)


def test_config_sampling_seed_changes_the_start():
    base = load_spec("short_nominal")
    q_a = Mission(base).q0
    q_a2 = Mission(load_spec("short_nominal")).q0
    q_b = Mission(with_overrides(base, {"config_sampling.seed": 1})).q0
    np.testing.assert_array_equal(q_a, q_a2)
    assert not np.array_equal(q_a[7:], q_b[7:])
    assert np.all(np.abs(q_b[7:] - np.asarray(base.robot.q_bar)) <= 0.05)
