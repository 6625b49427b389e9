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
def test_gamma_rows_match_finite_differences(robot, seed):
    """ν = Γ v: [ṗ_c (t frame); ω_b; R_et (ṗ_e − ṗ_c); vee(R_teᵀ Ṙ_te)], each by FD."""
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    kin = Kinematics(robot)
    qp, qm = _shifted(robot, q, v)
    (pc_p, pe_p, R_p), (pc_m, pe_m, R_m) = kin(qp), kin(qm)
    pc_dot = (pc_p - pc_m) / (2 * H)
    pe_dot = (pe_p - pe_m) / (2 * H)
    R_dot = (R_p - R_m) / (2 * H)
    R_et = T.R_te.T

    nu = T.gamma @ v
    np.testing.assert_allclose(nu[0:3], pc_dot, atol=FD_ATOL, err_msg=f"v_c, seed {seed}")
    np.testing.assert_allclose(nu[3:6], v[3:6], atol=1e-15, err_msg=f"ω_b, seed {seed}")
    np.testing.assert_allclose(nu[6:9], R_et @ (pe_dot - pc_dot), atol=FD_ATOL,
                               err_msg=f"camera linear twist about the CoM, seed {seed}")
    np.testing.assert_allclose(nu[9:12], _vee(R_et @ R_dot), atol=FD_ATOL,
                               err_msg=f"camera angular velocity, seed {seed}")
    # The FD reference is not trivially small: the check has something to compare.
    assert np.linalg.norm(pc_dot) > 1e-2 and np.linalg.norm(pe_dot - pc_dot) > 1e-2


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


@pytest.mark.parametrize("seed", SEEDS)
def test_gamma_inverse_closed_form_equals_numerical_inverse(robot, seed):
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    assert T.s_min_J > robot.floor  # the damped inverse is exact here
    inv = np.linalg.inv(T.gamma)
    scale = np.abs(inv).max()
    np.testing.assert_allclose(T.gamma_inv, inv, atol=1e-10 * scale)
    np.testing.assert_allclose(T.J_oplus_inv, np.linalg.inv(T.J_oplus),
                               atol=1e-10 * np.abs(T.J_oplus_inv).max())
    # Block-triangular structure: det Γ = det R_tb · det I₃ · det J⊕ = det J⊕.
    assert np.linalg.det(T.gamma) == pytest.approx(np.linalg.det(T.J_oplus), rel=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_gamma_dot_matches_central_difference(robot, seed):
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    qp, qm = _shifted(robot, q, v)
    zero = np.zeros(robot.model.nv)
    fd = (robot.terms(qp, zero, dynamics=False).gamma
          - robot.terms(qm, zero, dynamics=False).gamma) / (2 * H)
    np.testing.assert_allclose(T.gamma_dot, fd, atol=FD_ATOL, err_msg=f"seed {seed}")
    assert np.abs(fd).max() > 1e-2


@pytest.mark.parametrize("seed", SEEDS)
def test_conditioning_readouts_match_svd(robot, seed):
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng, spread=1.0, margin=0.0)
    T = robot.terms(q, v)
    for A, smin, kappa in ((T.J_oplus, T.s_min_J, T.kappa_J), (T.gamma, T.s_min_G, T.kappa_G)):
        s = np.linalg.svd(A, compute_uv=False)
        assert smin == pytest.approx(s[-1], rel=1e-10)
        assert kappa == pytest.approx(s[0] / s[-1], rel=1e-10)


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
def test_M_hat_block_structure(robot, seed):
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    m = _file_mass(robot)
    scale = np.abs(T.M_hat).max()
    np.testing.assert_allclose(T.M_hat[:3, :3], m * np.eye(3), atol=1e-10 * scale)
    np.testing.assert_allclose(T.M_hat[:3, 3:], 0.0, atol=1e-10 * scale)
    np.testing.assert_allclose(T.M_hat[3:, :3], 0.0, atol=1e-10 * scale)
    np.testing.assert_allclose(T.reduced_inertia, T.M_hat[3:, 3:], atol=0)
    # M̆ is SPD.
    assert np.linalg.eigvalsh(T.reduced_inertia).min() > 0


