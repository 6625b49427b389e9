"""Eq. 37 beyond the cross-check's four checks: the determinant kernel against exact rational
arithmetic, the extended transform at n = 6 against eqs. 5–6, a second 7-DoF arm from the
collection, and the stages' refusal of a redundant arm until its loop exists."""

from __future__ import annotations

from fractions import Fraction
from importlib import metadata
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg

from pipeline.errors import SpecError
from pipeline.paths import SHIPPED_SPECS
from pipeline.sim import redundancy as rd
from pipeline.sim.linalg import determinant
from pipeline.sim.mission import Mission
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.robot_file import camera_frame_id, load_robot_model
from pipeline.sim.task_transform import gamma_inverse, gamma_matrix, kinematic_terms
from pipeline.spec import load_spec, with_overrides
from pipeline.verify.checks_base import draw_state
from pipeline.verify.checks_redundancy import transform_terms

COLLECTION = Path(metadata.distribution("example-robot-data").locate_file(
    "cmeel.prefix/share/example-robot-data/robots"))


def _exact_det(A: np.ndarray) -> Fraction:
    """det A in exact rationals (Bareiss-free Gaussian elimination on Fractions)."""
    M = [[Fraction(float(x)) for x in row] for row in A]
    n, det = len(M), Fraction(1)
    for k in range(n):
        p = next((i for i in range(k, n) if M[i][k] != 0), None)
        if p is None:
            return Fraction(0)
        if p != k:
            M[k], M[p] = M[p], M[k]
            det = -det
        det *= M[k][k]
        for i in range(k + 1, n):
            f = M[i][k] / M[k][k]
            M[i] = [a - f * b for a, b in zip(M[i], M[k], strict=True)]
    return det


@pytest.mark.parametrize("seed", range(5))
def test_determinant_against_exact_rationals(seed):
    A = np.random.default_rng(seed).standard_normal((6, 6))
    exact = float(_exact_det(A))
    assert determinant(A) == pytest.approx(exact, rel=1e-12)


def test_determinant_of_a_singular_minor_is_zero_not_an_error():
    A = np.arange(36.0).reshape(6, 6)
    A[:, 3] = 0.0
    assert determinant(A) == 0.0


def test_six_joints_reduce_to_eqs_5_and_6():
    """k = 0: no null-space rows, the weighted inverse of a square J⊕ is its inverse, so the
    extended Γ and Γ⁻¹ are eqs. 5 and 6 (above the damped floor)."""
    robot = GiordanoRobot(load_spec("nominal"))
    q, _ = draw_state(robot, np.random.default_rng(6))
    R_tb, p_b, R_te, p_e, J_e, M = (np.array(x) for x in robot.kinematic_inputs(q))
    M = np.triu(M) + np.triu(M, 1).T
    p_bc, _, _, _, J_bar_v, J_oplus, G_wb = kinematic_terms(R_tb, p_b, R_te, p_e, J_e, M,
                                                            robot.mass)
    ns = rd.null_space_terms(J_oplus, G_wb, M, robot.mass, robot.floor, robot.damping)
    assert ns.Z.shape == (6, 0) and ns.Y.shape == (0, 9)
    gamma = gamma_matrix(R_tb, p_bc, J_bar_v, G_wb, J_oplus)
    np.testing.assert_array_equal(rd.extended_gamma(gamma, ns.Y), gamma)
    eq6 = gamma_inverse(R_tb, p_bc, J_bar_v, G_wb, np.linalg.inv(J_oplus))
    np.testing.assert_allclose(rd.extended_gamma_inverse(R_tb, p_bc, J_bar_v, ns), eq6,
                               rtol=0, atol=1e-10)


def test_the_collections_xarm7_self_motion():
    """A second 7-DoF arm (xArm7, bare: its base link is the body on the free joint): the
    null-space velocity of a random state moves the end-effector link not at all, and Z̃ is
    SciPy's null space up to sign."""
    path = COLLECTION / "xarm_description" / "urdf" / "xarm7.urdf"
    model = load_robot_model(path, "link_eef")
    fid = camera_frame_id(model, "link_eef")
    data = model.createData()
    g = np.random.default_rng(7)
    q = np.r_[g.uniform(-1, 1, 3), [0, 0, 0, 1.0],
              g.uniform(model.lowerPositionLimit[7:] / 2, model.upperPositionLimit[7:] / 2)]
    (R_tb, p_bc, _, _, _, J_bar_v, J_oplus, _), ns, _ = transform_terms(model, fid, q)
    z = scipy.linalg.null_space(J_oplus)[:, 0]
    assert abs(abs(ns.Z[:, 0] @ z) - 1.0) < 1e-12
    v = rd.extended_gamma_inverse(R_tb, p_bc, J_bar_v, ns) @ np.r_[np.zeros(12), 0.5]
    pin.forwardKinematics(model, data, q, v)
    twist = pin.getFrameVelocity(model, data, fid, pin.ReferenceFrame.LOCAL).vector
    assert np.abs(twist).max() < 1e-12 and np.linalg.norm(v[6:]) == pytest.approx(0.5)


def test_the_stages_refuse_a_redundant_arm_without_its_null_space_impedance():
    spec = with_overrides(load_spec("nominal"), {
        "robot.file": str(SHIPPED_SPECS / "robots" / "servicer_panda.urdf"),
        "robot.locked_joints": {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0},
        "robot.q_bar": [0.0] * 7})
    with pytest.raises(SpecError, match=r"field controller\.null_space: 7 arm joints .*give "
                                        r"their impedance .*or lock 1 joint in "
                                        r"robot\.locked_joints"):
        Mission(spec)
