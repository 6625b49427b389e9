"""Robot files: one loader for URDF and MJCF, validated, and the robot card (eq. 1).

A robot of this project is a free-floating bus (the root body, on a free joint) carrying a
6-DoF arm with a camera frame. A URDF describes the bus and the arm; the free joint is added
here. An MJCF declares it itself (``<freejoint/>`` on the root body), as MuJoCo models do.
Either way the loaded model must have nq = 13, nv = 12, a free flyer as joint 1 and the
camera frame; anything else is a :class:`~pipeline.errors.SpecError` naming the file. The
file is then read a second time, by MuJoCo, and the two models compared
(:mod:`pipeline.sim.robot_crosscheck`, once per file content): the robot the code sees is the
robot in the file.
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.errors import SpecError
from pipeline.shapes import MAX_JOINTS, TASK_DOF, Q, RobotShape
from pipeline.sim.inertial import set_inertial
from pipeline.sim.robot_crosscheck import crosscheck_robot_file
from pipeline.spec import Spec

MJCF_SUFFIXES = (".xml", ".mjcf")


def _parse(path: Path) -> pin.Model:
    """Pinocchio's model of the file. The C++ parsers write their reasons to the process's
    stderr (urdfdom's "Error: XML_ERROR_PARSING … Line number=1"): caught here, so that a
    refusal is one line holding the parser's whole reason, and a parse that succeeds with
    remarks says them in one warning line."""
    with _stderr_of_c_code() as said:
        try:
            if path.suffix.lower() in MJCF_SUFFIXES:
                model = pin.buildModelFromMJCF(str(path))
            else:
                model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
        except Exception as exc:  # Pinocchio raises RuntimeError, ValueError or its own kinds
            error = exc
        else:
            error = None
    reason = " ".join(" ".join(said()).split())
    if error is not None:
        message = " ".join(str(error).split()) or type(error).__name__
        detail = f"{message}; the parser said: {reason}" if reason else message
        second = _mujoco_reason(path)
        if second:
            detail += f"; MuJoCo's reading: {second}"
        raise SpecError(f"{path}: not a loadable robot file ({detail[:900]})")
    if reason:
        print(f"warning: {path}: the robot file's parser said: {reason[:600]}",
              file=sys.stderr)
    return model


def _mujoco_reason(path: Path) -> str:
    """MuJoCo's reason for refusing the file ("" when it reads it): Pinocchio's parsers often
    fail with a bare C++ message (``unordered_map::at``) where MuJoCo names the element."""
    import mujoco

    try:
        mujoco.MjSpec.from_file(str(path))
    except Exception as exc:  # MuJoCo raises ValueError with its XML error
        return " ".join(str(exc).split())
    return ""


@contextmanager
def _stderr_of_c_code() -> Iterator[Callable[[], list[str]]]:
    """Capture what native code writes to file descriptor 2 (Python's own sys.stderr is
    flushed first and is unaffected); yields a function returning the captured lines."""
    sys.stderr.flush()
    saved = os.dup(2)
    lines: list[str] = []
    with tempfile.TemporaryFile() as buf:
        os.dup2(buf.fileno(), 2)
        try:
            yield lambda: lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            buf.seek(0)
            lines += buf.read().decode(errors="replace").splitlines()


_WARNED: set[str] = set()


def _warn_once(line: str) -> None:
    """A warning on stderr, once per process: the loader runs for every mission and
    analysis, the terminal should not repeat it."""
    if line not in _WARNED:
        _WARNED.add(line)
        print(line, file=sys.stderr)


def load_robot_model(path: Path | str, camera_frame: str,
                     bus_inertia_scale: float = 1.0,
                     package_dirs: tuple[Path, ...] = (),
                     locked_joints: Mapping[str, float] | None = None,
                     inertial: Mapping | None = None) -> pin.Model:
    """The Pinocchio model of a robot file, gravity off, validated (eq. 1).

    The file's joints named in ``locked_joints`` are held at the given values (Pinocchio's
    reduced model: a gripper's jaw, a finger); every other joint must be a revolute joint on
    the chain from the bus to the camera frame (:func:`arm_joints`). The parse is
    cross-checked against MuJoCo's (:func:`crosscheck_robot_file`, on the file as written:
    meshes are needed only for a body whose inertia comes from them, ``package://`` URIs are
    looked for in ``package_dirs``) before the locks, before ``inertial`` replaces the bus's
    or the payload's inertial parameters (:func:`pipeline.sim.inertial.set_inertial`, eq. 39)
    and before ``bus_inertia_scale`` multiplies the rotational inertia of the rigid body on
    the free joint about its own centre of mass (its mass and centre of mass stay): the check
    is about the file.
    """
    path = Path(path)
    model, _ = as_revolute(_parse(path))
    kinds = [j.shortname() for j in model.joints[1:]]
    if model.njoints < 2 or kinds[0] != "JointModelFreeFlyer":
        raise SpecError(f"{path}: the root joint must be a free joint (the bus); found "
                        f"{kinds[0] if kinds else 'none'}")
    camera_frame_id(model, camera_frame, path)
    reduced = _locked(model, dict(locked_joints or {}), path)
    arm_joints(reduced, camera_frame, path)
    check = crosscheck_robot_file(path, model, camera_frame, package_dirs)
    for note in check.notes:  # what the cross-parse left out (a missing mesh), said once
        _warn_once(f"warning: {path}: {note}")
    model = reduced
    model.gravity.setZero()
    if inertial:
        set_inertial(model, inertial, camera_frame_id(model, camera_frame, path), path)
    if bus_inertia_scale != 1.0:
        bus = model.inertias[1]
        model.inertias[1] = pin.Inertia(bus.mass, bus.lever.copy(),
                                        bus_inertia_scale * bus.inertia)
    return model


# Pinocchio's one-coordinate revolute joints: about x, y or z of the joint frame, or about an
# axis the file gives. A URDF "continuous" joint is Pinocchio's unbounded revolute (RUB: two
# coordinates, cos and sin, for one velocity); the loader flies it as the revolute joint of the
# same axis without limits (:func:`as_revolute`).
REVOLUTE_KINDS = ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned")
_REVOLUTE_OF = {"JointModelRUBX": pin.JointModelRX, "JointModelRUBY": pin.JointModelRY,
                "JointModelRUBZ": pin.JointModelRZ}


def _is_continuous(kind: str) -> bool:
    """Whether a joint kind is Pinocchio's unbounded revolute (an axis x, y or z: RUBX/Y/Z;
    any other axis, a URDF's ``0 0 -1`` included: RevoluteUnboundedUnaligned)."""
    return kind.startswith("JointModelRUB") or kind == "JointModelRevoluteUnboundedUnaligned"


