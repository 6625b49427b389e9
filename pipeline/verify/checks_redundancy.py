"""Checks of a redundant arm's null-space terms (eq. 37) on the shipped 7-DoF robot
(``specs/robots/servicer_panda.urdf``, its fingers locked): the basis against SciPy's null
space, H against the kinetic energy, the null-space velocity against Pinocchio's velocities of
a self-motion, the closed-form Γ⁻¹ against NumPy's inverse and M̂'s blocks.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin
import scipy.linalg

from pipeline.paths import SHIPPED_SPECS
from pipeline.verify.checks_base import Outcome, check, fmt, maxdiff, rng

ROBOT_FILE = SHIPPED_SPECS / "robots" / "servicer_panda.urdf"
LOCKED = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}
FLOOR = DAMPING = 0.02  # the spec defaults of eq. 6
H_STEP = 1e-6


@cache
def _model() -> tuple[pin.Model, int, float]:
    from pipeline.sim.robot_file import camera_frame_id, load_robot_model

    model = load_robot_model(ROBOT_FILE, "camera", locked_joints=LOCKED)
    return model, camera_frame_id(model, "camera"), float(pin.computeTotalMass(model))


def _state(salt: int) -> tuple[np.ndarray, np.ndarray]:
    """A random (q, v): bus within ±2 m, uniform attitude, joints uniform within their limits
    but 0.3 rad, v ~ N(0, 0.2²)."""
    model, _, _ = _model()
    g = rng(370 + salt)
    lo, hi = model.lowerPositionLimit[7:] + 0.3, model.upperPositionLimit[7:] - 0.3
    quat = g.standard_normal(4)
    q = np.r_[g.uniform(-2, 2, 3), quat / np.linalg.norm(quat), g.uniform(lo, hi)]
    return q, 0.2 * g.standard_normal(model.nv)


def _terms(q: np.ndarray):
    """:func:`transform_terms` of the checks' robot at q."""
    model, fid, _ = _model()
    return transform_terms(model, fid, q)


def transform_terms(model: pin.Model, fid: int, q: np.ndarray):
    """((R_tb, kinematic terms of eqs. 2–4), null-space terms of eq. 37, M) of a redundant
    ``model`` at q, camera frame ``fid``, through the code under test (Pinocchio's inputs
    copied, M symmetric)."""
    from pipeline.sim.redundancy import null_space_terms
    from pipeline.sim.task_transform import kinematic_terms

    mass = float(pin.computeTotalMass(model))
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J_e = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL).copy()
    M = pin.crba(model, data, q).copy()
    M = np.triu(M) + np.triu(M, 1).T
    R_tb, p_b = data.oMi[1].rotation.copy(), data.oMi[1].translation.copy()
    R_te, p_e = data.oMf[fid].rotation.copy(), data.oMf[fid].translation.copy()
    kin = kinematic_terms(R_tb, p_b, R_te, p_e, J_e, M, mass)
    return (R_tb, *kin), null_space_terms(kin[5], kin[6], M, mass, FLOOR, DAMPING), M


def _gammas(q: np.ndarray):
    from pipeline.sim.redundancy import extended_gamma, extended_gamma_inverse
    from pipeline.sim.task_transform import gamma_matrix

    (R_tb, p_bc, _, _, _, J_bar_v, J_oplus, G_wb), ns, M = _terms(q)
    return (extended_gamma(gamma_matrix(R_tb, p_bc, J_bar_v, G_wb, J_oplus), ns.Y),
            extended_gamma_inverse(R_tb, p_bc, J_bar_v, ns), ns, M)


def _text(salt: int) -> str:
    return (f"servicer_panda (n = 7, fingers locked), random (q, v), seed {370 + salt}, "
            f"joints 0.3 rad inside their limits")


@check("37a", "Z̃ spans null(J⊕): ‖J⊕Z̃‖, |1 − |Z̃ᵀz|| against SciPy's null space, and "
       "‖Z̃(q ⊕ hv) − Z̃(q ⊖ hv)‖/2h bounded (no sign flip)",
       "pipeline.sim.redundancy.null_space_basis")
