"""The conventions of a foreign log and their conversion to the project's (eq. 33).

The project's logs hold q = [p_b (world, m); quaternion x, y, z, w of R_tb; 6 joint angles
(rad)] and v = [v_b; ω_b; q̇]: Pinocchio's free-flyer velocity, the bus origin's linear
velocity and the bus angular velocity both in the bus frame (LOCAL), joint rates in rad/s.
A foreign log may differ in

- the quaternion's order (``xyzw`` or ``wxyz``),
- the frame of the bus velocities (``bus`` or ``world``: world axes),
- the point whose linear velocity is logged (``origin`` of the bus frame, or ``bus_com``, the
  bus body's centre of mass: v_origin = v_com − ω × c, c the CoM in the bus frame),
- its units (angles in ``rad`` or ``deg``, lengths in ``m`` or ``mm``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from pipeline.errors import SpecError
from pipeline.shapes import Q, V

QuatOrder = Literal["xyzw", "wxyz"]
VelocityFrame = Literal["bus", "world"]
LinearPoint = Literal["origin", "bus_com"]
UNIT_QUAT_TOL = 1e-6  # |‖quat‖ − 1| above this is not a unit quaternion rounded: refused
QUAT_ROUNDING = 4 * np.finfo(float).eps  # |‖quat‖ − 1| of a unit quaternion in float64


@dataclass(frozen=True)
class Conventions:
    quaternion: QuatOrder = "xyzw"
    velocity_frame: VelocityFrame = "bus"
    linear_velocity: LinearPoint = "origin"
    angle_unit: Literal["rad", "deg"] = "rad"
    length_unit: Literal["m", "mm"] = "m"

    def describe(self) -> str:
        return (f"quaternion {self.quaternion}, velocities in the {self.velocity_frame} frame, "
                f"linear velocity of the bus {self.linear_velocity.replace('_', ' ')}")

    def alternatives(self, bus_com_offset: float) -> list[Conventions]:
        """Every other choice of the conventions a consistency check can tell apart (the
        linear velocity's point only when the bus CoM is off its origin)."""
        points = ("origin", "bus_com") if bus_com_offset > 0 else (self.linear_velocity,)
        out = []
        for quat, frame, point in itertools.product(("xyzw", "wxyz"), ("bus", "world"), points):
            c = replace(self, quaternion=quat, velocity_frame=frame, linear_velocity=point)
            if c != self:
                out.append(c)
        return out

    def differences(self, other: Conventions) -> tuple[str, str]:
        """What ``other`` changes: its names, and the options that set it."""
        names, options = [], []
        for field, name, option in (("quaternion", "the quaternion order", "--quaternion"),
                                    ("velocity_frame", "the velocity frame", "--velocity-frame"),
                                    ("linear_velocity", "the linear velocity's point",
                                     "--linear-velocity")):
            if getattr(other, field) != getattr(self, field):
                names.append(name)
                options.append(f"{option} {getattr(other, field)}")
        return " and ".join(names), " ".join(options)


@dataclass(frozen=True)
class Converted:
    q: np.ndarray  # N×13, the project's conventions
    v: np.ndarray  # N×12
    quat_norm_error: float  # max |‖quat‖ − 1| before normalising


def to_project(q_raw: np.ndarray, v_raw: np.ndarray, conv: Conventions,
               bus_com: np.ndarray) -> Converted:
    """q and v in the project's conventions from a log in ``conv`` (eq. 33). ``bus_com``: the
    bus body's centre of mass in the bus frame (m). The quaternion is normalised (its norm
    error is returned); a non-unit one is a SpecError naming the likely cause."""
    q = np.array(q_raw, dtype=float, copy=True)
    v = np.array(v_raw, dtype=float, copy=True)
    if conv.length_unit == "mm":
        q[:, Q.p_b] *= 1e-3
        v[:, V.v_b] *= 1e-3
    if conv.angle_unit == "deg":
        q[:, Q.joints] = np.deg2rad(q[:, Q.joints])
        rates = slice(V.omega_b.start, None)  # every angular rate: ω_b and the joints'
        v[:, rates] = np.deg2rad(v[:, rates])
    if conv.quaternion == "wxyz":
        q[:, Q.quat_tb] = q[:, Q.quat_tb][:, [1, 2, 3, 0]]  # (w, x, y, z) → (x, y, z, w)
    norm = np.linalg.norm(q[:, Q.quat_tb], axis=1)
    err = float(np.max(np.abs(norm - 1.0))) if len(norm) else 0.0
    if not err <= UNIT_QUAT_TOL:
        k = int(np.argmax(np.abs(norm - 1.0)))
        raise SpecError(f"q: row {k}: the bus quaternion q[3:7] has norm {norm[k]:.6g}, not 1 "
                        f"(are the columns the position, the quaternion and the joints, in "
                        f"that order?)")
    # Normalised where the norm is off by more than a unit quaternion stored in float64 can
    # be (a few ulps: one rounding of each of four components and of the sum): a log of unit
    # quaternions is taken bit for bit, a float32 one or a rounded print is made unit.
    off = np.abs(norm - 1.0) > QUAT_ROUNDING
    q[off, 3:7] /= norm[off, None]
    if conv.velocity_frame == "world":
        # Imported here: the mapping (which names these conventions) is read before the log
        # and should not wait for SciPy's spatial package (a refusal there is quick).
        from scipy.spatial.transform import Rotation

        R_bt = Rotation.from_quat(q[:, Q.quat_tb]).inv()  # world axes → bus axes
        v[:, V.v_b] = R_bt.apply(v[:, V.v_b])
        v[:, V.omega_b] = R_bt.apply(v[:, V.omega_b])
    if conv.linear_velocity == "bus_com":
        v[:, V.v_b] -= np.cross(v[:, V.omega_b], bus_com)
    return Converted(q, v, err)
