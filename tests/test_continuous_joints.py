"""Continuous joints flown (issue 51, item 1): the loader makes each of the file's continuous
joints (Pinocchio's unbounded revolute, its angle held as cos and sin) the revolute joint of
the same axis without a range, one unwrapped angle in q. Checked against Pinocchio's own
(cos, sin) joint on the collection's Kinova, and flown end to end on a seven-joint arm with
four continuous joints (the collection's Panda, as the servicer carries it, joints 1, 3, 5
and 7 declared continuous as a Kinova Gen3's are), one of them turning past π."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import run_cli_in_process
from test_robot_files import KINOVA

from pipeline.paths import SHIPPED_SPECS
from pipeline.shapes import Q
from pipeline.sim.mission import Mission
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.robot_file import as_revolute
from pipeline.spec import load_spec, with_overrides

CONTINUOUS = ("panda_joint1", "panda_joint3", "panda_joint5", "panda_joint7")


def _cos_sin(full: pin.Model, model: pin.Model, theta: np.ndarray) -> np.ndarray:
    """``full``'s configuration (its continuous joints as cos and sin) at ``model``'s angles
    θ (the same joints, each continuous one made one angle by ``as_revolute``)."""
    cs = np.concatenate([theta[:7], np.zeros(full.nq - 7)])
    for j in range(2, full.njoints):
        a, b = full.joints[j], model.joints[j]
        angle = theta[b.idx_q]
        cs[a.idx_q:a.idx_q + a.nq] = (math.cos(angle), math.sin(angle)) if a.nq == 2 else angle
    return cs


def _same_placements_and_inertia(full, model, theta, atol: float) -> tuple:
    """Frames and CRBA of ``model`` at θ against ``full``'s at (cos θ, sin θ); the data."""
    cs = _cos_sin(full, model, theta)
    d_full, d_model = full.createData(), model.createData()
    pin.framesForwardKinematics(full, d_full, cs)
    pin.framesForwardKinematics(model, d_model, theta)
    for f in range(len(full.frames)):
        np.testing.assert_allclose(d_model.oMf[f].homogeneous, d_full.oMf[f].homogeneous,
                                   rtol=0, atol=atol)
    np.testing.assert_allclose(pin.crba(model, d_model, theta), pin.crba(full, d_full, cs),
                               rtol=0, atol=atol)
    return cs, d_full, d_model


@pytest.fixture(scope="module")
def gen3like(tmp_path_factory) -> Path:
    """The servicer's Panda with joints 1, 3, 5 and 7 declared continuous, and a spec."""
    folder = tmp_path_factory.mktemp("gen3like")
    text = (SHIPPED_SPECS / "robots" / "servicer_panda.urdf").read_text()
    for name in CONTINUOUS:
        text, n = re.subn(rf'(<joint name="{name}" type=")revolute(")', r"\1continuous\2",
                          text)
        assert n == 1
    (folder / "gen3like.urdf").write_text(text)
    spec = folder / "gen3like.yaml"
    spec.write_text(f"extends: short_panda_nominal\nrobot: {{file: {folder / 'gen3like.urdf'}}}\n"
                    "mission: {duration: 6.0}\n")
    return spec


def test_a_continuous_joint_is_pinocchios_cos_sin_joint_at_its_angle():
    """On the Kinova (joints 1, 4 and 6 continuous): frames, CRBA and the Coriolis matrix of
    the converted model at angles θ (far past ±π too) equal those of Pinocchio's own
    (cos θ, sin θ) joints, to round-off (a ulp)."""
    full = pin.buildModelFromUrdf(str(KINOVA), pin.JointModelFreeFlyer())
    model, names = as_revolute(full)
    assert names == ["j2s6s200_joint_1", "j2s6s200_joint_4", "j2s6s200_joint_6"]
    assert (full.nq, model.nq, model.nv) == (16, 13, 12)
    rng = np.random.default_rng(3)
    for _ in range(10):
        theta = pin.neutral(model)
        theta[7:] = rng.uniform(-9.0, 9.0, 6)
        v = rng.normal(size=12)
        cs, d_full, d_model = _same_placements_and_inertia(full, model, theta, 1e-15)
        np.testing.assert_allclose(pin.computeCoriolisMatrix(model, d_model, theta, v),
                                   pin.computeCoriolisMatrix(full, d_full, cs, v),
                                   rtol=0, atol=1e-12)


