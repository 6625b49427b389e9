"""Rate and acceleration saturations of the two loops (eq. 16)."""

from __future__ import annotations

import functools
import math

import numpy as np

from pipeline.shapes import BREVE_BLOCK_NAMES
from pipeline.sim.jit import jit
from pipeline.sim.linalg import dot
from pipeline.spec import Limits, NullSpaceImpedance

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
    """Saturate each block of v̆ by its bound: the three task blocks of three components, then
    a redundant arm's null-space block, the rest (eq. 37f); which blocks were limited."""
    out = np.empty(x.size)
    hit = np.zeros(bounds.size, dtype=np.bool_)
    for b in range(bounds.size):
        hi = 3 * b + 3 if b < 3 else x.size
        out[3 * b:hi], hit[b] = saturate(x[3 * b:hi], bounds[b])
    return out, hit


@functools.lru_cache(maxsize=64)
def breve_bounds(lim: Limits, kind: str, null_space: NullSpaceImpedance | None = None
                 ) -> np.ndarray:
    """The bounds of v̆'s blocks for ``kind`` 'acc' or 'rate': the three task blocks', then a
    redundant arm's null-space block's (``controller.null_space``) when given."""
    b = [getattr(lim, f"{name}_{kind}") for name, _ in BREVE_BLOCKS]
    if null_space is not None:
        b.append(getattr(null_space, kind))
    out = np.array(b)
    out.flags.writeable = False
    return out
