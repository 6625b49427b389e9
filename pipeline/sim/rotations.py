"""Small rotation helpers shared by guidance, controllers and metrics (docs/equations.md §1)."""

from __future__ import annotations

import numpy as np


def skew(a: np.ndarray) -> np.ndarray:
    """[a]×, the matrix with [a]× b = a × b."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix, with w >= 0 (Shepperd's method)."""
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    return q if q[3] >= 0 else -q


def attitude_error(R: np.ndarray, R_des: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quaternion-vector attitude error and its kinematic map (eq. 14).

    With q_err = quat(R_desᵀ R) = (ε, η), η >= 0: x̃ = 2ε, and ẋ̃ = E (ω − R_errᵀ ω_des)
    with E = η I + [ε]×, ω and ω_des in their own body frames.
    """
    q = quat_from_matrix(R_des.T @ R)
    eps, eta = q[:3], q[3]
    return 2.0 * eps, eta * np.eye(3) + skew(eps)


def look_at(z_axis: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Rotation whose z column is ``z_axis`` and whose x column is ``x_hint`` made orthogonal."""
    z = z_axis / np.linalg.norm(z_axis)
    x = x_hint - z * (z @ x_hint)
    nx = np.linalg.norm(x)
    if nx < 1e-9:  # hint parallel to z: take any orthogonal direction
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
        nx = np.linalg.norm(x)
    x = x / nx
    return np.column_stack([x, np.cross(z, x), z])
