"""Attitude and camera loop on the reduced velocity v̆ = [ω_b; ν_e⊕] (eqs. 13–16).

    RHS = −C̆ v̆ − D̆ (v̆ − v̆_des) − J_xᵀ K̆ x̃ − (C_c + D̆ G_vc) ẋ̃_c + posture + FF

Each term is a named function so the cross-check can point at it. Two integrators advance v̆:
``explicit`` (forward Euler, eq. 15a) and ``imex`` (damping implicit, eq. 15b).
"""

from __future__ import annotations

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.limits import saturate_breve
from pipeline.spec import Limits


def coriolis_term(C_breve: np.ndarray, v_breve: np.ndarray) -> np.ndarray:
    """−C̆ v̆ (eq. 13a)."""
    return -C_breve @ v_breve


def damping_term(D_breve: np.ndarray, v_breve: np.ndarray, v_breve_des: np.ndarray) -> np.ndarray:
    """−D̆ (v̆ − v̆_des) (eq. 13b)."""
    return -D_breve @ (v_breve - v_breve_des)


def stiffness_term(J_x: np.ndarray, K_breve: np.ndarray, x_tilde: np.ndarray) -> np.ndarray:
    """−J_xᵀ K̆ x̃ (eq. 13c)."""
    return -J_x.T @ (K_breve @ x_tilde)


def com_coupling_term(C_c: np.ndarray, D_breve: np.ndarray, G_vc: np.ndarray,
                      com_vel_err: np.ndarray) -> np.ndarray:
    """−(C_c + D̆ G_vc) ẋ̃_c (eq. 13d): CoM velocity error seen by the camera loop."""
    return -(C_c + D_breve @ G_vc) @ com_vel_err


def posture_term(gamma_inv: np.ndarray, k_posture: float, q_joint: np.ndarray,
                 q_bar: np.ndarray) -> np.ndarray:
    """Joint posture spring mapped into the reduced coordinates (eq. 13e).

    The joint-space force τ = [0; 0; −k (q − q̄)] is a covector, so it maps as F̂ = Γ⁻ᵀ τ; the
    reduced rows are F̂[3:] = −(Γ⁻¹[6:, 3:])ᵀ k (q − q̄).
    """
    return -gamma_inv[6:, 3:].T @ (k_posture * (q_joint - q_bar))


def feedforward_term(M_breve: np.ndarray, v_breve_dot_des: np.ndarray, C_breve: np.ndarray,
                     v_breve_des: np.ndarray) -> np.ndarray:
    """FF = M̆ v̆̇_des + C̆ v̆_des (eq. 13f)."""
    return M_breve @ v_breve_dot_des + C_breve @ v_breve_des


def explicit_step(M_breve: np.ndarray, rhs: np.ndarray, v_breve: np.ndarray, dt: float,
                  lim: Limits) -> tuple[np.ndarray, dict[str, bool]]:
    """Forward Euler (eq. 15a): v̆⁺ = sat(v̆ + dt · sat(M̆⁻¹ RHS))."""
    acc, f_acc = saturate_breve(np.linalg.solve(M_breve, rhs), lim, "acc")
    v_new, f_rate = saturate_breve(v_breve + dt * acc, lim, "rate")
    return v_new, f_acc | f_rate


def imex_step(M_breve: np.ndarray, D_breve: np.ndarray, rhs: np.ndarray, v_breve: np.ndarray,
              dt: float, lim: Limits) -> tuple[np.ndarray, dict[str, bool]]:
    """Damping implicit (eq. 15b): (M̆ + dt D̆) v̆⁺ = M̆ v̆ + dt (RHS + D̆ v̆), same limits.

    The implicit solution defines an acceleration (v̆⁺ − v̆)/dt that passes through the same
    acceleration and rate saturations as the explicit step.
    """
    v_raw = np.linalg.solve(M_breve + dt * D_breve,
                            M_breve @ v_breve + dt * (rhs + D_breve @ v_breve))
    acc, f_acc = saturate_breve((v_raw - v_breve) / dt, lim, "acc")
    v_new, f_rate = saturate_breve(v_breve + dt * acc, lim, "rate")
    return v_new, f_acc | f_rate


INTEGRATORS = {"explicit": explicit_step, "imex": imex_step}


@jit
def damping_rates(M_breve: np.ndarray, D_breve: np.ndarray) -> np.ndarray:
    """μ = eig(M̆⁻¹D̆), ascending (eq. 21): with M̆ = L Lᵀ, the eigenvalues of L⁻¹ D̆ L⁻ᵀ.

    M̆ is symmetric positive definite, so M̆⁻¹D̆ is similar to that symmetric matrix and its
    eigenvalues, the damping-mode decay rates, are real.
    """
    L_inv = np.linalg.inv(np.linalg.cholesky(np.ascontiguousarray(M_breve)))
    S = L_inv @ np.ascontiguousarray(D_breve) @ L_inv.T
    return np.linalg.eigvalsh(0.5 * (S + S.T))
