"""SciPy's LAPACK routines called by name from the kernels, the same routine in both modes.

Compiled, a routine is bound by symbol name, not as a ctypes pointer, so the kernels that call
it can be cached: the name is registered again at every import. Under ``NUMBA_DISABLE_JIT=1``
that binding would be only a Numba *type*, and calling a type in Python builds a signature and
returns it: LAPACK would never run, and a kernel would hand back its ``np.empty`` output
buffers as results. There :func:`routine` binds the same address through ctypes instead, which
takes each array's ``.ctypes`` as its data pointer, as the compiled call does.

NumPy's ``linalg`` is not Numba's: ``np.linalg.cholesky`` factors with LAPACK's 'L' variant
where Numba's uses 'U', and ``np.linalg.inv`` solves A X = I (dgesv) where Numba's inverts the LU
factors (dgetri); the two modes differed in the last bits. :func:`cholesky_lower` and
:func:`inverse` make Numba's LAPACK calls themselves, so either mode gives Numba's results to
the bit.
"""

from __future__ import annotations

import ctypes

import llvmlite.binding as llvm
import numpy as np
from numba import types
from numba.core import config
from numba.extending import get_cython_function_address

from pipeline.sim.jit import jit


def routine(name: str, nargs: int):
    """``scipy.linalg.cython_lapack.<name>`` (``nargs`` pointer arguments, no result),
    callable from a kernel compiled or not."""
    address = get_cython_function_address("scipy.linalg.cython_lapack", name)
    if config.DISABLE_JIT:
        return ctypes.CFUNCTYPE(None, *([ctypes.c_void_p] * nargs))(address)
    llvm.add_symbol(f"pipeline_{name}", address)
    return types.ExternalFunction(f"pipeline_{name}", types.void(*([types.voidptr] * nargs)))


_dpotrf = routine("dpotrf", 5)
_dgetrf = routine("dgetrf", 6)
_dgetri = routine("dgetri", 7)


@jit
def cholesky_lower(a: np.ndarray) -> np.ndarray:
    """L with a = L Lᵀ (C order), as Numba's ``np.linalg.cholesky``: dpotrf 'U' on a C-ordered
    copy, which LAPACK reads as aᵀ, then the strict upper triangle zeroed. Reads a's lower
    triangle; LinAlgError if a is not positive definite."""
    n = a.shape[-1]
    if a.shape[-2] != n:
        raise np.linalg.LinAlgError("Last 2 dimensions of the array must be square.")
    out = a.copy()
    if n == 0:
        return out
    uplo = np.array([ord("U")], dtype=np.uint8)
    ints = np.array([n], dtype=np.int32)
    info = np.zeros(1, dtype=np.int32)
    _dpotrf(uplo.ctypes, ints.ctypes, out.ctypes, ints.ctypes, info.ctypes)
    if info[0] != 0:
        raise np.linalg.LinAlgError("Matrix is not positive definite.")
    for col in range(n):
        out[:col, col] = 0
    return out


@jit
def inverse(a: np.ndarray) -> np.ndarray:
    """a⁻¹ as Numba's ``np.linalg.inv``: dgetrf, then dgetri with its queried workspace, on a
    Fortran-ordered copy; the result Fortran-ordered like Numba's. LinAlgError if a is not
    finite or is singular."""
    n = a.shape[-1]
    if a.shape[-2] != n:
        raise np.linalg.LinAlgError("Last 2 dimensions of the array must be square.")
    if not np.all(np.isfinite(a)):
        raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
    t = np.ascontiguousarray(a.T).copy()  # row-major aᵀ: a in Fortran order
    if n == 0:
        return t.T
    ints = np.array([n, -1], dtype=np.int32)  # N = M = LDA, LWORK of the workspace query
    ipiv = np.empty(n, dtype=np.int32)
    info = np.zeros(1, dtype=np.int32)
    _dgetrf(ints[0:1].ctypes, ints[0:1].ctypes, t.ctypes, ints[0:1].ctypes, ipiv.ctypes,
            info.ctypes)
    if info[0] != 0:
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
    query = np.empty(1)
    _dgetri(ints[0:1].ctypes, t.ctypes, ints[0:1].ctypes, ipiv.ctypes, query.ctypes,
            ints[1:2].ctypes, info.ctypes)
    lwork = max(1, int(query[0]))
    work = np.empty(lwork)
    ints[1] = lwork
    _dgetri(ints[0:1].ctypes, t.ctypes, ints[0:1].ctypes, ipiv.ctypes, work.ctypes,
            ints[1:2].ctypes, info.ctypes)
    if info[0] != 0:
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
    return t.T
