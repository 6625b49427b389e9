"""The 18×18 discrete map of the linearised loop, its spectrum and the critical steps (eqs. 22–24).

The map linearises the attitude-and-camera loop about a rest state (v̆ = v̆_des, x̃ = 0,
saturations inactive, γ constant). With z = [x̃; e], e = v̆ − v̆_des:

    explicit:  A_e = I − dt M̆⁻¹D̆,         B = −dt M̆⁻¹ K_x
    imex:      A_e = (M̆ + dt D̆)⁻¹ M̆,      B = −dt (M̆ + dt D̆)⁻¹ K_x
    K_x = J_xᵀ K̆ + K_posture

Two update orders of the configuration (eq. 22):

    simulator:  x̃⁺ = x̃ + dt J_x e⁺  (v̆ first, then q moves with the new velocity)
                Φ = [[I + dt J_x B, dt J_x A_e], [B, A_e]]
    note:       x̃⁺ = x̃ + dt J_x e   (fully explicit: q moves with the old velocity, the order
                the seed note's eigenvalue −2.81 matches)
                Φ = [[I, dt J_x], [B, A_e]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def critical_step(mu_max: float) -> float:
    """dt*_damping = 2/μ_max: forward Euler on the damping alone is stable iff dt < it (eq. 24).
    With the stiffness the map's own bound (:func:`bisect_critical_step`) may be lower."""
    return 2.0 / mu_max


UPDATE_ORDERS = ("simulator", "note")


def discrete_map(M_breve: np.ndarray, D_breve: np.ndarray, K_x: np.ndarray, J_x: np.ndarray,
                 dt: float, integrator: str, order: str = "simulator") -> np.ndarray:
    """Φ, the 18×18 map z⁺ = Φ z of the linearised loop (eq. 22), for the simulator's update
    order (x̃ advances with e⁺) or the note's fully explicit one (x̃ advances with e)."""
    n = M_breve.shape[0]
    if integrator == "explicit":
        A_e = np.eye(n) - dt * np.linalg.solve(M_breve, D_breve)
        B = -dt * np.linalg.solve(M_breve, K_x)
    elif integrator == "imex":
        W = M_breve + dt * D_breve
        A_e = np.linalg.solve(W, M_breve)
        B = -dt * np.linalg.solve(W, K_x)
    else:
        raise ValueError(f"unknown integrator {integrator!r}")
    if order == "simulator":
        return np.block([[np.eye(n) + dt * J_x @ B, dt * J_x @ A_e], [B, A_e]])
    if order == "note":
        return np.block([[np.eye(n), dt * J_x], [B, A_e]])
    raise ValueError(f"unknown update order {order!r} (one of {', '.join(UPDATE_ORDERS)})")


@dataclass(frozen=True)
class MapSpectrum:
    eigenvalues: np.ndarray
    dominant: complex
    spectral_radius: float
    dominant_vector: np.ndarray  # eigenvector of the dominant eigenvalue (18)


def spectrum(Phi: np.ndarray) -> MapSpectrum:
    """Eigenvalues of Φ, its dominant one (largest modulus) and its eigenvector."""
    w, V = np.linalg.eig(Phi)
    i = int(np.argmax(np.abs(w)))
    return MapSpectrum(w, complex(w[i]), float(abs(w[i])), V[:, i])


def bisect_critical_step(M_breve, D_breve, K_x, J_x, integrator: str = "explicit",
                         lo: float = 1e-6, hi: float = 1.0, tol: float = 1e-10) -> float | None:
    """Smallest dt in [lo, hi] with spectral radius of Φ(dt) reaching 1, by bisection.

    Assumes ρ(Φ(lo)) < 1 (a stable small step); returns None if ρ(Φ(hi)) < 1 (no bound in
    range, as for imex). The radius crosses 1 once on this bracket for a damped loop.
    """
    def radius(dt: float) -> float:
        return spectrum(discrete_map(M_breve, D_breve, K_x, J_x, dt, integrator)).spectral_radius

    if radius(hi) < 1.0:
        return None
    if radius(lo) >= 1.0:
        return lo
    while hi - lo > tol * hi:
        mid = 0.5 * (lo + hi)
        if radius(mid) < 1.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def posture_stiffness(gamma_inv: np.ndarray, k_posture: float, J_x: np.ndarray) -> np.ndarray:
    """Posture spring in x̃ coordinates: (Γ⁻¹[6:, 3:])ᵀ k Γ⁻¹[6:, 3:] J_x⁻¹ (eq. 13e, 22)."""
    P = gamma_inv[6:, 3:]
    return k_posture * P.T @ P @ np.linalg.inv(J_x)
