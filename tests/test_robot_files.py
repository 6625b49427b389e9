"""What is an arm: robot descriptions nobody here wrote (the example-robot-data collection),
loaded as users load them, refused where they are not a six-joint task-space arm, with the
reason named; locked joints (Pinocchio's reduced model) checked against the full model.

The collection's bare arms have their base link on the free joint (no bus): enough for the
loader's refusals, which look at the joints; the dynamics of a locked model are compared with
the file's full model, an independent computation of the same physics.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from importlib import metadata
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import run_cli

from pipeline.errors import SpecError
from pipeline.sim.robot_file import load_robot_model, robot_card, robot_shape

COLLECTION = Path(metadata.distribution("example-robot-data").locate_file(
    "cmeel.prefix/share/example-robot-data/robots"))
PACKAGES = (COLLECTION.parent.parent,)  # package://example-robot-data/... resolves from here
SO100 = COLLECTION / "so_arm_description" / "urdf" / "so100.urdf"
Z1 = COLLECTION / "z1_description" / "urdf" / "z1.urdf"
KINOVA = COLLECTION / "kinova_description" / "robots" / "kinova.urdf"
PANDA = COLLECTION / "panda_description" / "urdf" / "panda.urdf"
UR5 = COLLECTION / "ur_description" / "urdf" / "ur5_robot.urdf"
FINGERS = {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.02}


def load(path: Path, camera: str, **locked: float) -> pin.Model:
    return load_robot_model(path, camera, package_dirs=PACKAGES, locked_joints=locked)


def _refusal(path: Path, camera: str, **locked: float) -> str:
    with pytest.raises(SpecError) as exc:
        load(path, camera, **locked)
    return str(exc.value)


def test_collection_is_there():
    for path in (SO100, Z1, KINOVA, PANDA, UR5):
        assert path.is_file(), path


def test_a_jaw_is_not_an_arm_joint():
    """so100: five arm joints and a jaw; counted as six before. The jaw is refused by name."""
    msg = _refusal(SO100, "gripper")
    assert "joint gripper does not move the camera frame 'gripper'" in msg
    assert "robot.locked_joints" in msg and "\n" not in msg


def test_five_joints_are_refused_with_the_count():
    msg = _refusal(SO100, "gripper", gripper=0.0)
    assert "5 arm joints (shoulder_pan, shoulder_lift, elbow_flex, wrist_flex, wrist_roll)" in msg
    assert "needs at least 6" in msg


def test_unlocked_gripper_refused_then_locked_loads():
    assert "joint jointGripper does not move" in _refusal(Z1, "gripperStator")
    model = load(Z1, "gripperStator", jointGripper=-0.5)
    assert robot_shape(model).joints == tuple(f"joint{i}" for i in range(1, 7))
    assert (model.nq, model.nv) == (13, 12)


def test_fingers_refused_by_name_then_locked():
    msg = _refusal(PANDA, "panda_hand")
    assert "joints panda_finger_joint1, panda_finger_joint2 do not move" in msg
    assert "lock them in robot.locked_joints" in msg
    assert robot_shape(load(PANDA, "panda_hand", **FINGERS)).n == 7


def test_continuous_joints_are_flown_as_one_angle_and_lockable():
    """The Kinova's continuous joints (1, 4 and 6; issue 51) load as revolute joints of one
    angle without a range: a six-joint arm, nq 13. Locked, they are held at their angles: the
    camera placement is Pinocchio's own model's at those angles (its joints' cos and sin)."""
    model = load(KINOVA, "j2s6s200_end_effector")
    assert robot_shape(model).n == 6 and (model.nq, model.nv) == (13, 12)
    from pipeline.sim.robot_file import _locked, unbounded_joints

    assert unbounded_joints(model) == ["j2s6s200_joint_1", "j2s6s200_joint_4",
                                       "j2s6s200_joint_6"]
    angles = {"j2s6s200_joint_1": 0.3, "j2s6s200_joint_4": -1.2, "j2s6s200_joint_6": 2.5}
    full = pin.buildModelFromUrdf(str(KINOVA), pin.JointModelFreeFlyer())
    assert "3 arm joints" in _refusal(KINOVA, "j2s6s200_end_effector", **angles)
    from pipeline.sim.robot_file import as_revolute

    locked = _locked(as_revolute(full)[0], angles, KINOVA)
    assert locked.nq == 10
    q_f = pin.neutral(full)
    for name, a in angles.items():
        i = full.joints[full.getJointId(name)].idx_q
        q_f[i:i + 2] = np.cos(a), np.sin(a)
    data_r, data_f = locked.createData(), full.createData()
    pin.framesForwardKinematics(locked, data_r, pin.neutral(locked))
    pin.framesForwardKinematics(full, data_f, q_f)
    fid = "j2s6s200_end_effector"
    np.testing.assert_allclose(
        data_r.oMf[locked.getFrameId(fid, pin.FrameType.BODY)].homogeneous,
        data_f.oMf[full.getFrameId(fid, pin.FrameType.BODY)].homogeneous, rtol=0, atol=1e-12)


@pytest.mark.parametrize(("locked", "needle"), [
    ({"jointGripper": -3.0}, "robot.locked_joints.jointGripper: -3.0 is outside the joint's "
                             "limits [-1.5707, 0]"),
    ({"no_such_joint": 0.0}, "robot.locked_joints.no_such_joint: the file has no arm joint"),
])
def test_bad_locks_name_the_field(locked, needle):
    assert needle in _refusal(Z1, "gripperStator", **locked)


def _file_masses(path: Path) -> float:
    return sum(float(m.get("value")) for m in ET.parse(path).getroot().iter("mass"))


def test_locked_model_is_the_full_model_held_still():
    """Panda with its fingers and joint 7 locked: the reduced model's mass is the file's, and
    its joint-space inertia at a configuration is the full model's rows and columns of the
    joints left at the same configuration (the locked joints held at their values), its camera
    placement the full model's."""
    locked = {**FINGERS, "panda_joint7": 0.4}
    reduced = load(PANDA, "panda_hand", **locked)
    full = pin.buildModelFromUrdf(str(PANDA), pin.JointModelFreeFlyer())
    assert pin.computeTotalMass(reduced) == pytest.approx(_file_masses(PANDA), rel=1e-12)
    rng = np.random.default_rng(3)
    q_r = pin.randomConfiguration(reduced, -np.ones(reduced.nq), np.ones(reduced.nq))
    q_r[:3] = rng.uniform(-1, 1, 3)
    q_f = pin.neutral(full)
    q_f[:13] = q_r
    for name, value in locked.items():
        q_f[full.joints[full.getJointId(name)].idx_q] = value
    M_r = pin.crba(reduced, reduced.createData(), q_r)
    M_f = pin.crba(full, full.createData(), q_f)
    keep = list(range(12))  # the free flyer's six and panda_joint1..6, first in both models
    np.testing.assert_allclose(M_r, M_f[np.ix_(keep, keep)], rtol=0, atol=1e-12)
    data_r, data_f = reduced.createData(), full.createData()
    pin.framesForwardKinematics(reduced, data_r, q_r)
    pin.framesForwardKinematics(full, data_f, q_f)
    a = data_r.oMf[reduced.getFrameId("panda_hand", pin.FrameType.BODY)]
    b = data_f.oMf[full.getFrameId("panda_hand", pin.FrameType.BODY)]
    np.testing.assert_allclose(a.homogeneous, b.homogeneous, rtol=0, atol=1e-12)


def test_bare_arm_bus_is_remarked():
    """ur5 with no bus link: its 4 kg base link is the body on the free joint; the card says
    so (validate prints it) rather than presenting μ_bus as a bus's."""
    model = load(UR5, "tool0")
    card = robot_card(model, pin.neutral(model), 1.0)
    assert card.bus_mass == pytest.approx(4.0)
    assert card.arm_mass == pytest.approx(_file_masses(UR5) - 4.0)
    assert card.light_bus is not None and "base_link" in card.light_bus


def test_mjcf_parse_error_says_why(tmp_path):
    """Pinocchio's MJCF parser fails with a bare C++ message; MuJoCo's reading names it."""
    bad = tmp_path / "bad.xml"
    bad.write_text('<mujoco model="x"><worldbody><body name="bus"><freejoint/>'
                   '<geom type="box" size="1 1 1" mass="100"/><body name="l1">'
                   '<joint name="j1" type="hinge" class="nope"/>'
                   '<geom type="sphere" size="0.1" mass="1"/></body></body></worldbody>'
                   '</mujoco>')
    with pytest.raises(SpecError, match="unknown default class name 'nope'"):
        load_robot_model(bad, "camera")


def test_cli_refuses_a_jaw_in_one_line(tmp_path):
    spec = tmp_path / "so100.yaml"
    spec.write_text(f"robot:\n  file: {SO100}\n  camera_frame: gripper\n"
                    f"  package_dirs: [{PACKAGES[0]}]\n")
    out = run_cli("validate", spec)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "joint gripper does not move the camera frame" in lines[0], lines
