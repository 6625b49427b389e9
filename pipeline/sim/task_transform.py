"""The task-space transform Γ, its inverse and rate, and the transformed dynamics (eqs. 2–11).

Pure functions of arrays for one state, compiled with Numba: a step needs some thirty small
dense products, and at a few microseconds of NumPy call overhead each they would cost ten
times the rigid-body terms of the step. The simulator and the analysis call these same
functions, so a Γ rebuilt from a logged q is the simulator's Γ to the bit.

Conventions: v = [v_b; ω_b; q̇] in Pinocchio's free-flyer convention (b frame), camera
Jacobian J_e in the camera's LOCAL frame, R_xy rotates y-coordinates into x.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pipeline.shapes import TASK_DOF
from pipeline.sim.damped_inverse import damped_pinv
from pipeline.sim.jit import jit
from pipeline.sim.linalg import matmul, matvec
from pipeline.sim.redundancy import (
    NullSpace,
    extended_gamma,
    extended_gamma_dot,
    extended_gamma_inverse,
    null_space_map,
    null_space_terms,
)
from pipeline.sim.rotations import skew
from pipeline.sim.sampling import conditioning_from


class DynamicsInputs(NamedTuple):
    """The rigid-body terms at (q, v) that eqs. 2–11 take, by name
    (:func:`pipeline.sim.rigid_body_terms.dynamics_terms`)."""

    R_tb: np.ndarray  # bus attitude
    p_b: np.ndarray  # bus origin, t frame
    R_te: np.ndarray  # camera attitude
    p_e: np.ndarray  # camera origin, t frame
    J_e: np.ndarray  # 6×12 camera Jacobian, LOCAL
    dJ_e: np.ndarray  # its time variation
    M: np.ndarray  # CRBA mass matrix
    C: np.ndarray  # Coriolis matrix
    Ag: np.ndarray  # centroidal momentum map, t frame
    dAg: np.ndarray  # its time variation


class Transform(NamedTuple):
    """What :func:`full_transform` computes for one state (eqs. 2–9, 19)."""

    p_bc: np.ndarray
    p_c: np.ndarray
    J_bar_v: np.ndarray
    J_oplus: np.ndarray
    G_wb: np.ndarray
    J_oplus_inv: np.ndarray
    s_min_J: float
    kappa_J: float
    gamma: np.ndarray  # Γ
    gamma_inv: np.ndarray
    gamma_dot: np.ndarray
    M_hat: np.ndarray
    C_hat: np.ndarray
    s_min_G: float
    kappa_G: float
    gamma_vt: np.ndarray  # Γ's right singular vectors, the next step's start (eq. 19)


@jit
def kinematic_terms(R_tb, p_b, R_te, p_e, J_e, M, mass):
    """p_bc, p_c, R_eb, p_ec, J̄_v, J⊕, G_ωb from placements, J_e and M (eqs. 2–4).

    M's bus block gives the CoM offset, M[0:3, 3:6] = −m [p_bc]×, and J̄_v = M[0:3, 6:]/m
    (eq. 2); J⊕ = J_e[:, 6:] − [R_eb; 0] J̄_v (eq. 3); G_ωb = [[p_ec]× R_eb; R_eb] (eq. 4).
    """
    p_bc = np.array([M[1, 5], M[2, 3], M[0, 4]]) / mass
    R_tb = np.ascontiguousarray(R_tb)
    R_et = np.ascontiguousarray(R_te.T)
    p_c = p_b + matvec(R_tb, p_bc)
    R_eb = matmul(R_et, R_tb)
    p_ec = matvec(R_et, p_c - p_e)
    J_bar_v = np.ascontiguousarray(M[0:3, 6:]) / mass
    J_oplus = np.ascontiguousarray(J_e[:, 6:])
    J_oplus[0:3, :] -= matmul(R_eb, J_bar_v)
    G_wb = np.empty((6, 3))
    G_wb[0:3] = matmul(skew(p_ec), R_eb)
    G_wb[3:6] = R_eb
    return p_bc, p_c, R_eb, p_ec, J_bar_v, J_oplus, G_wb


@jit
def gamma_matrix(R_tb, p_bc, J_bar_v, G_wb, J_oplus):
    """Γ (eq. 5): ν = [v_c; ω_b; ν_e⊕] = Γ v.

    Γ = [[R_tb, −R_tb [p_bc]×, R_tb J̄_v], [0, I₃, 0], [0, G_ωb, J⊕]]; for a redundant arm
    (n > 6) the rows of ν_n below, zeros here, are eq. 37c's (:func:`extended_gamma`).
    """
    n = J_oplus.shape[1]
    g = np.zeros((6 + n, 6 + n))
    g[0:3, 0:3] = R_tb
    g[0:3, 3:6] = -matmul(R_tb, skew(p_bc))
    g[0:3, 6:] = matmul(R_tb, J_bar_v)
    g[3, 3] = g[4, 4] = g[5, 5] = 1.0
    g[6:12, 3:6] = G_wb
    g[6:12, 6:] = J_oplus
    return g


@jit
def gamma_inverse(R_tb, p_bc, J_bar_v, G_wb, J_oplus_inv):
    """Closed-form Γ⁻¹ through J⊕⁻¹ (eq. 6).

    Γ⁻¹ = [[R_tbᵀ, [p_bc]× + J̄_v J⊕⁻¹ G_ωb, −J̄_v J⊕⁻¹], [0, I₃, 0], [0, −J⊕⁻¹ G_ωb, J⊕⁻¹]].
    """
    n = J_oplus_inv.shape[0]
    JiG = matmul(J_oplus_inv, G_wb)
    g = np.zeros((6 + n, 6 + n))
    g[0:3, 0:3] = R_tb.T
    g[0:3, 3:6] = skew(p_bc) + matmul(J_bar_v, JiG)
    g[0:3, 6:] = -matmul(J_bar_v, J_oplus_inv)
    g[3, 3] = g[4, 4] = g[5, 5] = 1.0
    g[6:, 3:6] = -JiG
    g[6:, 6:] = J_oplus_inv
    return g


@jit
def gamma_time_derivative(R_tb, R_te, R_eb, p_bc, p_ec, J_bar_v, J_e, v, dJ_e, Ag, dAg, mass):
    """Γ̇ (eq. 7) from the Jacobian and centroidal-map time variations.

    Ṙ_tb = R_tb [ω_b]×;  ṗ_bc = J̄_v q̇;  J̄̇_v = −[ω_b]× J̄_v + R_bt Ȧg[0:3, 6:]/m;
    Ṙ_eb = R_eb [ω_b]× − [ω_e]× R_eb;  ṗ_ec = R_et Ag[0:3] v/m − [ω_e]× p_ec − v_e;
    Ġ_ωb = [[ṗ_ec]× R_eb + [p_ec]× Ṙ_eb; Ṙ_eb];  J̇⊕ = J̇_e[:, 6:] − [Ṙ_eb J̄_v + R_eb J̄̇_v; 0].
    """
    w_b = v[3:6].copy()
    qd = v[6:].copy()
    twist_e = matvec(np.ascontiguousarray(J_e), v)
    v_e, w_e = twist_e[:3].copy(), twist_e[3:].copy()
    S_wb, S_we = skew(w_b), skew(w_e)
    R_bt = np.ascontiguousarray(R_tb.T)
    J_bar_v_dot = (-matmul(S_wb, J_bar_v)
                   + matmul(R_bt, np.ascontiguousarray(dAg[0:3, 6:])) / mass)
    p_bc_dot = matvec(J_bar_v, qd)
    R_eb_dot = matmul(R_eb, S_wb) - matmul(S_we, R_eb)
    p_c_dot = matvec(np.ascontiguousarray(Ag[0:3]), v) / mass
    p_ec_dot = matvec(np.ascontiguousarray(R_te.T), p_c_dot) - matvec(S_we, p_ec) - v_e
    R_tb_dot = matmul(R_tb, S_wb)
    # The rows of [v_c; ω_b; ν_e⊕] (square for six joints; eq. 37e adds a redundant arm's).
    g = np.zeros((12, J_e.shape[1]))
    g[0:3, 0:3] = R_tb_dot
    g[0:3, 3:6] = -matmul(R_tb_dot, skew(p_bc)) - matmul(R_tb, skew(p_bc_dot))
    g[0:3, 6:] = matmul(R_tb_dot, J_bar_v) + matmul(R_tb, J_bar_v_dot)
    g[6:9, 3:6] = matmul(skew(p_ec_dot), R_eb) + matmul(skew(p_ec), R_eb_dot)
    g[9:12, 3:6] = R_eb_dot
    g[6:, 6:] = dJ_e[:, 6:]
    g[6:9, 6:] -= matmul(R_eb_dot, J_bar_v) + matmul(R_eb, J_bar_v_dot)
    return g


@jit
def transformed_dynamics(M, C, gamma_inv, gamma_dot):
    """M̂ = Γ⁻ᵀ M Γ⁻¹ (eq. 8) and Ĉ = Γ⁻ᵀ (C − M Γ⁻¹ Γ̇) Γ⁻¹ (eq. 9)."""
    M = np.ascontiguousarray(M)
    MGi = matmul(M, gamma_inv)
    GiT = np.ascontiguousarray(gamma_inv.T)
    M_hat = matmul(GiT, MGi)
    C_hat = matmul(GiT, matmul(np.ascontiguousarray(C), gamma_inv)
                   - matmul(MGi, matmul(gamma_dot, gamma_inv)))
    return M_hat, C_hat


@jit
def inverse_terms(R_tb, p_bc, J_bar_v, G_wb, J_oplus, gamma_task, M, mass, floor, damping):
    """(Γ, Γ⁻¹, null-space terms) for an arm of any n from eq. 5's rows ``gamma_task``.

    Six joints: Γ as it is and its closed form of eq. 6 through the damped J⊕⁻¹; the
    ``NullSpace`` then holds that J⊕⁻¹ as X_e with its (σ_min, κ), and empty blocks. A
    redundant arm (n > 6): eq. 37c's Γ with the null-space rows and eq. 37d's inverse.
    """
    if J_oplus.shape[1] > TASK_DOF:
        ns = null_space_terms(J_oplus, G_wb, M, mass, floor, damping)
        return (extended_gamma(gamma_task, ns.Y),
                extended_gamma_inverse(R_tb, p_bc, J_bar_v, ns), ns)
    J_inv, s_min_J, kappa_J = damped_pinv(J_oplus, floor, damping)
    ns = NullSpace(Z=np.zeros((TASK_DOF, 0)), H=np.zeros((0, 0)), Lambda_n=np.zeros((0, 0)),
                   Y=np.zeros((0, 0)), X_w=np.zeros((0, 0)), X_e=J_inv, s_min_J=s_min_J,
                   kappa_J=kappa_J)
    return gamma_task, gamma_inverse(R_tb, p_bc, J_bar_v, G_wb, J_inv), ns


@jit
def task_transform(R_tb, p_b, R_te, p_e, J_e, M, mass, floor, damping):
    """Eqs. 2–6 (37a–d for a redundant arm) in one call: the kinematic terms, the damped J⊕⁻¹
    (H-weighted for n > 6) with J⊕'s (σ_min, κ), Γ, Γ⁻¹."""
    p_bc, p_c, R_eb, p_ec, J_bar_v, J_oplus, G_wb = kinematic_terms(R_tb, p_b, R_te, p_e, J_e,
                                                                   M, mass)
    R_tb = np.ascontiguousarray(R_tb)
    gamma, gamma_inv, ns = inverse_terms(R_tb, p_bc, J_bar_v, G_wb, J_oplus,
                                         gamma_matrix(R_tb, p_bc, J_bar_v, G_wb, J_oplus), M,
                                         mass, floor, damping)
    return (p_bc, p_c, R_eb, p_ec, J_bar_v, J_oplus, G_wb, ns.X_e, ns.s_min_J, ns.kappa_J,
            gamma, gamma_inv)


