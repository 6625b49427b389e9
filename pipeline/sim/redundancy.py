"""Redundant arms (n > 6): the task coordinates completed by null-space velocities (eq. 37).

With n > 6 joints the camera's six task velocities leave k = n − 6 joint motions free (the
arm's self-motion), and Γ of eq. 5 is not square. The task coordinates are completed as in
Ott's dynamically consistent null-space formulation (C. Ott, *Cartesian Impedance Control of
Redundant and Flexible-Joint Robots*, Springer STAR 49, 2008, ch. 3), applied to the
free-floating robot's task coordinates of Giordano et al. (A. M. Giordano, C. Ott,
A. Albu-Schäffer, "Coordinated control of spacecraft's attitude and end-effector for space
robots", IEEE RA-L 4(2), 2019): v̂ = [v_c; ω_b; ν_e⊕; ν_n] = Γ v, Γ square (6 + n), with the
null-space velocity ν_n chosen so that the kinetic energy has no cross term between ν_n and
the other coordinates. M̂ is then block diagonal, [m I₃, Λ_t, Λ_n]: the camera and bus loop
(Λ_t, 9×9, the M̆ of eq. 10) and the null-space motion (Λ_n, k×k) have separate damping modes.

These are pure functions of one state's arrays, compiled as the other kernels are, on the
project's own dense algebra (:mod:`pipeline.sim.linalg`). For n = 6 (k = 0) the simulator
keeps eqs. 5–6 as they are; these functions are the redundant arm's.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pipeline.sim.damped_inverse import damped_pinv
from pipeline.sim.jit import jit
from pipeline.sim.linalg import cholesky_lower, determinant, inverse, matmul, matvec, solve
from pipeline.sim.rotations import skew


class NullSpace(NamedTuple):
    """A redundant arm's null-space terms at one state (eq. 37)."""

    Z: np.ndarray  # n×k, unit columns spanning null(J⊕)
    H: np.ndarray  # (3+n)×(3+n), the inertia of [ω_b; q̇] at a still CoM
    Lambda_n: np.ndarray  # k×k, Zᵀ H_qq Z: the null-space inertia
    Y: np.ndarray  # k×(3+n), ν_n = Y [ω_b; q̇]
    X_w: np.ndarray  # n×3, q̇ per ω_b at ν_e⊕ = 0, ν_n = 0
    X_e: np.ndarray  # n×6, q̇ per ν_e⊕: the inertia-weighted (damped) inverse of J⊕
    s_min_J: float  # σ_min of the inertia-weighted J⊕ (eq. 19's conditioning of the task)
    kappa_J: float


@jit
def null_space_basis(J):
    """Z̃ (n×k, k = n − 6) spanning null(J) of a 6×n J of rank 6, each column of unit norm
    (eq. 37a).

    Column j is the generalised cross product of J's first six columns and column 6 + j:
    z_{c_p} = (−1)^p det(J without column c_p) over the seven columns c = (0, …, 5, 6 + j).
    J z = 0 by Laplace's expansion of a determinant with a repeated row. Its entries are
    polynomials in J, so the basis moves continuously with q and never flips sign, as an SVD
    basis may; it vanishes only where those seven columns lose rank (for n = 7: where J
    does).
    """
    m, n = J.shape
    k = n - m
    Z = np.zeros((n, k))
    sub = np.empty((m, m))
    cols = np.empty(m + 1, dtype=np.int64)
    for j in range(k):
        for i in range(m):
            cols[i] = i
        cols[m] = m + j
        for p in range(m + 1):
            c = 0
            for r in range(m + 1):
                if r != p:
                    for i in range(m):
                        sub[i, c] = J[i, cols[r]]
                    c += 1
            Z[cols[p], j] = (-1.0 if p % 2 else 1.0) * determinant(sub)
        norm = 0.0
        for i in range(n):
            norm += Z[i, j] * Z[i, j]
        norm = math.sqrt(norm)
        if norm == 0.0:
            raise np.linalg.LinAlgError("J⊕ has lost rank: no null-space basis")
        for i in range(n):
            Z[i, j] /= norm
    return Z