def as_revolute(model: pin.Model) -> tuple[pin.Model, list[str]]:
    """``model`` with each continuous joint (Pinocchio's unbounded revolute, its angle held as
    (cos θ, sin θ)) replaced by the revolute joint of the same axis, placement and body with
    the range (−∞, ∞), and the names of those joints; ``model`` itself when it has none.

    One coordinate per joint, the angle θ itself: q ⊕ v·dt adds v·dt to it, so a
    joint turning past ±π stays continuous in q (unwrapped), and the kinematics and dynamics
    are those of the (cos, sin) joint at that angle, to round-off (a ulp at most, on the
    collection's Kinova and on unaligned axes: tests/test_continuous_joints.py). Each joint's
    effort, velocity, friction and damping limits, margins, armature and rotor parameters are
    copied; the frames in order (their inertias already in the joints' bodies, not appended
    again)."""
    kinds = [model.joints[j].shortname() for j in range(model.njoints)]
    if not any(_is_continuous(k) for k in kinds):
        return model, []
    new, names = pin.Model(), []
    new.name = model.name
    for j in range(1, model.njoints):
        joint, kind = model.joints[j], kinds[j]
        qs = slice(joint.idx_q, joint.idx_q + joint.nq)
        vs = slice(joint.idx_v, joint.idx_v + joint.nv)
        lower, upper = model.lowerPositionLimit[qs], model.upperPositionLimit[qs]
        margin = model.positionLimitMargin[qs]
        if _is_continuous(kind):
            names.append(model.names[j])
            if kind in _REVOLUTE_OF:
                joint = _REVOLUTE_OF[kind]()
            else:  # its axis: the motion subspace's angular part (this binding has no .axis)
                axis = np.asarray(joint.createData().S).ravel()[3:]
                joint = pin.JointModelRevoluteUnaligned(axis)
            lower, upper, margin = np.array([-np.inf]), np.array([np.inf]), margin[:1]
        jid = new.addJoint(model.parents[j], joint, model.jointPlacements[j], model.names[j],
                           model.lowerEffortLimit[vs], model.upperEffortLimit[vs],
                           model.lowerVelocityLimit[vs], model.upperVelocityLimit[vs], lower,
                           upper, margin, model.lowerDryFrictionLimit[vs],
                           model.upperDryFrictionLimit[vs], model.damping[vs])
        new.appendBodyToJoint(jid, model.inertias[j], pin.SE3.Identity())
        at = new.joints[jid]
        to = slice(at.idx_v, at.idx_v + at.nv)
        new.armature[to] = model.armature[vs]
        new.rotorInertia[to] = model.rotorInertia[vs]
        new.rotorGearRatio[to] = model.rotorGearRatio[vs]
    for frame in list(model.frames)[1:]:
        new.addFrame(pin.Frame(frame), False)
    return new, names


