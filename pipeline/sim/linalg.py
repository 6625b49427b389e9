"""Small dense linear algebra of the project's own: the same bits on every processor.

The step's matrices are small and fixed-size (3 to 18). Through NumPy, Numba's ``@`` and
``np.linalg`` they went to OpenBLAS and LAPACK, whose kernels are chosen at run time for the
processor: a product or a decomposition then differed in its last bits from one processor to
the next, and the unstable nominal loop amplified that to 1e-6 in the logs (issue 21). These
kernels do the same work in plain loops of IEEE operations in a fixed order, which no
processor, Numba CPU target or BLAS build can change (``fastmath`` stays off, so LLVM may
neither reorder a sum nor fuse a multiply-add). Under ``NUMBA_DISABLE_JIT=1`` the same loops
run in Python on the same floats, with the same results.

- Products sum k = 0, 1, … sequentially from 0.0 (:func:`matmul`, :func:`matvec`, :func:`dot`).
- :func:`solve`, :func:`inverse` and :func:`determinant`: LU with partial pivoting (the
  first largest pivot).
- :func:`cholesky_lower`: Cholesky–Banachiewicz, row by row.
- :func:`eigvalsh`: cyclic Jacobi on a symmetric matrix.
- :func:`svd`, :func:`singular_values`, :func:`svd_right`: one-sided (Hestenes) Jacobi on the
  rows of Aᵀ, i.e. A's columns, which it rotates until they are orthogonal to working
  precision; σ are then their norms, each to a small multiple of n √m ε relative to itself
  when A's columns are well scaled (better than LAPACK's bidiagonal QR for the small σ).

All take and return C-ordered float64 arrays; a caller passes C-ordered copies, so each
kernel has one compiled specialisation (``tests/test_compile.py``). ``tests/test_linalg.py``
checks every kernel against SciPy on random and ill-conditioned matrices.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.sim.jit import jit

EPS = 2.0**-52  # the spacing of doubles at 1
MAX_SWEEPS = 60  # Jacobi sweeps: quadratic convergence needs fewer than 10 at n <= 18


@jit
def dot(a: np.ndarray, b: np.ndarray) -> float:
    """Σ_k a_k b_k, summed in order from 0.0."""
    s = 0.0
    for k in range(a.shape[0]):
        s += a[k] * b[k]
    return s


@jit
def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x, each entry summed in order from 0.0."""
    m, n = A.shape
    y = np.empty(m)
    for i in range(m):
        s = 0.0
        for k in range(n):
            s += A[i, k] * x[k]
        y[i] = s
    return y


@jit
def matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A B, each entry summed in order from 0.0."""
    m, n = A.shape
    p = B.shape[1]
    C = np.empty((m, p))
    for i in range(m):
        for j in range(p):
            s = 0.0
            for k in range(n):
                s += A[i, k] * B[k, j]
            C[i, j] = s
    return C


@jit
def _all_finite(A: np.ndarray) -> bool:
    for x in A.ravel():
        if not math.isfinite(x):
            return False
    return True


@jit
def _pivot(lu: np.ndarray, k: int) -> tuple[int, float]:
    """Partial pivoting at column k: the first row i >= k of the largest |lu[i, k]|, and that
    magnitude."""
    p = k
    big = abs(lu[k, k])
    for i in range(k + 1, lu.shape[0]):
        if abs(lu[i, k]) > big:
            p, big = i, abs(lu[i, k])
    return p, big


@jit
def _lu(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P A = L U in place of a copy (L unit lower, below the diagonal; U on and above), with
    the row order ``perm``; LinAlgError if A is not finite or a pivot is exactly 0."""
    n = A.shape[0]
    if A.shape[1] != n:
        raise np.linalg.LinAlgError("the matrix is not square")
    if not _all_finite(A):
        raise np.linalg.LinAlgError("the matrix is not finite")
    lu = A.copy()
    perm = np.arange(n)
    for k in range(n):
        p, big = _pivot(lu, k)
        if big == 0.0:
            raise np.linalg.LinAlgError("the matrix is singular")
        if p != k:
            for j in range(n):
                lu[k, j], lu[p, j] = lu[p, j], lu[k, j]
            perm[k], perm[p] = perm[p], perm[k]
        for i in range(k + 1, n):
            f = lu[i, k] / lu[k, k]
            lu[i, k] = f
            for j in range(k + 1, n):
                lu[i, j] -= f * lu[k, j]
    return lu, perm


