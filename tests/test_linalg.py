"""The project's own small dense linear algebra (pipeline/sim/linalg.py) against exact
arithmetic and SciPy/LAPACK, each within a stated rounding-error bound, and its bits against
themselves: twice, from a strided view, in Python mode and under another OpenBLAS core type.

Notation. u = 2⁻⁵³, the unit roundoff of float64; γ_k = k u/(1 − k u) (Higham, *Accuracy and
Stability of Numerical Algorithms*, 2nd ed., §3.1); ‖·‖ is the 2-norm; N is the larger
dimension of the matrix. Where the worst-case constant of a bound is a higher power of N than
the algorithms attain (LU's growth factor, the number of Jacobi rotations), the bound is written
with ε = C N u, C = 10, the "p(N) u" of Higham's theorems taken linear in N; both the kernel and
LAPACK satisfy it, so a difference of the two is bounded by 2ε where the text says so. The
tolerances below are these bounds, evaluated; none was tuned to the results.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from pipeline.sim import linalg

U_ROUND = 2.0**-53
C = 10
SIZES = (1, 2, 3, 6, 9, 12, 18)
TALL = ((2, 1), (3, 2), (6, 1), (9, 3), (12, 9), (18, 6), (18, 12))
WIDE = ((1, 6), (2, 3), (3, 9), (6, 18), (9, 12))
SHAPES = tuple((n, n) for n in SIZES) + TALL
ROOT = Path(__file__).resolve().parents[1]


def eps(N: int) -> float:
    """ε = C N u: the normwise backward error the kernels (and LAPACK) stay within."""
    return C * N * U_ROUND


def gamma(k: int) -> Fraction:
    """γ_k = k u/(1 − k u), exactly: k/(2⁵³ − k)."""
    return Fraction(k, 2**53 - k)


def carr(X) -> np.ndarray:
    """The C-ordered float64 array the kernels take."""
    return np.ascontiguousarray(X, dtype=np.float64)


def ld(X) -> np.ndarray:
    return np.asarray(X, dtype=np.longdouble)


def norm2(X) -> float:
    return float(np.linalg.norm(np.asarray(X, dtype=np.float64), 2))


def same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


# -- matrices --------------------------------------------------------------------------------

def orthonormal(rng: np.random.Generator, m: int, r: int) -> np.ndarray:
    """m×r with orthonormal columns (QR of a Gaussian, signs fixed by R's diagonal)."""
    if r == 0:
        return np.zeros((m, 0))
    Q, R = np.linalg.qr(rng.standard_normal((m, r)))
    return Q * np.where(np.diag(R) < 0.0, -1.0, 1.0)


def with_singular_values(rng: np.random.Generator, m: int, n: int, s) -> np.ndarray:
    """U diag(s) Vᵀ with random orthonormal U (m×r), V (n×r), r = min(m, n) = len(s)."""
    r = min(m, n)
    return carr((orthonormal(rng, m, r) * np.asarray(s, dtype=float)) @ orthonormal(rng, n, r).T)


def symmetric_with_eigenvalues(rng: np.random.Generator, w) -> np.ndarray:
    """Q diag(w) Qᵀ for a random orthogonal Q, made exactly symmetric."""
    w = np.asarray(w, dtype=float)
    Q = orthonormal(rng, len(w), len(w))
    S = (Q * w) @ Q.T
    return carr(0.5 * (S + S.T))


SVD_KINDS = ("random", "graded", "identity", "orthogonal", "repeated", "zero_column",
             "rank_half", "zero")


def svd_matrix(kind: str, rng: np.random.Generator, m: int, n: int) -> np.ndarray:
    """An m×n test matrix: Gaussian; σ graded 1 … 1e-12; the identity; orthonormal columns
    (σ all 1); σ repeated in threes (…, 2, 2, 2, 1, 1, 1); a zero column; rank ⌊r/2⌋ (a
    product B C); zero."""
    r = min(m, n)
    if kind == "random":
        return carr(rng.standard_normal((m, n)))
    if kind == "graded":
        return with_singular_values(rng, m, n, np.logspace(0, -12, r))
    if kind == "identity":
        return carr(np.eye(m, n))
    if kind == "orthogonal":
        return with_singular_values(rng, m, n, np.ones(r))
    if kind == "repeated":
        return with_singular_values(rng, m, n, 1.0 + np.arange(r)[::-1] // 3)
    if kind == "zero_column":
        A = rng.standard_normal((m, n))
        A[:, n // 2] = 0.0
        return carr(A)
    if kind == "rank_half":
        k = r // 2
        return carr(rng.standard_normal((m, k)) @ rng.standard_normal((k, n)))
    if kind == "zero":
        return np.zeros((m, n))
    raise ValueError(kind)


# -- products --------------------------------------------------------------------------------

def product_operands(rng: np.random.Generator, shape, scaled: bool) -> np.ndarray:
    """Gaussian entries, or (``scaled``) Gaussian times 10^U{-8..8}: sums with cancellation,
    whose rounding depends on the order of summation."""
    X = rng.standard_normal(shape)
    if scaled:
        X *= 10.0 ** rng.integers(-8, 9, shape)
    return carr(X)


def exact_dot(a, b) -> tuple[Fraction, Fraction]:
    """(Σ a_k b_k, Σ |a_k b_k|) in exact rational arithmetic."""
    terms = [Fraction(x) * Fraction(y) for x, y in zip(a.tolist(), b.tolist(), strict=True)]
    return sum(terms, Fraction(0)), sum((abs(t) for t in terms), Fraction(0))


def sequential_dot(a, b) -> float:
    """s = 0.0; s += a_k b_k for k = 0, 1, …, in Python floats (IEEE double, no FMA)."""
    s = 0.0
    for x, y in zip(a.tolist(), b.tolist(), strict=True):
        s += x * y
    return s


def reversed_dot(a, b) -> float:
    return sequential_dot(a[::-1], b[::-1])


def assert_within_gamma_k(computed: float, a, b, where: str) -> None:
    """|fl(aᵀb) − aᵀb| ≤ γ_k |a|ᵀ|b| (Higham Thm 3.5 / (3.4)), for any order of summation."""
    exact, absolute = exact_dot(a, b)
    err = abs(Fraction(computed) - exact)
    bound = gamma(len(a)) * absolute
    assert err <= bound, (f"{where}: |error| = {float(err):.3e} > γ_k |a|ᵀ|b| = "
                          f"{float(bound):.3e} (k = {len(a)}, exact {float(exact):.17g}, "
                          f"computed {computed:.17g})")


@pytest.mark.parametrize("k", SIZES)
@pytest.mark.parametrize("scaled", [False, True], ids=["gaussian", "scaled"])
def test_dot_within_gamma_k_of_the_exact_sum(rng, k, scaled):
    """dot(a, b) within γ_k |a|ᵀ|b| of Σ a_k b_k computed exactly (fractions)."""
    for draw in range(5):
        a, b = product_operands(rng, k, scaled), product_operands(rng, k, scaled)
        d = linalg.dot(a, b)
        assert isinstance(d, float)
        assert_within_gamma_k(d, a, b, f"k = {k}, draw {draw}")


@pytest.mark.parametrize("m,k", [(1, 1), (3, 2), (6, 6), (9, 12), (18, 18), (12, 18), (1, 18)])
@pytest.mark.parametrize("scaled", [False, True], ids=["gaussian", "scaled"])
def test_matvec_within_gamma_k_of_the_exact_sum(rng, m, k, scaled):
    """Each (A x)_i within γ_k |A_i,:| |x| of the exact sum."""
    for draw in range(3):
        A, x = product_operands(rng, (m, k), scaled), product_operands(rng, k, scaled)
        y = linalg.matvec(A, x)
        assert y.shape == (m,) and y.dtype == np.float64
        for i in range(m):
            assert_within_gamma_k(float(y[i]), A[i], x, f"({m}×{k}), draw {draw}, row {i}")


MATMUL_SHAPES = [(1, 1, 1), (2, 3, 4), (3, 3, 3), (6, 6, 6), (9, 12, 3), (12, 1, 9),
                 (18, 6, 12), (1, 18, 1), (18, 18, 18)]


@pytest.mark.parametrize("m,k,n", MATMUL_SHAPES)
@pytest.mark.parametrize("scaled", [False, True], ids=["gaussian", "scaled"])
def test_matmul_within_gamma_k_of_the_exact_sum(rng, m, k, n, scaled):
    """Each (A B)_ij within γ_k |A_i,:| |B_:,j| of the exact sum; the result C-ordered m×n."""
    A, B = product_operands(rng, (m, k), scaled), product_operands(rng, (k, n), scaled)
    Cm = linalg.matmul(A, B)
    assert Cm.shape == (m, n) and Cm.dtype == np.float64 and Cm.flags.c_contiguous
    Bt = carr(B.T)
    for i in range(m):
        for j in range(n):
            assert_within_gamma_k(float(Cm[i, j]), A[i], Bt[j], f"({m}×{k} @ {k}×{n})[{i},{j}]")


def test_matmul_of_small_integers_is_exact():
    """[[1, 2], [3, 4]] [[5, 6], [7, 8]] = [[19, 22], [43, 50]]: every partial sum is an
    integer below 2⁵³, so there is no rounding at all."""
    A = carr([[1, 2], [3, 4]])
    B = carr([[5, 6], [7, 8]])
    assert same_bits(linalg.matmul(A, B), carr([[19, 22], [43, 50]]))
    assert same_bits(linalg.matvec(A, carr([5, 7])), carr([19, 43]))
    assert linalg.dot(carr([1, 2]), carr([5, 7])) == 19.0


def test_products_sum_sequentially_from_zero_bitwise(rng):
    """Every entry of dot, matvec and matmul is, to the bit, ``s = 0.0; s += a_k b_k`` for
    k ascending, in Python floats. The data are order-sensitive: on them the reverse order
    differs from the forward one somewhere (checked), so another order would fail. Starting
    from 0.0 also means 0.0 + (−0.0) = +0.0: dot([−0.0], [1.0]) is +0.0."""
    order_sensitive = 0
    for k in (3, 6, 9, 12, 18):
        for _ in range(4):
            a, b = product_operands(rng, k, True), product_operands(rng, k, True)
            d = linalg.dot(a, b)
            assert same_bits(np.float64(d), np.float64(sequential_dot(a, b))), (k, a, b)
            order_sensitive += reversed_dot(a, b) != sequential_dot(a, b)
        A, x = product_operands(rng, (7, k), True), product_operands(rng, k, True)
        y = linalg.matvec(A, x)
        assert same_bits(y, np.array([sequential_dot(A[i], x) for i in range(7)])), (k, A, x)
        B = product_operands(rng, (k, 5), True)
        Cm = linalg.matmul(A, B)
        ref = np.array([[sequential_dot(A[i], B[:, j]) for j in range(5)] for i in range(7)])
        assert same_bits(Cm, ref), (k, A, B)
        order_sensitive += int(np.sum(ref != np.array(
            [[reversed_dot(A[i], B[:, j]) for j in range(5)] for i in range(7)])))
    assert order_sensitive > 0, "the data cannot tell one summation order from another"
    z = linalg.dot(carr([-0.0]), carr([1.0]))
    assert z == 0.0 and not math.copysign(1.0, z) < 0.0, "dot([-0.0], [1.0]) must be +0.0"


# -- solve and inverse -----------------------------------------------------------------------

SOLVE_KINDS = ("random", "ill_conditioned")


def solve_matrix(kind: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """Gaussian, or U diag(s) Vᵀ with s = 1 … 1e-10 log-spaced (κ₂ = 1e10)."""
    if kind == "random":
        return carr(rng.standard_normal((n, n)))
    return with_singular_values(rng, n, n, np.logspace(0, -10, n))


def relative_backward_error(A, x, b) -> float:
    """η = ‖A x − b‖ / (‖A‖ ‖x‖ + ‖b‖) (Rigal–Gaches; Higham Thm 7.1), the residual formed in
    long double so that its own rounding does not count."""
    r = np.asarray(ld(A) @ ld(x) - ld(b), dtype=np.float64)
    return float(np.linalg.norm(r)) / (norm2(A) * float(np.linalg.norm(x))
                                       + float(np.linalg.norm(b)))


def forward_tolerance(kappa: float, eta: float) -> float:
    """Two solutions each with normwise backward error ≤ η differ by at most
    2κη/(1 − 2κη) relative to either (Higham Thm 7.2: ‖Δx‖/‖x‖ ≤ κη/(1 − κη) each)."""
    ke = 2.0 * kappa * eta
    return ke / (1.0 - ke) if ke < 1.0 else math.inf


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kind", SOLVE_KINDS)
def test_solve_is_backward_stable_and_agrees_with_scipy(rng, n, kind):
    """LU with partial pivoting: ‖A x − b‖ ≤ ε (‖A‖ ‖x‖ + ‖b‖), ε = C n u (Higham Thm 9.4 with
    a growth factor of order 1, as for these matrices); and ‖x − x_scipy‖ ≤
    2κε/(1 − 2κε) ‖x_scipy‖."""
    for draw in range(3):
        A, b = solve_matrix(kind, rng, n), carr(rng.standard_normal(n))
        A0, b0 = A.copy(), b.copy()
        x = linalg.solve(A, b)
        assert same_bits(A, A0) and same_bits(b, b0), "solve wrote into its input"
        assert x.shape == (n,) and x.dtype == np.float64
        eta = relative_backward_error(A, x, b)
        assert eta <= eps(n), f"{kind} n={n} draw {draw}: backward error {eta:.3e} > {eps(n):.3e}"
        x_ref = scipy.linalg.solve(A, b)
        kappa = float(np.linalg.cond(A))
        rel = float(np.linalg.norm(x - x_ref) / np.linalg.norm(x_ref))
        tol = forward_tolerance(kappa, eps(n))
        assert rel <= tol, f"{kind} n={n} draw {draw}: |x - x_scipy|/|x| = {rel:.3e} > {tol:.3e}"


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kind", SOLVE_KINDS)
def test_inverse_has_small_right_residual_and_agrees_with_scipy(rng, n, kind):
    """The inverse is solved column by column from one LU (A x_j = e_j), so each column has
    the backward error of a solve: ‖A x_j − e_j‖ ≤ ε (‖A‖ ‖x_j‖ + 1), ε = C n u; and the
    forward error of X, and of SciPy's getri inverse, is ≤ κε/(1 − κε) each (Higham §14.1),
    so ‖X − X_scipy‖_F ≤ 2κε/(1 − 2κε) ‖X_scipy‖_F."""
    for draw in range(3):
        A = solve_matrix(kind, rng, n)
        X = linalg.inverse(A)
        assert X.shape == (n, n) and X.flags.c_contiguous
        for j in range(n):
            e = np.zeros(n)
            e[j] = 1.0
            eta = relative_backward_error(A, X[:, j], e)
            assert eta <= eps(n), f"{kind} n={n} draw {draw} column {j}: η = {eta:.3e}"
        X_ref = scipy.linalg.inv(A)
        rel = float(np.linalg.norm(X - X_ref) / np.linalg.norm(X_ref))
        tol = forward_tolerance(float(np.linalg.cond(A)), eps(n))
        assert rel <= tol, f"{kind} n={n} draw {draw}: ‖X - X_scipy‖/‖X‖ = {rel:.3e} > {tol:.3e}"


def singular_cases(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """Exactly singular matrices on which LU meets an exactly zero pivot: a zero column, a
    zero row, two equal rows (their elimination leaves an exactly zero row), zero."""
    cases = {"zero": np.zeros((n, n))}
    if n >= 2:
        A = rng.standard_normal((n, n))
        cases["zero_column"] = A.copy()
        cases["zero_column"][:, n // 2] = 0.0
        cases["zero_row"] = A.copy()
        cases["zero_row"][n - 1] = 0.0
        cases["equal_rows"] = A.copy()
        cases["equal_rows"][n - 1] = A[0]
    return {k: carr(v) for k, v in cases.items()}


def non_finite_cases(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """A well-conditioned SPD matrix with one NaN or ±inf entry, on and off the diagonal."""
    G = rng.standard_normal((n, n))
    base = G @ G.T + n * np.eye(n)
    cases = {}
    for name, (i, j), v in (("nan_first", (0, 0), np.nan), ("nan_last", (n - 1, n - 1), np.nan),
                            ("nan_lower", (n - 1, 0), np.nan), ("inf_first", (0, 0), np.inf),
                            ("inf_last", (n - 1, n - 1), np.inf),
                            ("minus_inf_lower", (n - 1, 0), -np.inf)):
        A = base.copy()
        A[i, j] = v
        cases[name] = carr(A)
    return cases


@pytest.mark.parametrize("n", SIZES)
def test_solve_and_inverse_refuse_singular_and_non_finite_matrices(rng, n):
    """LinAlgError, not a result, for an exactly singular A and for a NaN or ±inf in A."""
    b = carr(rng.standard_normal(n))
    for name, A in {**singular_cases(rng, n), **non_finite_cases(rng, n)}.items():
        with pytest.raises(np.linalg.LinAlgError):
            linalg.solve(A, b)
            pytest.fail(f"solve accepted {name} (n = {n})")
        with pytest.raises(np.linalg.LinAlgError):
            linalg.inverse(A)
            pytest.fail(f"inverse accepted {name} (n = {n})")


# -- Cholesky --------------------------------------------------------------------------------

SPD_KINDS = ("random", "ill_conditioned", "graded", "identity")


def spd_matrix(kind: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """G Gᵀ + I; eigenvalues 1 … 1e-10 (κ = 1e10); D (G Gᵀ + I) D with D = diag(1 … 1e-6)
    (entries spanning 12 decades); the identity. All exactly symmetric."""
    if kind == "identity":
        return np.eye(n)
    if kind == "ill_conditioned":
        return symmetric_with_eigenvalues(rng, np.logspace(0, -10, n))
    G = rng.standard_normal((n, n))
    A = G @ G.T + np.eye(n)
    if kind == "graded":
        d = np.logspace(0, -6, n)
        A = d[:, None] * A * d[None, :]
    return carr(0.5 * (A + A.T))


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kind", SPD_KINDS)
def test_cholesky_componentwise_backward_error(rng, n, kind):
    """|A − L Lᵀ| ≤ γ_{n+1} |L| |Lᵀ| entry by entry (Higham Thm 10.3, for any order of the
    inner products), evaluated exactly (fractions); and normwise ‖A − L Lᵀ‖ ≤ C n u ‖A‖."""
    A = spd_matrix(kind, rng, n)
    L = linalg.cholesky_lower(A)
    assert L.shape == (n, n) and L.dtype == np.float64 and L.flags.c_contiguous
    Lf = [[Fraction(v) for v in row] for row in L.tolist()]
    g = gamma(n + 1)
    for i in range(n):
        for j in range(i + 1):
            prod = sum((Lf[i][k] * Lf[j][k] for k in range(n)), Fraction(0))
            absprod = sum((abs(Lf[i][k] * Lf[j][k]) for k in range(n)), Fraction(0))
            err = abs(Fraction(A[i, j]) - prod)
            assert err <= g * absprod, (
                f"{kind} n={n} [{i},{j}]: |A - LLᵀ| = {float(err):.3e} > γ_(n+1)|L||Lᵀ| = "
                f"{float(g * absprod):.3e}")
    res = norm2(np.asarray(ld(A) - ld(L) @ ld(L).T, dtype=np.float64))
    assert res <= eps(n) * norm2(A), f"{kind} n={n}: ‖A - LLᵀ‖ = {res:.3e}"


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kind", SPD_KINDS)
def test_cholesky_is_lower_with_positive_diagonal_and_matches_numpy(rng, n, kind):
    """Strict upper triangle exactly 0, diagonal > 0 (the unique factor); only A's lower
    triangle is read (garbage above it changes no bit); and, since each factor is the exact
    one of A + ΔA with ‖ΔA‖_F ≤ √n C n u ‖A‖, the first-order perturbation bound
    ‖ΔL‖_F ≤ 2^(-1/2) κ(A) ‖L‖ ‖ΔA‖_F/‖A‖ (Sun 1991; Higham Thm 10.8) gives
    ‖L − L_numpy‖_F ≤ √(2n) C n u κ(A) ‖L‖ for the two."""
    A = spd_matrix(kind, rng, n)
    L = linalg.cholesky_lower(A)
    assert np.all(np.triu(L, 1) == 0.0) and np.all(np.diag(L) > 0.0)
    junk = carr(np.tril(A) + np.triu(rng.standard_normal((n, n)) * 1e3, 1))
    assert same_bits(linalg.cholesky_lower(junk), L), "cholesky_lower read A's upper triangle"
    L_ref = np.linalg.cholesky(A)
    err = float(np.linalg.norm(L - L_ref))
    tol = math.sqrt(2 * n) * eps(n) * float(np.linalg.cond(A)) * norm2(L_ref)
    assert err <= tol, f"{kind} n={n}: ‖L - L_numpy‖_F = {err:.3e} > {tol:.3e}"


@pytest.mark.parametrize("n", SIZES)
def test_cholesky_refuses_matrices_that_are_not_positive_definite(rng, n):
    """LinAlgError for −I, for a matrix with one eigenvalue −1e-2 among 1 … 1e-3 (far beyond
    the C n u ‖A‖ a rounding error could move it), and for zero."""
    w = np.logspace(0, -3, n)
    w[-1] = -1e-2
    for name, A in (("-I", -np.eye(n)), ("negative eigenvalue", symmetric_with_eigenvalues(rng, w)),
                    ("zero", np.zeros((n, n)))):
        with pytest.raises(np.linalg.LinAlgError):
            linalg.cholesky_lower(carr(A))
            pytest.fail(f"cholesky_lower accepted {name} (n = {n})")


@pytest.mark.parametrize("n", SIZES)
def test_cholesky_refuses_non_finite_matrices(rng, n):
    """LinAlgError for a NaN or ±inf in A's lower triangle: the module docstring's "LinAlgError
    if A is not positive definite (or not finite)"."""
    accepted = []
    for name, A in non_finite_cases(rng, n).items():
        try:
            L = linalg.cholesky_lower(A)
        except np.linalg.LinAlgError:
            continue
        accepted.append(f"{name}: diag(L) = {np.diag(L)}")
    assert accepted == [], f"n = {n}: cholesky_lower accepted " + "; ".join(accepted)


# -- symmetric eigenvalues -------------------------------------------------------------------

EIG_KINDS = ("random", "identity", "repeated", "graded", "graded_signed", "rank_half", "zero")


def symmetric_matrix(kind: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """(G + Gᵀ)/2; I; eigenvalues repeated in threes, rotated; eigenvalues 1e-8 … 1e4, rotated,
    positive or of alternating sign; a PSD matrix of rank ⌊n/2⌋ (B Bᵀ); zero."""
    if kind == "random":
        G = rng.standard_normal((n, n))
        return carr(0.5 * (G + G.T))
    if kind == "identity":
        return np.eye(n)
    if kind == "repeated":
        return symmetric_with_eigenvalues(rng, 1.0 + np.arange(n) // 3)
    if kind == "graded":
        return symmetric_with_eigenvalues(rng, np.logspace(-8, 4, n))
    if kind == "graded_signed":
        return symmetric_with_eigenvalues(rng, np.logspace(-8, 4, n) * (-1.0) ** np.arange(n))
    if kind == "rank_half":
        B = rng.standard_normal((n, n // 2))
        S = B @ B.T
        return carr(0.5 * (S + S.T))
    if kind == "zero":
        return np.zeros((n, n))
    raise ValueError(kind)


def assert_weyl(w, w_ref, bound: float, where: str) -> None:
    err = float(np.max(np.abs(np.asarray(w) - w_ref))) if len(w_ref) else 0.0
    i = int(np.argmax(np.abs(np.asarray(w) - w_ref))) if len(w_ref) else 0
    assert err <= bound, (f"{where}: max |λ - λ_ref| = {err:.3e} > {bound:.3e} (index {i}: "
                          f"{w[i]!r} against {w_ref[i]!r})")


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kind", EIG_KINDS)
def test_eigvalsh_within_weyl_bound_of_scipy(rng, n, kind):
    """Ascending, and |λ_i − λ_i,scipy| ≤ 2 C n u ‖S‖: each is the exact spectrum of S + ΔS with
    ‖ΔS‖ ≤ C n u ‖S‖ (Jacobi and LAPACK's tridiagonal reduction are backward stable), and
    Weyl's theorem moves each ordered eigenvalue by at most ‖ΔS‖."""
    for draw in range(3):
        S = symmetric_matrix(kind, rng, n)
        S0 = S.copy()
        w = linalg.eigvalsh(S)
        assert same_bits(S, S0), "eigvalsh wrote into its input"
        assert w.shape == (n,) and w.dtype == np.float64
        assert np.all(np.diff(w) >= 0.0), f"{kind} n={n}: not ascending: {w}"
        w_ref = scipy.linalg.eigvalsh(S)
        assert_weyl(w, w_ref, 2 * eps(n) * norm2(S), f"{kind} n={n} draw {draw}")


@pytest.mark.parametrize("n", SIZES)
def test_eigvalsh_of_a_diagonal_matrix_is_its_sorted_diagonal(rng, n):
    """With no off-diagonal entry there is nothing to rotate: the eigenvalues are the
    diagonal, sorted, to the bit (the Weyl bound with ΔS = 0); repeats included."""
    d = np.round(rng.standard_normal(n) * 3.0) + rng.integers(0, 2, n) * 0.125 + 0.0  # no -0.0
    assert same_bits(linalg.eigvalsh(carr(np.diag(d))), np.sort(d))


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("cond_M", [1.0e1, 1.0e3])
def test_damping_rates_through_cholesky_inverse_and_products(rng, n, cond_M):
    """The controller's case (eq. 21): μ = eig(M⁻¹D) as eigvalsh(L⁻¹ D L⁻ᵀ), M = L Lᵀ, every
    step by these kernels. On the formed S, eigvalsh meets the Weyl bound 2 C n u ‖S‖ against
    SciPy. End to end, against scipy.linalg.eigh(D, M): the Cholesky backward error
    ‖ΔM‖ ≤ ε‖M‖ moves μ by ≤ εκ(M)‖S‖ (Ostrowski), the inverse's column-wise backward error
    acts as a perturbation 2√n ε κ(L) ‖D‖ of D, and the products and eigvalsh add ε‖S‖ each;
    with ‖S‖ ≤ ‖M⁻¹‖ ‖D‖ and κ(L) = √κ(M), each computation is within
    ε (κ(M) + 2√(n κ(M)) + 2) ‖M⁻¹‖ ‖D‖ of the exact μ, and twice that of the other."""
    for draw in range(3):
        M = symmetric_with_eigenvalues(rng, 5.0 * np.logspace(0, -math.log10(cond_M), n))
        G = rng.standard_normal((n, n))
        D = carr(0.5 * (G @ G.T + (G @ G.T).T) + np.diag(rng.uniform(0.0, 4.0, n)))
        L_inv = linalg.inverse(linalg.cholesky_lower(M))
        S = linalg.matmul(linalg.matmul(L_inv, D), carr(L_inv.T))
        S = carr(0.5 * (S + S.T))
        mu = linalg.eigvalsh(S)
        where = f"κ(M)={cond_M:g} n={n} draw {draw}"
        assert_weyl(mu, scipy.linalg.eigvalsh(S), 2 * eps(n) * norm2(S), where + " (same S)")
        kappa = float(np.linalg.cond(M))
        scale = float(norm2(np.linalg.inv(M)) * norm2(D))
        bound = 2 * eps(n) * (kappa + 2 * math.sqrt(n * kappa) + 2) * scale
        assert_weyl(mu, scipy.linalg.eigh(D, M, eigvals_only=True), bound, where + " (end to end)")


def test_eigvalsh_of_a_non_finite_matrix_is_nan():
    """The module docstring: NaN everywhere if S is not finite."""
    for v in (np.nan, np.inf):
        S = np.eye(6)
        S[4, 1] = S[1, 4] = v
        assert np.isnan(linalg.eigvalsh(carr(S))).all()


# -- SVD -------------------------------------------------------------------------------------

def assert_orthonormal_columns(Q, N: int, where: str) -> None:
    """‖QᵀQ − I‖ ≤ C N u: rotations and normalisations each lose O(u) of orthogonality."""
    Q = np.asarray(Q)
    err = norm2(np.asarray(ld(Q).T @ ld(Q) - np.eye(Q.shape[1]), dtype=np.float64))
    assert err <= eps(N), f"{where}: ‖QᵀQ - I‖ = {err:.3e} > {eps(N):.3e}"


def singular_clusters(sigma, tau: float) -> list[list[int]]:
    """Runs of consecutive σ (descending) less than τ apart."""
    groups: list[list[int]] = [[0]] if len(sigma) else []
    for i in range(1, len(sigma)):
        if sigma[i - 1] - sigma[i] <= tau:
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups


def assert_subspaces_match(V, V_ref, sigma_ref, norm_A: float, e: float, zero_gap: bool,
                           where: str) -> int:
    """For each σ alone, and each cluster of σ within 1e-8 ‖A‖ of each other, the spectral
    projector P = V_c V_cᵀ of the kernel's vectors (columns of V) against SciPy's:
    ‖P − P_ref‖ = ‖sin Θ‖ ≤ √2 e‖A‖/δ for each computation (Wedin's theorem, residuals ≤
    e‖A‖ on either side), δ the gap from the cluster's σ to the others (and to 0 for the left
    vectors of a tall matrix, ``zero_gap``), so ≤ 2√2 e‖A‖/δ + 2e between the two, the 2e for
    the vectors' own loss of orthonormality. For one σ this is the angle between the two
    vectors: the vector up to sign. Checked where that bound is below 1; returns how many
    projectors were checked."""
    k = len(sigma_ref)
    groups = [[i] for i in range(k)] + [
        g for g in singular_clusters(sigma_ref, 1e-8 * norm_A) if len(g) > 1]
    checked = 0
    for g in groups:
        others = [sigma_ref[j] for j in range(k) if j not in g]
        lo, hi = min(sigma_ref[g]), max(sigma_ref[g])
        delta = min([min(abs(lo - s), abs(hi - s)) for s in others], default=math.inf)
        if zero_gap:
            delta = min(delta, lo)
        if delta == 0.0:
            continue
        bound = 2 * math.sqrt(2) * e * norm_A / delta + 2 * e
        if bound >= 1.0:
            continue
        P = V[:, g] @ V[:, g].T
        P_ref = V_ref[:, g] @ V_ref[:, g].T
        err = norm2(P - P_ref)
        assert err <= bound, (f"{where}: σ{g} = {sigma_ref[g]}, gap {delta:.3e}: "
                              f"‖P - P_scipy‖ = {err:.3e} > {bound:.3e}")
        checked += 1
    return checked


@pytest.mark.parametrize("m,n", SHAPES)
@pytest.mark.parametrize("kind", SVD_KINDS)
def test_svd_singular_values_within_weyl_bound_of_scipy(rng, m, n, kind):
    """σ descending, and |σ_i − σ_i,scipy| ≤ 2 C N u ‖A‖ for svd and singular_values (Weyl for
    singular values: each is exact for A + ΔA, ‖ΔA‖ ≤ C N u ‖A‖). On the graded matrices
    this is a relative bound on σ_min = 1e-12: |Δσ_min|/σ_min ≤ 2 C N u ‖A‖/σ_min."""
    A = svd_matrix(kind, rng, m, n)
    U, s, Vt = linalg.svd(A)
    assert U.shape == (m, n) and s.shape == (n,) and Vt.shape == (n, n)
    assert all(x.dtype == np.float64 and x.flags.c_contiguous for x in (U, s, Vt))
    assert np.all(np.diff(s) <= 0.0) and np.all(s >= 0.0), f"{kind} {m}×{n}: σ = {s}"
    s_ref = scipy.linalg.svdvals(A)
    norm_A = float(s_ref[0])
    bound = 2 * eps(max(m, n)) * norm_A
    assert_weyl(s, s_ref, bound, f"svd, {kind} {m}×{n}")
    s2 = linalg.singular_values(A)
    assert np.all(np.diff(s2) <= 0.0)
    assert_weyl(s2, s_ref, bound, f"singular_values, {kind} {m}×{n}")
    if kind == "graded" and n > 1:
        rel = abs(s[-1] - s_ref[-1]) / s_ref[-1]
        assert rel <= bound / s_ref[-1], f"{m}×{n}: σ_min relative error {rel:.3e}"


@pytest.mark.parametrize("m,n", SHAPES)
@pytest.mark.parametrize("kind", SVD_KINDS)
def test_svd_factors_are_orthonormal_and_reconstruct_A(rng, m, n, kind):
    """U (m×n) has orthonormal columns and Vt is orthogonal, to C N u, also where σ = 0 (a
    thin SVD's U completes the null directions); and ‖A − U diag(s) Vt‖ ≤ C N u ‖A‖ (the
    one-sided Jacobi SVD is backward stable; Demmel & Veselić 1992), the product formed in
    long double."""
    A = svd_matrix(kind, rng, m, n)
    U, s, Vt = linalg.svd(A)
    N = max(m, n)
    where = f"{kind} {m}×{n}"
    assert_orthonormal_columns(U, N, where + ", U")
    assert_orthonormal_columns(Vt.T, N, where + ", Vt")
    res = norm2(np.asarray(ld(A) - (ld(U) * ld(s)) @ ld(Vt), dtype=np.float64))
    assert res <= eps(N) * norm2(A), f"{where}: ‖A - U S Vt‖ = {res:.3e} > C N u ‖A‖"


@pytest.mark.parametrize("m,n", SHAPES)
@pytest.mark.parametrize("kind", SVD_KINDS)
def test_svd_singular_vectors_match_scipy(rng, m, n, kind):
    """Left and right singular vectors of separated σ, up to sign, and the subspaces of
    repeated σ, against scipy.linalg.svd (see :func:`assert_subspaces_match` for the bound)."""
    A = svd_matrix(kind, rng, m, n)
    U, _, Vt = linalg.svd(A)
    U_ref, s_ref, Vt_ref = scipy.linalg.svd(A, full_matrices=False)
    e = eps(max(m, n))
    norm_A = float(s_ref[0])
    if norm_A == 0.0:
        return
    where = f"{kind} {m}×{n}"
    checked = assert_subspaces_match(Vt.T, Vt_ref.T, s_ref, norm_A, e, False, where + ", V")
    checked += assert_subspaces_match(U, U_ref, s_ref, norm_A, e, m > n, where + ", U")
    assert checked > 0, f"{where}: no singular vector or subspace was compared"


@pytest.mark.parametrize("m,n", [(2, 2), (3, 3), (6, 6), (9, 9), (12, 12), (18, 18), (9, 3),
                                 (18, 6), (18, 12)])
def test_rank_deficient_matrices_have_zero_trailing_singular_values(rng, m, n):
    """A zero column makes σ_min exactly 0, so the computed σ_min ≤ C N u ‖A‖ (Weyl against 0,
    no reference needed). fl(B C) with B m×r, C r×n, r = ⌊n/2⌋, is B C + E with
    |E| ≤ γ_r |B||C| (Higham (3.13)), so σ_(r+1..n) ≤ γ_r ‖|B||C|‖ + C N u ‖A‖."""
    N = max(m, n)
    A = rng.standard_normal((m, n))
    A[:, n // 2] = 0.0
    A = carr(A)
    for s in (linalg.svd(A)[1], linalg.singular_values(A)):
        assert s[-1] <= eps(N) * norm2(A), f"zero column {m}×{n}: σ_min = {s[-1]:.3e}"
    r = n // 2
    B, Cf = rng.standard_normal((m, r)), rng.standard_normal((r, n))
    A = carr(B @ Cf)
    bound = float(gamma(max(r, 1))) * norm2(np.abs(B) @ np.abs(Cf)) + eps(N) * norm2(A)
    for s in (linalg.svd(A)[1], linalg.singular_values(A)):
        assert np.all(s[r:] <= bound), f"rank {r} of {m}×{n}: σ = {s[r:]} > {bound:.3e}"
        assert np.all(s[:r] > 1e3 * bound), f"rank {r} of {m}×{n}: σ = {s}"


def test_svd_of_a_1x1_and_of_a_zero_matrix():
    """[−3] = (±1)(3)(∓1) exactly; the zero matrix has σ = 0 exactly (the bound C N u ‖A‖ is
    0), with orthonormal U and orthogonal Vt."""
    U, s, Vt = linalg.svd(carr([[-3.0]]))
    assert s.tolist() == [3.0] and U[0, 0] * s[0] * Vt[0, 0] == -3.0 and abs(U[0, 0]) == 1.0
    assert linalg.singular_values(carr([[-3.0]])).tolist() == [3.0]
    for m, n in ((1, 1), (3, 3), (6, 2), (18, 18)):
        U, s, Vt = linalg.svd(np.zeros((m, n)))
        assert np.all(s == 0.0), (m, n, s)
        assert_orthonormal_columns(U, max(m, n), f"zero {m}×{n}, U")
        assert_orthonormal_columns(Vt.T, max(m, n), f"zero {m}×{n}, Vt")
        assert np.all(linalg.singular_values(np.zeros((n, m))) == 0.0)


@pytest.mark.parametrize("m,n", SHAPES)
def test_svd_of_a_non_finite_matrix_is_nan(rng, m, n):
    """NaN everywhere in U, s and Vt (and in singular_values) for a NaN or ±inf entry."""
    for (i, j), v in (((0, 0), np.nan), ((m - 1, n - 1), np.inf), ((m // 2, 0), -np.inf)):
        A = rng.standard_normal((m, n))
        A[i, j] = v
        A = carr(A)
        U, s, Vt = linalg.svd(A)
        assert np.isnan(U).all() and np.isnan(s).all() and np.isnan(Vt).all(), (m, n, i, j, v)
        assert U.shape == (m, n) and s.shape == (n,) and Vt.shape == (n, n)
        assert np.isnan(linalg.singular_values(A)).all()
        assert np.isnan(linalg.singular_values(carr(A.T))).all()


def test_svd_refuses_a_wide_matrix():
    """svd takes m ≥ n (its docstring); a wide matrix is a ValueError."""
    with pytest.raises(ValueError):
        linalg.svd(np.zeros((2, 3)))


@pytest.mark.parametrize("m,n", WIDE + TALL + ((18, 18),))
@pytest.mark.parametrize("kind", ("random", "graded", "rank_half", "identity"))
def test_singular_values_of_any_shape(rng, m, n, kind):
    """singular_values for wide, tall and square A: min(m, n) values, descending, within the
    Weyl bound 2 C N u ‖A‖ of SciPy's; σ(A) = σ(Aᵀ) within the same bound."""
    A = svd_matrix(kind, rng, m, n)
    s = linalg.singular_values(A)
    assert s.shape == (min(m, n),) and np.all(np.diff(s) <= 0.0)
    s_ref = scipy.linalg.svdvals(A)
    bound = 2 * eps(max(m, n)) * float(s_ref[0])
    assert_weyl(s, s_ref, bound, f"{kind} {m}×{n}")
    assert_weyl(linalg.singular_values(carr(A.T)), s, bound, f"{kind} {m}×{n}, transposed")


def batch(rng: np.random.Generator, m: int, n: int) -> np.ndarray:
    """One matrix of each SVD kind, stacked (len(SVD_KINDS)×m×n)."""
    return carr(np.stack([svd_matrix(k, rng, m, n) for k in SVD_KINDS]))


@pytest.mark.parametrize("m,n", SHAPES + WIDE)
def test_batched_singular_values(rng, m, n):
    """Row k is singular_values(A[k]) to the bit, within the Weyl bound of SciPy's; a
    non-finite A[k] gives a NaN row and leaves the other rows' bits unchanged."""
    A = batch(rng, m, n)
    S = linalg.batched_singular_values(A)
    assert S.shape == (len(A), min(m, n)) and S.flags.c_contiguous
    for k, kind in enumerate(SVD_KINDS):
        assert same_bits(S[k], linalg.singular_values(carr(A[k]))), kind
        s_ref = scipy.linalg.svdvals(A[k])
        assert_weyl(S[k], s_ref, 2 * eps(max(m, n)) * float(s_ref[0]), f"{kind} {m}×{n}")
    A_bad = A.copy()
    A_bad[1, 0, 0] = np.nan
    S_bad = linalg.batched_singular_values(A_bad)
    assert np.isnan(S_bad[1]).all()
    assert same_bits(np.delete(S_bad, 1, axis=0), np.delete(S, 1, axis=0))


@pytest.mark.parametrize("n", SIZES)
def test_svd_right(rng, n):
    """For each square A[k] of a batch of every SVD kind: S[k] descending within the Weyl
    bound 2 C n u ‖A‖ of SciPy's; Vt[k] orthogonal to C n u; each right vector an
    eigenvector of AᵀA, ‖AᵀA v_i − σ_i² v_i‖ ≤ 4 C n u ‖A‖² (from A = U S Vᵀ + E,
    ‖E‖ ≤ C n u ‖A‖, U and V orthonormal to C n u: ‖A v_i − σ_i u_i‖ and ‖Aᵀ u_i − σ_i v_i‖
    ≤ 2 C n u ‖A‖); the vectors against SciPy's as for svd; and batch members independent:
    A[k] alone gives the same bits, and a NaN A[k] gives NaN there and changes no other bit."""
    A = batch(rng, n, n)
    S, Vt = linalg.svd_right(A)
    assert S.shape == (len(A), n) and Vt.shape == (len(A), n, n)
    e = eps(n)
    for k, kind in enumerate(SVD_KINDS):
        where = f"{kind} n={n}"
        _, s_ref, Vt_ref = scipy.linalg.svd(A[k])
        norm_A = float(s_ref[0])
        assert np.all(np.diff(S[k]) <= 0.0)
        assert_weyl(S[k], s_ref, 2 * e * norm_A, where)
        assert_orthonormal_columns(Vt[k].T, n, where + ", Vt")
        AtA = ld(A[k]).T @ ld(A[k])
        for i in range(n):
            v = ld(Vt[k, i])
            r = float(np.linalg.norm(np.asarray(AtA @ v - ld(S[k, i]) ** 2 * v, dtype=float)))
            assert r <= 4 * e * norm_A**2, f"{where}: ‖AᵀA v_{i} - σ² v_{i}‖ = {r:.3e}"
        if norm_A > 0.0:
            assert_subspaces_match(Vt[k].T, Vt_ref.T, s_ref, norm_A, e, False, where + ", V")
        S1, Vt1 = linalg.svd_right(carr(A[k:k + 1]))
        assert same_bits(S1[0], S[k]) and same_bits(Vt1[0], Vt[k]), where
    A_bad = A.copy()
    A_bad[2, n - 1, 0] = np.inf
    A_bad[4, 0, n - 1] = np.nan
    S_bad, Vt_bad = linalg.svd_right(A_bad)
    assert np.isnan(S_bad[[2, 4]]).all() and np.isnan(Vt_bad[[2, 4]]).all()
    keep = [k for k in range(len(A)) if k not in (2, 4)]
    assert same_bits(S_bad[keep], S[keep]) and same_bits(Vt_bad[keep], Vt[keep])


# -- the same bits ---------------------------------------------------------------------------

def determinism_inputs() -> dict[str, np.ndarray]:
    """Fixed inputs for every kernel (seed 7); made once and passed to other processes as a
    file, since making them again there would go through OpenBLAS."""
    rng = np.random.default_rng(7)
    G = rng.standard_normal((18, 18))
    return {
        "a": carr(rng.standard_normal(18) * 10.0 ** rng.integers(-4, 5, 18)),
        "b": carr(rng.standard_normal(18)),
        "A": carr(rng.standard_normal((18, 18))),
        "B": carr(rng.standard_normal((18, 12))),
        "spd": carr(0.5 * ((G @ G.T + np.eye(18)) + (G @ G.T + np.eye(18)).T)),
        "sym": symmetric_matrix("graded_signed", rng, 18),
        "graded": svd_matrix("graded", rng, 12, 12),
        "tall": carr(rng.standard_normal((18, 6))),
        "wide": carr(rng.standard_normal((6, 18))),
        "stack": batch(rng, 6, 6),
    }


def kernel_outputs(x: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every kernel's output on :func:`determinism_inputs`, by name."""
    out = {
        "dot": np.float64(linalg.dot(x["a"], x["b"])),
        "matvec": linalg.matvec(x["A"], x["b"]),
        "matmul": linalg.matmul(x["A"], x["B"]),
        "solve": linalg.solve(x["A"], x["b"]),
        "inverse": linalg.inverse(x["A"]),
        "cholesky_lower": linalg.cholesky_lower(x["spd"]),
        "eigvalsh": linalg.eigvalsh(x["sym"]),
        "singular_values": linalg.singular_values(x["wide"]),
        "singular_values_graded": linalg.singular_values(x["graded"]),
        "batched_singular_values": linalg.batched_singular_values(x["stack"]),
    }
    for name in ("A", "graded", "tall"):
        out[f"svd_{name}_U"], out[f"svd_{name}_s"], out[f"svd_{name}_Vt"] = linalg.svd(x[name])
    out["svd_right_S"], out["svd_right_Vt"] = linalg.svd_right(x["stack"])
    out["svd_right_sequence_S"], out["svd_right_sequence_Vt"] = linalg.svd_right_sequence(
        x["stack"], np.empty((0, 0)))
    return out


def drifting_sequence(rng: np.random.Generator, n: int, steps: int) -> np.ndarray:
    """A_k = U_k diag(s_k) V_kᵀ with U, V turned by a fixed small rotation each step and σ
    graded 3 … 0.03, each moving by up to 0.4 % a step (at n = 12 some neighbours cross): a
    Γ over consecutive steps."""
    def turn(scale):
        X = rng.standard_normal((n, n)) * scale
        return scipy.linalg.expm(X - X.T)
    U, V = orthonormal(rng, n, n), orthonormal(rng, n, n)
    dU, dV = turn(2e-3), turn(2e-3)
    s0 = np.logspace(np.log10(3.0), np.log10(0.03), n)
    out = np.empty((steps, n, n))
    for k in range(steps):
        s = s0 * (1.0 + 0.3 * np.sin(1e-3 * k * np.arange(1, n + 1)))
        out[k] = (U * s) @ V.T
        U, V = dU @ U, dV @ V
    return carr(out)


@pytest.mark.parametrize("n", (6, 12))
def test_svd_right_sequence_on_a_drifting_sequence(rng, n):
    """Started from the step before's vectors: every member within the Weyl bound of SciPy's σ,
    its vectors eigenvectors of AᵀA and orthonormal to C n u at the end of 3,000 steps (the
    start re-orthonormalised, so rounding does not build up); a sequence cut in two and
    continued from the first part's last vectors, some of them negated (as the analysis'
    sign-continuous vectors are), gives the same bits; a jumping batch of every SVD kind is
    still right; a NaN member gives NaN there and the next starts again from the identity."""
    A = drifting_sequence(rng, n, 3000)
    S, Vt = linalg.svd_right_sequence(A, np.empty((0, 0)))
    # Started from the step before, not from the identity: other rotations, other last bits
    # (a cold start would give svd_right's bits on every member but the first).
    S_cold, _ = linalg.svd_right(A)
    assert same_bits(S[0], S_cold[0]) and not same_bits(S[1:], S_cold[1:])
    e = eps(n)
    s_ref = np.linalg.svd(A, compute_uv=False)
    for k in (0, 1, 1500, 2999):
        assert_weyl(S[k], s_ref[k], 2 * e * s_ref[k, 0], f"step {k}")
    assert np.all(np.abs(S - s_ref) <= 2 * e * s_ref[:, :1])
    assert_orthonormal_columns(Vt[-1].T, n, "Vt at step 2999")
    AtA = ld(A[-1]).T @ ld(A[-1])
    for i in range(n):
        v = ld(Vt[-1, i])
        r = float(np.linalg.norm(np.asarray(AtA @ v - ld(S[-1, i]) ** 2 * v, dtype=float)))
        assert r <= 4 * e * s_ref[-1, 0] ** 2, f"‖AᵀA v_{i} - σ² v_{i}‖ = {r:.3e}"
    S1, Vt1 = linalg.svd_right_sequence(carr(A[:1234]), np.empty((0, 0)))
    flip = np.where(np.arange(n) % 3 == 1, -1.0, 1.0)[:, None]
    S2, Vt2 = linalg.svd_right_sequence(carr(A[1234:]), carr(Vt1[-1] * flip))
    assert same_bits(np.concatenate([S1, S2]), S)
    assert same_bits(np.abs(np.concatenate([Vt1, Vt2])), np.abs(Vt))
    J = batch(rng, n, n)
    SJ, VtJ = linalg.svd_right_sequence(J, np.empty((0, 0)))
    for k, kind in enumerate(SVD_KINDS):
        _, sj, _ = scipy.linalg.svd(J[k])
        assert_weyl(SJ[k], sj, 2 * e * sj[0], f"{kind} after {SVD_KINDS[k - 1]}")
        assert_orthonormal_columns(VtJ[k].T, n, f"{kind}, Vt")
    bad = A[:20].copy()
    bad[7, 0, 0] = np.nan
    Sb, Vtb = linalg.svd_right_sequence(bad, np.empty((0, 0)))
    assert np.isnan(Sb[7]).all() and np.isnan(Vtb[7]).all()
    assert same_bits(Sb[:7], S[:7])
    S8, _ = linalg.svd_right_sequence(carr(A[8:20]), np.empty((0, 0)))
    assert same_bits(Sb[8:], S8)


def differing(out: dict, ref: dict) -> list[str]:
    return [k for k in ref if not same_bits(out[k], ref[k])]


def test_the_same_input_gives_the_same_bits_twice_and_is_not_modified():
    x = determinism_inputs()
    x0 = {k: v.copy() for k, v in x.items()}
    first = kernel_outputs(x)
    assert differing(x, x0) == [], "a kernel wrote into its input"
    assert differing(kernel_outputs(x), first) == []


def test_a_c_order_copy_of_a_strided_or_fortran_view_gives_the_same_bits():
    """The same values reached through a non-contiguous view (every 2nd row, 3rd column of a
    larger array) or a Fortran-ordered copy, then copied to C order, give the same bits."""
    x = determinism_inputs()
    ref = kernel_outputs(x)
    strided, fortran = {}, {}
    for k, v in x.items():
        big = np.full((*(2 * d + 1 for d in v.shape[:-1]), 3 * v.shape[-1] + 2), np.nan)
        index = (*(slice(0, 2 * d, 2) for d in v.shape[:-1]), slice(0, 3 * v.shape[-1], 3))
        big[index] = v
        view = big[index]
        assert not view.flags.c_contiguous and same_bits(np.ascontiguousarray(view), v)
        strided[k] = np.ascontiguousarray(view)
        fortran[k] = np.ascontiguousarray(np.asfortranarray(v))
    assert differing(kernel_outputs(strided), ref) == []
    assert differing(kernel_outputs(fortran), ref) == []


CHILD = """
import importlib.util, sys
import numpy as np
spec = importlib.util.spec_from_file_location("linalg_checks", sys.argv[1])
checks = importlib.util.module_from_spec(spec)
spec.loader.exec_module(checks)
with np.load(sys.argv[2]) as z:
    x = {k: z[k] for k in z.files}
out = checks.kernel_outputs(x)
out["numpy_matmul"] = x["A"] @ x["B"]
out["numpy_svdvals"] = np.linalg.svd(x["A"], compute_uv=False)
np.savez(sys.argv[3], **out)
"""


@pytest.mark.parametrize("env", [{"NUMBA_DISABLE_JIT": "1"}, {"OPENBLAS_CORETYPE": "Prescott"},
                                 {"OPENBLAS_CORETYPE": "Sandybridge"}],
                         ids=["python_mode", "openblas_prescott", "openblas_sandybridge"])
def test_another_process_gives_the_same_bits(tmp_path, env):
    """The kernels' outputs in a fresh process, as plain Python (``NUMBA_DISABLE_JIT=1``) or
    compiled with OpenBLAS forced to another processor's kernels, equal this process's to the
    bit: they are loops of IEEE operations in a fixed order. Under OPENBLAS_CORETYPE NumPy's
    own product or SVD changes bits (on this project's hosts it does); where it does not, the
    test could not have told, and is skipped after its check."""
    x = determinism_inputs()
    np.savez(tmp_path / "in.npz", **x)
    child_env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
    child_env.update(env)
    r = subprocess.run([sys.executable, "-c", CHILD, __file__, str(tmp_path / "in.npz"),
                        str(tmp_path / "out.npz")], cwd=ROOT, env=child_env,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    with np.load(tmp_path / "out.npz") as z:
        out = {k: z[k] for k in z.files}
    ref = kernel_outputs(x)
    assert differing(out, ref) == []
    if "OPENBLAS_CORETYPE" in env and same_bits(out["numpy_matmul"], x["A"] @ x["B"]) and \
            same_bits(out["numpy_svdvals"], np.linalg.svd(x["A"], compute_uv=False)):
        pytest.skip(f"{env}: NumPy's own results did not change either")