def _lock(names: list[str]) -> str:
    return f"lock {'them' if len(names) > 1 else 'it'} in robot.locked_joints"


# Where a name is several frames (a URDF's fixed joint and its child link may share it), the
# camera is the body, else an MJCF site, else the joint's frame.
FRAME_PREFERENCE = (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT,
                    pin.FrameType.JOINT)


def camera_frame_id(model: pin.Model, name: str, path: Path | str = "") -> int:
    """The id of the frame ``name`` (robot.camera_frame): the body of that name, else the
    site, else the joint frame; a SpecError naming the file when there is none."""
    ids = {f.type: i for i, f in reversed(list(enumerate(model.frames))) if f.name == name}
    for kind in FRAME_PREFERENCE:
        if kind in ids:
            return ids[kind]
    if ids:
        return min(ids.values())
    raise SpecError(f"{path or 'robot file'}: no frame {name!r} (robot.camera_frame)")


def _locked(model: pin.Model, locked: dict[str, float], path: Path) -> pin.Model:
    """``model`` with the joints named in ``locked`` held at their values (Pinocchio's
    ``buildReducedModel``; a continuous joint, flown as a revolute joint without limits
    (:func:`as_revolute`), at any angle); a name the file does not have, a joint of several
    degrees of freedom or a value outside the joint's limits is a SpecError naming the
    field."""
    if not locked:
        return model
    model = pin.Model(model)  # a copy: the file's model is cross-checked as parsed
    ids, q = [], pin.neutral(model)
    for name, value in locked.items():
        where = f"{path}: field robot.locked_joints.{name}"
        if not model.existJointName(name) or model.getJointId(name) < 2:
            raise SpecError(f"{where}: the file has no arm joint {name!r} (its joints: "
                            f"{', '.join(list(model.names)[2:])})")
        j = model.getJointId(name)
        joint = model.joints[j]
        if joint.nq != 1 or joint.nv != 1:
            raise SpecError(f"{where}: a {joint.shortname()} joint has {joint.nq} "
                            f"coordinates; only one-coordinate and continuous joints can be "
                            f"locked")
        else:
            lo = model.lowerPositionLimit[joint.idx_q]
            hi = model.upperPositionLimit[joint.idx_q]
            if not lo <= value <= hi:
                raise SpecError(f"{where}: {value} is outside the joint's limits "
                                f"[{lo:.6g}, {hi:.6g}]")
            q[joint.idx_q] = value
        ids.append(j)
        # A locked joint becomes a fixed frame of its name; Pinocchio's reduction looks frames
        # up by name and fails where a body shares it (so100's joint and link "gripper"), so
        # the joint's own frame is renamed first, in the copy.
        for i, f in enumerate(model.frames):
            if f.name == name and f.type == pin.FrameType.JOINT:
                f.name = f"{name} (locked)"
                model.frames[i] = f
        model.names[j] = f"{name} (locked)"
    return pin.buildReducedModel(model, sorted(ids), q)