@jit
def floating_inertia(M, mass):
    """H = M_ww − M_wb M_bw / m (eq. 37b): the inertia of w = [ω_b; q̇] with the CoM still,
    the Schur complement of M's bus-translation block m I₃ (König: ½vᵀMv = ½m‖v_c‖² +
    ½wᵀHw)."""
    M = np.ascontiguousarray(M)
    M_wb = np.ascontiguousarray(M[3:, 0:3])
    M_bw = np.ascontiguousarray(M[0:3, 3:])
    return np.ascontiguousarray(M[3:, 3:]) - matmul(M_wb, M_bw) / mass


@jit
def null_space_map(J_oplus, M, mass):
    """(Z̃, H, Λ_n, Y) at one state (eqs. 37a–c): the basis, the inertia at a still CoM, the
    null-space inertia Λ_n = Z̃ᵀ H_qq Z̃ and the map ν_n = Y [ω_b; q̇],
    Y = Λ_n⁻¹ Z̃ᵀ [H_qω, H_qq]. What Γ's null-space rows need and no more (the analysis'
    rebuild of Γ from a logged q)."""
    n = J_oplus.shape[1]
    Z = null_space_basis(J_oplus)
    H = floating_inertia(M, mass)
    Zt = np.ascontiguousarray(Z.T)
    Lambda_n = matmul(Zt, matmul(np.ascontiguousarray(H[3:, 3:]), Z))
    ZtH = np.empty((Z.shape[1], 3 + n))
    ZtH[:, 0:3] = matmul(Zt, np.ascontiguousarray(H[3:, 0:3]))
    ZtH[:, 3:] = matmul(Zt, np.ascontiguousarray(H[3:, 3:]))
    return Z, H, Lambda_n, matmul(inverse(Lambda_n), ZtH)


@jit
def null_space_terms(J_oplus, G_wb, M, mass, floor, damping):
    """The null-space terms of eq. 37 at one state, as a ``NullSpace``.

    Λ_n = Z̃ᵀ H_qq Z̃;  Y = Λ_n⁻¹ Z̃ᵀ [H_qω, H_qq], so ν_n = Y w (:func:`null_space_map`);
    X_e = L⁻ᵀ (J⊕ L⁻ᵀ)⁺ with H_qq = L Lᵀ (the H_qq-weighted inverse of J⊕, damped as eq. 6);
    X_ω = −X_e G_ωb − Z̃ Λ_n⁻¹ Z̃ᵀ H_qω = −X_e G_ωb − Z̃ Y_ω.
    """
    Z, H, Lambda_n, Y = null_space_map(J_oplus, M, mass)
    H_qq = np.ascontiguousarray(H[3:, 3:])
    L_inv_t = np.ascontiguousarray(inverse(cholesky_lower(H_qq)).T)
    J_w = matmul(np.ascontiguousarray(J_oplus), L_inv_t)
    # The SVD kernel takes tall matrices: (Aᵀ)⁺ = (A⁺)ᵀ, damped alike (the same σ).
    J_w_inv_t, s_min, kappa = damped_pinv(np.ascontiguousarray(J_w.T), floor, damping)
    X_e = matmul(L_inv_t, np.ascontiguousarray(J_w_inv_t.T))
    X_w = -matmul(X_e, np.ascontiguousarray(G_wb)) - matmul(Z, np.ascontiguousarray(Y[:, 0:3]))
    return NullSpace(Z=Z, H=H, Lambda_n=Lambda_n, Y=Y, X_w=X_w, X_e=X_e, s_min_J=s_min,
                     kappa_J=kappa)


@jit
def extended_gamma(gamma_task, Y):
    """Γ (6+n square, eq. 37c): eq. 5's rows [v_c; ω_b; ν_e⊕] (``gamma_task``, zeros below
    them) and the null-space velocity's, ν_n = Y [ω_b; q̇]."""
    g = gamma_task.copy()
    g[12:, 3:] = Y
    return g


@jit
def extended_gamma_inverse(R_tb, p_bc, J_bar_v, ns):
    """Closed-form Γ⁻¹ of eq. 37c (eq. 37d), from the ``NullSpace`` ``ns``:

    q̇ = X_ω ω_b + X_e ν_e⊕ + Z̃ ν_n,  v_b = R_tbᵀ v_c + [p_bc]× ω_b − J̄_v q̇.
    """
    n = ns.Z.shape[0]
    g = np.zeros((6 + n, 6 + n))
    g[0:3, 0:3] = np.ascontiguousarray(R_tb).T
    g[3, 3] = g[4, 4] = g[5, 5] = 1.0
    g[6:, 3:6] = ns.X_w
    g[6:, 6:12] = ns.X_e
    g[6:, 12:] = ns.Z
    g[0:3, 3:] = -matmul(np.ascontiguousarray(J_bar_v), np.ascontiguousarray(g[6:, 3:]))
    g[0:3, 3:6] += skew(p_bc)
    return g


