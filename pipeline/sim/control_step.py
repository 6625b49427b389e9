"""One controller step in one compiled call (eq. 22's update order), and the flat layouts it
reads and writes.

The mission calls Pinocchio, then :func:`controller_step` with Pinocchio's outputs, the
references, the controller's parameters, the carried state and the log. A step computes some
forty small arrays; handed between Python and compiled code one by one, their boxing would
cost several times the Pinocchio calls themselves (architecture §7). So the state, the parameters
and the log row are flat float vectors whose layouts are named here, next to the code that
reads them (:mod:`pipeline.sim.layout`). Inside, the kernels read and write them by name, through
namedtuples built from the vectors and each field's place frozen as a constant.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from pipeline.log_layout import ROW_FIELDS
from pipeline.sim import breve_controller as bc
from pipeline.sim.base_guidance import read_reference
from pipeline.sim.com_controller import com_update
from pipeline.sim.jit import jit
from pipeline.sim.layout import field_places, offsets
from pipeline.sim.linalg import dot, matvec
from pipeline.sim.plant import commanded_force
from pipeline.sim.rotations import attitude_error
from pipeline.sim.sampling import scale_by_svd
from pipeline.sim.target import mark_visible
from pipeline.sim.task_transform import DynamicsInputs, full_transform

# The carried state: what step k hands to step k + 1, and the increment v_{k+1} dt that
# Pinocchio's integrate turns into q_{k+1} (eq. 22).
STATE_FIELDS = (("q", 13), ("v", 12), ("v_c", 3), ("v_breve", 9), ("tau", 1), ("integral", 3),
                ("v_breve_des_prev", 9), ("has_prev", 1), ("dq", 12))
STATE = offsets(STATE_FIELDS)
STATE_SIZE = sum(n for _, n in STATE_FIELDS)
STATE_AT = field_places("StatePlaces", STATE_FIELDS)

# One log row (architecture §6, pipeline/log_layout.py), written by the kernel; the mission
# fills ``t`` and ``step``.
ROW = offsets(ROW_FIELDS)
ROW_AT = field_places("RowPlaces", ROW_FIELDS)

# The controller's parameters, from the spec and the robot (see ``controller_vector``): the
# gains of eq. 13, the posture spring, the integrator, the limits of eq. 16, the CoM loop of
# eq. 12, the γ ramp of eq. 20 and the damped inverse of eq. 6.
CONTROLLER_FIELDS = (("k", 9), ("d", 9), ("derate_gain", 1), ("k_posture", 1), ("q_bar", 6),
                     ("imex", 1), ("dt", 1), ("acc_bounds", 3), ("rate_bounds", 3),
                     ("com_K", 1), ("com_D", 1), ("com_Ki", 1), ("com_i_max", 1),
                     ("v_c_acc", 1), ("v_c_rate", 1), ("v_max", 1), ("ramp_low", 1),
                     ("ramp_high", 1), ("ramp_floor", 1), ("mass", 1), ("inverse_floor", 1),
                     ("inverse_damping", 1))
CONTROLLER_SIZE = sum(n for _, n in CONTROLLER_FIELDS)
CONTROLLER_AT = field_places("ControllerPlaces", CONTROLLER_FIELDS)

# The bundles the kernels pass by name: the controller's parameters (flags as booleans), the
# carried state at the start of a step (all but ``dq``, which the step only writes), the task
# errors of eq. 14 and what the loops of one step return.
ControlParams = namedtuple("ControlParams", [name for name, _ in CONTROLLER_FIELDS])
StepState = namedtuple("StepState", [name for name, _ in STATE_FIELDS if name != "dq"])
TaskErrors = namedtuple("TaskErrors", ["x_tilde", "J_x", "v_breve_des", "G_vc", "com_vel_err",
                                       "com_pos_err"])
LoopResult = namedtuple("LoopResult", ["v", "v_c", "v_breve", "integral", "x_tilde",
                                       "v_breve_des", "mu_max", "hit_acc", "hit_rate",
                                       "sat_v_c_acc", "sat_v_c_rate", "sat_v_max",
                                       "com_pos_err"])


@jit
def read_params(c):
    """The controller vector (``CONTROLLER_FIELDS``) by name. The arrays are copies: the step
    scales the gains in place."""
    return ControlParams(
        k=c[CONTROLLER_AT.k].copy(), d=c[CONTROLLER_AT.d].copy(),
        derate_gain=c[CONTROLLER_AT.derate_gain] > 0.5, k_posture=c[CONTROLLER_AT.k_posture],
        q_bar=c[CONTROLLER_AT.q_bar].copy(), imex=c[CONTROLLER_AT.imex] > 0.5,
        dt=c[CONTROLLER_AT.dt], acc_bounds=c[CONTROLLER_AT.acc_bounds].copy(),
        rate_bounds=c[CONTROLLER_AT.rate_bounds].copy(), com_K=c[CONTROLLER_AT.com_K],
        com_D=c[CONTROLLER_AT.com_D], com_Ki=c[CONTROLLER_AT.com_Ki],
        com_i_max=c[CONTROLLER_AT.com_i_max], v_c_acc=c[CONTROLLER_AT.v_c_acc],
        v_c_rate=c[CONTROLLER_AT.v_c_rate], v_max=c[CONTROLLER_AT.v_max],
        ramp_low=c[CONTROLLER_AT.ramp_low], ramp_high=c[CONTROLLER_AT.ramp_high],
        ramp_floor=c[CONTROLLER_AT.ramp_floor], mass=c[CONTROLLER_AT.mass],
        inverse_floor=c[CONTROLLER_AT.inverse_floor],
        inverse_damping=c[CONTROLLER_AT.inverse_damping])


@jit
def read_state(s):
    """The carried state (``STATE_FIELDS``, but ``dq``) by name, as contiguous copies."""
    return StepState(
        q=s[STATE_AT.q].copy(), v=s[STATE_AT.v].copy(), v_c=s[STATE_AT.v_c].copy(),
        v_breve=s[STATE_AT.v_breve].copy(), tau=s[STATE_AT.tau],
        integral=s[STATE_AT.integral].copy(),
        v_breve_des_prev=s[STATE_AT.v_breve_des_prev].copy(),
        has_prev=s[STATE_AT.has_prev] > 0.5)


@jit
def task_error_terms(R_tb, R_te, p_e, p_c, ref, gamma, v_c):
    """x̃, J_x, v̆_des, G_vc, ẋ̃_c and the CoM position error against the references ``ref``
    (a ``Reference``) (eq. 14), as ``TaskErrors``.

    x̃ = [2ε_b; p_e − p_e,des; 2ε_e], J_x = blockdiag(E_b, R_te, E_e),
    v̆_des = [R_bt γω_b,des; R_et γ(ṗ_e,des − ṗ_c,des); R_et γω_e,des], G_vc = [0; R_et; 0].
    """
    x_b, E_b = attitude_error(R_tb, ref.R_b)
    x_o, E_e = attitude_error(R_te, ref.R_e)
    R_et = np.ascontiguousarray(R_te.T)
    R_bt = np.ascontiguousarray(R_tb.T)
    J_x = np.zeros((9, 9))
    J_x[0:3, 0:3] = E_b
    J_x[3:6, 3:6] = R_te
    J_x[6:9, 6:9] = E_e
    v_des = np.empty(9)
    v_des[0:3] = matvec(R_bt, gamma * ref.w_b)
    v_des[3:6] = matvec(R_et, gamma * (ref.v_e - ref.v_c))
    v_des[6:9] = matvec(R_et, gamma * ref.w_e)
    G_vc = np.zeros((9, 3))
    G_vc[3:6] = R_et
    x = np.empty(9)
    x[0:3] = x_b
    x[3:6] = p_e - ref.p_e
    x[6:9] = x_o
    return TaskErrors(x_tilde=x, J_x=J_x, v_breve_des=v_des, G_vc=G_vc,
                      com_vel_err=v_c - gamma * ref.v_c, com_pos_err=p_c - ref.p_c)


@jit
def loop_update(pose, tr, ref, p, s, gamma, K_breve, D_breve):
    """Both loops of one step and the velocity reconstruction (eqs. 12–16).

    From the placements ``pose`` (``DynamicsInputs``), the transform ``tr`` (``Transform``),
    the references ``ref``, the parameters ``p`` (``ControlParams``), the state ``s``
    (``StepState``), γ and the gains K̆, D̆: task errors (eq. 14), the breve RHS (eq. 13) and
    its step (eq. 15a or 15b), μ_max of M̆⁻¹D̆ (eq. 21), the CoM step (eq. 12), then
    v = clip(Γ⁻¹ [v_c; v̆], ±v_max) (eq. 16). Returns a ``LoopResult``.
    """
    err = task_error_terms(pose.R_tb, pose.R_te, pose.p_e, tr.p_c, ref, gamma, s.v_c)
    v_dot_des = ((err.v_breve_des - s.v_breve_des_prev) / p.dt if s.has_prev
                 else np.zeros(9))
    M_breve = np.ascontiguousarray(tr.M_hat[3:, 3:])
    C_breve = np.ascontiguousarray(tr.C_hat[3:, 3:])
    rhs = bc.breve_rhs(M_breve, C_breve, tr.C_hat[3:, :3], tr.gamma_inv, s.v_breve, v_dot_des,
                       err, K_breve, D_breve, p.k_posture, s.q[7:].copy(), p.q_bar)
    mu_max = bc.damping_rates(M_breve, D_breve)[-1]
    if p.imex:
        v_b_new, hit_acc, hit_rate = bc.imex_update(M_breve, D_breve, rhs, s.v_breve, p.dt,
                                                    p.acc_bounds, p.rate_bounds)
    else:
        v_b_new, hit_acc, hit_rate = bc.explicit_update(M_breve, rhs, s.v_breve, p.dt,
                                                        p.acc_bounds, p.rate_bounds)
    v_c_new, integral_new, sat_c_acc, sat_c_rate = com_update(
        x_c=err.com_pos_err, xd_c=err.com_vel_err, v_c=s.v_c, a_ff=gamma * gamma * ref.a_c,
        integral=s.integral, K=p.com_K, D=p.com_D, Ki=p.com_Ki, i_max=p.com_i_max,
        acc_bound=p.v_c_acc, rate_bound=p.v_c_rate, dt=p.dt)
    nu = np.empty(12)
    nu[0:3] = v_c_new
    nu[3:12] = v_b_new
    v_raw = matvec(np.ascontiguousarray(tr.gamma_inv), nu)
    sat_v_max = np.any(np.abs(v_raw) > p.v_max)
    v_new = np.minimum(np.maximum(v_raw, -p.v_max), p.v_max)
    return LoopResult(v=v_new, v_c=v_c_new, v_breve=v_b_new, integral=integral_new,
                      x_tilde=err.x_tilde, v_breve_des=err.v_breve_des, mu_max=mu_max,
                      hit_acc=hit_acc, hit_rate=hit_rate, sat_v_c_acc=sat_c_acc,
                      sat_v_c_rate=sat_c_rate, sat_v_max=sat_v_max,
                      com_pos_err=err.com_pos_err)


@jit
def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two vectors in degrees."""
    c = dot(a, b) / math.sqrt(dot(a, a) * dot(b, b))
    # math.acos is the C library's acos compiled and in Python mode alike (NumPy's arccos may
    # run SIMD code chosen for the processor); degrees as Numba's and NumPy's x·(180/π), not
    # CPython's math.degrees, x/(π/180), which differs in the last bit.
    return math.acos(max(-1.0, min(1.0, c))) * (180.0 / math.pi)


