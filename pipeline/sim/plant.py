"""The sampled-data plant: the robot between two control instants under a held command (eq. 29).

By default the simulator integrates the closed loop in reduced coordinates at the control step
(eqs. 15, 22): the velocity the controller commands is the next velocity. A flight computer
does something else: it samples the state every dt, computes a command, and holds it (zero-
order hold) while the plant moves continuously. ``mission.plant.model: sampled`` runs that:

    ν̇_k = (ν_{k+1}^cmd − ν_k) / dt          the reduced acceleration the step commands
    a_k = Γ⁻¹(q_k) (ν̇_k − Γ̇(q_k, v_k) v_k)   the generalized acceleration it means (ν = Γ v)
    τ_k = M(q_k) a_k + C(q_k, v_k) v_k       its generalized force at the sampled state (RNEA)
    M(q) v̇ + C(q, v) v = τ_{k−d}  on [t_k, t_k + dt]     d = mission.plant.delay_steps ∈ {0, 1}

integrated by classical Runge–Kutta (RK4) in ``substeps`` steps on the configuration's 7 + n
numbers (the bus position, its unit quaternion and the joint angles, whose rates are
:func:`configuration_rate`), the forward dynamics by the compiled articulated-body algorithm
(:mod:`pipeline.sim.forward_dynamics`): the whole step's motion is one kernel call, no Python
per substep. The next step's controller measures the plant: ν = Γ(q) v.

τ is the bus wrench and the joint torques (the free flyer's 6 and the arm's n entries of
the generalized force, in Pinocchio's convention). For one rigid body spinning about a
principal axis under a held torque −D ω_k, the hold is exact: ω_{k+1} = (1 − dt·D/I) ω_k, the
forward-Euler map of eq. 23, so a damping mode with dt·μ > 2 rings in the sampled-data loop
too. The delayed hold (d = 1) applies the command of the previous instant; before the first,
the command that holds the initial velocity (zero acceleration). ``bus_torque_max`` saturates
the bus torque of the held command (:func:`limit_bus_torque`), an actuator's limit where the
loop's own limits bound accelerations.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from pipeline.sim.forward_dynamics import RigidTree, forward_dynamics
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


@jit
def configuration_rate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """q̇ of Pinocchio's free-flyer configuration (7 + n numbers) for the velocity v (eq. 1):
    ṗ_b = R_tb v_b = v_b + 2w (ε × v_b) + 2ε × (ε × v_b) (v_b in the bus frame, the unit
    quaternion (ε, w), ε = (x, y, z)), its rate (ε̇, ẇ) = ½ [w ω + ε × ω ; −ε·ω] (ω in the bus
    frame), q̇_a = v[6:].
    """
    w = q[6]
    e0, e1, e2 = q[3], q[4], q[5]
    t0 = e1 * v[2] - e2 * v[1]
    t1 = e2 * v[0] - e0 * v[2]
    t2 = e0 * v[1] - e1 * v[0]
    dq = np.empty(q.size)
    dq[0] = v[0] + 2.0 * w * t0 + 2.0 * (e1 * t2 - e2 * t1)
    dq[1] = v[1] + 2.0 * w * t1 + 2.0 * (e2 * t0 - e0 * t2)
    dq[2] = v[2] + 2.0 * w * t2 + 2.0 * (e0 * t1 - e1 * t0)
    dq[3] = 0.5 * (w * v[3] + (e1 * v[5] - e2 * v[4]))
    dq[4] = 0.5 * (w * v[4] + (e2 * v[3] - e0 * v[5]))
    dq[5] = 0.5 * (w * v[5] + (e0 * v[4] - e1 * v[3]))
    dq[6] = -0.5 * (e0 * v[3] + e1 * v[4] + e2 * v[5])
    for i in range(7, q.size):
        dq[i] = v[i - 1]
    return dq


@jit
def _normalised(q: np.ndarray) -> np.ndarray:
    out = q.copy()
    n = math.sqrt(q[3] * q[3] + q[4] * q[4] + q[5] * q[5] + q[6] * q[6])
    for i in range(3, 7):
        out[i] = q[i] / n
    return out


def limit_bus_torque(tau: np.ndarray, bound: float) -> tuple[np.ndarray, bool]:
    """τ with the bus torque (the free flyer's angular entries τ[3:6], bus frame) saturated to
    norm ``bound`` (eq. 29; 0: no bound), and whether the bound was active."""
    if bound <= 0.0:
        return tau, False
    n = float(np.linalg.norm(tau[3:6]))
    if n <= bound:
        return tau, False
    out = tau.copy()
    out[3:6] *= bound / n
    return out, True


@jit
def _rk4_step(tree: RigidTree, q: np.ndarray, v: np.ndarray, tau: np.ndarray,
              h: float) -> tuple[np.ndarray, np.ndarray]:
    """One classical RK4 step of length h on (q, v) under the held force τ (eq. 29), each
    stage's quaternion normalised before it is used and the result's after the step."""
    q1 = _normalised(q)
    dq1, dv1 = configuration_rate(q1, v), forward_dynamics(tree, q1, v, tau)
    q2 = _normalised(q + 0.5 * h * dq1)
    v2 = v + 0.5 * h * dv1
    dq2, dv2 = configuration_rate(q2, v2), forward_dynamics(tree, q2, v2, tau)
    q3 = _normalised(q + 0.5 * h * dq2)
    v3 = v + 0.5 * h * dv2
    dq3, dv3 = configuration_rate(q3, v3), forward_dynamics(tree, q3, v3, tau)
    q4 = _normalised(q + h * dq3)
    v4 = v + h * dv3
    dq4, dv4 = configuration_rate(q4, v4), forward_dynamics(tree, q4, v4, tau)
    return (_normalised(q + h / 6.0 * (dq1 + 2.0 * dq2 + 2.0 * dq3 + dq4)),
            v + h / 6.0 * (dv1 + 2.0 * dv2 + 2.0 * dv3 + dv4))


@jit
def integrate_held(tree: RigidTree, q: np.ndarray, v: np.ndarray, tau: np.ndarray,
                   dt: float, substeps: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(q, v) after dt under the held generalized force τ (eq. 29), and the bus attitude's
    excursion over the step (:func:`attitude_excursion`): classical RK4 in ``substeps`` steps
    on (q, v), q̇ from :func:`configuration_rate` and v̇ from the compiled articulated-body
    algorithm (:func:`pipeline.sim.forward_dynamics.forward_dynamics`), each stage's
    quaternion normalised before it is used and the result's after each step (the ODE keeps
    |quat| = 1; RK4 drifts from it by O(h⁵) per step)."""
    h = dt / substeps
    path = np.empty((substeps, 4))
    start = _normalised(q)[3:7]
    for k in range(substeps):
        q, v = _rk4_step(tree, q, v, tau, h)
        path[k] = q[3:7]
    return q, v, attitude_excursion(start, path)


@jit
def integrate_split(tree: RigidTree, q: np.ndarray, v: np.ndarray, tau_before: np.ndarray,
                    tau_after: np.ndarray, dt: float, split: float, substeps: int
                    ) -> tuple[np.ndarray, np.ndarray, float]:
    """(q, v) after dt when the command arrives within the step (eq. 41): τ_before held for
    the first ``split``·dt, then τ_after for the rest, each piece in RK4 steps of at most
    dt/``substeps`` (at least one), and the bus attitude's excursion over the whole step
    (:func:`attitude_excursion_timed`)."""
    first = max(1, math.ceil(substeps * split))
    second = max(1, math.ceil(substeps * (1.0 - split)))
    h1, h2 = split * dt / first, (1.0 - split) * dt / second
    path = np.empty((first + second, 4))
    times = np.empty(first + second)
    start = _normalised(q)[3:7]
    for k in range(first):
        q, v = _rk4_step(tree, q, v, tau_before, h1)
        path[k], times[k] = q[3:7], split * (k + 1) / first
    for k in range(second):
        q, v = _rk4_step(tree, q, v, tau_after, h2)
        path[first + k] = q[3:7]
        times[first + k] = split + (1.0 - split) * (k + 1) / second
    return q, v, attitude_excursion_timed(start, path, times)


@jit
def _quat_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊗ b of quaternions (x, y, z, w) (Hamilton's product)."""
    out = np.empty(4)
    out[0] = a[3] * b[0] + b[3] * a[0] + a[1] * b[2] - a[2] * b[1]
    out[1] = a[3] * b[1] + b[3] * a[1] + a[2] * b[0] - a[0] * b[2]
    out[2] = a[3] * b[2] + b[3] * a[2] + a[0] * b[1] - a[1] * b[0]
    out[3] = a[3] * b[3] - (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
    return out


@jit
def _conjugate(a: np.ndarray) -> np.ndarray:
    return np.array([-a[0], -a[1], -a[2], a[3]])


@jit
def _angle(a: np.ndarray) -> float:
    """The rotation angle in [0, π] of the unit quaternion a: 2 atan2(|ε|, |w|)."""
    return 2.0 * math.atan2(math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]), abs(a[3]))


@jit
def _chord(q_start: np.ndarray, path_end: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(rel, |ε_rel|, θ): the rotation from ``q_start`` to ``path_end`` the shorter way
    round, its vector part's norm and its angle."""
    rel = _quat_product(_conjugate(q_start), path_end)
    if rel[3] < 0.0:  # the shorter way round
        rel = -rel
    s = math.sqrt(rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2])
    return rel, s, 2.0 * math.atan2(s, rel[3])


@jit
def _off_geodesic(q_start: np.ndarray, rel: np.ndarray, s: float, half: float,
                  point: np.ndarray) -> float:
    """The angle between ``point`` and the geodesic's attitude at half-angle ``half``."""
    step = np.zeros(4)
    step[3] = math.cos(half)
    if s > 0.0:
        for i in range(3):
            step[i] = rel[i] / s * math.sin(half)
    geodesic = _quat_product(q_start, step)
    return _angle(_quat_product(_conjugate(geodesic), point))


@jit
def attitude_excursion(q_start: np.ndarray, path: np.ndarray) -> float:
    """The largest angle (rad) between the bus attitude along ``path`` (the unit quaternions
    (x, y, z, w) at equal substeps of one control step, the last at its end) and the geodesic
    from the step's first attitude ``q_start`` to its last (eqs. 29, 32): the motion between
    two control instants that the instants do not see. A rotation at constant rate, as the
    update of eq. 15 makes, has none; under a held torque about a principal axis the rate
    ramps from ω_k to ω_{k+1} and the excursion is |ω_{k+1} − ω_k| dt/8, at mid-step."""
    n = path.shape[0]
    rel, s, theta = _chord(q_start, path[n - 1])
    worst = 0.0
    for j in range(1, n):
        half = 0.5 * theta * j / n
        worst = max(worst, _off_geodesic(q_start, rel, s, half, path[j - 1]))
    return worst


@jit
def attitude_excursion_timed(q_start: np.ndarray, path: np.ndarray, times: np.ndarray
                             ) -> float:
    """:func:`attitude_excursion` for a path at unequal times (``times``: each point's
    fraction of the step, the last 1), as a step split by a command's arrival makes
    (eq. 41)."""
    n = path.shape[0]
    rel, s, theta = _chord(q_start, path[n - 1])
    worst = 0.0
    for j in range(n - 1):
        worst = max(worst, _off_geodesic(q_start, rel, s, 0.5 * theta * times[j], path[j]))
    return worst
