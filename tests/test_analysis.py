"""Analysis stages against synthetic signals, closed forms and the simulator's own step."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import footer_metadata, run_cli_in_process, sealed

from pipeline.analysis import signals, theory
from pipeline.analysis.directions import project_chunk, sign_continuous
from pipeline.analysis.linearization import simulator_map
from pipeline.spec import load_spec, with_overrides

N = 4000  # samples of the synthetic series; white-noise r₁ has std 1/√N ≈ 0.016


@pytest.mark.parametrize("seed", range(5))
def test_lag1_of_synthetic_signals(seed):
    rng = np.random.default_rng(seed)
    k = np.arange(N)
    alternating = (-1.0) ** k * (1 + 0.01 * rng.standard_normal(N))
    slow_sine = np.sin(2 * np.pi * k / 500 + rng.uniform(0, 2 * np.pi))
    noise = rng.standard_normal(N)
    assert signals.lag1_autocorrelation(alternating) < -0.99
    assert signals.lag1_autocorrelation(slow_sine) > 0.99
    # 5 standard deviations of the white-noise estimator (1/√N)
    assert abs(signals.lag1_autocorrelation(noise)) < 5 / np.sqrt(N)


def test_lag1_columns_match_scalar_definition(rng):
    x = rng.standard_normal((300, 4)).cumsum(axis=0)
    for i in range(4):
        d = x[:, i] - x[:, i].mean()
        assert signals.lag1_autocorrelation(x)[i] == pytest.approx(
            np.dot(d[:-1], d[1:]) / np.dot(d, d), rel=1e-12)


def test_a_series_without_motion_has_no_lag1():
    """A constant column (zero, or a value whose mean rounds: 0.1 repeated) has no lag-1: its
    spread is round-off. A ripple of 1e-12 on a unit offset is motion (1e-12 ≫ 64 ulps of 1)
    and is judged: period-2 reads −1."""
    k = np.arange(200)
    x = np.c_[np.zeros(200), np.full(200, 0.1), 1.0 + 1e-12 * (-1.0) ** k]
    r = signals.lag1_or_none(x)
    assert r[0] is None and r[1] is None
    assert r[2] == pytest.approx(-1.0, abs=0.02)
    assert signals.lag1_or_none(np.full(50, -3.7)) == [None]


def test_velocity_jump_and_alignment():
    v = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.0]])
    assert signals.velocity_jumps(v).tolist() == [5.0, 0.0]
    assert signals.abs_cos([1, 0], [-2, 0]) == pytest.approx(1.0)
    assert signals.abs_cos([1, 0], [0, 3]) == pytest.approx(0.0)


def test_dominant_step_direction_finds_the_alternating_axis(rng):
    k = np.arange(1000)
    axis = rng.standard_normal(5)
    axis /= np.linalg.norm(axis)
    x = np.outer(np.sin(k / 200), rng.standard_normal(5)) + 0.1 * np.outer((-1.0) ** k, axis)
    assert signals.abs_cos(signals.dominant_step_direction(x), axis) > 0.999


def test_sign_continuity_removes_svd_sign_flips(rng):
    """Random sign flips of smooth vectors are undone, across chunk boundaries too."""
    t = np.linspace(0, 1, 50)
    V = np.stack([np.linalg.qr(np.eye(3) + 0.3 * np.array(
        [[0, -tk, 0], [tk, 0, -tk], [0, tk, 0]]))[0] for tk in t])
    flipped = V * rng.choice([-1.0, 1.0], size=(50, 1, 3))
    fixed = np.concatenate([sign_continuous(flipped[:20]),
                            sign_continuous(flipped[20:], sign_continuous(flipped[:20])[-1])])
    dots = np.einsum("kij,kij->kj", fixed[1:], fixed[:-1])
    assert np.all(dots > 0)


def test_projection_equals_u_transpose_gamma_v(rng):
    G = rng.standard_normal((6, 12, 12))
    v = rng.standard_normal((6, 12))
    part = project_chunk(G, v)
    U, s, _ = np.linalg.svd(G)
    direct = np.einsum("kji,kj->ki", U, np.einsum("kij,kj->ki", G, v))
    assert np.allclose(np.abs(part.y), np.abs(direct), atol=1e-10)
    assert np.allclose(part.s_min, s[:, -1])


@pytest.mark.parametrize("dt,mu,m", [(0.03, 98.0, 0.01), (0.01, 5.0, 2.0), (0.1, 30.0, 0.5)])
def test_scalar_mode_eigenvalues(dt, mu, m):
    """One mode, no stiffness: Φ's e-eigenvalue is 1 − dt·μ (explicit), 1/(1 + dt·μ) (imex)."""
    M, D = np.array([[m]]), np.array([[mu * m]])
    K_x, J_x = np.zeros((1, 1)), np.eye(1)
    for integ, expected in (("explicit", 1 - dt * mu), ("imex", 1 / (1 + dt * mu))):
        eig = np.linalg.eigvals(theory.discrete_map(M, D, K_x, J_x, dt, integ))
        assert np.any(np.isclose(eig, expected, atol=1e-12))
        assert theory.amplification(dt, [mu], integ)[0] == pytest.approx(expected)


