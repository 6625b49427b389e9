"""A rigid body's inertial parameters as a spec sets them (eq. 39): the six numbers of the
tensor, its physical check, and their place in the loaded model.

A rotational inertia about the centre of mass is physical when it is the second moment of a
non-negative mass distribution: symmetric positive definite, and each principal moment at most
the sum of the other two (I₁ + I₂ ≥ I₃: Σ = ½ tr(I)·1 − I, the distribution's covariance times
its mass, is positive semi-definite). A Monte Carlo that disperses a tensor must stay there,
and the loader refuses a tensor outside it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pinocchio as pin

from pipeline.errors import SpecError

# Relative slack of the triangle inequality (a flat plate meets it with equality; its moments
# as written to 15 digits may miss it by round-off).
TRIANGLE_SLACK = 1e-12


def inertia_matrix(six: list[float] | np.ndarray) -> np.ndarray:
    """The 3×3 tensor of [I_xx, I_yy, I_zz, I_xy, I_xz, I_yz] (eq. 39)."""
    xx, yy, zz, xy, xz, yz = (float(x) for x in six)
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def inertia_six(I: np.ndarray) -> list[float]:
    """[I_xx, I_yy, I_zz, I_xy, I_xz, I_yz] of a symmetric 3×3 tensor (eq. 39)."""
    return [float(I[0, 0]), float(I[1, 1]), float(I[2, 2]),
            float(I[0, 1]), float(I[0, 2]), float(I[1, 2])]


def physical_problem(I: np.ndarray) -> str | None:
    """Why ``I`` is not a rigid body's rotational inertia about its centre of mass (eq. 39), or
    None: not positive definite, or a principal moment above the sum of the other two."""
    if not np.all(np.isfinite(I)):
        return "not finite"
    moments = np.linalg.eigvalsh(0.5 * (I + I.T))
    if moments[0] <= 0.0:
        return f"not positive definite (principal moments {_moments(moments)})"
    if moments[2] > (moments[0] + moments[1]) * (1.0 + TRIANGLE_SLACK):
        return (f"principal moments {_moments(moments)} break the triangle inequality "
                f"(I₁ + I₂ ≥ I₃: no mass distribution has them)")
    return None


def _moments(m: np.ndarray) -> str:
    return ", ".join(f"{x:.6g}" for x in m)


def body_joint(model: pin.Model, body: str, camera_frame: int) -> int:
    """The model's joint whose body is ``body``: "bus", the free joint's; "payload", the one
    the camera frame is on."""
    return 1 if body == "bus" else int(model.frames[camera_frame].parentJoint)


def set_inertial(model: pin.Model, inertial: Mapping, camera_frame: int, path) -> None:
    """Replace the bodies' inertial parameters in ``model`` (robot.inertial, eq. 39); a
    SpecError naming the field for a tensor that is not physical."""
    for body, p in inertial.items():
        I = inertia_matrix(p.inertia)
        why = physical_problem(I)
        if why is not None:
            raise SpecError(f"{path}: field robot.inertial.{body}.inertia: {why}")
        model.inertias[body_joint(model, body, camera_frame)] = pin.Inertia(
            float(p.mass), np.asarray(p.com, dtype=float), I)
