"""The step's linear algebra: the project's kernels against BLAS and LAPACK, inside compiled code.

The simulator calls :mod:`pipeline.sim.linalg` from its compiled step; before, the same
compiled code called Numba's ``@`` and ``np.linalg``, which go to SciPy's BLAS and LAPACK. Each
operation here is timed the way the step meets it, in a compiled loop of ``calls`` calls on
the step's sizes, the two implementations alternating within each repeat (A B A B …) so a
drift of the host's speed falls on both. Reported per call, median over repeats, and the
ratio own / library per repeat (its median), below 1 where the own kernel is faster.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numba import njit

from pipeline.sim import linalg as la

CALLS = 2000


def _looped(kernel: Callable) -> Callable:
    """A compiled loop of ``n`` calls of ``kernel`` on the same arguments (not cached: the
    bench compiles it once per process)."""

    @njit
    def loop(n, a, b):
        out = kernel(a, b)
        for _ in range(n - 1):
            out = kernel(a, b)
        return out

    return loop


# Two-argument wrappers, so every case runs through the same loop; compiled, they inline.
@njit
def _own_matmul(a, b):
    return la.matmul(a, b)


@njit
def _blas_matmul(a, b):
    return a @ b


@njit
def _own_matvec(a, b):
    return la.matvec(a, b)


@njit
def _blas_matvec(a, b):
    return a @ b


@njit
def _own_solve(a, b):
    return la.solve(a, b)


@njit
def _lapack_solve(a, b):
    return np.linalg.solve(a, b)


@njit
def _own_cholesky(a, b):
    return la.cholesky_lower(a)


@njit
def _lapack_cholesky(a, b):
    return np.linalg.cholesky(a)


@njit
def _own_eigvalsh(a, b):
    return la.eigvalsh(a)


@njit
def _lapack_eigvalsh(a, b):
    return np.linalg.eigvalsh(a)


@njit
def _own_svd(a, b):
    return la.svd(a)[1]


@njit
def _lapack_svd(a, b):
    return np.linalg.svd(a)[1]


@njit
def _own_singular_values(a, b):
    return la.singular_values(a)


@njit
def _lapack_singular_values(a, b):
    # Numba's np.linalg.svd always forms the vectors (dgesdd 'A'); the step's old call asked
    # LAPACK for σ alone, so this row overstates LAPACK's cost.
    return np.linalg.svd(a)[1]


def _cases(rng: np.random.Generator) -> list[tuple[str, Callable, Callable, tuple]]:
    """(name, own, library, arguments) on the step's sizes: Γ and its products 12×12, M̆ 9×9
    (SPD), J⊕ 6×6."""
    g = rng.standard_normal((12, 12))
    a9 = rng.standard_normal((9, 9))
    spd = a9 @ a9.T + 9 * np.eye(9)
    j = rng.standard_normal((6, 6))
    return [
        ("matmul 12×12", _own_matmul, _blas_matmul, (g, g.copy())),
        ("matvec 12", _own_matvec, _blas_matvec, (g, g[0].copy())),
        ("solve 9 (M̆ v̆̇ = RHS)", _own_solve, _lapack_solve, (spd, a9[0].copy())),
        ("Cholesky 9 (M̆)", _own_cholesky, _lapack_cholesky, (spd, spd)),
        ("eigvalsh 9 (μ)", _own_eigvalsh, _lapack_eigvalsh, (spd, spd)),
        ("SVD 6×6 (damped J⊕⁻¹)", _own_svd, _lapack_svd, (j, j)),
        ("σ of 12×12 (Γ's conditioning; LAPACK with vectors)", _own_singular_values,
         _lapack_singular_values, (g, g)),
    ]


def linalg_costs(repeats: int, calls: int = CALLS, seed: int = 0) -> dict[str, dict]:
    """Per-call µs of each own kernel and its BLAS/LAPACK counterpart, both compiled, timed
    alternately; {name: {"own_us", "library_us", "ratio"}} with median, min and max."""
    rng = np.random.default_rng(seed)
    out = {}
    for name, own, lib, args in _cases(rng):
        loops = (_looped(own), _looped(lib))
        for loop in loops:  # compile and warm up outside the timing
            loop(2, *args)
        times: tuple[list[float], list[float]] = ([], [])
        for _ in range(repeats):
            for loop, t in zip(loops, times, strict=True):
                t0 = time.perf_counter()
                loop(calls, *args)
                t.append((time.perf_counter() - t0) / calls * 1e6)
        own_us, lib_us = np.asarray(times[0]), np.asarray(times[1])
        out[name] = {key: summary(x) for key, x in
                     (("own_us", own_us), ("library_us", lib_us), ("ratio", own_us / lib_us))}
    return out


def summary(samples) -> dict:
    """Median, min and max of repeated measurements, and how many (``make bench``'s figures)."""
    a = np.asarray(samples, dtype=float)
    return {"median": float(np.median(a)), "min": float(a.min()), "max": float(a.max()),
            "repeats": len(a)}


def linalg_markdown(costs: dict[str, dict]) -> str:
    rows = ["| operation | own (µs) | BLAS/LAPACK (µs) | own / library |", "|---|---|---|---|"]
    for name, c in costs.items():
        r = c["ratio"]
        rows.append(f"| {name} | {c['own_us']['median']:.2f} | {c['library_us']['median']:.2f} "
                    f"| {r['median']:.2f} [{r['min']:.2f}–{r['max']:.2f}] |")
    return "\n".join(rows)