def test_damping_rates_are_eigenvalues_of_minv_d(rng):
    A = rng.standard_normal((9, 9))
    M = A @ A.T + 9 * np.eye(9)
    D = np.diag(rng.uniform(0.5, 3, 9))
    mu = theory.damping_rates(M, D)
    ref = np.sort(np.linalg.eigvals(np.linalg.solve(M, D)).real)
    assert np.allclose(mu, ref, rtol=1e-10)


def test_map_critical_step_matches_two_over_mu_when_stiffness_is_negligible(rng):
    A = rng.standard_normal((9, 9))
    M = A @ A.T + np.eye(9)
    D = np.diag(rng.uniform(1, 5, 9))
    J_x = np.eye(9)
    mu_max = theory.damping_rates(M, D)[-1]
    # Stiffness 1e-4 against damping O(1): its shift of the bound is O(k/d) ~ 1e-4.
    dt_map = theory.map_critical_step(M, D, 1e-4 * np.eye(9), J_x)
    assert dt_map == pytest.approx(2 / mu_max, rel=1e-3)
    # With real stiffness the bound moves; the map, not 2/μ_max, is then the truth.
    dt_stiff = theory.map_critical_step(M, D, 50 * np.eye(9), J_x)
    assert dt_stiff != pytest.approx(2 / mu_max, rel=1e-3)
    assert theory.map_critical_step(M, D, np.eye(9), J_x, "imex") is None


@pytest.mark.parametrize("plant,delay,fraction", [("reduced", 0, 0.0), ("sampled", 1, 0.0),
                                                  ("sampled", 1, 0.4)])
def test_map_critical_step_is_where_the_radius_crosses_one(rng, plant, delay, fraction):
    # Independently of the search: NumPy's eigenvalues of the map just either side of the
    # step returned, on random loops with real stiffness.
    for _ in range(5):
        A = rng.standard_normal((9, 9))
        M = A @ A.T + np.eye(9)
        D = np.diag(rng.uniform(1, 5, 9))
        K_x = np.diag(rng.uniform(1, 80, 9))
        J_x = np.eye(9) + 0.1 * rng.standard_normal((9, 9))
        dt = theory.map_critical_step(M, D, K_x, J_x, plant=plant, delay=delay,
                                      fraction=fraction)

        radius = [float(np.max(np.abs(np.linalg.eig(theory.flown_map(
            M, D, K_x, J_x, h, "explicit", plant, delay, fraction))[0])))
            for h in (dt * (1 - 1e-8), dt * (1 + 1e-8))]
        assert radius[0] < 1.0 <= radius[1]


@pytest.mark.parametrize("overrides", [
    {}, {"controller.integrator": "imex"}, {"mission.dt": 0.01},
    {"controller.gains.posture": 0.5},
])
def test_discrete_map_matches_simulator_linearisation(overrides):
    """The 18×18 map equals the finite-difference Jacobian of Mission.step to 1e-6."""
    lin = simulator_map(with_overrides(load_spec("short_nominal"), overrides))
    assert lin.max_abs_diff < 1e-6


def test_regimes():
    assert theory.regime(0.5) == "monotone decay"
    assert theory.regime(1.5) == "decaying 2-cycle"
    assert theory.regime(2.0) == "marginal period-2"
    assert theory.regime(2.95) == "growing period-2"


# --- the analyze command on real logs ----------------------------------------------------

def _analyze(*args):
    return subprocess.run([sys.executable, "-m", "pipeline", "analyze", *map(str, args)],
                          capture_output=True, text=True)