def _null_space_basis() -> Outcome:
    from pipeline.sim.redundancy import null_space_basis

    q, v = _state(1)
    (_, _, _, _, _, _, J_oplus, _), ns, _ = _terms(q)
    z = scipy.linalg.null_space(J_oplus)[:, 0]
    model = _model()[0]
    Zp, Zm = (null_space_basis(_terms(pin.integrate(model, q, s * H_STEP * v))[0][6])
              for s in (1, -1))
    rate = float(np.abs(Zp - Zm).max() / (2 * H_STEP))
    d = [float(np.abs(J_oplus @ ns.Z).max()), abs(1.0 - abs(float(ns.Z[:, 0] @ z)))]
    # A sign flip between q ⊖ hv and q ⊕ hv would show as a rate of order 1/h = 1e6.
    jump = rate if rate > 1e3 else 0.0
    return Outcome(_text(1), max(*d, jump), 1e-12,
                   f"‖J⊕Z̃‖ {fmt(d[0])}, |1 − |Z̃ᵀz|| against SciPy {fmt(d[1])}; rate of Z̃ "
                   f"along v {fmt(rate)} (a sign flip: ~{fmt(1 / H_STEP)})")


@check("37b", "H: ½vᵀMv − ½m‖v_c‖² = ½wᵀHw, v_c from Pinocchio's centroidal momentum",
       "pipeline.sim.redundancy.floating_inertia")
def _floating_inertia() -> Outcome:
    q, v = _state(2)
    model, _, mass = _model()
    data = model.createData()
    _, ns, _ = _terms(q)
    pin.ccrba(model, data, q, v)
    v_c = data.hg.linear / mass
    energy = float(pin.computeKineticEnergy(model, data, q, v))
    w = v[3:]
    d = abs(energy - 0.5 * mass * v_c @ v_c - 0.5 * w @ ns.H @ w)
    return Outcome(_text(2), d, 1e-12 * max(1.0, energy),
                   f"kinetic energy {fmt(energy)} J; difference {fmt(d)}")


@check("37c", "ν_n is the self-motion: v = Γ⁻¹[0; 0; 0; ν_n] moves neither the camera "
       "(Pinocchio's frame velocity) nor the CoM nor the bus attitude",
       "pipeline.sim.redundancy.extended_gamma")
def _self_motion() -> Outcome:
    q, _ = _state(3)
    model, fid, mass = _model()
    G, Gi, _, _ = _gammas(q)
    nu = np.zeros(model.nv)
    nu[12:] = 0.3
    v = Gi @ nu
    data = model.createData()
    pin.forwardKinematics(model, data, q, v)
    twist = pin.getFrameVelocity(model, data, fid, pin.ReferenceFrame.LOCAL).vector
    pin.ccrba(model, data, q, v)
    d = [float(np.abs(twist).max()), float(np.abs(data.hg.linear / mass).max()),
         float(np.abs(v[3:6]).max()), maxdiff(G @ v, nu)]
    return Outcome(_text(3) + ", ν_n = 0.3", max(d), 1e-12,
                   f"camera twist {fmt(d[0])}, v_c {fmt(d[1])}, ω_b {fmt(d[2])}, Γv − ν "
                   f"{fmt(d[3])}; joint rates of the self-motion ‖q̇‖ "
                   f"{fmt(float(np.linalg.norm(v[6:])))}")


@check("37d", "closed-form Γ⁻¹ vs numpy.linalg.inv(Γ); M̂ = Γ⁻ᵀMΓ⁻¹ block diagonal "
       "[m I₃, Λ_t, Λ_n], Λ_n = Z̃ᵀH_qqZ̃",
       "pipeline.sim.redundancy.extended_gamma_inverse")
def _extended_inverse() -> Outcome:
    q, _ = _state(4)
    mass = _model()[2]
    G, Gi, ns, M = _gammas(q)
    M_hat = np.linalg.inv(G).T @ M @ np.linalg.inv(G)
    d = [maxdiff(Gi, np.linalg.inv(G)), maxdiff(M_hat[:3, :3], mass * np.eye(3)),
         float(np.abs(M_hat[:3, 3:]).max()), float(np.abs(M_hat[3:12, 12:]).max()),
         maxdiff(M_hat[12:, 12:], ns.Lambda_n)]
    return Outcome(_text(4), max(d), 1e-9,
                   f"Γ⁻¹ {fmt(d[0])}; CoM block {fmt(d[1])}, CoM–rest {fmt(d[2])}, "
                   f"task–null-space {fmt(d[3])}, Λ_n {fmt(d[4])} "
                   f"(Λ_n = {fmt(float(ns.Lambda_n[0, 0]))} kg·m²)")