@jit
def pointing_errors(R_tb, p_b, R_te, p_e, aim) -> tuple[float, float]:
    """Bus pointing error (z_b against the line to the target at the origin) and camera
    boresight error (z_e against the line to the aim point), in degrees (eq. 18)."""
    return (angle_deg(np.ascontiguousarray(R_tb[:, 2]), -p_b),
            angle_deg(np.ascontiguousarray(R_te[:, 2]), aim - p_e))


@jit
def state_is_finite(q, v, v_breve, v_c) -> bool:
    """True when every entry of the carried state is finite."""
    for a in (q, v, v_breve, v_c):
        for x in a:
            if not np.isfinite(x):
                return False
    return True


@jit
def write_row(row, s, tr, gamma, dt, out, u, pointing, boresight, coverage):
    """Log row k (``ROW_FIELDS``) by name: the state ``s`` at the start of the step, the
    transform's conditioning, γ, dt·μ_max, the loops' ``out`` (``LoopResult``), the commanded
    generalized force ``u`` (eq. 29; the plant of eq. 15 applies it as it is, the sampled-data
    plant overwrites ``u_applied`` and ``attitude_excursion_deg``), the pointing errors and the
    coverage fraction."""
    row[ROW_AT.tau] = s.tau
    row[ROW_AT.q] = s.q
    row[ROW_AT.v] = s.v
    row[ROW_AT.v_c] = s.v_c
    row[ROW_AT.v_breve] = s.v_breve
    row[ROW_AT.v_breve_des] = out.v_breve_des
    row[ROW_AT.x_tilde] = out.x_tilde
    row[ROW_AT.u_cmd] = u
    row[ROW_AT.u_applied] = u
    row[ROW_AT.s_min_G] = tr.s_min_G
    row[ROW_AT.kappa_G] = tr.kappa_G
    row[ROW_AT.s_min_J] = tr.s_min_J
    row[ROW_AT.kappa_J] = tr.kappa_J
    row[ROW_AT.gamma] = gamma
    row[ROW_AT.dt_mu_max] = dt * out.mu_max
    row[ROW_AT.pointing_err_deg] = pointing
    row[ROW_AT.boresight_err_deg] = boresight
    row[ROW_AT.com_err] = math.sqrt(dot(out.com_pos_err, out.com_pos_err))
    row[ROW_AT.coverage] = coverage
    # The update of eq. 15 turns the bus at a constant rate over the step: no excursion from
    # the geodesic between the instants (eq. 32). The sampled-data plant overwrites it.
    row[ROW_AT.attitude_excursion_deg] = 0.0
    row[ROW_AT.sat_omega_b_acc] = 1.0 if out.hit_acc[0] else 0.0
    row[ROW_AT.sat_omega_b_rate] = 1.0 if out.hit_rate[0] else 0.0
    row[ROW_AT.sat_nu_e_lin_acc] = 1.0 if out.hit_acc[1] else 0.0
    row[ROW_AT.sat_nu_e_lin_rate] = 1.0 if out.hit_rate[1] else 0.0
    row[ROW_AT.sat_nu_e_ang_acc] = 1.0 if out.hit_acc[2] else 0.0
    row[ROW_AT.sat_nu_e_ang_rate] = 1.0 if out.hit_rate[2] else 0.0
    row[ROW_AT.sat_v_c_acc] = 1.0 if out.sat_v_c_acc else 0.0
    row[ROW_AT.sat_v_c_rate] = 1.0 if out.sat_v_c_rate else 0.0
    row[ROW_AT.sat_v_max] = 1.0 if out.sat_v_max else 0.0


