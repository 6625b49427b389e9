"""Finite-difference linearisation of the simulator's own step, to check the map Φ (eq. 22).

The simulator is put at a rest steady state: a static reference equal to the start pose and
the posture spring's q̄ at the start posture, so x̃ = 0 and e = v̆ − v̆_des = 0 there.
Each coordinate of z = [x̃; e] is perturbed by ±h (x̃ through a configuration change that
keeps the CoM fixed, δθ = Γ⁻¹ [0; J_x⁻¹ δx̃]) and one ``Mission.step`` is taken; the central
differences give ∂z⁺/∂z, to compare with ``theory.discrete_map`` at the same state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.analysis.theory import discrete_map, posture_stiffness
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.base_guidance import Reference
from pipeline.sim.mission import LoopState, Mission, task_errors
from pipeline.spec import Spec


class StaticGuidance:
    """A reference that holds the pose of a given state: desired = actual, all rates zero."""

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
    Phi_theory: np.ndarray  # discrete_map at the same state
    max_abs_diff: float


def _rest_reference(mission: Mission, q: np.ndarray) -> Reference:
    T = mission.robot.terms(q, np.zeros(mission.robot.model.nv), dynamics=False)
    z3 = np.zeros(3)
    # Aim along the camera's own boresight, so the orientation error is zero at rest.
    return Reference(p_c=T.p_c, v_c=z3, a_c=z3, R_b=T.R_tb, w_b=z3, p_e=T.p_e, v_e=z3,
                     R_e=T.R_te, w_e=z3, aim=T.p_e + T.R_te[:, 2])


def _z(mission: Mission, s: LoopState) -> np.ndarray:
    """z = [x̃; v̆ − v̆_des] of a state under the mission's (static) guidance."""
    T = mission.robot.terms(s.q, s.v, dynamics=False)
    gamma = conditioning_scale(T.s_min_G, mission.spec.controller)
    err = task_errors(T, mission.guidance.reference(s.tau), gamma, s.v_c)
    return np.concatenate([err.x_tilde, s.v_breve - err.v_breve_des])


def _state(mission: Mission, q: np.ndarray, v_breve: np.ndarray) -> LoopState:
    T = mission.robot.terms(q, np.zeros(mission.robot.model.nv), dynamics=False)
    v = T.gamma_inv @ np.concatenate([np.zeros(3), v_breve])
    return LoopState(q=q, v=v, v_c=np.zeros(3), v_breve=v_breve.copy())


def simulator_map(spec: Spec, h: float = 1e-6) -> Linearization:
    """∂z⁺/∂z of ``Mission.step`` about the rest state at the start pose, and Φ there."""
    mission = Mission(spec)
    q0 = mission.q0.copy()
    mission.guidance = StaticGuidance(_rest_reference(mission, q0))
    mission.robot.q_bar = q0[7:].copy()  # the posture spring is at rest too
    model = mission.robot.model
    T0 = mission.robot.terms(q0, np.zeros(model.nv))
    gamma = conditioning_scale(T0.s_min_G, spec.controller)
    err0 = task_errors(T0, mission.guidance.reference(0.0), gamma, np.zeros(3))
    J_x = err0.J_x

    Z, Zp = np.zeros((18, 18)), np.zeros((18, 18))
    for j in range(18):
        cols = []
        for sgn in (1.0, -1.0):
            dz = np.zeros(18)
            dz[j] = sgn * h
            dtheta = T0.gamma_inv @ np.concatenate([np.zeros(3), np.linalg.solve(J_x, dz[:9])])
            s = _state(mission, pin.integrate(model, q0, dtheta), dz[9:])
            nxt, _ = mission.step(s)
            cols.append((_z(mission, s), _z(mission, nxt)))
        Z[:, j] = cols[0][0] - cols[1][0]
        Zp[:, j] = cols[0][1] - cols[1][1]
    Phi_fd = Zp @ np.linalg.inv(Z)

    K, D = block_gains(spec.controller, gamma)
    K_x = J_x.T @ K + posture_stiffness(T0.gamma_inv, spec.controller.gains.posture, J_x)
    Phi = discrete_map(T0.reduced_inertia, D, K_x, J_x, spec.mission.dt,
                       spec.controller.integrator)
    return Linearization(Phi_fd, Phi, float(np.abs(Phi_fd - Phi).max()))
