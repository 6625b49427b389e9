"""Singular values, and right-singular vectors, from LAPACK inside compiled kernels.

NumPy's and SciPy's wrappers cost more than the decomposition of a 12×12 matrix; calling
SciPy's Cython LAPACK entry points from Numba removes that overhead and lets the simulator read
Γ's conditioning inside its per-step kernel. :func:`singular_values` is LAPACK's dgesdd without
vectors, bit-identical to ``scipy.linalg.lapack.dgesdd(A, compute_uv=0)``; the analysis'
batched :func:`svd_right` is dgesvd computing Vᵀ but not U, which it does not need.
"""

from __future__ import annotations

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.lapack import routine

# Bound by name in compiled code, through ctypes under NUMBA_DISABLE_JIT (see
# :func:`pipeline.sim.lapack.routine`): the same LAPACK routine in both modes.
_dgesdd = routine("dgesdd", 14)
_dgesvd = routine("dgesvd", 14)


@jit
def singular_values(A: np.ndarray) -> np.ndarray:
    """σ of A, descending; NaN everywhere if A is not finite or LAPACK reports failure."""
    m, n = A.shape
    k = min(m, n)
    if not np.all(np.isfinite(A)):  # LAPACK's QR sweeps can loop forever on NaN
        return np.full(k, np.nan)
    a = np.ascontiguousarray(A.T)  # LAPACK is column-major: this is A's Fortran layout
    s = np.empty(k)
    jobz = np.array([ord("N")], dtype=np.uint8)
    dims = np.array([m, n, m, 1], dtype=np.int32)  # M, N, LDA, LDU = LDVT
    lwork = 3 * k + max(max(m, n), 7 * k)
    work = np.empty(lwork)
    lw = np.array([lwork], dtype=np.int32)
    iwork = np.empty(8 * k, dtype=np.int32)
    info = np.zeros(1, dtype=np.int32)
    unused = np.empty(1)
    _dgesdd(jobz.ctypes, dims[0:1].ctypes, dims[1:2].ctypes, a.ctypes, dims[2:3].ctypes,
            s.ctypes, unused.ctypes, dims[3:4].ctypes, unused.ctypes, dims[3:4].ctypes,
            work.ctypes, lw.ctypes, iwork.ctypes, info.ctypes)
    if info[0] != 0:
        s[:] = np.nan
    return s


@jit
def batched_singular_values(A: np.ndarray) -> np.ndarray:
    """σ of each A[k] (N×m×n → N×min(m, n)), by :func:`singular_values`."""
    out = np.empty((A.shape[0], min(A.shape[1], A.shape[2])))
    for k in range(A.shape[0]):
        out[k] = singular_values(A[k])
    return out


@jit
def svd_right(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """σ and Vᵀ of each square A[k] = U_k diag(σ_k) V_kᵀ (N×n×n → N×n, N×n×n), U not formed:
    the analysis' per-direction SVD of Γ (eq. 26).

    A C-ordered A[k] is A[k]ᵀ to LAPACK, and svd(Aᵀ) = V S Uᵀ: dgesvd with JOBU = 'S' and
    JOBVT = 'N' on it returns V as its U, in column-major order, which read row-major is Vᵀ.
    NaN everywhere for a matrix that is not finite or where LAPACK reports failure.
    """
    N, n = A.shape[0], A.shape[1]
    S = np.empty((N, n))
    Vt = np.empty((N, n, n))
    a = np.empty((n, n))
    u = np.empty((n, n))
    s = np.empty(n)
    unused = np.empty(1)
    jobs = np.array([ord("S"), ord("N")], dtype=np.uint8)
    lwork = 8 * n + 64
    work = np.empty(lwork)
    ints = np.array([n, 1, lwork], dtype=np.int32)  # M = N = LDA = LDU, LDVT, LWORK
    info = np.zeros(1, dtype=np.int32)
    for k in range(N):
        if not np.all(np.isfinite(A[k])):  # LAPACK's QR sweeps can loop forever on NaN
            S[k] = np.nan
            Vt[k] = np.nan
            continue
        a[:] = A[k]
        _dgesvd(jobs[0:1].ctypes, jobs[1:2].ctypes, ints[0:1].ctypes, ints[0:1].ctypes,
                a.ctypes, ints[0:1].ctypes, s.ctypes, u.ctypes, ints[0:1].ctypes, unused.ctypes,
                ints[1:2].ctypes, work.ctypes, ints[2:3].ctypes, info.ctypes)
        if info[0] != 0:
            S[k] = np.nan
            Vt[k] = np.nan
        else:
            S[k] = s
            Vt[k] = u
    return S, Vt
