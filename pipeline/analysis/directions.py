"""Rebuild Γ from the logged q and project the logged velocity on its singular directions.

Stage 1 (provenance) and stage 2 (per-direction SVD, eq. 26) of architecture §3. Γ is rebuilt at
every step by the simulator's own kernels (``GiordanoRobot.gamma_matrices``) from q alone;
nothing logged but q and v is trusted. The SVDs run batched, compiled, over slices of the log,
each started from the step before's right-singular vectors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.sim.linalg import svd_right_sequence
from pipeline.sim.robot import GiordanoRobot


def rebuild_gamma(robot: GiordanoRobot, q: np.ndarray) -> np.ndarray:
    """Γ(q_k) for every row of q (N×13) → N×12×12 (eq. 26), by the simulator's own code."""
    return robot.gamma_matrices(q)


def sign_continuous(V: np.ndarray, previous: np.ndarray | None = None) -> np.ndarray:
    """Flip each singular vector (columns of V[k]) to keep v_i,k · v_i,k−1 >= 0 (eq. 26).

    V is N×n×n (right-singular vectors as columns); ``previous`` is the last n×n of the
    preceding chunk, so continuity holds across row groups. The flips compose along time,
    so the sign of step k is the product of the sign changes up to k.
    """
    dots = np.einsum("kij,kij->kj", V[1:], V[:-1])
    flips = np.where(dots < 0, -1.0, 1.0)
    first = np.ones((1, V.shape[2]))
    if previous is not None:
        first = np.where(np.einsum("ij,ij->j", V[0], previous) < 0, -1.0, 1.0)[None]
    signs = np.cumprod(np.vstack([first, flips]), axis=0)
    return V * signs[:, None, :]


@dataclass
class DirectionChunk:
    """Per-step results of one chunk of the log."""

    sigma: np.ndarray  # N×12 singular values of Γ_k, descending
    y: np.ndarray  # N×12 projections y_i,k = σ_i v_iᵀ v_k (eq. 26)
    s_min: np.ndarray  # N, σ_min of the rebuilt Γ
    kappa: np.ndarray  # N, κ of the rebuilt Γ
    V_last: np.ndarray  # 12×12, sign-continuous right-singular vectors of the last step


def singular_directions(gamma: np.ndarray, Vt_prev: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """σ and Vᵀ of each Γ_k (N×12×12 → N×12, N×12×12; eq. 26). Γ moves little from one
    step to the next, so each SVD starts from the step before's right vectors (``Vt_prev``
    across chunks, those of the chunk before's last step): the same bits whatever the chunks."""
    start = np.empty((0, 0)) if Vt_prev is None else np.ascontiguousarray(Vt_prev)
    return svd_right_sequence(np.ascontiguousarray(gamma), start)


def project_directions(s: np.ndarray, Vt: np.ndarray, v: np.ndarray,
                       V_prev: np.ndarray | None = None) -> DirectionChunk:
    """y_i,k = u_iᵀ Γ_k v_k = σ_i (v_iᵀ v_k) from Γ_k = U S Vᵀ (eq. 26), the vectors made
    sign-continuous from ``V_prev`` (the chunk before's last, or none)."""
    V = sign_continuous(np.swapaxes(Vt, 1, 2), V_prev)
    y = s * np.einsum("kji,kj->ki", V, v)
    return DirectionChunk(s, y, s[:, -1], s[:, 0] / s[:, -1], V[-1])


def project_chunk(gamma: np.ndarray, v: np.ndarray,
                  V_prev: np.ndarray | None = None) -> DirectionChunk:
    """Batched SVD of Γ_k = U S Vᵀ and y_i,k = u_iᵀ Γ_k v_k = σ_i (v_iᵀ v_k) (eq. 26)."""
    s, Vt = singular_directions(gamma, None if V_prev is None else V_prev.T)
    return project_directions(s, Vt, v, V_prev)