@jit
def gamma_of_placements(R_tb, p_b, R_te, p_e, J_e, M, mass):
    """Γ alone (eqs. 2–5, 37c) from the placements, J_e and M: the analysis' rebuild."""
    p_bc, _, _, _, J_bar_v, J_oplus, G_wb = kinematic_terms(R_tb, p_b, R_te, p_e, J_e, M, mass)
    gamma = gamma_matrix(np.ascontiguousarray(R_tb), p_bc, J_bar_v, G_wb, J_oplus)
    if J_oplus.shape[1] > TASK_DOF:
        return extended_gamma(gamma, null_space_map(J_oplus, M, mass)[3])
    return gamma


@jit
def full_transform(d, mass, floor, damping, v, gamma_vt):
    """Eqs. 2–9 and 19 (37 for a redundant arm) in one call from the rigid-body terms ``d``
    (``DynamicsInputs``) at (q, v): :func:`task_transform`'s terms, then Γ̇, M̂, Ĉ and Γ's
    (σ_min, κ), its SVD started from ``gamma_vt`` (the step before's right vectors; empty:
    from the identity), as a ``Transform``."""
    p_bc, p_c, R_eb, p_ec, J_bar_v, J_oplus, G_wb = kinematic_terms(d.R_tb, d.p_b, d.R_te,
                                                                   d.p_e, d.J_e, d.M, mass)
    R_tb = np.ascontiguousarray(d.R_tb)
    gamma, gamma_inv, ns = inverse_terms(R_tb, p_bc, J_bar_v, G_wb, J_oplus,
                                         gamma_matrix(R_tb, p_bc, J_bar_v, G_wb, J_oplus), d.M,
                                         mass, floor, damping)
    gamma_dot = gamma_time_derivative(R_tb, d.R_te, R_eb, p_bc, p_ec, J_bar_v, d.J_e, v,
                                      d.dJ_e, d.Ag, d.dAg, mass)
    if ns.Z.shape[1] > 0:
        gamma_dot = extended_gamma_dot(gamma_dot, J_oplus, d.M, d.C, mass, ns)
    M_hat, C_hat = transformed_dynamics(d.M, d.C, gamma_inv, gamma_dot)
    s_min_G, kappa_G, Vt = conditioning_from(gamma, gamma_vt)
    return Transform(p_bc=p_bc, p_c=p_c, J_bar_v=J_bar_v, J_oplus=J_oplus, G_wb=G_wb,
                     J_oplus_inv=ns.X_e, s_min_J=ns.s_min_J, kappa_J=ns.kappa_J, gamma=gamma,
                     gamma_inv=gamma_inv, gamma_dot=gamma_dot, M_hat=M_hat, C_hat=C_hat,
                     s_min_G=s_min_G, kappa_G=kappa_G, gamma_vt=Vt)
