"""Finite-difference linearisation of the simulator's own step, to check the map Φ of the loop
as flown (eqs. 22, 34): the simulator's update, or the sampled-data plant with its delay.

The simulator is put at a rest steady state: a static reference equal to the start pose and
the posture spring's q̄ at the start posture, so x̃ = 0 and e = v̆ − v̆_des = 0 there.
Each coordinate of z = [x̃; e] is perturbed by ±h (x̃ through a configuration change that
keeps the CoM fixed, δθ = Γ⁻¹ [0; J_x⁻¹ δx̃]) and one ``Mission.step`` is taken; the central
differences give ∂z⁺/∂z, to compare with ``theory.flown_map`` at the same state. A redundant
arm's z = [x̃; η; e] adds its null-space coordinate η (η̇ = ν_n, eq. 37f), perturbed along the
self-motion (Γ⁻¹'s null-space columns) and read from a configuration as the null-space rows
of Γ(q_0) applied to its difference from q_0 (exact to first order, which central differences
keep).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.analysis.theory import flown_map
from pipeline.shapes import Q
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.base_guidance import Reference
from pipeline.sim.mission import LoopState, Mission, task_errors
from pipeline.sim.stability import loop_stiffness, position_jacobian
from pipeline.spec import Spec


class StaticGuidance:
    """A reference that holds the pose of a given state: desired = actual, all rates zero."""

    # No guidance constants: the compiled mission loop then flies the reference vector as
    # ``reference_into`` left it (``ReducedLoop.guidance`` empty).
    params = np.empty(0)

    def __init__(self, ref: Reference):
        self.ref = ref
        self._vector = ref.as_vector()

    def reference(self, tau: float, p_b: np.ndarray | None = None) -> Reference:
        return self.ref

    def reference_into(self, out: np.ndarray, tau: float, p_b: np.ndarray) -> None:
        out[:] = self._vector


@dataclass(frozen=True)
class Linearization:
    Phi_fd: np.ndarray  # ∂z⁺/∂z from the simulator's step
    Phi_theory: np.ndarray  # flown_map at the same state
    max_abs_diff: float


def _rest_reference(mission: Mission, q: np.ndarray) -> Reference:
    T = mission.robot.terms(q, np.zeros(mission.robot.model.nv), dynamics=False)
    z3 = np.zeros(3)
    # Aim along the camera's own boresight, so the orientation error is zero at rest.
    return Reference(p_c=T.p_c, v_c=z3, a_c=z3, R_b=T.R_tb, w_b=z3, p_e=T.p_e, v_e=z3,
                     R_e=T.R_te, w_e=z3, aim=T.p_e + T.R_te[:, 2])


def _z(mission: Mission, s: LoopState, q0: np.ndarray, Y0: np.ndarray) -> np.ndarray:
    """z = [x̃; η; v̆ − v̆_des] of a state under the mission's (static) guidance; η, a
    redundant arm's null-space coordinate, is Y0 (Γ(q0)'s null-space rows) on the state's
    configuration difference from q0 (empty for six joints)."""
    T = mission.robot.terms(s.q, s.v, dynamics=False)
    gamma = conditioning_scale(T.s_min_G, mission.spec.controller)
    err = task_errors(T, mission.guidance.reference(s.tau), gamma, s.v_c)
    eta = Y0 @ pin.difference(mission.robot.model, q0, s.q)
    return np.concatenate([err.x_tilde, eta, s.v_breve - err.v_breve_des])


def _state(mission: Mission, q: np.ndarray, v_breve: np.ndarray) -> LoopState:
    T = mission.robot.terms(q, np.zeros(mission.robot.model.nv), dynamics=False)
    v = T.gamma_inv @ np.concatenate([np.zeros(3), v_breve])
    return LoopState(q=q, v=v, v_c=np.zeros(3), v_breve=v_breve.copy())


def _increment_force(mission: Mission, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The generalized force that moves the reduced velocity by p over one step at rest at q
    (eq. 29 at first order: τ = M Γ⁻¹ [0; p/dt]); the held command a delayed plant carries."""
    T = mission.robot.terms(q, np.zeros(mission.robot.model.nv))
    return T.M @ (T.gamma_inv @ np.concatenate([np.zeros(3), p / mission.dt]))


