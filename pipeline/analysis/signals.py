"""Signal statistics of the analysis: lag-1, RMS, step jumps, directions (eqs. 25–28).

Pure functions of arrays; each works along axis 0 (time) and accepts N or N×k inputs.
"""

from __future__ import annotations

import numpy as np


def lag1_autocorrelation(x: np.ndarray) -> np.ndarray:
    """r₁ = Σ(x_k − x̄)(x_{k+1} − x̄) / Σ(x_k − x̄)² along axis 0 (eq. 25).

    Period-2 → −1, smooth → +1, white noise → 0 (± ~1/√N). A constant series gives NaN.
    """
    x = np.asarray(x, dtype=float)
    d = x - x.mean(axis=0)
    num = np.sum(d[:-1] * d[1:], axis=0)
    den = np.sum(d * d, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return num / den


def rms(x: np.ndarray) -> np.ndarray:
    """Root mean square along axis 0."""
    x = np.asarray(x, dtype=float)
    return np.sqrt(np.mean(x * x, axis=0))


def step_rms(x: np.ndarray) -> np.ndarray:
    """RMS of the step-to-step change x_{k+1} − x_k along axis 0 (step energy, eq. 26)."""
    return rms(np.diff(np.asarray(x, dtype=float), axis=0))


def velocity_jumps(v: np.ndarray) -> np.ndarray:
    """‖Δv_k‖ = ‖v_{k+1} − v_k‖ for each step (eq. 28); v is N×n."""
    return np.linalg.norm(np.diff(np.asarray(v, dtype=float), axis=0), axis=1)


def dominant_step_direction(x: np.ndarray) -> np.ndarray:
    """Unit direction of most step-to-step energy: first right-singular vector of Δx (eq. 27)."""
    d = np.diff(np.asarray(x, dtype=float), axis=0)
    _, _, Vt = np.linalg.svd(d, full_matrices=False)
    return Vt[0]


def abs_cos(a: np.ndarray, b: np.ndarray) -> float:
    """|cos| between two directions (eq. 27)."""
    a, b = np.asarray(a).ravel(), np.asarray(b).ravel()
    return float(abs(np.vdot(a, b)) / (np.linalg.norm(a) * np.linalg.norm(b)))