def test_a_continuous_joint_about_any_axis_is_converted_and_loads(tmp_path):
    """A URDF continuous joint about −z or about (0, 0.6, 0.8) is Pinocchio's unbounded
    revolute of an unaligned axis: converted too (its axis from the joint's motion subspace),
    the same placements and CRBA as the (cos, sin) joints at any angle, and the file loads
    (the MuJoCo cross-parse included)."""
    text = (SHIPPED_SPECS / "robots" / "servicer_panda.urdf").read_text()
    for name, axis in (("panda_joint1", "0 0 -1"), ("panda_joint3", "0 0.6 0.8")):
        start = text.index(f'<joint name="{name}" type="revolute">')
        end = text.index("</joint>", start)
        joint = text[start:end].replace('type="revolute"', 'type="continuous"')
        joint = re.sub(r'<axis xyz="[^"]*" */>', f'<axis xyz="{axis}" />', joint)
        text = text[:start] + joint + text[end:]
    path = tmp_path / "unaligned.urdf"
    path.write_text(text)
    full = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    assert full.joints[2].shortname() == "JointModelRevoluteUnboundedUnaligned"
    model, names = as_revolute(full)
    assert names == ["panda_joint1", "panda_joint3"] and model.nq == full.nq - 2
    rng = np.random.default_rng(4)
    for _ in range(10):
        theta = pin.neutral(model)
        theta[7:] = rng.uniform(-7.0, 7.0, model.nq - 7)
        _same_placements_and_inertia(full, model, theta, 1e-13)
    from pipeline.sim.robot_file import load_robot_model

    loaded = load_robot_model(path, "camera", locked_joints={"panda_finger_joint1": 0.0,
                                                             "panda_finger_joint2": 0.0})
    assert (loaded.nq, loaded.nv) == (14, 13)


def test_a_seven_joint_arm_with_four_continuous_joints_validates_runs_and_is_analysed(
        gen3like, tmp_path):
    r = run_cli_in_process("validate", gen3like)
    assert r.returncode == 0, r.stderr
    assert ("continuous joints (no range; flown as one unwrapped angle each): "
            + ", ".join(CONTINUOUS)) in r.stdout
    r = run_cli_in_process("run", gen3like, "--out", tmp_path / "logs")
    assert r.returncode == 0, r.stderr
    log = tmp_path / "logs" / "gen3like" / "run.parquet"
    r = run_cli_in_process("analyze", log, "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    record = json.loads((tmp_path / "out" / "gen3like" / "analysis.json").read_text())
    assert record["robot"]["continuous_joints"] == list(CONTINUOUS)
    robot = GiordanoRobot(load_spec(gen3like))
    assert (robot.model.nq, robot.model.nv) == (14, 13)  # v of width 13: 6 + 7
    assert record["joint_ranges"]["max_excess"] == 0.0  # no range to leave


def test_a_continuous_joint_turns_past_pi_with_q_continuous(gen3like):
    """panda_joint7 flown from q̄ 3.08 rad: its angle rises through π, one angle all along
    (no wrap to −π), and Γ rebuilt from the logged q past π is the (cos, sin) model's."""
    spec = load_spec(gen3like)
    q_bar = list(spec.robot.q_bar)
    q_bar[6] = 3.08
    spec = with_overrides(spec, {"robot.q_bar": q_bar})
    mission = Mission(spec)
    q = mission.run().columns["q"]
    q7 = q[:, Q.joints][:, 6]
    assert q7.min() < math.pi < q7.max()
    assert np.abs(np.diff(q7)).max() < 1e-3  # continuous: no jump of 2π
    k = int(np.argmax(q7 > math.pi + 0.01))
    assert k > 0
    # Γ at that step from the logged angle, and from Pinocchio's (cos, sin) joints at it: the
    # same placements and Jacobian, so the same Γ.
    gamma = mission.robot.gamma_matrices(q[k:k + 1])[0]
    full = pin.buildModelFromUrdf(str(spec.robot_path), pin.JointModelFreeFlyer())
    full = pin.buildReducedModel(full, [full.getJointId("panda_finger_joint1"),
                                        full.getJointId("panda_finger_joint2")],
                                 pin.neutral(full))
    model = mission.robot.model
    cs = _cos_sin(full, model, q[k])
    fid = mission.robot.frame_id
    d_full, d_model = full.createData(), model.createData()
    pin.computeJointJacobians(full, d_full, cs)
    pin.computeJointJacobians(model, d_model, q[k])
    pin.updateFramePlacements(full, d_full)
    pin.updateFramePlacements(model, d_model)
    np.testing.assert_allclose(
        pin.getFrameJacobian(model, d_model, fid, pin.LOCAL),
        pin.getFrameJacobian(full, d_full, full.getFrameId(model.frames[fid].name),
                             pin.LOCAL), rtol=0, atol=1e-12)
    assert np.isfinite(gamma).all() and gamma.shape == (13, 13)
