"""The compiled rigid-body terms and q ⊕ δ against Pinocchio (a second implementation), against
finite differences (Ṁ = C + Cᵀ), and the compiled mission loop against the step it repeats.

The terms are the controller's inputs (eqs. 2–11): placements, the camera Jacobian and its
rate (LOCAL), M, C, A_g, Ȧ_g. Pinocchio's own routines are the reference here; the simulator
no longer calls them per step (issue 48).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg

from pipeline.sim.configuration import SERIES_BELOW, integrate_configuration
from pipeline.sim.linalg import singular_values, svd_right_from
from pipeline.sim.mission import Mission
from pipeline.sim.rigid_body_terms import dynamics_terms, placement_terms, robot_terms
from pipeline.sim.robot import GiordanoRobot
from pipeline.spec import load_spec, with_overrides

LOCAL = pin.ReferenceFrame.LOCAL
# Relative to the largest entry of Pinocchio's matrix: the two sum the same products in
# another order, so they agree to rounding, a few ε times the operands' scale.
TOL = 1e-12


def _branching_tree() -> tuple[pin.Model, int]:
    """A free-floating tree with two branches off the bus, revolute joints about x, y, z and
    unaligned axes, off-centre masses and placements, and a camera frame placed off its joint
    on the second branch: what no shipped arm (a chain) exercises."""
    rng = np.random.default_rng(7)
    model = pin.Model()
    model.gravity.setZero()

    def inertia() -> pin.Inertia:
        A = rng.standard_normal((3, 3))
        return pin.Inertia(float(rng.uniform(0.5, 3.0)), rng.standard_normal(3) * 0.2,
                           A @ A.T + np.eye(3) * 0.1)

    def placement() -> pin.SE3:
        return pin.SE3(pin.exp3(rng.standard_normal(3)), rng.standard_normal(3) * 0.3)

    bus = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "bus")
    model.appendBodyToJoint(bus, inertia(), pin.SE3.Identity())
    kinds = [pin.JointModelRX(), pin.JointModelRY(),
             pin.JointModelRevoluteUnaligned(*(np.array([1.0, 2.0, -0.5]) / np.sqrt(5.25))),
             pin.JointModelRZ(), pin.JointModelRevoluteUnaligned(0.0, -0.6, 0.8)]
    parents = [bus, 2, bus, 4, 5]  # joints 2–3 on one branch, 4–6 on the other
    for i, (kind, parent) in enumerate(zip(kinds, parents, strict=True)):
        j = model.addJoint(parent, kind, placement(), f"j{i}")
        model.appendBodyToJoint(j, inertia(), pin.SE3.Identity())
    frame = model.addFrame(pin.Frame("camera", 6, 0, placement(), pin.FrameType.OP_FRAME))
    return model, frame


def _models() -> list[tuple[str, pin.Model, int]]:
    out = []
    for name in ("nominal", "servicer_nominal", "panda_nominal"):
        robot = GiordanoRobot(load_spec(name))
        out.append((name, robot.model, robot.frame_id))
    return [*out, ("branching", *_branching_tree())]


MODELS = _models()


def _state(model: pin.Model, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A seeded state: the bus anywhere within 3 m at any attitude, the joints within ±3 rad."""
    quat = rng.standard_normal(4)
    q = np.concatenate([rng.uniform(-3, 3, 3), quat / np.linalg.norm(quat),
                        rng.uniform(-3, 3, model.nq - 7)])
    return q, rng.standard_normal(model.nv)


def _pinocchio(model: pin.Model, fid: int, q: np.ndarray, v: np.ndarray) -> dict:
    """Each term by Pinocchio's own routine, on fresh data."""
    d = model.createData()
    pin.computeJointJacobiansTimeVariation(model, d, q, v)
    pin.updateFramePlacements(model, d)
    out = {"R_tb": d.oMi[1].rotation.copy(), "p_b": d.oMi[1].translation.copy(),
           "R_te": d.oMf[fid].rotation.copy(), "p_e": d.oMf[fid].translation.copy(),
           "J_e": pin.getFrameJacobian(model, d, fid, LOCAL).copy(),
           "dJ_e": pin.getFrameJacobianTimeVariation(model, d, fid, LOCAL).copy(),
           "M": pin.crba(model, d, q).copy(),
           "C": pin.computeCoriolisMatrix(model, d, q, v).copy()}
    # Pinocchio 4.1's map rate reads data.vcom without computing it: computed here first.
    pin.computeCentroidalMomentum(model, d, q, v)
    out["dAg"] = pin.computeCentroidalMapTimeVariation(model, d, q, v).copy()
    out["Ag"] = d.Ag.copy()
    return out