@jit
def null_space_basis_rate(J, J_dot, Z):
    """Ż̃ (eq. 37e): the rate of :func:`null_space_basis` along a motion with J̇ = ``J_dot``.

    J z_j = 0 gives J ż_j = −J̇ z_j, so ż_j = −J⁺ J̇ z_j + Z̃ a_j (J⁺ = Jᵀ(JJᵀ)⁻¹, exact) with
    a_j fixed by what the construction holds for all time: ‖z_j‖ = 1 (z_jᵀ ż_j = 0) and z_j's
    zeros at the other null columns 6 + i, i ≠ j. For k = 1, a = 0.
    """
    m, n = J.shape
    k = n - m
    J = np.ascontiguousarray(J)
    Jt = np.ascontiguousarray(J.T)
    JJt_inv = inverse(matmul(J, Jt))
    P = matmul(Jt, JJt_inv)  # J⁺
    Zd = np.empty((n, k))
    A = np.empty((k, k))
    b = np.empty(k)
    for j in range(k):
        zj = np.ascontiguousarray(Z[:, j])
        u = -matvec(P, matvec(np.ascontiguousarray(J_dot), zj))
        A[0, :] = matvec(np.ascontiguousarray(Z.T), zj)
        b[0] = 0.0
        r = 1
        for i in range(k):
            if i != j:
                A[r, :] = Z[m + i, :]
                b[r] = -u[m + i]
                r += 1
        a = solve(A, b)
        Zd[:, j] = u + matvec(np.ascontiguousarray(Z), a)
    return Zd


@jit
def extended_gamma_dot(gamma_dot_task, J_oplus, M, C, mass, ns):
    """Γ̇ of eq. 37c (eq. 37e): eq. 7's twelve rows ``gamma_dot_task`` and the null-space
    rows [0, Ẏ], with

    Ẏ = Λ_n⁻¹ (Ż̃ᵀ H_r + Z̃ᵀ Ḣ_r − Λ̇_n Y),  H_r = [H_qω, H_qq],
    Λ̇_n = Ż̃ᵀ H_qq Z̃ + Z̃ᵀ Ḣ_qq Z̃ + Z̃ᵀ H_qq Ż̃,
    Ḣ = Ṁ_ww − (Ṁ_wb M_bw + M_wb Ṁ_bw)/m,  Ṁ = C + Cᵀ,  J̇⊕ = Γ̇[6:12, 6:].
    """
    n = J_oplus.shape[1]
    M = np.ascontiguousarray(M)
    M_dot = np.ascontiguousarray(C) + np.ascontiguousarray(C.T)
    H_dot = (np.ascontiguousarray(M_dot[3:, 3:])
             - (matmul(np.ascontiguousarray(M_dot[3:, 0:3]), np.ascontiguousarray(M[0:3, 3:]))
                + matmul(np.ascontiguousarray(M[3:, 0:3]),
                         np.ascontiguousarray(M_dot[0:3, 3:]))) / mass)
    J_dot = np.ascontiguousarray(gamma_dot_task[6:12, 6:])
    Z = ns.Z
    Zd = null_space_basis_rate(J_oplus, J_dot, Z)
    Zt, Zdt = np.ascontiguousarray(Z.T), np.ascontiguousarray(Zd.T)
    H_r = np.ascontiguousarray(ns.H[3:, :])
    H_qq = np.ascontiguousarray(ns.H[3:, 3:])
    H_r_dot = np.ascontiguousarray(H_dot[3:, :])
    H_qq_dot = np.ascontiguousarray(H_dot[3:, 3:])
    Lambda_dot = (matmul(Zdt, matmul(H_qq, Z)) + matmul(Zt, matmul(H_qq_dot, Z))
                  + matmul(Zt, matmul(H_qq, Zd)))
    Y_dot = matmul(inverse(ns.Lambda_n), matmul(Zdt, H_r) + matmul(Zt, H_r_dot)
                   - matmul(Lambda_dot, ns.Y))
    g = np.zeros((6 + n, 6 + n))
    g[0:12, :] = gamma_dot_task
    g[12:, 3:] = Y_dot
    return g
