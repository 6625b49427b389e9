"""The inspection mission: one controller step after another, logged per step (DESIGN §2).

Order of one step k (the discrete map of eq. 22 follows exactly this order):
1. terms of (q_k, v_k); γ_k from s_min_G; references at guidance time τ_k;
2. breve loop: v̆_{k+1} from v̆_k (explicit or imex); CoM loop: v_c,{k+1} from v_c,k;
3. v_{k+1} = clip(Γ⁻¹(q_k) [v_c,{k+1}; v̆_{k+1}], ±v_max);  q_{k+1} = q_k ⊕ v_{k+1} dt;
4. τ_{k+1} = τ_k + γ_k dt.
Row k of the log holds the state at the start of step k and what step k computed from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from tqdm import tqdm

from pipeline.logs import SCALAR_COLUMNS, VECTOR_COLUMNS
from pipeline.sim import breve_controller as bc
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.base_guidance import BaseGuidance, Reference
from pipeline.sim.com_controller import com_update
from pipeline.sim.jit import jit
from pipeline.sim.limits import LIMIT_FLAGS, breve_bounds
from pipeline.sim.robot import GiordanoRobot, Terms
from pipeline.sim.rotations import attitude_error, quat_from_matrix
from pipeline.sim.target import CoverageCounter, build_target
from pipeline.spec import Spec


@dataclass
class LoopState:
    """What one step carries to the next."""

    q: np.ndarray
    v: np.ndarray
    v_c: np.ndarray
    v_breve: np.ndarray
    tau: float = 0.0
    integral: np.ndarray = field(default_factory=lambda: np.zeros(3))
    v_breve_des_prev: np.ndarray | None = None


@dataclass(frozen=True)
class TaskErrors:
    """x̃, J_x, v̆_des, G_vc and ẋ̃_c of one step (eq. 14)."""

    x_tilde: np.ndarray
    J_x: np.ndarray
    v_breve_des: np.ndarray
    G_vc: np.ndarray
    com_vel_err: np.ndarray
    com_pos_err: np.ndarray


@dataclass
class MissionResult:
    columns: dict[str, np.ndarray]
    status: str
    failed_step: int | None = None
    error: str = ""
    warnings: list[str] = field(default_factory=list)


def task_errors(T: Terms, ref: Reference, gamma: float, v_c: np.ndarray) -> TaskErrors:
    """Task errors and desired reduced velocity against the references (eq. 14).

    x̃ = [2ε_b; p_e − p_e,des; 2ε_e], J_x = blockdiag(E_b, R_te, E_e),
    v̆_des = [R_bt γω_b,des; R_et γ(ṗ_e,des − ṗ_c,des); R_et γω_e,des], G_vc = [0; R_et; 0].
    """
    return TaskErrors(*task_error_terms(T.R_tb, T.R_te, T.p_e, T.p_c, ref.R_b, ref.R_e, ref.p_e,
                                        ref.p_c, ref.w_b, ref.v_e, ref.v_c, ref.w_e, gamma, v_c))


@jit
def task_error_terms(R_tb, R_te, p_e, p_c, R_b_des, R_e_des, p_e_des, p_c_des, w_b_des,
                     v_e_des, v_c_des, w_e_des, gamma, v_c):
    """The arrays of :func:`task_errors` (eq. 14), compiled."""
    x_b, E_b = attitude_error(R_tb, R_b_des)
    x_o, E_e = attitude_error(R_te, R_e_des)
    R_et = np.ascontiguousarray(R_te.T)
    R_bt = np.ascontiguousarray(R_tb.T)
    J_x = np.zeros((9, 9))
    J_x[0:3, 0:3] = E_b
    J_x[3:6, 3:6] = R_te
    J_x[6:9, 6:9] = E_e
    v_des = np.empty(9)
    v_des[0:3] = R_bt @ (gamma * w_b_des)
    v_des[3:6] = R_et @ (gamma * (v_e_des - v_c_des))
    v_des[6:9] = R_et @ (gamma * w_e_des)
    G_vc = np.zeros((9, 3))
    G_vc[3:6] = R_et
    x = np.empty(9)
    x[0:3] = x_b
    x[3:6] = p_e - p_e_des
    x[6:9] = x_o
    return x, J_x, v_des, G_vc, v_c - gamma * v_c_des, p_c - p_c_des


@jit
def loop_update(R_tb, R_te, p_e, p_c, M_hat, C_hat, gamma_inv,
                R_b_des, R_e_des, p_e_des, p_c_des, w_b_des, v_e_des, v_c_des, w_e_des, a_c_des,
                gamma, v_c, v_breve, v_breve_des_prev, has_prev, integral, q_joint,
                K_breve, D_breve, k_posture, q_bar, imex, dt, acc_bounds, rate_bounds,
                com_K, com_D, com_Ki, com_i_max, com_acc_bound, com_rate_bound, v_max):
    """Both loops of one step and the velocity reconstruction (eqs. 12–16).

    Task errors (eq. 14), the breve RHS (eq. 13) and its step (eq. 15a or 15b), μ_max of
    M̆⁻¹D̆ (eq. 21), the CoM step (eq. 12), then v = clip(Γ⁻¹ [v_c; v̆], ±v_max) (eq. 16).
    Returns the new v, v_c, v̆ and CoM integral, x̃, v̆_des, μ_max, the limit flags in the
    order of ``LIMIT_FLAGS`` and the CoM position error.
    """
    x_tilde, J_x, v_des, G_vc, com_vel_err, com_pos_err = task_error_terms(
        R_tb, R_te, p_e, p_c, R_b_des, R_e_des, p_e_des, p_c_des, w_b_des, v_e_des, v_c_des,
        w_e_des, gamma, v_c)
    v_dot_des = (v_des - v_breve_des_prev) / dt if has_prev else np.zeros(9)
    M_breve = np.ascontiguousarray(M_hat[3:, 3:])
    C_breve = np.ascontiguousarray(C_hat[3:, 3:])
    rhs = bc.breve_rhs(M_breve, C_breve, C_hat[3:, :3], gamma_inv, v_breve, v_des, v_dot_des,
                       J_x, K_breve, x_tilde, D_breve, G_vc, com_vel_err, k_posture, q_joint,
                       q_bar)
    mu_max = bc.damping_rates(M_breve, D_breve)[-1]
    if imex:
        v_b_new, hit_acc, hit_rate = bc.imex_update(M_breve, D_breve, rhs, v_breve, dt,
                                                    acc_bounds, rate_bounds)
    else:
        v_b_new, hit_acc, hit_rate = bc.explicit_update(M_breve, rhs, v_breve, dt, acc_bounds,
                                                        rate_bounds)
    v_c_new, integral_new, sat_c_acc, sat_c_rate = com_update(
        com_pos_err, com_vel_err, v_c, gamma * gamma * a_c_des, integral, com_K, com_D, com_Ki,
        com_i_max, com_acc_bound, com_rate_bound, dt)
    nu = np.empty(12)
    nu[0:3] = v_c_new
    nu[3:12] = v_b_new
    v_raw = np.ascontiguousarray(gamma_inv) @ nu
    sat_v_max = np.any(np.abs(v_raw) > v_max)
    v_new = np.minimum(np.maximum(v_raw, -v_max), v_max)
    hits = np.array([hit_acc[0], hit_rate[0], hit_acc[1], hit_rate[1], hit_acc[2], hit_rate[2],
                     sat_c_acc, sat_c_rate, sat_v_max])
    return (v_new, v_c_new, v_b_new, integral_new, x_tilde, v_des, mu_max, hits, com_pos_err)


@jit
def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two vectors in degrees."""
    c = (a @ b) / np.sqrt((a @ a) * (b @ b))
    return np.degrees(np.arccos(max(-1.0, min(1.0, c))))


