"""Rotation helpers shared by the robot, guidance, controllers and metrics (eqs. 1, 14, 17)."""

from __future__ import annotations

import math

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.linalg import dot, matmul


@jit
def skew(a: np.ndarray) -> np.ndarray:
    """[a]×, the matrix with [a]× b = a × b."""
    S = np.empty((3, 3))
    skew_into(S, a)
    return S


@jit
def skew_into(S: np.ndarray, a: np.ndarray) -> None:
    """S := [a]×."""
    S[0, 0], S[0, 1], S[0, 2] = 0.0, -a[2], a[1]
    S[1, 0], S[1, 1], S[1, 2] = a[2], 0.0, -a[0]
    S[2, 0], S[2, 1], S[2, 2] = -a[1], a[0], 0.0


@jit
def vee(W: np.ndarray) -> np.ndarray:
    """The vector w of the skew part of W: vee([w]×) = w."""
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


@jit
def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix, with w >= 0 (Shepperd's method)."""
    t = R[0, 0] + R[1, 1] + R[2, 2]
    q = np.empty(4)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q[0] = (R[2, 1] - R[1, 2]) / s
        q[1] = (R[0, 2] - R[2, 0]) / s
        q[2] = (R[1, 0] - R[0, 1]) / s
        q[3] = 0.25 * s
    else:
        i = 0
        if R[1, 1] > R[i, i]:
            i = 1
        if R[2, 2] > R[i, i]:
            i = 2
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    if q[3] < 0:
        q = -q
    return q


@jit
def attitude_error(R: np.ndarray, R_des: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quaternion-vector attitude error and its kinematic map (eq. 14).

    With q_err = quat(R_desᵀ R) = (ε, η), η >= 0: x̃ = 2ε, and ẋ̃ = E (ω − R_errᵀ ω_des)
    with E = η I + [ε]×, ω and ω_des in their own body frames.
    """
    q = quat_from_matrix(matmul(np.ascontiguousarray(R_des.T), np.ascontiguousarray(R)))
    eps = q[:3].copy()
    return 2.0 * eps, q[3] * np.eye(3) + skew(eps)


@jit
def look_at(z_axis: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Rotation whose z column is ``z_axis`` and whose x column is ``x_hint`` made orthogonal
    (eq. 17); a hint parallel to z is replaced by a fixed orthogonal direction."""
    z = z_axis / math.sqrt(dot(z_axis, z_axis))
    x = x_hint - z * dot(z, x_hint)
    nx = math.sqrt(dot(x, x))
    if nx < 1e-9:
        other = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(z, other)
        nx = math.sqrt(dot(x, x))
    x = x / nx
    R = np.empty((3, 3))
    R[:, 0] = x
    R[:, 1] = np.cross(z, x)
    R[:, 2] = z
    return R
