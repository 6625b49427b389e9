"""The shapes of a robot's vectors, from its arm's joints (eq. 1).

A robot of this project is a free-floating bus carrying an arm of n revolute joints, each with
one coordinate. Its configuration and velocity are Pinocchio's free-flyer vectors

    q = [p_b (3); quat_tb (4, x y z w); q_arm (n)],     nq = 7 + n,
    v = [v_b (3); ω_b (3); q̇ (n)],                      nv = 6 + n,

and the task transform Γ (eq. 5) maps v to v̂ = [v_c (3); ω_b (3); ν_e⊕ (6); ...], whose part
after the CoM velocity is the reduced velocity v̆ (eq. 10) of 3 + 6 = 9 components for a
six-joint arm. :class:`RobotShape` holds these sizes and the named blocks of each vector, so
that code takes a block by its name (``shape.q["joints"]``) and a reader sees which 12 means
6 + n.

The shape is read from the loaded model (:func:`pipeline.sim.robot_file.robot_shape`), never
typed: the joints are the model's, in its order, with their names from the robot file.
"""

from __future__ import annotations

from dataclasses import dataclass

# A task-space arm moves the camera in six degrees of freedom (eq. 3): it needs six joints.
TASK_DOF = 6


def _blocks(*sizes: tuple[str, int]) -> dict[str, slice]:
    out, i = {}, 0
    for name, n in sizes:
        out[name] = slice(i, i + n)
        i += n
    return out


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
    def q(self) -> dict[str, slice]:
        """q's blocks: the bus position, its attitude quaternion (x, y, z, w), the joints."""
        return _blocks(("p_b", 3), ("quat_tb", 4), ("joints", self.n))

    @property
    def v(self) -> dict[str, slice]:
        """v's blocks: the bus velocity and angular rate (bus frame), the joint rates."""
        return _blocks(("v_b", 3), ("omega_b", 3), ("joints", self.n))
