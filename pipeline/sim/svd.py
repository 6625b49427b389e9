"""Singular values alone, from LAPACK's dgesdd (jobz = 'N'), callable inside compiled kernels.

NumPy's and SciPy's wrappers cost more than the decomposition of a 12×12 matrix; calling
SciPy's Cython LAPACK entry point from Numba removes that overhead and lets the simulator read
Γ's conditioning inside its per-step kernel. The results are bit-identical to
``scipy.linalg.lapack.dgesdd(A, compute_uv=0)``.
"""

from __future__ import annotations

import llvmlite.binding as llvm
import numpy as np
from numba import types
from numba.extending import get_cython_function_address

from pipeline.sim.jit import jit

# Bound by symbol name, not as a ctypes pointer, so the kernels that call it can be cached:
# the name is registered again at every import.
llvm.add_symbol("pipeline_dgesdd",
                get_cython_function_address("scipy.linalg.cython_lapack", "dgesdd"))
_dgesdd = types.ExternalFunction("pipeline_dgesdd", types.void(*([types.voidptr] * 14)))


@jit
def singular_values(A: np.ndarray) -> np.ndarray:
    """σ of A, descending; NaN everywhere if LAPACK reports failure (non-finite input)."""
    m, n = A.shape
    k = min(m, n)
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