def arm_joints(model: pin.Model, camera_frame: str, path: Path | str) -> RobotShape:
    """The arm's shape (its joints, eq. 1), after refusing what is not a task-space arm.

    Every joint after the free one must move the camera: it is on the chain from the bus to
    the camera frame (a jaw, a finger or a second branch is not; it is refused by name, to be
    locked), it is revolute with one coordinate (a continuous joint is, once the loader has
    made it a revolute joint without limits, :func:`as_revolute`; a prismatic or multi-axis
    joint is refused by name), and there are at
    least :data:`~pipeline.shapes.TASK_DOF` of them (fewer cannot place the camera in six
    degrees of freedom). More is a redundant arm, whose null-space terms are eq. 37's; the
    stages' loader (:func:`load_spec_robot`) refuses it until the loop runs it.
    """
    camera_joint = model.frames[camera_frame_id(model, camera_frame, path)].parentJoint
    chain = set(model.supports[camera_joint])
    names = list(model.names)
    off = [names[j] for j in range(2, model.njoints) if j not in chain]
    if off:
        raise SpecError(f"{path}: joint{'s' if len(off) > 1 else ''} {', '.join(off)} "
                        f"{'do' if len(off) > 1 else 'does'} not move the camera frame "
                        f"{camera_frame!r} (not on the chain from the bus to it: a jaw, a "
                        f"finger, another branch); {_lock(off)}")
    kinds = {names[j]: model.joints[j].shortname() for j in range(2, model.njoints)}
    other = [f"{n} ({k.removeprefix('JointModel')})" for n, k in kinds.items()
             if k not in REVOLUTE_KINDS]
    if other:
        raise SpecError(f"{path}: not revolute: {', '.join(other)}; the arm's joints must be "
                        f"revolute with one coordinate, or {_lock(other)}")
    shape = RobotShape(tuple(names[2:]))
    if shape.n < TASK_DOF:
        raise SpecError(f"{path}: {shape.n} arm joint{'s' if shape.n != 1 else ''} "
                        f"({', '.join(shape.joints) or 'none'}) to the camera frame "
                        f"{camera_frame!r}: placing the camera in position and orientation "
                        f"needs at least {TASK_DOF}")
    return shape


def robot_shape(model: pin.Model) -> RobotShape:
    """The shape of a loaded model's vectors (eq. 1): its joints after the free one."""
    return RobotShape(tuple(model.names)[2:])


def load_spec_robot(spec: Spec) -> pin.Model:
    """The model of a spec's robot block: :func:`load_robot_model` with its file, camera frame,
    bus inertia scale, package folders and locked joints, for the stages: 6 to ``MAX_JOINTS``
    arm joints (a loop of a redundant arm needs its null-space impedance:
    :func:`check_null_space`), and ``robot.q_bar`` one angle per arm joint."""
    model = load_robot_model(spec.robot_path, spec.robot.camera_frame,
                             spec.robot.bus_inertia_scale, spec.package_dirs,
                             spec.robot.locked_joints, spec.robot.inertial)
    shape = robot_shape(model)
    if shape.n > MAX_JOINTS:
        raise SpecError(f"{spec.robot_path}: {shape.n} arm joints ({', '.join(shape.joints)}): "
                        f"the loop runs arms of {TASK_DOF} to {MAX_JOINTS} joints; lock "
                        f"{shape.n - MAX_JOINTS} in robot.locked_joints")
    if len(spec.robot.q_bar) != shape.n:
        raise SpecError(f"spec {spec.name}: field robot.q_bar: {len(spec.robot.q_bar)} joint "
                        f"angles for the {shape.n} arm joints of {spec.robot_path.name} "
                        f"({', '.join(shape.joints)})")
    return model