@jit
def _lu_substitute(lu: np.ndarray, perm: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with A x = b from A's :func:`_lu` factors."""
    n = lu.shape[0]
    x = np.empty(n)
    for i in range(n):
        s = b[perm[i]]
        for k in range(i):
            s -= lu[i, k] * x[k]
        x[i] = s
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= lu[i, k] * x[k]
        x[i] = s / lu[i, i]
    return x


@jit
def solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with A x = b (LU with partial pivoting); LinAlgError if A is singular or not
    finite."""
    lu, perm = _lu(A)
    return _lu_substitute(lu, perm, b)


@jit
def inverse(A: np.ndarray) -> np.ndarray:
    """A⁻¹, column by column from one LU factorisation; LinAlgError if A is singular or not
    finite."""
    lu, perm = _lu(A)
    n = A.shape[0]
    out = np.empty((n, n))
    e = np.zeros(n)
    for j in range(n):
        e[j] = 1.0
        out[:, j] = _lu_substitute(lu, perm, e)
        e[j] = 0.0
    return out


@jit
def determinant(A: np.ndarray) -> float:
    """det A: the product of the pivots of Gaussian elimination with partial pivoting, signed
    by the row swaps; exactly 0.0 when a column has no nonzero pivot (a singular minor is a
    value here, not an error)."""
    n = A.shape[0]
    lu = A.copy()
    det = 1.0
    for k in range(n):
        p, big = _pivot(lu, k)
        if big == 0.0:
            return 0.0
        if p != k:
            for j in range(n):
                lu[k, j], lu[p, j] = lu[p, j], lu[k, j]
            det = -det
        det *= lu[k, k]
        for i in range(k + 1, n):
            f = lu[i, k] / lu[k, k]
            for j in range(k + 1, n):
                lu[i, j] -= f * lu[k, j]
    return det


@jit
def cholesky_lower(A: np.ndarray) -> np.ndarray:
    """L lower triangular with A = L Lᵀ, from A's lower triangle; LinAlgError if A is not
    finite or not positive definite."""
    n = A.shape[0]
    if A.shape[1] != n:
        raise np.linalg.LinAlgError("the matrix is not square")
    if not _all_finite(A):
        raise np.linalg.LinAlgError("the matrix is not finite")
    L = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if not s > 0.0:  # NaN too
                    raise np.linalg.LinAlgError("the matrix is not positive definite")
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    return L


@jit
def _rotation(zeta: float) -> tuple[float, float]:
    """(c, s) of the plane rotation with tangent t = sign(ζ)/(|ζ| + √(1 + ζ²)), the smaller
    root of t² + 2ζt − 1 = 0 (Rutishauser)."""
    if abs(zeta) > 1e150:  # ζ² would overflow
        t = 0.5 / zeta
    else:
        t = 1.0 / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
        if zeta < 0.0:
            t = -t
    c = 1.0 / math.sqrt(1.0 + t * t)
    return c, c * t


@jit
def eigvalsh(S: np.ndarray) -> np.ndarray:
    """Eigenvalues of the symmetric S (its lower triangle is read), ascending: cyclic Jacobi,
    each off-diagonal entry rotated to 0 in turn until all are negligible against their
    diagonal, |a_pq| <= ε √|a_pp a_qq|. NaN everywhere if S is not finite."""
    n = S.shape[0]
    w = np.empty(n)
    if not _all_finite(S):
        w[:] = np.nan
        return w
    a = np.empty((n, n))
    for i in range(n):
        for j in range(i + 1):
            a[i, j] = S[i, j]
            a[j, i] = S[i, j]
    for _ in range(MAX_SWEEPS):
        rotated = False
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = a[p, q]
                if abs(apq) <= EPS * math.sqrt(abs(a[p, p] * a[q, q])):
                    continue
                c, s = _rotation((a[q, q] - a[p, p]) / (2.0 * apq))
                for r in range(n):  # columns p and q: A J
                    arp, arq = a[r, p], a[r, q]
                    a[r, p] = c * arp - s * arq
                    a[r, q] = s * arp + c * arq
                for r in range(n):  # rows p and q: Jᵀ (A J)
                    apr, aqr = a[p, r], a[q, r]
                    a[p, r] = c * apr - s * aqr
                    a[q, r] = s * apr + c * aqr
                a[p, q] = 0.0
                a[q, p] = 0.0
                rotated = True
        if not rotated:
            break
    for i in range(n):
        w[i] = a[i, i]
    return np.sort(w)


@jit
def _orthogonalise_rows(B: np.ndarray, W: np.ndarray) -> None:
    """One-sided Jacobi in place: rotate pairs of B's rows until every pair is orthogonal to
    working precision, |b_i · b_j| <= √m ε ‖b_i‖ ‖b_j‖ (LAPACK dgesvj's tolerance: a computed
    dot product of length m carries about √m ε of rounding), applying each rotation to W's
    rows too unless W is empty (no literal flag: a literal would compile one specialisation
    per value)."""
    n, m = B.shape
    with_vectors = W.shape[0] > 0
    tol = math.sqrt(m) * EPS
    for _ in range(MAX_SWEEPS):
        rotated = False
        for i in range(n - 1):
            for j in range(i + 1, n):
                alpha = 0.0
                beta = 0.0
                g = 0.0
                for k in range(m):
                    alpha += B[i, k] * B[i, k]
                    beta += B[j, k] * B[j, k]
                    g += B[i, k] * B[j, k]
                if abs(g) <= tol * math.sqrt(alpha) * math.sqrt(beta):
                    continue
                c, s = _rotation((beta - alpha) / (2.0 * g))
                for k in range(m):
                    bi, bj = B[i, k], B[j, k]
                    B[i, k] = c * bi - s * bj
                    B[j, k] = s * bi + c * bj
                if with_vectors:
                    for k in range(W.shape[1]):
                        wi, wj = W[i, k], W[j, k]
                        W[i, k] = c * wi - s * wj
                        W[j, k] = s * wi + c * wj
                rotated = True
        if not rotated:
            return


@jit
def _row_norms(B: np.ndarray) -> np.ndarray:
    n = B.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = math.sqrt(dot(B[i], B[i]))
    return out


@jit
def _descending(s: np.ndarray) -> np.ndarray:
    """The order that sorts s descending, ties kept in index order (a stable sort)."""
    return np.argsort(-s, kind="mergesort")


@jit
def singular_values(A: np.ndarray) -> np.ndarray:
    """σ of A (m×n), descending; NaN everywhere if A is not finite."""
    m, n = A.shape
    k = min(m, n)
    if not _all_finite(A):
        return np.full(k, np.nan)
    # The rows to orthogonalise: A's columns (Aᵀ's rows) when A is tall, else A's rows.
    B = np.ascontiguousarray(A.T) if m >= n else A.copy()
    _orthogonalise_rows(B, np.empty((0, 0)))
    s = _row_norms(B)
    return s[_descending(s)]


@jit
def svd(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD of A (m×n, m >= n): A = U diag(s) Vt, U m×n with orthonormal columns, s
    descending, Vt n×n orthogonal. With Aᵀ's rows rotated into orthogonal rows σ_i u_iᵀ by
    Jᵀ, V = J accumulates the rotations. A zero σ's column of U completes the others to an
    orthonormal set. NaN everywhere if A is not finite."""
    m, n = A.shape
    if m < n:
        raise ValueError("svd takes a square or tall matrix")
    U = np.empty((m, n))
    s = np.empty(n)
    Vt = np.empty((n, n))
    if not _all_finite(A):
        U[:] = np.nan
        s[:] = np.nan
        Vt[:] = np.nan
        return U, s, Vt
    B = np.ascontiguousarray(A.T)
    W = np.eye(n)
    _orthogonalise_rows(B, W)
    norms = _row_norms(B)
    order = _descending(norms)
    for c in range(n):
        i = order[c]
        s[c] = norms[i]
        Vt[c] = W[i]
        if norms[i] > 0.0:
            U[:, c] = B[i] / norms[i]
        else:
            U[:, c] = 0.0
    for c in range(n):
        if s[c] == 0.0:
            _complete_column(U, c)
    return U, s, Vt


@jit
def _complete_column(U: np.ndarray, c: int) -> None:
    """U[:, c] := the first unit vector e_r that keeps the most after Gram–Schmidt (twice)
    against U's other nonzero columns, normalised."""
    m, n = U.shape
    best = np.zeros(m)
    best_norm = -1.0
    for r in range(m):
        x = np.zeros(m)
        x[r] = 1.0
        for _ in range(2):
            for j in range(n):
                if j != c:
                    u = np.ascontiguousarray(U[:, j])
                    x -= dot(u, x) * u
        nx = math.sqrt(dot(x, x))
        if nx > best_norm:  # the first of equals wins
            best, best_norm = x, nx
    U[:, c] = best / best_norm


@jit
def batched_singular_values(A: np.ndarray) -> np.ndarray:
    """σ of each A[k] (N×m×n → N×min(m, n)), by :func:`singular_values`."""
    out = np.empty((A.shape[0], min(A.shape[1], A.shape[2])))
    for k in range(A.shape[0]):
        out[k] = singular_values(np.ascontiguousarray(A[k]))
    return out


@jit
def svd_right(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """σ and Vᵀ of each square A[k] = U_k diag(σ_k) V_kᵀ (N×n×n → N×n, N×n×n), U not kept:
    the analysis' per-direction SVD of Γ (eq. 26). NaN for an A[k] that is not finite."""
    N, n = A.shape[0], A.shape[1]
    S = np.empty((N, n))
    Vt = np.empty((N, n, n))
    for k in range(N):
        _, s, vt = svd(np.ascontiguousarray(A[k]))
        S[k] = s
        Vt[k] = vt
    return S, Vt


@jit
def _orthonormality_defect(P: np.ndarray) -> np.ndarray:
    """E = I − P Pᵀ (symmetric, each entry from one :func:`dot`)."""
    n = P.shape[0]
    E = np.empty((n, n))
    for i in range(n):
        for j in range(i + 1):
            e = (1.0 if i == j else 0.0) - dot(P[i], P[j])
            E[i, j] = e
            E[j, i] = e
    return E


@jit
def _reorthonormalise_rows(P: np.ndarray, E: np.ndarray) -> None:
    """One Newton–Schulz step towards the nearest matrix with orthonormal rows, in place:
    P ← P + ½ (I − P Pᵀ) P, with E = I − P Pᵀ given, which takes rows orthonormal to δ to
    rows orthonormal to O(δ²)."""
    C = matmul(E, P)
    for i in range(P.shape[0]):
        for k in range(P.shape[1]):
            P[i, k] += 0.5 * C[i, k]


@jit
def _near_orthonormal(E: np.ndarray) -> bool:
    """Whether ‖E‖_max < ½, E = I − P Pᵀ: P's rows close enough to orthonormal for the
    Newton–Schulz step to bring them closer (it converges for ‖I − P Pᵀ‖ < 1); a zero or
    arbitrary matrix is not a start."""
    for e in E.ravel():
        if abs(e) >= 0.5:
            return False
    return True


@jit
def svd_right_from(A: np.ndarray, Vt_before: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """σ (descending) and Vᵀ of the square A, started from the right vectors ``Vt_before`` of
    a matrix near it (the step before's), made orthonormal again by one Newton–Schulz step;
    from the identity if ``Vt_before`` is empty, not finite or far from orthonormal (then σ is
    :func:`singular_values`' to the bit). NaN everywhere if A is not finite.

    One-sided Jacobi started from V rotates the columns of A V, which are orthogonal but for
    A's change since, so it needs two or three sweeps where a start from the identity needs
    seven or eight. The rows rotated are those of A V, a product, so each σ is right to about
    n ε ‖A‖ absolutely (a small σ of a graded A to that, not to a small multiple of ε relative
    to itself as from the identity)."""
    n = A.shape[0]
    s = np.empty(n)
    Vt = np.empty((n, n))
    if not _all_finite(A):
        s[:] = np.nan
        Vt[:] = np.nan
        return s, Vt
    start = np.eye(n)
    if Vt_before.shape[0] == n and _all_finite(Vt_before):
        E = _orthonormality_defect(Vt_before)
        if _near_orthonormal(E):
            start = Vt_before.copy()
            _reorthonormalise_rows(start, E)
    B = matmul(start, np.ascontiguousarray(A.T))  # rows (A v_i)ᵀ: A V_start's columns
    _orthogonalise_rows(B, start)
    norms = _row_norms(B)
    order = _descending(norms)
    for c in range(n):
        s[c] = norms[order[c]]
        Vt[c] = start[order[c]]
    return s, Vt


@jit
def svd_right_sequence(A: np.ndarray, Vt0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """σ and Vᵀ of each square A[k] of a slowly varying sequence (N×n×n → N×n, N×n×n), as
    :func:`svd_right`, each started from the right vectors of the one before
    (:func:`svd_right_from`): the first from ``Vt0`` (the identity if ``Vt0`` is empty or not
    finite), a member after a non-finite one from the identity. About 1e-16 absolutely for the
    analysis' Γ, whose ‖Γ‖ is near 1 (eq. 26)."""
    N, n = A.shape[0], A.shape[1]
    S = np.empty((N, n))
    Vt = np.empty((N, n, n))
    before = Vt0
    for k in range(N):
        S[k], Vt[k] = svd_right_from(np.ascontiguousarray(A[k]), before)
        before = Vt[k]
    return S, Vt