@pytest.mark.parametrize("seed", SEEDS)
def test_kinetic_energy_is_invariant(robot, seed):
    """½ vᵀ M v = ½ νᵀ M̂ ν (ν = Γ v), with the energy from Pinocchio's own energy routine."""
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    ke = pin.computeKineticEnergy(robot.model, robot.model.createData(), q, v)
    nu = T.gamma @ v
    assert 0.5 * v @ T.M @ v == pytest.approx(ke, rel=1e-12)
    assert 0.5 * nu @ T.M_hat @ nu == pytest.approx(ke, rel=1e-10)
    # Split: CoM translation carries ½ m |v_c|², the reduced part the rest.
    assert 0.5 * nu[3:] @ T.reduced_inertia @ nu[3:] == pytest.approx(
        ke - 0.5 * _file_mass(robot) * nu[:3] @ nu[:3], rel=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_M_breve_dot_minus_2C_breve_is_skew(robot, seed):
    rng = np.random.default_rng(seed)
    q, v = random_state(robot, rng)
    T = robot.terms(q, v)
    qp, qm = _shifted(robot, q, v)
    zero = np.zeros(robot.model.nv)
    Mdot = (robot.terms(qp, zero).reduced_inertia - robot.terms(qm, zero).reduced_inertia) / (2 * H)
    S = Mdot - 2 * T.reduced_coriolis
    scale = np.abs(T.reduced_coriolis).max()
    assert scale > 1e-2
    assert np.abs(S + S.T).max() <= 1e-7 * scale, f"seed {seed}"
    # The full transformed system too: M̂̇ − 2Ĉ skew.
    Mh_dot = (robot.terms(qp, zero).M_hat - robot.terms(qm, zero).M_hat) / (2 * H)
    S_full = Mh_dot - 2 * T.C_hat
    assert np.abs(S_full + S_full.T).max() <= 1e-7 * np.abs(T.C_hat).max()
    np.testing.assert_array_equal(T.com_coupling, T.C_hat[3:, :3])


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


@pytest.mark.parametrize("seed", SEEDS)
def test_damped_pinv_is_exact_inverse_above_floor(seed):
    rng = np.random.default_rng(seed)
    floor, damping = 0.02, 0.02
    s = np.sort(rng.uniform(floor, 2.0, 6))[::-1]
    s[-1] = floor * (1 + rng.uniform(0, 0.5))  # σ_min at or just above the floor
    J, _, _ = _with_singular_values(rng, s)
    Ji, smin, kappa = damped_pinv(J, floor, damping)
    np.testing.assert_allclose(Ji, np.linalg.inv(J), rtol=0, atol=1e-9 * np.abs(Ji).max())
    np.testing.assert_allclose(Ji @ J, np.eye(6), atol=1e-10)
    assert smin == pytest.approx(s[-1], rel=1e-12)
    assert kappa == pytest.approx(s[0] / s[-1], rel=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_damped_pinv_below_floor_matches_formula_and_is_bounded(seed):
    """Below the floor: J⁺ = V diag(σ/(σ² + λ²)) Uᵀ, λ² = d²(1 − (σ_min/f)²), ‖J⁺‖ <= f/d²."""
    rng = np.random.default_rng(seed)
    floor, damping = 0.02, 0.015
    bound = max(floor / damping**2, 1 / floor)  # valid for damping <= floor
    for smin in (0.019, 1e-3, 1e-6, 0.0):
        s = np.concatenate([np.sort(rng.uniform(0.1, 2.0, 5))[::-1], [smin]])
        J, U, V = _with_singular_values(rng, s)
        Ji, got_smin, _ = damped_pinv(J, floor, damping)
        lam2 = damping**2 * (1 - (smin / floor) ** 2)
        expected = V @ np.diag(s / (s * s + lam2)) @ U.T
        np.testing.assert_allclose(Ji, expected, atol=1e-9 * max(1.0, np.abs(expected).max()))
        assert np.linalg.norm(Ji, 2) <= bound * (1 + 1e-9)
        assert got_smin == pytest.approx(smin, abs=1e-12)


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