@pytest.mark.parametrize("name,model,fid", MODELS, ids=[m[0] for m in MODELS])
def test_every_term_is_pinocchios_to_rounding(name, model, fid):
    bundle = robot_terms(model, fid)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, v = _state(model, rng)
        ours = dynamics_terms(bundle, q, v)
        ref = _pinocchio(model, fid, q, v)
        for field in ours._fields:
            want = ref[field]
            scale = max(1.0, float(np.max(np.abs(want))))
            np.testing.assert_allclose(getattr(ours, field), want, rtol=0, atol=TOL * scale,
                                       err_msg=f"{name}: {field}")


def test_pinocchios_map_rate_leaves_out_the_com_velocity_term_and_ours_has_it():
    """Pinocchio 4.1's computeCentroidalMapTimeVariation alone misses A_g,lin × v_com in Ȧ_g's
    angular rows (its vcom not computed there); after computeCentroidalMomentum it has it. The
    step reads only the linear rows, which the two share."""
    _name, model, fid = MODELS[0]
    q, v = _state(model, np.random.default_rng(5))
    ours = dynamics_terms(robot_terms(model, fid), q, v)
    alone = model.createData()
    dAg = pin.computeCentroidalMapTimeVariation(model, alone, q, v).copy()
    assert np.max(np.abs(dAg[3:] - ours.dAg[3:])) > 1e-3
    np.testing.assert_allclose(dAg[:3], ours.dAg[:3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("name,model,fid", MODELS, ids=[m[0] for m in MODELS])
def test_the_mass_matrix_rate_is_c_plus_c_transpose(name, model, fid):
    """Ṁ = C + Cᵀ (the factorisation's defining property), Ṁ by central differences of our own
    M along q ⊕ ±h v, and J̇_e v = d/dt (J_e) v likewise: independent of Pinocchio. The
    difference's error is its rounding, about ε ‖M‖/h = 2e-10 ‖M‖, and h² ‖M‴‖/6 (1e-12):
    allowed 1e-8 of the matrix's scale."""
    bundle = robot_terms(model, fid)
    q, v = _state(model, np.random.default_rng(11))
    h = 1e-6
    plus, minus = pin.integrate(model, q, h * v), pin.integrate(model, q, -h * v)
    terms = dynamics_terms(bundle, q, v)
    M_dot = (placement_terms(bundle, plus)[5] - placement_terms(bundle, minus)[5]) / (2 * h)
    np.testing.assert_allclose(terms.C + terms.C.T, M_dot, rtol=0,
                               atol=1e-8 * max(1.0, np.max(np.abs(terms.M))))
    J_dot = (placement_terms(bundle, plus)[4] - placement_terms(bundle, minus)[4]) / (2 * h)
    np.testing.assert_allclose(terms.dJ_e @ v, J_dot @ v, rtol=0,
                               atol=1e-8 * max(1.0, np.max(np.abs(terms.J_e))))


def test_the_placement_terms_are_the_dynamics_terms_to_the_bit():
    """Γ rebuilt from a logged q (placement_terms) must be the simulator's Γ to the bit."""
    _name, model, fid = MODELS[2]
    bundle = robot_terms(model, fid)
    q, v = _state(model, np.random.default_rng(2))
    d = dynamics_terms(bundle, q, v)
    for got, want in zip(placement_terms(bundle, q), (d.R_tb, d.p_b, d.R_te, d.p_e, d.J_e, d.M),
                         strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("scale", [1e-9, 0.3 * SERIES_BELOW, 3 * SERIES_BELOW, 0.03, 1.0, 3.0])
def test_q_plus_delta_is_pinocchios_integrate(scale):
    """Both branches of the series (|δθ| below and above SERIES_BELOW), to a few ulps."""
    _name, model, _fid = MODELS[0]
    rng = np.random.default_rng(int(scale * 1e9) % 1000)
    for _ in range(50):
        q, dq = _state(model, rng)
        dq[3:6] *= scale / np.linalg.norm(dq[3:6])
        np.testing.assert_allclose(integrate_configuration(q, dq), pin.integrate(model, q, dq),
                                   rtol=0, atol=8e-15 * max(1.0, np.max(np.abs(q))))


def test_a_warm_started_svd_is_rounding_away_from_lapacks_and_cold_is_the_cold_kernels():
    rng = np.random.default_rng(4)
    A = rng.standard_normal((12, 12))
    s_cold, Vt = svd_right_from(A, np.empty((0, 0)))
    np.testing.assert_array_equal(s_cold, singular_values(A))
    B = A + 1e-3 * rng.standard_normal((12, 12))  # the next step's matrix
    s_warm, Vt_warm = svd_right_from(B, Vt)
    lapack = scipy.linalg.svdvals(B)
    np.testing.assert_allclose(s_warm, lapack, rtol=0, atol=64 * np.finfo(float).eps * lapack[0])
    np.testing.assert_allclose(Vt_warm @ Vt_warm.T, np.eye(12), rtol=0, atol=1e-13)


@pytest.mark.parametrize("spec_name", ["short_nominal", "panda_nominal"])
def test_the_compiled_loop_is_the_step_repeated_to_the_bit(spec_name):
    """A run's rows (the compiled loop, many steps per call) against Mission.step chained from
    the same start (one step per call, the state carried through Python)."""
    spec = with_overrides(load_spec(spec_name), {"mission.duration": 20 * load_spec(
        spec_name).mission.dt})
    mission = Mission(spec)
    cols = mission.run().columns
    s = mission.initial_state()
    for k in range(spec.n_steps):
        for name in ("q", "v", "v_c", "v_breve"):
            np.testing.assert_array_equal(getattr(s, name), cols[name][k], f"{name} {k}")
        s, row = mission.step(s)
        for name in ("s_min_G", "kappa_G", "dt_mu_max", "u_cmd"):
            np.testing.assert_array_equal(row[name], cols[name][k], f"{name} {k}")


def test_a_model_not_numbered_depth_first_is_refused():
    """Two branches off the bus, the first's child added after the second: its subtree's
    velocities are not one range, which the kernel's M and C need."""
    from pipeline.errors import SpecError

    model = pin.Model()
    bus = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "bus")
    a = model.addJoint(bus, pin.JointModelRX(), pin.SE3.Identity(), "a")
    model.addJoint(bus, pin.JointModelRY(), pin.SE3.Identity(), "b")
    c = model.addJoint(a, pin.JointModelRZ(), pin.SE3.Identity(), "c")
    for j in range(1, model.njoints):
        model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    frame = model.addFrame(pin.Frame("camera", c, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    with pytest.raises(SpecError, match="depth first"):
        robot_terms(model, frame)


def test_a_start_far_from_orthonormal_is_not_a_start():
    """A zero or arbitrary Vᵀ (a hand-built LoopState) starts from the identity, not from it."""
    A = np.random.default_rng(8).standard_normal((12, 12))
    for start in (np.zeros((12, 12)), 3.0 * np.eye(12)):
        np.testing.assert_array_equal(svd_right_from(A, start)[0], singular_values(A))


def test_the_terms_do_not_lose_digits_far_from_the_target():
    """M, C, the LOCAL Jacobians and the centroidal maps do not depend on where the bus is:
    moved 2e4 m out they agree with the terms at 3 m to the arm's rounding (about a far
    origin the inertias' m ĉ ĉ would cancel some eight digits)."""
    _name, model, fid = MODELS[0]
    bundle = robot_terms(model, fid)
    q, v = _state(model, np.random.default_rng(12))
    far = q.copy()
    far[0:3] += [1.2e4, -2.0e4, 3.0e3]
    near_t, far_t = dynamics_terms(bundle, q, v), dynamics_terms(bundle, far, v)
    for field in ("M", "C", "J_e", "dJ_e", "Ag", "dAg", "R_te"):
        want = getattr(near_t, field)
        np.testing.assert_allclose(getattr(far_t, field), want, rtol=0,
                                   atol=1e-12 * max(1.0, np.max(np.abs(want))), err_msg=field)
    np.testing.assert_allclose(far_t.p_e - far_t.p_b, near_t.p_e - near_t.p_b, rtol=0,
                               atol=1e-11)