@jit
def pointing_errors(R_tb, p_b, R_te, p_e, aim) -> tuple[float, float]:
    """Bus pointing error (z_b against the line to the target at the origin) and camera
    boresight error (z_e against the line to the aim point), in degrees (eq. 18)."""
    return (angle_deg(np.ascontiguousarray(R_tb[:, 2]), -p_b),
            angle_deg(np.ascontiguousarray(R_te[:, 2]), aim - p_e))


class Mission:
    """Robot, target and guidance of one spec, and the step that advances them."""

    def __init__(self, spec: Spec, robot: GiordanoRobot | None = None):
        self.spec = spec
        self.robot = robot or GiordanoRobot(spec)
        self.target = build_target(spec.target)
        self.dt = spec.mission.dt
        # Without the bus derate the gains do not depend on γ: build them once.
        self.gains = None if spec.controller.base.derate.gain else block_gains(spec.controller, 1.0)
        self._zero9 = np.zeros(9)
        q_start = self.robot.start_configuration()
        T0 = self.robot.terms(q_start, np.zeros(self.robot.model.nv), dynamics=False)
        self.guidance = BaseGuidance(spec.guidance, T0.p_e - T0.p_c, T0.R_te[:, 0])
        ref0 = self.guidance.reference(0.0)
        q0 = q_start.copy()
        q0[0:3] = ref0.p_c - ref0.R_b @ T0.p_bc
        q0[3:7] = quat_from_matrix(ref0.R_b)
        self.q0 = q0
        # The CoM starts on the orbit at the orbit's speed (the bus was inserted into it),
        # with the arm and bus at rest relative to it.
        gamma0 = conditioning_scale(T0.s_min_G, spec.controller)
        self.v_c0 = gamma0 * ref0.v_c

    def initial_state(self) -> LoopState:
        nv = self.robot.model.nv
        T0 = self.robot.terms(self.q0, np.zeros(nv), dynamics=False)
        v_c0 = self.v_c0.copy()
        v0 = T0.gamma_inv @ np.concatenate([v_c0, np.zeros(9)])
        return LoopState(q=self.q0.copy(), v=v0, v_c=v_c0, v_breve=np.zeros(9))

    def step(self, s: LoopState) -> tuple[LoopState, dict]:
        """One controller step from state ``s`` (eq. 22's update order, the limits of eq. 16,
        the guard's dt·μ_max of eq. 21): the next state and the row to log."""
        ctrl, dt = self.spec.controller, self.dt
        T = self.robot.terms(s.q, s.v)
        gamma = conditioning_scale(T.s_min_G, ctrl)
        ref = self.guidance.reference(s.tau, T.p_b)
        K, D = self.gains if self.gains is not None else block_gains(ctrl, gamma)
        prev = s.v_breve_des_prev
        lim, com = ctrl.limits, ctrl.com
        (v_new, v_c, v_breve, integral, x_tilde, v_des, mu_max, hits,
         com_pos_err) = loop_update(
            T.R_tb, T.R_te, T.p_e, T.p_c, T.M_hat, T.C_hat, T.gamma_inv,
            ref.R_b, ref.R_e, ref.p_e, ref.p_c, ref.w_b, ref.v_e, ref.v_c, ref.w_e, ref.a_c,
            gamma, s.v_c, s.v_breve, self._zero9 if prev is None else prev, prev is not None,
            s.integral, s.q[7:], K, D, ctrl.gains.posture, self.robot.q_bar,
            ctrl.integrator == "imex", dt, breve_bounds(lim, "acc"), breve_bounds(lim, "rate"),
            com.K, com.D, com.Ki, com.i_max, lim.v_c_acc, lim.v_c_rate, lim.v_max)
        pointing, boresight = pointing_errors(T.R_tb, T.p_b, T.R_te, T.p_e, ref.aim)
        row = {
            "tau": s.tau, "q": s.q, "v": s.v, "v_c": s.v_c, "v_breve": s.v_breve,
            "v_breve_des": v_des, "x_tilde": x_tilde,
            "s_min_G": T.s_min_G, "kappa_G": T.kappa_G, "s_min_J": T.s_min_J,
            "kappa_J": T.kappa_J, "gamma": gamma, "dt_mu_max": dt * mu_max,
            "pointing_err_deg": pointing, "boresight_err_deg": boresight,
            "com_err": math.sqrt(float(com_pos_err @ com_pos_err)),
            "_p_e": T.p_e, "_R_te": T.R_te, **dict(zip(LIMIT_FLAGS, hits, strict=True)),
        }
        q_new = pin.integrate(self.robot.model, s.q, v_new * dt)
        nxt = LoopState(q=q_new, v=v_new, v_c=v_c, v_breve=v_breve, tau=s.tau + gamma * dt,
                        integral=integral, v_breve_des_prev=v_des)
        return nxt, row

    def run(self, progress: bool = False) -> MissionResult:
        """Run every step; a non-finite state ends the run with status ``failed``."""
        n = self.spec.n_steps
        cols = {c: np.zeros((n, w)) for c, w in VECTOR_COLUMNS.items()}
        cols |= {c: np.zeros(n) for c in SCALAR_COLUMNS}
        cols |= {c: np.zeros(n, dtype=bool) for c in LIMIT_FLAGS}
        cols["step"] = np.arange(n, dtype=np.int64)
        cols["t"] = np.arange(n) * self.dt
        coverage = CoverageCounter(self.target, self.spec.camera)
        s = self.initial_state()
        warned: list[str] = []
        # Overflow shows as a non-finite state, caught below at the step it happens.
        with np.errstate(all="ignore"), tqdm(total=n, disable=not progress, unit="step",
                                             mininterval=0.5, desc=self.spec.name) as bar:
            for k in range(n):
                try:
                    s_next, row = self.step(s)
                    finite = state_is_finite(s_next.q, s_next.v, s_next.v_breve, s_next.v_c)
                except (np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
                    finite, why = False, f"{type(exc).__name__}: {exc}"
                else:
                    why = "non-finite state"
                if not finite:
                    cut = {c: a[:k] for c, a in cols.items()}
                    return MissionResult(cut, "failed", k, f"step {k}: {why}", warned)
                row["coverage"] = coverage.update(row.pop("_p_e"), row.pop("_R_te"))
                for c, val in row.items():
                    cols[c][k] = val
                if (not warned and self.spec.controller.integrator == "explicit"
                        and row["dt_mu_max"] > 2):
                    warned.append(stability_warning(k, row["dt_mu_max"], self.dt))
                s = s_next
                bar.update()
        return MissionResult(cols, "complete", warnings=warned)


@jit
def state_is_finite(q, v, v_breve, v_c) -> bool:
    """True when every entry of the carried state is finite."""
    for a in (q, v, v_breve, v_c):
        for x in a:
            if not np.isfinite(x):
                return False
    return True


def stability_warning(step: int, dt_mu_max: float, dt: float) -> str:
    """The online guard's one message (eq. 21): name the bound and both fixes."""
    dt_star = 2 * dt / dt_mu_max
    return (f"step {step}: dt·μ_max = {dt_mu_max:.3g} > 2 under the explicit integrator: the "
            f"velocity damping is period-2 unstable (forward Euler). Fix: set "
            f"controller.integrator: imex, or mission.dt below dt* = 2/μ_max = {dt_star:.4g} s")
