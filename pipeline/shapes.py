"""The shapes of a robot's vectors, from its arm's joints (eq. 1).

A robot of this project is a free-floating bus carrying an arm of n revolute joints, each with
one coordinate. Its configuration and velocity are Pinocchio's free-flyer vectors

    q = [p_b (3); quat_tb (4, x y z w); q_arm (n)],     nq = 7 + n,
    v = [v_b (3); ω_b (3); q̇ (n)],                      nv = 6 + n,

and the task transform Γ (eq. 5) maps v to v̂ = [v_c (3); ω_b (3); ν_e⊕ (6); ...], whose part
after the CoM velocity is the reduced velocity v̆ (eq. 10) of 3 + 6 = 9 components for a
six-joint arm (9 + k with k = n − 6 null-space velocities for a redundant one, eq. 37).
:data:`Q`, :data:`V`, :data:`U` and :data:`BREVE` name each vector's blocks, the same for
every arm (the joints run to the end), so code takes a block by its name
(``v[:, V.omega_b]``) and a reader sees which slice means what; :class:`RobotShape` holds
one robot's sizes and its joints' names.

The shape is read from the loaded model (:func:`pipeline.sim.robot_file.robot_shape`), never
typed: the joints are the model's, in its order, with their names from the robot file.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

# A task-space arm moves the camera in six degrees of freedom (eq. 3): it needs six joints.
TASK_DOF = 6
# The most arm joints the compiled step has places for (pipeline.sim.control_step.STEP_PLACES).
MAX_JOINTS = 12
# The reduced velocity v̆'s task blocks (eq. 10), three components each: the bus's angular
# velocity and the camera's linear and angular velocity about the CoM; a redundant arm's
# null-space velocities follow them (eq. 37).
BREVE_BLOCK_NAMES = ("omega_b", "nu_e_lin", "nu_e_ang")
NULL_SPACE_BLOCK = "null_space"
# The task error x̃ and the task part of v̆ have this many components (eq. 14).
TASK_ERROR_SIZE = 3 * len(BREVE_BLOCK_NAMES)
# The log's columns of a generalised force (the dual of v: bus force, bus torque, joint
# torques) and of the reduced velocity's blocks (eq. 10).
GENERALISED_FORCES = ("u_cmd", "u_applied")
REDUCED_VECTORS = ("v_breve", "v_breve_des")
# The task error x̃ = [2ε_b; p_e − p_e,des; 2ε_e] (eq. 14): the blocks v̆'s blocks are the
# rates of.
TASK_ERROR_BLOCKS = ("bus_attitude", "camera_position", "camera_attitude")


class QBlocks(NamedTuple):
    """q's blocks (eq. 1): the bus position (t frame), its attitude quaternion (x, y, z, w),
    the arm's joint coordinates."""

    p_b: slice
    quat_tb: slice
    joints: slice


class VBlocks(NamedTuple):
    """v's blocks (eq. 1): the bus's linear and angular velocity (bus frame), the joint
    rates."""

    v_b: slice
    omega_b: slice
    joints: slice


class UBlocks(NamedTuple):
    """A generalised force's blocks (v's dual: u_cmd, u_applied, eq. 29): the force and the
    torque on the bus (bus frame), the joint torques."""

    f_b: slice
    tau_b: slice
    joints: slice


class BreveBlocks(NamedTuple):
    """The reduced velocity v̆'s blocks (eq. 10): ω_b, the camera's linear and angular
    velocity about the CoM (ν_e⊕), and a redundant arm's null-space velocities (eq. 37)."""

    omega_b: slice
    nu_e_lin: slice
    nu_e_ang: slice
    null_space: slice


# The same for every arm: the joints' and the null-space blocks run to the vector's end.
Q = QBlocks(p_b=slice(0, 3), quat_tb=slice(3, 7), joints=slice(7, None))
V = VBlocks(v_b=slice(0, 3), omega_b=slice(3, 6), joints=slice(6, None))
U = UBlocks(f_b=slice(0, 3), tau_b=slice(3, 6), joints=slice(6, None))
BREVE = BreveBlocks(omega_b=slice(0, 3), nu_e_lin=slice(3, 6), nu_e_ang=slice(6, 9),
                    null_space=slice(9, None))


@dataclass(frozen=True)
class RobotShape:
    """The vectors' sizes and blocks of a bus carrying the arm joints ``joints`` (eq. 1)."""

    joints: tuple[str, ...]  # the arm's joint names, from the bus out, as the model orders them

    @property
    def n(self) -> int:
        """The arm's joint count."""
        return len(self.joints)

    @property
    def nq(self) -> int:
        return 7 + self.n

    @property
    def nv(self) -> int:
        return 6 + self.n

    @property
    def null_space_dim(self) -> int:
        """k = n − 6: the arm's self-motion coordinates (eq. 37; 0 for a six-joint arm)."""
        return self.n - TASK_DOF

    @property
    def n_breve(self) -> int:
        """The reduced velocity v̆'s size: 9 task components and k null-space ones (eqs. 10,
        37)."""
        return TASK_ERROR_SIZE + self.null_space_dim

    @property
    def breve_blocks(self) -> tuple[str, ...]:
        """v̆'s blocks by name (eqs. 10, 37): the task blocks, then the null space if any."""
        return BREVE_BLOCK_NAMES + ((NULL_SPACE_BLOCK,) if self.null_space_dim else ())

    def labels(self, column: str) -> tuple[str, ...]:
        """The component labels of a log's vector column ``column``, as a labelled table
        shows them: ``p_b.x``, ``quat_tb.w``, ``q.<joint>`` for q; ``v_b.x``, ``omega_b.z``,
        ``qdot.<joint>`` for v; ``<column>.f_b.x``, ``<column>.tau_b.z``, ``<column>.<joint>``
        for a generalised force (u_cmd, u_applied: the dual of v); ``<column>.<block>.<axis>``
        for the reduced velocity's blocks (v_breve, v_breve_des, eq. 10) and the task error's
        (x_tilde, eq. 14), ``v_c.<axis>`` for the CoM velocity and ``joint_excess.<joint>``
        for each joint's excess beyond its range (eq. 42). A KeyError for a column it does not
        know."""
        if column == "q":
            return (*_axes("p_b"), *(f"quat_tb.{c}" for c in "xyzw"),
                    *(f"q.{j}" for j in self.joints))
        if column == "v":
            return (*_axes("v_b"), *_axes("omega_b"), *(f"qdot.{j}" for j in self.joints))
        if column in GENERALISED_FORCES:
            return (*_axes(f"{column}.f_b"), *_axes(f"{column}.tau_b"),
                    *(f"{column}.{j}" for j in self.joints))
        if column in REDUCED_VECTORS:
            null = tuple(f"{column}.{NULL_SPACE_BLOCK}.{i}" for i in range(self.null_space_dim))
            return (*(label for block in BREVE_BLOCK_NAMES
                      for label in _axes(f"{column}.{block}")), *null)
        if column == "x_tilde":
            return tuple(label for block in TASK_ERROR_BLOCKS
                         for label in _axes(f"{column}.{block}"))
        if column == "v_c":
            return _axes("v_c")
        if column == "joint_excess":  # eq. 42: one per arm joint
            return tuple(f"{column}.{j}" for j in self.joints)
        raise KeyError(f"no labels for a vector column {column!r}")


def _axes(prefix: str) -> tuple[str, str, str]:
    return (f"{prefix}.x", f"{prefix}.y", f"{prefix}.z")