def check_posture_limits(spec: Spec, model: pin.Model) -> None:
    """SpecError naming the first arm joint whose ``robot.q_bar`` angle lies outside the robot
    file's position range (issue 50): the posture the loop holds the arm near, and the start
    its sampler searches around, must be one the arm can take. The loop's check, not the
    robot's: an imported log's spec carries the robot and no posture of its own."""
    lo, hi = model.lowerPositionLimit[Q.joints], model.upperPositionLimit[Q.joints]
    for name, q, a, b in zip(robot_shape(model).joints, spec.robot.q_bar, lo, hi,
                             strict=True):
        if not a <= q <= b:
            raise SpecError(f"spec {spec.name}: field robot.q_bar: {name} at {q:.4g} rad is "
                            f"outside its range [{a:.4g}, {b:.4g}] rad in "
                            f"{spec.robot_path.name}")


def check_null_space(spec: Spec, shape: RobotShape) -> None:
    """The loop's null-space impedance against the arm (eq. 37f): ``controller.null_space``
    required for a redundant arm, refused for six joints. The loop's check, not the robot's:
    an imported log's spec carries the robot and no controller."""
    k = shape.null_space_dim
    if k and spec.controller.null_space is None:
        raise SpecError(f"spec {spec.name}: field controller.null_space: {shape.n} arm joints "
                        f"({', '.join(shape.joints)}) leave {k} null-space velocit"
                        f"{'y' if k == 1 else 'ies'} (eq. 37); give their impedance "
                        "(controller.null_space: {K: …, D: …}), or lock "
                        f"{k} joint{'s' if k > 1 else ''} in robot.locked_joints")
    if not k and spec.controller.null_space is not None:
        raise SpecError(f"spec {spec.name}: field controller.null_space: the {shape.n} arm "
                        f"joints of {spec.robot_path.name} leave no null space (eq. 37 is a "
                        f"redundant arm's, more than {TASK_DOF} joints)")


@dataclass(frozen=True)
class RobotCard:
    """The loaded model as the code sees it: masses, CoM, the bus rigid body's inertia, and
    the two damping rates it predicts in closed form (eqs. 21, 24): the bus yaw's and the
    camera roll's."""

    total_mass: float  # kg
    com_b: list[float]  # whole-robot CoM in the bus frame at the start configuration, m
    bus_mass: float  # kg, the rigid body on the free joint
    bus_com_b: list[float]  # its CoM in the bus frame, m
    bus_inertia: list[list[float]]  # its rotational inertia about its CoM, bus axes, kg·m²
    pan_axis_b: list[float]  # first arm joint's axis in the bus frame (unit)
    pan_axis_offset: float  # distance of the bus CoM from that axis, m
    I_zz_bus: float  # the bus body's inertia about that axis, kg·m²
    D_b: float  # bus damping gain, N·m·s/rad
    mu_bus: float  # the bus-yaw rate that holds (mu_bus_rule): the closed form or the mode's
    dt_star_bus: float  # 2 / mu_bus, s
    mu_bus_closed_form: float = 0.0  # D_b / I_zz,bus, 1/s: exact when the bus CoM is on â
    # The bus-yaw damping mode of (D̆, M̆) at this configuration (eq. 21: the mode with the
    # largest ω_b,z share), 1/s; None where M̆ was not at hand.
    mu_bus_mode: float | None = None
    bus_closed_form_holds: bool = True  # the bus CoM on the first joint's axis, â along z_b
    mu_bus_rule: str = ""  # which of the two mu_bus is, and why
    # The camera roll about the last arm joint's axis: the bodies it carries (the wrist link
    # and the payload, one inertia in the model) and the camera frame's alignment with it.
    roll_axis_offset: float = 0.0  # distance of that inertia's CoM from the axis, m
    roll_boresight_cos: float = 0.0  # |cos| of the camera z-axis against the axis
    roll_camera_offset: float = 0.0  # distance of the camera origin from the axis, m
    I_roll: float = 0.0  # that inertia about the axis, kg·m²
    D_o: float = 0.0  # camera orientation damping gain, N·m·s/rad
    mu_roll: float = 0.0  # D_o / I_roll, 1/s
    dt_star_roll: float = 0.0  # 2 / mu_roll, s
    # The file's bodies welded to the free joint, whose masses and inertias the bus body above
    # sums (a fixed arm base adds to the bus: μ_bus is not the user's bus alone).
    bus_links: list[str] = field(default_factory=list)
    arm_mass: float = 0.0  # kg, every body the arm joints move
    # The arm joints without a range: the file's continuous joints (flown as revolute joints
    # of one unwrapped angle, :func:`as_revolute`) and any joint it leaves unbounded.
    continuous_joints: list[str] = field(default_factory=list)

    @property
    def light_bus(self) -> str | None:
        """A remark when the bus body is not heavier than the arm (None otherwise): a bare
        arm's base link taken for the bus gives a bus yaw rate (eq. 21) of that link."""
        if self.bus_mass > self.arm_mass:
            return None
        return (f"the bus body ({', '.join(self.bus_links)}, {self.bus_mass:.4g} kg) is not "
                f"heavier than the arm ({self.arm_mass:.4g} kg): if the file is a bare arm, "
                f"its base link is taken for the bus; mount the arm on a bus link")


