"""One controller step in one compiled call (eq. 22's update order), and the flat layouts it
reads and writes.

The mission calls Pinocchio, then :func:`controller_step` with Pinocchio's outputs, the
references, the controller's parameters, the carried state and the log. A step computes some
forty small arrays; handed between Python and compiled code one by one, their boxing would
cost several times the Pinocchio calls themselves (architecture §7). So the state, the parameters
and the log row are flat float vectors whose layouts are named here, next to the code that
reads them.
"""

from __future__ import annotations

import numpy as np

from pipeline.sim import breve_controller as bc
from pipeline.sim.base_guidance import unpack_reference
from pipeline.sim.com_controller import com_update
from pipeline.sim.jit import jit
from pipeline.sim.limits import LIMIT_FLAGS
from pipeline.sim.rotations import attitude_error
from pipeline.sim.sampling import scale_by_svd
from pipeline.sim.target import mark_visible
from pipeline.sim.task_transform import full_transform


def _offsets(fields: tuple[tuple[str, int], ...]) -> dict[str, slice]:
    out, i = {}, 0
    for name, n in fields:
        out[name] = slice(i, i + n)
        i += n
    return out


def pack(fields: tuple[tuple[str, int], ...], values: dict) -> np.ndarray:
    """A flat vector laid out as ``fields`` from named values (arrays, numbers or booleans);
    fields not given are zero."""
    unknown = set(values) - {name for name, _ in fields}
    if unknown:
        raise ValueError(f"no field {sorted(unknown)} in the layout")
    out = np.zeros(sum(n for _, n in fields))
    for name, sl in _offsets(fields).items():
        if name in values:
            a = np.asarray(values[name], dtype=float).ravel()
            if a.size != sl.stop - sl.start:
                raise ValueError(f"{name}: {a.size} values for {sl.stop - sl.start} places")
            out[sl] = a
    return out


# The carried state: what step k hands to step k + 1, and the increment v_{k+1} dt that
# Pinocchio's integrate turns into q_{k+1} (eq. 22).
STATE_FIELDS = (("q", 13), ("v", 12), ("v_c", 3), ("v_breve", 9), ("tau", 1), ("integral", 3),
                ("v_breve_des_prev", 9), ("has_prev", 1), ("dq", 12))
STATE = _offsets(STATE_FIELDS)
STATE_SIZE = sum(n for _, n in STATE_FIELDS)

# One log row (architecture §6), written by the kernel; the mission fills ``t`` and ``step``.
ROW_FIELDS = (("tau", 1), ("q", 13), ("v", 12), ("v_c", 3), ("v_breve", 9), ("v_breve_des", 9),
              ("x_tilde", 9), ("s_min_G", 1), ("kappa_G", 1), ("s_min_J", 1), ("kappa_J", 1),
              ("gamma", 1), ("dt_mu_max", 1), ("pointing_err_deg", 1), ("boresight_err_deg", 1),
              ("com_err", 1), ("coverage", 1), *((f, 1) for f in LIMIT_FLAGS))
ROW = _offsets(ROW_FIELDS)
ROW_SIZE = sum(n for _, n in ROW_FIELDS)

# The controller's parameters, from the spec and the robot (see ``controller_vector``).
CONTROLLER_FIELDS = (("k", 9), ("d", 9), ("derate_gain", 1), ("k_posture", 1), ("q_bar", 6),
                     ("imex", 1), ("dt", 1), ("acc_bounds", 3), ("rate_bounds", 3),
                     ("com_K", 1), ("com_D", 1), ("com_Ki", 1), ("com_i_max", 1),
                     ("v_c_acc", 1), ("v_c_rate", 1), ("v_max", 1), ("ramp", 3), ("mass", 1),
                     ("floor", 1), ("damping", 1))
CONTROLLER_SIZE = sum(n for _, n in CONTROLLER_FIELDS)


@jit
def unpack_controller(c):
    """The fields of a controller vector, in the order of ``CONTROLLER_FIELDS``."""
    return (c[0:9].copy(), c[9:18].copy(), c[18] > 0.5, c[19], c[20:26].copy(), c[26] > 0.5,
            c[27], c[28:31].copy(), c[31:34].copy(), c[34], c[35], c[36], c[37], c[38], c[39],
            c[40], c[41], c[42], c[43], c[44], c[45], c[46])


@jit
def task_error_terms(R_tb, R_te, p_e, p_c, R_b_des, R_e_des, p_e_des, p_c_des, w_b_des,
                     v_e_des, v_c_des, w_e_des, gamma, v_c):
    """x̃, J_x, v̆_des, G_vc, ẋ̃_c and the CoM position error against the references (eq. 14).

    x̃ = [2ε_b; p_e − p_e,des; 2ε_e], J_x = blockdiag(E_b, R_te, E_e),
    v̆_des = [R_bt γω_b,des; R_et γ(ṗ_e,des − ṗ_c,des); R_et γω_e,des], G_vc = [0; R_et; 0].
    """
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