@jit
def controller_step(inputs, ref, ctrl, state, rows, k, coverage):
    """Step k of the mission from Pinocchio's outputs at (q_k, v_k) (eq. 22's order).

    ``inputs`` is a ``DynamicsInputs``; ``ref``, ``ctrl`` and ``state`` are the flat vectors of
    ``REFERENCE_FIELDS``, ``CONTROLLER_FIELDS`` and ``STATE_FIELDS``; ``coverage`` is a
    ``CoverageCounter``. Eqs. 2–9 and 19 (:func:`full_transform`), γ (eq. 20), both loops
    (:func:`loop_update`), the pointing errors and coverage (eq. 18); writes log row k
    (``ROW_FIELDS``) and advances ``state`` in place to step k + 1, all but q: its increment
    v_{k+1} dt is left in the ``dq`` field for Pinocchio's integrate. Returns whether the new
    state is finite.
    """
    p = read_params(ctrl)
    r = read_reference(ref)
    s = read_state(state)
    # Copies: C-ordered, as the kernels downstream are written for.
    pose = DynamicsInputs(R_tb=np.ascontiguousarray(inputs.R_tb).copy(), p_b=inputs.p_b.copy(),
                          R_te=np.ascontiguousarray(inputs.R_te).copy(), p_e=inputs.p_e.copy(),
                          J_e=inputs.J_e, dJ_e=inputs.dJ_e, M=inputs.M, C=inputs.C,
                          Ag=inputs.Ag, dAg=inputs.dAg)
    tr = full_transform(pose, p.mass, p.inverse_floor, p.inverse_damping, s.v)
    gamma = scale_by_svd(tr.s_min_G, p.ramp_low, p.ramp_high, p.ramp_floor)
    if p.derate_gain:  # the bus block of K̆ and D̆ scales with γ (eq. 20)
        p.k[0:3] *= gamma
        p.d[0:3] *= gamma
    out = loop_update(pose, tr, r, p, s, gamma, np.diag(p.k), np.diag(p.d))
    nu = np.empty(12)
    nu[0:3] = s.v_c
    nu[3:12] = s.v_breve
    nu_next = np.empty(12)
    nu_next[0:3] = out.v_c
    nu_next[3:12] = out.v_breve
    u = commanded_force(pose.M, pose.C, tr.gamma_inv, tr.gamma_dot, s.v, nu, nu_next, p.dt)
    pointing, boresight = pointing_errors(pose.R_tb, pose.p_b, pose.R_te, pose.p_e, r.aim)
    coverage.count[0] += mark_visible(coverage.points, coverage.normals, pose.p_e, pose.R_te,
                                      coverage.tan_half_fov, coverage.d_min, coverage.d_max,
                                      coverage.cos_max, coverage.seen)
    write_row(rows[k], s, tr, gamma, p.dt, out, u, pointing, boresight,
              coverage.count[0] / coverage.seen.size)

    state[STATE_AT.v] = out.v
    state[STATE_AT.v_c] = out.v_c
    state[STATE_AT.v_breve] = out.v_breve
    state[STATE_AT.tau] = s.tau + gamma * p.dt
    state[STATE_AT.integral] = out.integral
    state[STATE_AT.v_breve_des_prev] = out.v_breve_des
    state[STATE_AT.has_prev] = 1.0
    state[STATE_AT.dq] = out.v * p.dt
    return state_is_finite(s.q, out.v, out.v_breve, out.v_c)
