"""The sampled-data plant: the robot between two control instants under a held command (eq. 29).

By default the simulator integrates the closed loop in reduced coordinates at the control step
(eqs. 15, 22): the velocity the controller commands is the next velocity. A flight computer
does something else: it samples the state every dt, computes a command, and holds it (zero-
order hold) while the plant moves continuously. ``mission.plant.model: sampled`` runs that:

    ν̇_k = (ν_{k+1}^cmd − ν_k) / dt          the reduced acceleration the step commands
    a_k = Γ⁻¹(q_k) (ν̇_k − Γ̇(q_k, v_k) v_k)   the generalized acceleration it means (ν = Γ v)
    τ_k = M(q_k) a_k + C(q_k, v_k) v_k       its generalized force at the sampled state (RNEA)
    M(q) v̇ + C(q, v) v = τ_{k−d}  on [t_k, t_k + dt]     d = mission.plant.delay_steps ∈ {0, 1}

integrated by classical Runge–Kutta (RK4) in ``substeps`` steps on the configuration's 13
numbers (the bus position, its unit quaternion and the joint angles, whose rates are
:func:`configuration_rate`), the forward dynamics by Pinocchio's ABA. The next step's
controller measures the plant: ν = Γ(q) v.

τ is the bus wrench and the six joint torques (the free flyer's 6 and the arm's 6 entries of
the generalized force, in Pinocchio's convention). For one rigid body spinning about a
principal axis under a held torque −D ω_k, the hold is exact: ω_{k+1} = (1 − dt·D/I) ω_k, the
forward-Euler map of eq. 23, so a damping mode with dt·μ > 2 rings in the sampled-data loop
too. The delayed hold (d = 1) applies the command of the previous instant; before the first,
the command that holds the initial velocity (zero acceleration). ``bus_torque_max`` saturates
the bus torque of the held command (:func:`limit_bus_torque`), an actuator's limit where the
loop's own limits bound accelerations.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pipeline.sim.jit import jit
from pipeline.sim.linalg import matvec


@jit
def commanded_force(M, C, gamma_inv, gamma_dot, v, nu, nu_next, dt):
    """The generalized force u_k = M(q_k) a_k + C(q_k, v_k) v_k that step k commands (eq. 29):
    a_k = Γ⁻¹(q_k) ((ν_{k+1} − ν_k)/dt − Γ̇(q_k, v_k) v_k), the generalized acceleration of the
    reduced velocity change it asks for (ν = Γ v). From the step's own M (CRBA), Coriolis
    matrix C, Γ⁻¹ and Γ̇; the log's ``u_cmd`` (the bus wrench [f_b; τ_b] in the bus frame,
    then the six joint torques)."""
    nu_dot = (nu_next - nu) / dt
    a = matvec(gamma_inv, nu_dot - matvec(gamma_dot, v))
    return matvec(M, a) + matvec(C, v)


def held_command(model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray,
                 a: np.ndarray) -> np.ndarray:
    """τ = M(q) a + C(q, v) v: the generalized force of acceleration a at (q, v) (eq. 29),
    gravity off as in the loaded model."""
    return pin.rnea(model, data, q, v, a).copy()


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of two 3-vectors: NumPy's np.cross costs ~10 µs of axis handling per call, and
    the RK4 stages call it a hundred times a step; same products and differences, same bits."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def configuration_rate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """q̇ of Pinocchio's free-flyer configuration (13 numbers on a robot of six joints) for the
    velocity v (eq. 1):
    ṗ_b = R_tb v_b = v_b + 2w (ε × v_b) + 2ε × (ε × v_b) (v_b in the bus frame, the unit
    quaternion (ε, w), ε = (x, y, z)), its rate (ε̇, ẇ) = ½ [w ω + ε × ω ; −ε·ω] (ω in the bus
    frame), q̇_a = v[6:].
    """
    w = q[6]
    eps, vb, om = q[3:6], v[0:3], v[3:6]
    t = _cross(eps, vb)
    dq = np.empty(len(q))
    dq[0:3] = vb + 2.0 * w * t + 2.0 * _cross(eps, t)
    dq[3:6] = 0.5 * (w * om + _cross(eps, om))
    dq[6] = -0.5 * (eps @ om)
    dq[7:] = v[6:]
    return dq


def _normalised(q: np.ndarray) -> np.ndarray:
    q = q.copy()
    q[3:7] /= np.linalg.norm(q[3:7])
    return q


def limit_bus_torque(tau: np.ndarray, bound: float) -> tuple[np.ndarray, bool]:
    """τ with the bus torque (the free flyer's angular entries τ[3:6], bus frame) saturated to
    norm ``bound`` (eq. 29; 0: no bound), and whether the bound was active."""
    n = float(np.linalg.norm(tau[3:6]))
    if bound <= 0.0 or n <= bound:
        return tau, False
    out = tau.copy()
    out[3:6] *= bound / n
    return out, True


def integrate_held(model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray,
                   tau: np.ndarray, dt: float, substeps: int,
                   path: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(q, v) after dt under the held generalized force τ (eq. 29): classical RK4 in
    ``substeps`` steps on (q, v) ∈ R¹³ × R¹², q̇ from :func:`configuration_rate` and v̇ from
    Pinocchio's ABA, each stage's quaternion normalised before it is used and the result's
    after each step (the ODE keeps |quat| = 1; RK4 drifts from it by O(h⁵) per step).
    With ``path``, each substep's q is appended to it."""
    h = dt / substeps

    def rates(qs: np.ndarray, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        qs = _normalised(qs)
        return configuration_rate(qs, vs), pin.aba(model, data, qs, vs, tau).copy()

    for _ in range(substeps):
        dq1, dv1 = rates(q, v)
        dq2, dv2 = rates(q + 0.5 * h * dq1, v + 0.5 * h * dv1)
        dq3, dv3 = rates(q + 0.5 * h * dq2, v + 0.5 * h * dv2)
        dq4, dv4 = rates(q + h * dq3, v + h * dv3)
        q = _normalised(q + h / 6.0 * (dq1 + 2.0 * dq2 + 2.0 * dq3 + dq4))
        v = v + h / 6.0 * (dv1 + 2.0 * dv2 + 2.0 * dv3 + dv4)
        if path is not None:
            path.append(q)
    return q, v


def attitude_excursion(q_start: np.ndarray, path: list[np.ndarray]) -> float:
    """The largest angle (rad) between the bus attitude along ``path`` (the configurations at
    equal substeps of one control step, the last at its end) and the geodesic from the
    step's first attitude to its last (eqs. 29, 32): the motion between two control instants
    that the instants do not see. A rotation at constant rate, as the update of eq. 15
    makes, has none; under a held torque about a principal axis the rate ramps from ω_k to
    ω_{k+1} and the excursion is |ω_{k+1} − ω_k| dt/8, at mid-step."""
    def rotation(qs: np.ndarray) -> np.ndarray:
        return pin.Quaternion(qs[6], qs[3], qs[4], qs[5]).normalized().toRotationMatrix()

    R0 = rotation(q_start)
    chord = pin.log3(R0.T @ rotation(path[-1]))
    worst = 0.0
    for j, qs in enumerate(path[:-1], start=1):
        R_geo = R0 @ pin.exp3(chord * (j / len(path)))
        worst = max(worst, float(np.linalg.norm(pin.log3(R_geo.T @ rotation(qs)))))
    return worst
