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
    """(kinematic terms of eqs. 2–4, null-space terms, M) at q, through the code under test."""
    from pipeline.sim.redundancy import null_space_terms
    from pipeline.sim.task_transform import kinematic_terms

    model, fid, mass = _model()
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

    (R_tb, p_bc, _, _, _, J_bar_v, J_oplus, G_wb), ns, M = _terms(q)
    return (extended_gamma(R_tb, p_bc, J_bar_v, G_wb, J_oplus, ns.Y),
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


CHECKS = [_null_space_basis, _floating_inertia, _self_motion, _extended_inverse]
