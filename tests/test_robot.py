"""Γ, Γ⁻¹, Γ̇ and the transformed dynamics against independent computations.

Independent references: positions and attitudes from a *separate* Pinocchio data object
(``centerOfMass``, ``framesForwardKinematics``: no Jacobian, CRBA or centroidal map involved),
differentiated by central differences along ``pin.integrate``; the kinetic energy from
``pin.computeKineticEnergy`` (RNEA-style pass, not CRBA); the total mass summed from the robot
file's text (URDF or MJCF); matrix inverses from ``np.linalg.inv``; SVDs from ``np.linalg.svd``.

Finite-difference tolerances. Central differences of a smooth f along q(t) = q ⊕ t v have
truncation error h² |f'''| / 6 and roundoff about ε |f| / h (ε = 2.2e-16). With h = 1e-5,
|f| <= ~10 (positions within ±6 m, unit rotations) and |f'''| = O(1): truncation ~1e-10,
roundoff ~2e-10. Observed maxima over the seeds: 8e-11 for Γ v, 1e-10 for Γ̇, relative
3e-9 for the skew test. The tolerances (1e-8 absolute, 1e-7 relative) leave a 50-100x margin
while any sign or frame error in a block shows up at O(1e-2..1).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
from conftest import SEEDS, random_state

from pipeline.sim.robot import GiordanoRobot, damped_pinv
from pipeline.spec import load_spec

H = 1e-5
FD_ATOL = 1e-8


def _vee(W: np.ndarray) -> np.ndarray:
    """Vector of the skew part of W."""
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


class Kinematics:
    """CoM and camera pose from a private Pinocchio data (independent of GiordanoRobot.terms)."""

    def __init__(self, robot):
        self.model = robot.model
        self.data = robot.model.createData()
        self.fid = robot.frame_id

    def __call__(self, q):
        p_c = pin.centerOfMass(self.model, self.data, q).copy()
        pin.framesForwardKinematics(self.model, self.data, q)
        oMe = self.data.oMf[self.fid]
        return p_c, oMe.translation.copy(), oMe.rotation.copy()


def _shifted(robot, q, v, h=H):
    return pin.integrate(robot.model, q, h * v), pin.integrate(robot.model, q, -h * v)


# Both shipped robots: the seed (MJCF, a 5 kg box bus) and the servicer (URDF, 150 kg).
ROBOT_SPECS = {"nominal": 17.18, "servicer_nominal": 160.13}  # total mass, kg, by hand


@pytest.fixture(scope="module", params=sorted(ROBOT_SPECS))
def robot(request) -> GiordanoRobot:
    return GiordanoRobot(load_spec(request.param))


def _file_mass(robot) -> float:
    """The masses written in the robot file, summed from its text (URDF or MJCF)."""
    root = ET.parse(robot.spec.robot_path).getroot()
    if root.tag == "mujoco":
        return sum(float(e.get("mass")) for e in root.iter("inertial"))
    return sum(float(m.get("value")) for m in root.iter("mass"))


# -- Γ against finite differences --------------------------------------------------------------

@pytest.mark.parametrize("seed", SEEDS)
def test_positions_match_independent_kinematics(robot, seed):
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    p_c, p_e, R_te = Kinematics(robot)(q)
    np.testing.assert_allclose(T.p_c, p_c, atol=1e-12)
    np.testing.assert_allclose(T.p_e, p_e, atol=1e-12)
    np.testing.assert_allclose(T.R_te, R_te, atol=1e-12)
    # The bus pose is the free-flyer configuration itself.
    np.testing.assert_allclose(T.p_b, q[0:3], atol=1e-15)
    np.testing.assert_allclose(T.R_tb, pin.Quaternion(q[3:7]).toRotationMatrix(), atol=1e-14)


@pytest.mark.parametrize("seed", SEEDS)
def test_gamma_columns_match_finite_differences(robot, seed):
    """Column by column: Γ e_i is the task velocity of the unit velocity e_i (all 12)."""
    rng = np.random.default_rng(seed)
    q, _ = random_state(robot, rng)
    T = robot.terms(q, np.zeros(robot.model.nv), dynamics=False)
    kin = Kinematics(robot)
    R_et = T.R_te.T
    for i in range(robot.model.nv):
        e = np.zeros(robot.model.nv)
        e[i] = 1.0
        (pc_p, pe_p, R_p), (pc_m, pe_m, R_m) = (kin(x) for x in _shifted(robot, q, e))
        pc_dot = (pc_p - pc_m) / (2 * H)
        col = np.concatenate([pc_dot, e[3:6], R_et @ ((pe_p - pe_m) / (2 * H) - pc_dot),
                              _vee(R_et @ (R_p - R_m) / (2 * H))])
        np.testing.assert_allclose(T.gamma[:, i], col, atol=FD_ATOL,
                                   err_msg=f"column {i}, seed {seed}")


def test_gamma_inverse_near_singularity_is_bounded(robot):
    """Elbow straight (q₃ = 0): J⊕ is singular; the damped Γ⁻¹ stays bounded."""
    q = robot.full_configuration(np.array([0.0, -1.6, 0.0, -0.95, 1.5708, 0.0]))
    T = robot.terms(q, np.zeros(robot.model.nv))
    assert T.s_min_J < 1e-3 < robot.floor
    assert np.all(np.isfinite(T.gamma_inv))
    # Each damped singular value of J⊕⁺ is σ/(σ² + λ²) <= floor/damping² (see damped_pinv).
    bound = robot.floor / robot.damping**2
    assert np.linalg.norm(T.J_oplus_inv, 2) <= bound * (1 + 1e-12)
    assert np.linalg.norm(np.linalg.pinv(T.J_oplus, rcond=0), 2) > 10 * bound


TERM_ARRAYS = ("R_tb", "p_b", "p_c", "p_e", "R_te", "p_bc", "J_bar_v", "J_oplus", "J_oplus_inv",
               "G_wb", "gamma", "gamma_inv", "gamma_dot", "M", "C", "M_hat", "C_hat")


@pytest.mark.parametrize("dynamics", [True, False])
def test_terms_own_their_arrays(robot, rng, dynamics):
    """A Terms object must not change when the robot evaluates another state: callers keep
    terms across calls (the mission's guidance keeps the start camera axis R_te[:, 0])."""
    q1, v1 = random_state(robot, rng)
    q2, v2 = random_state(robot, rng)
    T1 = robot.terms(q1, v1, dynamics=dynamics)
    before = {n: np.array(getattr(T1, n), copy=True) for n in TERM_ARRAYS}
    robot.terms(q2, v2, dynamics=True)
    robot.terms(q2, v2, dynamics=False)
    changed = [n for n in TERM_ARRAYS if not np.array_equal(getattr(T1, n), before[n])]
    assert changed == [], f"overwritten by a later call: {changed}"


# -- transformed dynamics ----------------------------------------------------------------------

def test_total_mass_is_the_file_sum(robot):
    assert robot.mass == pytest.approx(_file_mass(robot), rel=1e-12)
    assert robot.mass == pytest.approx(ROBOT_SPECS[robot.spec.name], rel=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_C_is_pinocchio_coriolis_consistent_with_M_dot(robot, seed):
    """Ṁ − 2C skew in joint space too (M by CRBA, Ṁ by FD): guards the M symmetrisation."""
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    qp, qm = _shifted(robot, q, v)
    zero = np.zeros(robot.model.nv)
    Mdot = (robot.terms(qp, zero).M - robot.terms(qm, zero).M) / (2 * H)
    S = Mdot - 2 * T.C
    assert np.abs(S + S.T).max() <= 1e-7 * max(np.abs(T.C).max(), 1.0)
    np.testing.assert_allclose(T.M, T.M.T, atol=0)


# -- damped_pinv -------------------------------------------------------------------------------

def _with_singular_values(rng, s):
    U, _ = np.linalg.qr(rng.standard_normal((len(s), len(s))))
    V, _ = np.linalg.qr(rng.standard_normal((len(s), len(s))))
    return U @ np.diag(s) @ V.T, U, V


def test_damped_pinv_is_continuous_at_the_floor(rng):
    """λ² → 0 as σ_min → floor from below: no jump when the damping switches off."""
    floor, damping = 0.02, 0.02
    s = np.array([1.0, 0.8, 0.5, 0.3, 0.1, floor])
    eps = 1e-9
    _, U, V = _with_singular_values(rng, s)
    d_lo, _, _ = damped_pinv(U @ np.diag(np.r_[s[:-1], floor - eps]) @ V.T, floor, damping)
    d_hi, _, _ = damped_pinv(U @ np.diag(np.r_[s[:-1], floor + eps]) @ V.T, floor, damping)
    # 1/σ changes by ~eps/σ² = 2.5e-6 over the step; a jump would be O(1/floor − floor/(f²+d²)).
    assert np.abs(d_lo - d_hi).max() < 1e-4
