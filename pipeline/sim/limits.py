"""Rate and acceleration saturations of the two loops (eq. 16)."""

from __future__ import annotations

import functools
import math

import numpy as np

from pipeline.log_layout import BREVE_BLOCK_NAMES
from pipeline.sim.jit import jit
from pipeline.sim.linalg import dot
from pipeline.spec import Limits

# Blocks of v̆ = [ω_b; ν_e,lin; ν_e,ang] and the limit names that bound each.
# (The names and the flags are the log's, pipeline/log_layout.py.)
BREVE_BLOCKS = tuple((name, slice(3 * i, 3 * i + 3)) for i, name in enumerate(BREVE_BLOCK_NAMES))


@jit
def saturate(x: np.ndarray, bound: float) -> tuple[np.ndarray, bool]:
    """sat(x) = x · min(1, bound/‖x‖): keeps the direction, bounds the norm (eq. 16)."""
    n = math.sqrt(dot(x, x))
    if n == math.inf:  # ‖x‖² overflowed: rescale, or x·bound/‖x‖ would silently be 0
        s = np.max(np.abs(x))
        n = s * math.sqrt(dot(x / s, x / s))
    if n > bound:
        return x * (bound / n), True
    return x.copy(), False


@jit
def saturate_blocks(x: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Saturate each 3-block of a 9-vector by its bound; which blocks were limited."""
    out = np.empty(9)
    hit = np.zeros(3, dtype=np.bool_)
    for b in range(3):
        out[3 * b:3 * b + 3], hit[b] = saturate(x[3 * b:3 * b + 3], bounds[b])
    return out, hit


@functools.lru_cache(maxsize=64)
def breve_bounds(lim: Limits, kind: str) -> np.ndarray:
    """The bounds of the three v̆ blocks for ``kind`` 'acc' or 'rate'."""
    b = np.array([getattr(lim, f"{name}_{kind}") for name, _ in BREVE_BLOCKS])
    b.flags.writeable = False
    return b