def _force_increment(mission: Mission, q: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """The reduced velocity increment over one step of a held force τ at rest at q: the
    inverse of :func:`_increment_force`."""
    T = mission.robot.terms(q, np.zeros(mission.robot.model.nv))
    return mission.dt * (T.gamma @ np.linalg.solve(T.M, tau))[3:]


def simulator_map(spec: Spec, h: float = 1e-6) -> Linearization:
    """∂w⁺/∂w of ``Mission.step`` about the rest state at the start pose, and the flown map Φ
    there (eq. 34): the spec's integrator, plant and delay. w = [x̃; e] (18; [x̃; η; e] of
    2(9 + k) for a redundant arm), and with one step of delay the velocity increment the held
    command carries (9 + k more); with a command arriving within the step (eq. 41) one more,
    the command it replaces, the map at the arrival the step draws."""
    mission = Mission(spec)
    shape = mission.robot.shape
    q0 = mission.q0.copy()
    mission.guidance = StaticGuidance(_rest_reference(mission, q0))
    mission.robot.q_bar = q0[Q.joints].copy()  # the posture spring is at rest too
    model = mission.robot.model
    plant = spec.mission.plant
    delay = plant.delay_steps if plant.model == "sampled" else 0
    split = plant.model == "sampled" and plant.timing is not None
    waiting = delay + split  # the commands the plant holds (Mission._hold's queue)
    mission._start_sensors()  # the arrival the step draws: its first (Mission.step restarts)
    fraction = mission._arrival() if split else 0.0
    T0 = mission.robot.terms(q0, np.zeros(model.nv))
    gamma = conditioning_scale(T0.s_min_G, spec.controller)
    err0 = task_errors(T0, mission.guidance.reference(0.0), gamma, np.zeros(3))
    n = shape.n_breve  # the map's position and velocity coordinates each
    J_x = position_jacobian(err0.J_x, n)
    Y0 = T0.gamma[12:]  # ν_n = Y0 v: the null-space rows (eq. 37c), none for six joints

    size = 2 * n + n * waiting
    W, Wp = np.zeros((size, size)), np.zeros((size, size))
    for j in range(size):
        cols = []
        for sgn in (1.0, -1.0):
            dw = np.zeros(size)
            dw[j] = sgn * h
            dtheta = T0.gamma_inv @ np.concatenate([np.zeros(3), np.linalg.solve(J_x, dw[:n])])
            s = _state(mission, pin.integrate(model, q0, dtheta), dw[n:2 * n])
            if waiting:
                mission._held = [_increment_force(mission, q0, dw[2 * n + j * n:3 * n + j * n])
                                 for j in range(waiting)]
            nxt, _ = mission.step(s)
            held = [_force_increment(mission, q0, tau) for tau in mission._held or []]
            cols.append((np.concatenate([_z(mission, s, q0, Y0), dw[2 * n:]]),
                         np.concatenate([_z(mission, nxt, q0, Y0), *held])))
        W[:, j] = cols[0][0] - cols[1][0]
        Wp[:, j] = cols[0][1] - cols[1][1]
    Phi_fd = Wp @ np.linalg.inv(W)

    ctrl = spec.controller
    K, D = block_gains(ctrl, gamma, shape.null_space_dim)
    K_x = loop_stiffness(J_x, K, T0.gamma_inv, ctrl)
    Phi = flown_map(T0.reduced_inertia, D, K_x, J_x, spec.mission.dt,
                    spec.controller.integrator, plant.model, delay, fraction)
    return Linearization(Phi_fd, Phi, float(np.abs(Phi_fd - Phi).max()))