def test_analyze_writes_json_and_table(short_logs, tmp_path):
    r = _analyze(short_logs["short_nominal"], "--against",
                 short_logs["short_omega_ripple_dt010"], "--out", tmp_path)
    assert r.returncode == 0, r.stderr
    rec = json.loads((tmp_path / "short_nominal" / "analysis.json").read_text())
    assert rec["dominant"]["lag1"] < -0.5
    assert rec["theory"]["dt_mu_max"] > 2
    assert rec["comparison"]["lag1_flip"] is True
    assert rec["provenance"]["max_abs_s_min_G"] < 1e-12
    assert np.array(rec["theory"]["M_breve"]).shape == (9, 9)
    table = pq.read_table(tmp_path / "short_nominal" / "directions.parquet")
    assert table.num_rows == 12


def test_tampered_log_fails_provenance(short_logs, tmp_path):
    src = short_logs["short_nominal"]
    t = pq.read_table(src)
    s = t.column("s_min_G").to_numpy().copy()
    s[57] *= 1.001
    bad = tmp_path / "tampered" / "run.parquet"
    bad.parent.mkdir()
    # Sealed again: a log whole but for one σ, which the provenance check must catch.
    pq.write_table(sealed(t.set_column(t.schema.get_field_index("s_min_G"), "s_min_G",
                                       pa.array(s)), footer_metadata(src)), bad)
    r = _analyze(bad, "--out", tmp_path / "out")
    assert r.returncode == 1
    assert "step 57" in r.stderr
    assert not (tmp_path / "out").exists()


def _write_variant(src, dst, drop=None, meta=None, rows=None):
    t = pq.read_table(src)
    if rows is not None:
        t = t.slice(0, rows)
    md = footer_metadata(src)
    if drop in t.column_names:
        t = t.drop_columns([drop])
    elif drop is not None:
        md.pop(drop.encode())
    md.update(meta or {})
    dst.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(sealed(t, md), dst)
    return dst


@pytest.mark.parametrize("case,needle", [
    ("missing", "not found"),
    ("not_parquet", "not a readable Parquet"),
    ("no_column", "'x_tilde'"),
    ("no_meta", "pipeline.spec_hash"),
    ("failed", "marked failed"),
    ("window", "window start"),
])
def test_bad_logs_exit_2_with_one_line(short_logs, tmp_path, case, needle):
    src = short_logs["short_nominal"]
    extra = []
    if case == "missing":
        path = tmp_path / "nope.parquet"
    elif case == "not_parquet":
        path = tmp_path / "x.parquet"
        path.write_text("not parquet")
    elif case == "no_column":
        path = _write_variant(src, tmp_path / "a" / "run.parquet", drop="x_tilde")
    elif case == "no_meta":
        path = _write_variant(src, tmp_path / "b" / "run.parquet", drop="pipeline.spec_hash")
    elif case == "failed":
        path = _write_variant(src, tmp_path / "c" / "run.parquet", rows=12,
                              meta={b"pipeline.status": b"failed", b"pipeline.rows": b"12",
                                    b"pipeline.failed_step": b"12"})
    else:
        path, extra = src, ["--window-start", "100"]
    r = run_cli_in_process("analyze", path, "--out", tmp_path / "out", *extra)
    assert r.returncode == 2
    assert needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_bus_rate_at_bound_share_counts_the_steps_at_dt_a_max_whatever_the_flag():
    """A synthetic ω_b built step by step: 60 steps of exactly dt·a_max, 20 short of it by
    3e-7 (a request just under the bound: at the bound, flag clear), 20 short by 2 %: the
    share at the bound is 80/100 by construction, and the median step is dt·a_max."""
    from pipeline.analysis.stages import bus_rate_statistics

    dt, a_max = 0.03, 10.0
    bound = dt * a_max
    sizes = np.array([1.0] * 60 + [1.0 - 3e-7] * 20 + [0.98] * 20)
    np.random.default_rng(3).shuffle(sizes)
    axis = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    x = np.concatenate([[0.0], np.cumsum(bound * sizes * (-1.0) ** np.arange(100))])
    w_b = x[:, None] * axis[None, :]
    got = bus_rate_statistics(w_b, dt, a_max)
    assert got.at_bound_share == pytest.approx(0.8, abs=1e-12)
    assert got.step_ratio == pytest.approx(1.0, abs=1e-12)
    assert got.lag1 < -0.9
