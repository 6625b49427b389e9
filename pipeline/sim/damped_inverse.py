"""The damped pseudo-inverse of the generalized Jacobian J⊕ and its conditioning (eqs. 6, 19).

Near a singularity J⊕'s exact inverse grows without bound; the damped inverse bounds it and
equals the exact one away from the floor. Eq. 6's Γ⁻¹ and eq. 37d's weighted inverse of a
redundant arm both take it.
"""

from __future__ import annotations

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.linalg import matmul, svd


@jit
def damped_pinv(J, floor, damping):
    """Damped SVD pseudo-inverse of J and its (σ_min, κ) from the same SVD (eqs. 6, 19).

    J⁺ = V diag(σ_i / (σ_i² + λ²)) Uᵀ,  λ² = damping² (1 − (σ_min/floor)²) if σ_min < floor,
    else 0: the exact inverse away from the singularity, a bounded one near it.
    """
    U, s, Vt = svd(J)
    smin = s[-1]
    lam2 = damping**2 * (1.0 - (smin / floor) ** 2) if smin < floor else 0.0
    J_inv = matmul(np.ascontiguousarray(Vt.T) * (s / (s * s + lam2)), np.ascontiguousarray(U.T))
    kappa = s[0] / smin if smin > 0 else np.inf
    return J_inv, smin, kappa
