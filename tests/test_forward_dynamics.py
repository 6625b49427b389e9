"""The compiled plant (eq. 29) against Pinocchio: the articulated-body algorithm against
``pin.aba`` (an independent implementation), the configuration rate against finite differences
of ``pin.integrate``, one held step against an RK4 written here on Pinocchio's ABA, and the
attitude excursion against ``log3``/``exp3``."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.sim.forward_dynamics import forward_dynamics, rigid_tree, spatial_inertia
from pipeline.sim.plant import attitude_excursion, configuration_rate, integrate_held
from pipeline.sim.robot_file import load_spec_robot
from pipeline.spec import load_spec


def _random_q(model: pin.Model, rng: np.random.Generator) -> np.ndarray:
    q = pin.neutral(model)
    q[:3] = rng.standard_normal(3)
    quat = rng.standard_normal(4)
    q[3:7] = quat / np.linalg.norm(quat)
    q[7:] = rng.uniform(-np.pi, np.pi, model.nq - 7)
    return q


def _unaligned_arm() -> pin.Model:
    """A free body with a chain of three revolute joints about unaligned axes, each body
    with an off-centre mass and a full inertia tensor: what no shipped robot has."""
    rng = np.random.default_rng(7)
    m = pin.Model()
    parent = m.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "bus")
    m.appendBodyToJoint(parent, pin.Inertia(4.0, np.array([0.01, -0.02, 0.03]),
                                            np.diag([0.3, 0.4, 0.5])), pin.SE3.Identity())
    for i in range(3):
        axis = rng.standard_normal(3)
        axis /= np.linalg.norm(axis)
        R = pin.exp3(rng.standard_normal(3))
        place = pin.SE3(R, rng.standard_normal(3) * 0.2)
        parent = m.addJoint(parent, pin.JointModelRevoluteUnaligned(axis), place, f"j{i}")
        A = rng.standard_normal((3, 3))
        m.appendBodyToJoint(parent, pin.Inertia(0.5 + i, rng.standard_normal(3) * 0.05,
                                                A @ A.T * 0.01 + 0.01 * np.eye(3)),
                            pin.SE3.Identity())
    m.gravity.setZero()
    return m


@pytest.mark.parametrize("name", ["nominal", "servicer_nominal", "panda_nominal", "unaligned"])
def test_forward_dynamics_is_pinocchios_aba(name, rng):
    model = _unaligned_arm() if name == "unaligned" else load_spec_robot(load_spec(name))
    data, tree = model.createData(), rigid_tree(model)
    for _ in range(10):
        q = _random_q(model, rng)
        v, tau = rng.standard_normal(model.nv), rng.standard_normal(model.nv)
        ref = pin.aba(model, data, q, v, tau)
        got = forward_dynamics(tree, q, v, tau)
        assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref)), name


def test_spatial_inertia_is_pinocchios(rng):
    for _ in range(5):
        inertia = pin.Inertia.Random()
        Y = spatial_inertia(inertia.mass, inertia.lever, inertia.inertia)
        assert np.allclose(Y, inertia.matrix(), rtol=0, atol=1e-13)


def test_forward_dynamics_can_fail(rng):
    """A wrong axis is seen: the check is not vacuous."""
    model = load_spec_robot(load_spec("nominal"))
    tree = rigid_tree(model)
    bad = tree._replace(axis=tree.axis[:, ::-1].copy())
    q, v, tau = _random_q(model, rng), rng.standard_normal(12), rng.standard_normal(12)
    ref = pin.aba(model, model.createData(), q, v, tau)
    assert np.max(np.abs(forward_dynamics(bad, q, v, tau) - ref)) > 1e-3 * np.max(np.abs(ref))


def test_configuration_rate_is_the_derivative_of_integrate(rng):
    model = load_spec_robot(load_spec("panda_nominal"))
    q, v = _random_q(model, rng), rng.standard_normal(model.nv)
    h = 1e-6
    fd = (pin.integrate(model, q, v * h) - pin.integrate(model, q, -v * h)) / (2 * h)
    assert np.max(np.abs(configuration_rate(q, v) - fd)) < 1e-8


def _reference_step(model, q, v, tau, dt, substeps):
    """RK4 on Pinocchio's aba, in Python (the plant as it was before it was compiled)."""
    data, h = model.createData(), dt / substeps

    def rates(qs, vs):
        qs = qs.copy()
        qs[3:7] /= np.linalg.norm(qs[3:7])
        return configuration_rate(qs, vs), pin.aba(model, data, qs, vs, tau).copy()

    path = []
    for _ in range(substeps):
        dq1, dv1 = rates(q, v)
        dq2, dv2 = rates(q + 0.5 * h * dq1, v + 0.5 * h * dv1)
        dq3, dv3 = rates(q + 0.5 * h * dq2, v + 0.5 * h * dv2)
        dq4, dv4 = rates(q + h * dq3, v + h * dv3)
        q = q + h / 6 * (dq1 + 2 * dq2 + 2 * dq3 + dq4)
        q[3:7] /= np.linalg.norm(q[3:7])
        v = v + h / 6 * (dv1 + 2 * dv2 + 2 * dv3 + dv4)
        path.append(q)
    return q, v, path


def _reference_excursion(q_start, path):
    def rotation(qs):
        return pin.Quaternion(qs[6], qs[3], qs[4], qs[5]).normalized().toRotationMatrix()

    R0 = rotation(q_start)
    chord = pin.log3(R0.T @ rotation(path[-1]))
    return max(float(np.linalg.norm(pin.log3((R0 @ pin.exp3(chord * j / len(path))).T
                                             @ rotation(qs))))
               for j, qs in enumerate(path[:-1], start=1))


def test_held_step_is_rk4_on_pinocchio(rng):
    model = load_spec_robot(load_spec("nominal"))
    tree = rigid_tree(model)
    q, v = _random_q(model, rng), rng.standard_normal(model.nv) * 0.3
    tau = rng.standard_normal(model.nv)
    q1, v1, excursion = integrate_held(tree, q, v, tau, 0.03, 8)
    q_ref, v_ref, path = _reference_step(model, q, v, tau, 0.03, 8)
    assert np.max(np.abs(q1 - q_ref)) < 1e-12
    assert np.max(np.abs(v1 - v_ref)) < 1e-12 * np.max(np.abs(v_ref))
    ref = _reference_excursion(q, path)
    assert ref > 1e-6  # the path bends: the comparison means something
    assert abs(excursion - ref) < 1e-10 * ref


def test_attitude_excursion_of_a_geodesic_is_zero():
    """A rotation at constant rate about a fixed axis is its own geodesic."""
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    q0 = np.array([0.1, 0.2, -0.3, 0.9]) / np.linalg.norm([0.1, 0.2, -0.3, 0.9])
    path = []
    for j in range(1, 9):
        half = 0.5 * 0.04 * j
        step = np.r_[axis * np.sin(half), np.cos(half)]
        x0, y0, z0, w0 = q0
        x1, y1, z1, w1 = step
        path.append([w0 * x1 + w1 * x0 + y0 * z1 - z0 * y1, w0 * y1 + w1 * y0 + z0 * x1 - x0 * z1,
                     w0 * z1 + w1 * z0 + x0 * y1 - y0 * x1, w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1])
    assert attitude_excursion(q0, np.array(path)) < 1e-14