def _gamma_dot(q: np.ndarray, v: np.ndarray):
    """(Γ, Γ⁻¹, Γ̇, M, C) of eq. 37 at (q, v), Γ̇ by the code under test (eqs. 7, 37e)."""
    from pipeline.sim.redundancy import extended_gamma_dot
    from pipeline.sim.task_transform import gamma_time_derivative

    model, fid, mass = _model()
    data = model.createData()
    pin.computeJointJacobiansTimeVariation(model, data, q, v)
    pin.updateFramePlacements(model, data)
    J_e = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL).copy()
    dJ_e = pin.getFrameJacobianTimeVariation(model, data, fid, pin.ReferenceFrame.LOCAL).copy()
    C = pin.computeCoriolisMatrix(model, data, q, v).copy()
    pin.computeCentroidalMapTimeVariation(model, data, q, v)
    Ag, dAg = np.ascontiguousarray(data.Ag), np.ascontiguousarray(data.dAg)  # as the step has them
    (R_tb, p_bc, _, R_eb, p_ec, J_bar_v, J_oplus, _), ns, M = _terms(q)
    R_te = data.oMf[fid].rotation.copy()
    task = gamma_time_derivative(R_tb, R_te, R_eb, p_bc, p_ec, J_bar_v, J_e, v, dJ_e, Ag, dAg,
                                 mass)
    G, Gi, _, _ = _gammas(q)
    return G, Gi, extended_gamma_dot(task, J_oplus, M, C, mass, ns), M, C


# Central differences of Γ and M̂ for eq. 37e: h = 1e-5 balances the truncation (h² times the
# third derivative) and the rounding (ε|M̂|/h, |M̂| of order 300 here with the 150 kg bus), so
# the comparisons are relative to the largest entry of the rate compared.
H_RATE = 1e-5


@check("37e", "Γ̇ (eq. 37e) vs the central difference (Γ(q ⊕ hv) − Γ(q ⊖ hv))/2h; "
       "Ĉ = Γ⁻ᵀ(C − MΓ⁻¹Γ̇)Γ⁻¹ with M̂̇ − 2Ĉ skew-symmetric (relative to the largest entry)",
       "pipeline.sim.redundancy.extended_gamma_dot")
def _extended_gamma_dot() -> Outcome:
    from pipeline.sim.task_transform import transformed_dynamics

    q, v = _state(5)
    model = _model()[0]
    _, Gi, G_dot, M, C = _gamma_dot(q, v)
    plus, minus = (_gammas(pin.integrate(model, q, s * H_RATE * v)) for s in (1, -1))
    fd = (plus[0] - minus[0]) / (2 * H_RATE)
    _, C_hat = transformed_dynamics(M, C, Gi, G_dot)
    M_hat_dot = (plus[1].T @ plus[3] @ plus[1] - minus[1].T @ minus[3] @ minus[1]) / (2 * H_RATE)
    S = M_hat_dot - 2 * C_hat
    d = [maxdiff(G_dot, fd) / max(1.0, float(np.abs(G_dot).max())),
         float(np.abs(S + S.T).max()) / max(1.0, float(np.abs(M_hat_dot).max()))]
    return Outcome(_text(5) + f"; central differences h = {H_RATE:g}", max(d), 1e-7,
                   f"Γ̇ vs central difference {fmt(d[0])} relative (null-space rows "
                   f"{fmt(maxdiff(G_dot[12:], fd[12:]))} absolute); (M̂̇ − 2Ĉ) + (M̂̇ − 2Ĉ)ᵀ "
                   f"{fmt(d[1])} of max |M̂̇| = {fmt(float(np.abs(M_hat_dot).max()))}")


CHECKS = [_null_space_basis, _floating_inertia, _self_motion, _extended_inverse,
          _extended_gamma_dot]
