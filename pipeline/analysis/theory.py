"""Theory at one step: the per-mode amplification, the regimes and the task Jacobian the map
takes (eqs. 14, 21–24). The 18×18 discrete map itself, its spectrum and the critical steps live
with the simulator (:mod:`pipeline.sim.stability`), whose online guard uses them too; they are
re-exported here for the analysis.
"""

from __future__ import annotations

import numpy as np

from pipeline.sim.breve_controller import damping_rates  # noqa: F401  (μ, eq. 21)
from pipeline.sim.rotations import skew
from pipeline.sim.stability import (  # noqa: F401  (eqs. 22, 24, 41)
    UPDATE_ORDERS,
    MapSpectrum,
    critical_step,
    discrete_map,
    flown_map,
    map_critical_step,
    mean_square_radius,
    posture_stiffness,
    spectrum,
    split_map_terms,
)


def amplification(dt: float, mu: np.ndarray, integrator: str) -> np.ndarray:
    """Per-mode multiplier: ρ = 1 − dt μ (explicit), 1/(1 + dt μ) (imex) (eq. 23)."""
    mu = np.asarray(mu, dtype=float)
    return 1.0 - dt * mu if integrator == "explicit" else 1.0 / (1.0 + dt * mu)


def regime(dt_mu: float) -> str:
    """Forward-Euler regime of one mode from dt·μ (eq. 23)."""
    if dt_mu < 1:
        return "monotone decay"
    if dt_mu < 2:
        return "decaying 2-cycle"
    if dt_mu == 2:
        return "marginal period-2"
    return "growing period-2"


def attitude_jacobian(x_att: np.ndarray) -> np.ndarray:
    """E = η I + [ε]× from a logged attitude error x̃ = 2ε, η = √(1 − ‖ε‖²) (eq. 14)."""
    eps = 0.5 * np.asarray(x_att, dtype=float)
    eta = np.sqrt(max(0.0, 1.0 - eps @ eps))
    return eta * np.eye(3) + skew(eps)


def task_jacobian(x_tilde: np.ndarray, R_te: np.ndarray) -> np.ndarray:
    """J_x = blockdiag(E_b, R_te, E_e) from the logged x̃ and the rebuilt R_te (eq. 14)."""
    J = np.zeros((9, 9))
    J[0:3, 0:3] = attitude_jacobian(x_tilde[0:3])
    J[3:6, 3:6] = R_te
    J[6:9, 6:9] = attitude_jacobian(x_tilde[6:9])
    return J