def unbounded_joints(model: pin.Model) -> list[str]:
    """The arm joints with no range (eq. 42's ``JointRanges``: both limits beyond
    ``UNLIMITED``): a continuous joint of the file, once :func:`as_revolute` has made it one
    angle."""
    from pipeline.joint_ranges import JointRanges

    r = JointRanges.of(model)
    return [n for n, lo, hi in zip(r.names, r.lower, r.upper, strict=True)
            if np.isinf(lo) and np.isinf(hi)]


def bus_rate_rule(closed_form: float, mode: float | None, holds: bool, offset: float,
                  axis: np.ndarray) -> tuple[float, str]:
    """(the bus-yaw rate that holds, which it is and why), from the closed form D_b/I_zz,bus,
    the bus-yaw damping mode's rate of (D̆, M̆) and whether the closed form's condition holds
    (eq. 21)."""
    where = (f"the bus CoM {offset:.3g} m from the first joint's axis, the axis at "
             f"|cos| {abs(axis[2]):.6f} to z_b")
    if holds:
        return closed_form, (f"closed form D_b/I_zz,bus ({where}: exact on the axis)"
                             + (f"; the mode of (D̆, M̆) {mode:.6g} 1/s"
                                if mode is not None else ""))
    if mode is None:
        return closed_form, (f"closed form D_b/I_zz,bus, which does NOT hold ({where}); the "
                             f"bus-yaw damping mode of (D̆, M̆) not computed here")
    return mode, (f"bus-yaw damping mode of (D̆, M̆) (eq. 21): the closed form "
                  f"D_b/I_zz,bus = {closed_form:.4g} 1/s does not hold ({where}; "
                  f"{100.0 * (closed_form / mode - 1.0):+.3g} % off)")


def _joint_axis(model: pin.Model, j: int) -> np.ndarray:
    """The unit axis of revolute joint j in its own frame."""
    joint = model.joints[j]
    local = {"JointModelRX": [1, 0, 0], "JointModelRY": [0, 1, 0], "JointModelRZ": [0, 0, 1]}
    name = joint.shortname()
    # JointModelRevoluteUnaligned carries its axis; the aligned ones name it.
    axis = np.array(local[name] if name in local else joint.axis, dtype=float)
    return axis / np.linalg.norm(axis)


def _inertia_about(inertia: pin.Inertia, axis: np.ndarray, point: np.ndarray
                   ) -> tuple[float, float]:
    """(âᵀ I_c â + m d², d): a rigid body's inertia about the line through ``point`` along
    ``axis`` (unit), and the distance d of its CoM from that line."""
    r = inertia.lever - point
    d = float(np.linalg.norm(r - axis * (axis @ r)))
    return float(axis @ inertia.inertia @ axis + inertia.mass * d**2), d


# The bus-yaw closed form holds when the bus CoM is on the first joint's axis and that axis is
# the bus z: within these (m, and 1 − |â·z_b|), the round-off of a file's numbers.
ON_AXIS_M = 1e-9
ALIGNED = 1e-12


