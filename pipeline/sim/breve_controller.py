"""Attitude and camera loop on the reduced velocity v̆ = [ω_b; ν_e⊕] (eqs. 13–16), and a
redundant arm's null-space velocity ν_n below them (v̆ = [ω_b; ν_e⊕; ν_n], eq. 37f).

    RHS = −C̆ v̆ − D̆ (v̆ − v̆_des) − J_xᵀ K̆ x̃ − (C_c + D̆ G_vc) ẋ̃_c + posture + FF
          [+ null-space stiffness in ν_n's rows]

Each term is a named function so the cross-check can point at it. Two integrators advance v̆:
``explicit`` (forward Euler, eq. 15a) and ``imex`` (damping implicit, eq. 15b).
"""

from __future__ import annotations

import numpy as np

from pipeline.shapes import TASK_ERROR_SIZE
from pipeline.sim.jit import jit
from pipeline.sim.limits import saturate_blocks
from pipeline.sim.linalg import cholesky_lower, eigvalsh, inverse, matmul, matvec, solve


@jit
def coriolis_term(C_breve: np.ndarray, v_breve: np.ndarray) -> np.ndarray:
    """−C̆ v̆ (eq. 13a)."""
    return -matvec(np.ascontiguousarray(C_breve), v_breve)


@jit
def damping_term(D_breve: np.ndarray, v_breve: np.ndarray, v_breve_des: np.ndarray) -> np.ndarray:
    """−D̆ (v̆ − v̆_des) (eq. 13b)."""
    return -matvec(np.ascontiguousarray(D_breve), v_breve - v_breve_des)


@jit
def stiffness_term(J_x: np.ndarray, K_breve: np.ndarray, x_tilde: np.ndarray) -> np.ndarray:
    """−J_xᵀ K̆ x̃ (eq. 13c): the task rows (nine)."""
    return -matvec(np.ascontiguousarray(J_x.T), matvec(np.ascontiguousarray(K_breve), x_tilde))


@jit
def null_space_stiffness_term(gamma_inv: np.ndarray, k_null: float, q_joint: np.ndarray,
                              q_bar: np.ndarray) -> np.ndarray:
    """−K_n Z̃ᵀ (q − q̄) (eq. 37f): the null-space spring on the posture error, ν_n's rows;
    Z̃ = Γ⁻¹[6:, 12:], the joint motion per unit ν_n (eq. 37d)."""
    Z_T = np.ascontiguousarray(gamma_inv[6:, 12:].T)
    return -matvec(Z_T, k_null * (q_joint - q_bar))


@jit
def com_coupling_term(C_c: np.ndarray, D_breve: np.ndarray, G_vc: np.ndarray,
                      com_vel_err: np.ndarray) -> np.ndarray:
    """−(C_c + D̆ G_vc) ẋ̃_c (eq. 13d): CoM velocity error seen by the camera loop."""
    D = np.ascontiguousarray(D_breve)
    return -matvec(np.ascontiguousarray(C_c) + matmul(D, np.ascontiguousarray(G_vc)), com_vel_err)


@jit
def posture_term(gamma_inv: np.ndarray, k_posture: float, q_joint: np.ndarray,
                 q_bar: np.ndarray) -> np.ndarray:
    """Joint posture spring mapped into the reduced coordinates (eq. 13e).

    The joint-space force τ = [0; 0; −k (q − q̄)] is a covector, so it maps as F̂ = Γ⁻ᵀ τ; the
    reduced rows are F̂[3:] = −(Γ⁻¹[6:, 3:])ᵀ k (q − q̄).
    """
    P_T = np.ascontiguousarray(gamma_inv[6:, 3:].T)
    return -matvec(P_T, k_posture * (q_joint - q_bar))


@jit
def feedforward_term(M_breve: np.ndarray, v_breve_dot_des: np.ndarray, C_breve: np.ndarray,
                     v_breve_des: np.ndarray) -> np.ndarray:
    """FF = M̆ v̆̇_des + C̆ v̆_des (eq. 13f)."""
    return (matvec(np.ascontiguousarray(M_breve), v_breve_dot_des)
            + matvec(np.ascontiguousarray(C_breve), v_breve_des))


@jit
def breve_rhs(M_breve, C_breve, C_c, gamma_inv, v_breve, v_breve_dot_des, err, K_breve,
              D_breve, k_posture, q_joint, q_bar, k_null):
    """RHS of eq. 13 (37f): the sum of its named terms, with the task errors ``err``
    (``TaskErrors``, eq. 14); a redundant arm's ν_n rows have no task stiffness and the
    null-space spring instead."""
    stiffness = stiffness_term(err.J_x, K_breve, err.x_tilde)
    redundant = v_breve.size > TASK_ERROR_SIZE
    if redundant:
        padded = np.zeros(v_breve.size)
        padded[:TASK_ERROR_SIZE] = stiffness
        stiffness = padded
    rhs = (coriolis_term(C_breve, v_breve)
           + damping_term(D_breve, v_breve, err.v_breve_des)
           + stiffness
           + com_coupling_term(C_c, D_breve, err.G_vc, err.com_vel_err)
           + posture_term(gamma_inv, k_posture, q_joint, q_bar)
           + feedforward_term(M_breve, v_breve_dot_des, C_breve, err.v_breve_des))
    if redundant:
        rhs[TASK_ERROR_SIZE:] += null_space_stiffness_term(gamma_inv, k_null, q_joint, q_bar)
    return rhs


@jit
def explicit_update(M_breve, rhs, v_breve, dt, acc_bounds, rate_bounds):
    """Forward Euler (eq. 15a): v̆⁺ = sat(v̆ + dt · sat(M̆⁻¹ RHS)); which blocks saturated."""
    acc, hit_acc = saturate_blocks(solve(np.ascontiguousarray(M_breve), rhs),
                                   acc_bounds)
    v_new, hit_rate = saturate_blocks(v_breve + dt * acc, rate_bounds)
    return v_new, hit_acc, hit_rate


@jit
def imex_update(M_breve, D_breve, rhs, v_breve, dt, acc_bounds, rate_bounds):
    """Damping implicit (eq. 15b): (M̆ + dt D̆) v̆⁺ = M̆ v̆ + dt (RHS + D̆ v̆), same limits.

    The implicit solution defines an acceleration (v̆⁺ − v̆)/dt that passes through the same
    acceleration and rate saturations as the explicit step.
    """
    M = np.ascontiguousarray(M_breve)
    D = np.ascontiguousarray(D_breve)
    v_implicit = solve(M + dt * D, matvec(M, v_breve) + dt * (rhs + matvec(D, v_breve)))
    acc, hit_acc = saturate_blocks((v_implicit - v_breve) / dt, acc_bounds)
    v_new, hit_rate = saturate_blocks(v_breve + dt * acc, rate_bounds)
    return v_new, hit_acc, hit_rate


@jit
def damping_rates(M_breve: np.ndarray, D_breve: np.ndarray) -> np.ndarray:
    """μ = eig(M̆⁻¹D̆), ascending (eq. 21): with M̆ = L Lᵀ, the eigenvalues of L⁻¹ D̆ L⁻ᵀ.

    M̆ is symmetric positive definite, so M̆⁻¹D̆ is similar to that symmetric matrix and its
    eigenvalues, the damping-mode decay rates, are real.
    """
    L_inv = inverse(cholesky_lower(np.ascontiguousarray(M_breve)))
    S = matmul(matmul(L_inv, np.ascontiguousarray(D_breve)), np.ascontiguousarray(L_inv.T))
    return eigvalsh(0.5 * (S + S.T))
