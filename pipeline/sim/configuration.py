"""The configuration's step q ⊕ δ (eq. 22), compiled: the reduced plant's update
q_{k+1} = q_k ⊕ v_{k+1} dt inside the mission loop, where Pinocchio's ``integrate`` cannot be
called.

q = [p_b; quat_tb (x, y, z, w); q_arm] (eq. 1) and δ = [δp (bus frame); δθ (bus frame);
δq_arm]. The bus moves along the screw of the constant twist (δp, δθ) over unit time:

    (R, p) ← (R, p) · exp(δp, δθ),   exp = (exp₃(δθ), V(δθ) δp),
    V(ω) x = x + (1 − cos θ)/θ² ω × x + (θ − sin θ)/θ³ ω × (ω × x),   θ = |ω|,

the quaternion of exp₃(ω) being (sin(θ/2) ω/θ, cos(θ/2)); the product quaternion is turned to
the hemisphere of the old one and brought back to unit norm to first order, (3 − |q|²)/2 q,
as Pinocchio's free-flyer ``integrate`` does; the arm's angles add. Checked against
Pinocchio's ``integrate`` (tests/test_rigid_body_terms.py).
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.sim.forward_dynamics import quat_rotation
from pipeline.sim.jit import jit

# Below this |δθ| the series of V's and exp₃'s coefficients (their error θ⁴/720 under 1e-16
# relative): the closed forms lose digits to cancellation there.
SERIES_BELOW = 1e-4


@jit
def integrate_configuration(q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """q ⊕ dq (module docstring): a new configuration vector."""
    w0, w1, w2 = dq[3], dq[4], dq[5]
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    t = math.sqrt(t2)
    if t < SERIES_BELOW:
        a = 0.5 - t2 / 24.0  # (1 − cos θ)/θ²
        b = 1.0 / 6.0 - t2 / 120.0  # (θ − sin θ)/θ³
        half = 0.5 - t2 / 48.0  # sin(θ/2)/θ
        c = 1.0 - t2 / 8.0  # cos(θ/2)
    else:
        a = (1.0 - math.cos(t)) / t2
        b = (t - math.sin(t)) / (t2 * t)
        half = math.sin(0.5 * t) / t
        c = math.cos(0.5 * t)
    x0, x1, x2 = dq[0], dq[1], dq[2]
    c0, c1, c2 = w1 * x2 - w2 * x1, w2 * x0 - w0 * x2, w0 * x1 - w1 * x0  # ω × x
    cc0, cc1, cc2 = w1 * c2 - w2 * c1, w2 * c0 - w0 * c2, w0 * c1 - w1 * c0  # ω × (ω × x)
    s = np.array([x0 + a * c0 + b * cc0, x1 + a * c1 + b * cc1, x2 + a * c2 + b * cc2])
    qx, qy, qz, qw = q[3], q[4], q[5], q[6]
    R = quat_rotation(qx, qy, qz, qw)
    out = q.copy()
    for i in range(3):
        out[i] = q[i] + R[i, 0] * s[0] + R[i, 1] * s[1] + R[i, 2] * s[2]
    ex, ey, ez, ew = half * w0, half * w1, half * w2, c
    # the Hamilton product q ⊗ e
    nx = qw * ex + qx * ew + qy * ez - qz * ey
    ny = qw * ey - qx * ez + qy * ew + qz * ex
    nz = qw * ez + qx * ey - qy * ex + qz * ew
    nw = qw * ew - qx * ex - qy * ey - qz * ez
    if nx * qx + ny * qy + nz * qz + nw * qw < 0.0:
        nx, ny, nz, nw = -nx, -ny, -nz, -nw
    alpha = (3.0 - (nx * nx + ny * ny + nz * nz + nw * nw)) / 2.0
    out[3], out[4], out[5], out[6] = alpha * nx, alpha * ny, alpha * nz, alpha * nw
    for i in range(7, q.size):
        out[i] = q[i] + dq[i - 1]
    return out