@jit
def state_is_finite(q, v, v_breve, v_c) -> bool:
    """True when every entry of the carried state is finite."""
    for a in (q, v, v_breve, v_c):
        for x in a:
            if not np.isfinite(x):
                return False
    return True


@jit
def controller_step(R_tb, p_b, R_te, p_e, J_e, dJ_e, M, C, Ag, dAg, ref, ctrl, state, rows, k,
                    points, normals, camera, seen, n_seen):
    """Step k of the mission from Pinocchio's outputs at (q_k, v_k) (eq. 22's order).

    Eqs. 2–9 and 19 (:func:`full_transform`), γ (eq. 20), both loops (:func:`loop_update`),
    the pointing errors and coverage (eq. 18); writes log row k (``ROW_FIELDS``) and advances
    ``state`` (``STATE_FIELDS``) in place to step k + 1, all but q: its increment v_{k+1} dt is
    left in the ``dq`` field for Pinocchio's integrate. ``n_seen`` (one integer) counts the
    target points in ``seen``. Returns whether the new state is finite.
    """
    (k_diag, d_diag, derate_gain, k_posture, q_bar, imex, dt, acc_bounds, rate_bounds, com_K,
     com_D, com_Ki, com_i_max, v_c_acc, v_c_rate, v_max, low, high, ramp_floor, mass, floor,
     damping) = unpack_controller(ctrl)
    (p_c_des, v_c_des, a_c_des, R_b_des, w_b_des, p_e_des, v_e_des, R_e_des, w_e_des,
     aim) = unpack_reference(ref)
    q, v = state[0:13].copy(), state[13:25].copy()
    v_c, v_breve, tau = state[25:28].copy(), state[28:37].copy(), state[37]
    integral, v_des_prev, has_prev = state[38:41].copy(), state[41:50].copy(), state[50] > 0.5
    # Copies: C-ordered, as the kernels downstream are written for.
    R_tb, p_b = np.ascontiguousarray(R_tb).copy(), p_b.copy()
    R_te, p_e = np.ascontiguousarray(R_te).copy(), p_e.copy()

    (_, p_c, _, _, _, _, s_min_J, kappa_J, _, gamma_inv, _, M_hat, C_hat, s_min_G,
     kappa_G) = full_transform(R_tb, p_b, R_te, p_e, J_e, M, mass, floor, damping, v, dJ_e,
                               Ag, dAg, C)
    gamma = scale_by_svd(s_min_G, low, high, ramp_floor)
    if derate_gain:  # the bus block of K̆ and D̆ scales with γ (eq. 20)
        k_diag[0:3] *= gamma
        d_diag[0:3] *= gamma
    (v_new, v_c_new, v_breve_new, integral_new, x_tilde, v_des, mu_max, hits,
     com_pos_err) = loop_update(
        R_tb, R_te, p_e, p_c, M_hat, C_hat, gamma_inv, R_b_des, R_e_des, p_e_des, p_c_des,
        w_b_des, v_e_des, v_c_des, w_e_des, a_c_des, gamma, v_c, v_breve, v_des_prev, has_prev,
        integral, q[7:].copy(), np.diag(k_diag), np.diag(d_diag), k_posture, q_bar, imex, dt,
        acc_bounds, rate_bounds, com_K, com_D, com_Ki, com_i_max, v_c_acc, v_c_rate, v_max)
    pointing, boresight = pointing_errors(R_tb, p_b, R_te, p_e, aim)
    n_seen[0] += mark_visible(points, normals, p_e, R_te, camera[0], camera[1], camera[2],
                              camera[3], seen)

    row = rows[k]
    row[0] = tau
    row[1:14] = q
    row[14:26] = v
    row[26:29] = v_c
    row[29:38] = v_breve
    row[38:47] = v_des
    row[47:56] = x_tilde
    row[56] = s_min_G
    row[57] = kappa_G
    row[58] = s_min_J
    row[59] = kappa_J
    row[60] = gamma
    row[61] = dt * mu_max
    row[62] = pointing
    row[63] = boresight
    row[64] = np.sqrt(com_pos_err @ com_pos_err)
    row[65] = n_seen[0] / seen.size
    for i in range(hits.size):
        row[66 + i] = 1.0 if hits[i] else 0.0

    state[13:25] = v_new
    state[25:28] = v_c_new
    state[28:37] = v_breve_new
    state[37] = tau + gamma * dt
    state[38:41] = integral_new
    state[41:50] = v_des
    state[50] = 1.0
    state[51:63] = v_new * dt
    return state_is_finite(q, v_new, v_breve_new, v_c_new)
