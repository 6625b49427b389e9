"""Rate and acceleration saturations of the two loops (eq. 16)."""

from __future__ import annotations

import numpy as np

from pipeline.spec import Limits

# Blocks of v̆ = [ω_b; ν_e,lin; ν_e,ang] and the limit names that bound each.
BREVE_BLOCKS = (("omega_b", slice(0, 3)), ("nu_e_lin", slice(3, 6)), ("nu_e_ang", slice(6, 9)))
LIMIT_FLAGS = tuple(
    [f"sat_{name}_{kind}" for name, _ in BREVE_BLOCKS for kind in ("acc", "rate")]
    + ["sat_v_c_acc", "sat_v_c_rate", "sat_v_max"]
)


def saturate(x: np.ndarray, bound: float) -> tuple[np.ndarray, bool]:
    """sat(x) = x · min(1, bound/‖x‖): keeps the direction, bounds the norm (eq. 16)."""
    n = float(np.sqrt(x @ x))
    if n > bound:
        return x * (bound / n), True
    return x, False


def saturate_breve(x: np.ndarray, lim: Limits, kind: str) -> tuple[np.ndarray, dict[str, bool]]:
    """Block-wise saturation of a 9-vector of rates (``kind='rate'``) or accelerations."""
    out = np.empty_like(x)
    flags = {}
    for name, sl in BREVE_BLOCKS:
        out[sl], flags[f"sat_{name}_{kind}"] = saturate(x[sl], getattr(lim, f"{name}_{kind}"))
    return out, flags