def robot_card(model: pin.Model, q: np.ndarray, D_b: float, D_o: float = 0.0,
               camera_frame: int | None = None, mu_bus_mode: float | None = None
               ) -> RobotCard:
    """The card of ``model`` at configuration q with bus damping gain D_b and camera
    orientation damping gain D_o (eq. 21).

    I_zz,bus = âᵀ I_c â + m d², â the first arm joint's axis and d the distance of the bus
    body's CoM from it. When d = 0 the bus yaw about â moves nothing else at a fixed camera
    pose and CoM, so it is an eigen-direction of M̆ with inertia I_zz,bus, and its damping
    rate is μ_bus = D_b / I_zz,bus.

    I_roll, likewise, is the last arm joint's body (the wrist link with the payload fixed to
    it) about that joint's axis. When its CoM is on the axis and the camera's z-axis (the
    boresight) runs along it, the camera roll about the boresight turns that body alone at
    a fixed bus, camera position and CoM: an eigen-direction of M̆ with inertia I_roll, and
    μ_roll = D_o / I_roll. The card gives the offsets and the alignment, so a reader sees
    when the closed form applies.

    ``mu_bus_mode``: the bus-yaw damping mode's rate of (D̆, M̆) at q (eq. 21), when the caller
    has M̆. The card's ``mu_bus`` is the value that holds: the closed form where the bus CoM is
    on â and â is the bus z (``ON_AXIS_M``, ``ALIGNED``), else the mode's (the closed form
    then kept beside it with its error), else, with no mode given, the closed form marked as
    not holding.
    """
    data = model.createData()
    com = pin.centerOfMass(model, data, q)
    bus = model.inertias[1]
    placement = model.jointPlacements[2]
    axis = placement.rotation @ _joint_axis(model, 2)
    I_axis, offset = _inertia_about(bus, axis, placement.translation)
    R_tb = data.oMi[1].rotation
    mu = D_b / I_axis
    last = model.njoints - 1
    roll_axis = _joint_axis(model, last)
    I_roll, roll_offset = _inertia_about(model.inertias[last], roll_axis, np.zeros(3))
    cos, cam_offset = 0.0, float("nan")
    if camera_frame is not None:
        pin.updateFramePlacements(model, data)
        oMj, oMf = data.oMi[last], data.oMf[camera_frame]
        axis_t = oMj.rotation @ roll_axis
        cos = float(abs(axis_t @ oMf.rotation[:, 2]))
        cam_offset = float(np.linalg.norm(np.cross(oMf.translation - oMj.translation, axis_t)))
    mu_roll = D_o / I_roll
    holds = bool(offset <= ON_AXIS_M and abs(axis[2]) >= 1.0 - ALIGNED)
    used, rule = bus_rate_rule(mu, mu_bus_mode, holds, offset, axis)
    return RobotCard(
        total_mass=float(sum(i.mass for i in model.inertias)),
        com_b=(R_tb.T @ (com - data.oMi[1].translation)).tolist(),
        bus_mass=float(bus.mass), bus_com_b=bus.lever.tolist(),
        bus_inertia=bus.inertia.tolist(), pan_axis_b=axis.tolist(), pan_axis_offset=offset,
        I_zz_bus=I_axis, D_b=float(D_b), mu_bus=used, dt_star_bus=2.0 / used,
        mu_bus_closed_form=mu, mu_bus_mode=mu_bus_mode, bus_closed_form_holds=holds,
        mu_bus_rule=rule,
        roll_axis_offset=roll_offset, roll_boresight_cos=cos, roll_camera_offset=cam_offset,
        I_roll=I_roll, D_o=float(D_o), mu_roll=mu_roll,
        dt_star_roll=2.0 / mu_roll if mu_roll > 0 else float("inf"),
        bus_links=[f.name for f in model.frames
                   if f.type == pin.FrameType.BODY and f.parentJoint == 1],
        arm_mass=float(sum(i.mass for i in model.inertias[2:])),
        continuous_joints=unbounded_joints(model))
