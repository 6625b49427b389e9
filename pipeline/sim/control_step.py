"""One controller step in one compiled call (eq. 22's update order), and the flat layouts it
reads and writes.

The mission loop (:mod:`pipeline.sim.mission_loop`, or the sampled-data plant's Python step)
computes the rigid-body terms, then calls :func:`controller_step` with them, the references,
the controller's parameters, the carried state and the log. A step computes some forty small
arrays; handed between Python and compiled code one by one, their boxing would cost several
times the terms themselves (architecture §7). So the state, the parameters
and the log row are flat float vectors whose layouts are named here, next to the code that
reads them (:mod:`pipeline.sim.layout`), sized by the robot's shape (:func:`step_layout`).
Inside, the kernels read and write them by name, through namedtuples built from the vectors
and each field's place, frozen as constants for every joint count (:data:`STEP_PLACES`; their
Numba type is the same for every shape, so one specialisation serves every arm).
"""

from __future__ import annotations

import functools
import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from pipeline.log_layout import row_fields
from pipeline.shapes import MAX_JOINTS, TASK_DOF, TASK_ERROR_SIZE, Q, RobotShape
from pipeline.sim import breve_controller as bc
from pipeline.sim.base_guidance import read_reference
from pipeline.sim.com_controller import com_update
from pipeline.sim.jit import jit
from pipeline.sim.layout import Layout, offsets, places
from pipeline.sim.linalg import dot, matvec
from pipeline.sim.plant import commanded_force
from pipeline.sim.rotations import attitude_error
from pipeline.sim.sampling import scale_by_svd
from pipeline.sim.target import mark_visible
from pipeline.sim.task_transform import full_transform


def state_fields(shape: RobotShape) -> Layout:
    """The carried state: what step k hands to step k + 1, and the increment v_{k+1} dt that
    q ⊕ δ turns into q_{k+1} (eq. 22). ``measure`` set: v_c and v̆ are not
    carried but measured at the step's start, ν = Γ(q) v (the sampled-data plant, eq. 29).
    ``gamma_vt``: the right singular vectors of the step's Γ, row-major, where the next step's
    SVD starts (eq. 19) when ``warm`` is set."""
    return (("q", shape.nq), ("v", shape.nv), ("v_c", 3), ("v_breve", shape.n_breve),
            ("tau", 1), ("integral", 3), ("v_breve_des_prev", shape.n_breve), ("has_prev", 1),
            ("measure", 1), ("gamma_vt", shape.nv * shape.nv), ("warm", 1), ("dq", shape.nv))


def controller_fields(shape: RobotShape) -> Layout:
    """The controller's parameters, from the spec and the robot (``controller_vector``): the
    stiffness gains of eq. 13 (on the task error x̃), the damping gains (on v̆, the null
    space's last, eq. 37f), the posture spring, the null-space stiffness, the integrator, the
    limits of eq. 16 (one per block of v̆), the CoM loop of eq. 12, the γ ramp of eq. 20 and
    the damped inverse of eq. 6."""
    blocks = len(shape.breve_blocks)
    return (("k", TASK_ERROR_SIZE), ("d", shape.n_breve), ("derate_gain", 1), ("k_posture", 1),
            ("q_bar", shape.n), ("k_null", 1), ("imex", 1), ("dt", 1), ("acc_bounds", blocks),
            ("rate_bounds", blocks), ("com_K", 1), ("com_D", 1), ("com_Ki", 1),
            ("com_i_max", 1), ("v_c_acc", 1), ("v_c_rate", 1), ("v_max", 1), ("ramp_low", 1),
            ("ramp_high", 1), ("ramp_floor", 1), ("mass", 1), ("inverse_floor", 1),
            ("inverse_damping", 1))


# Each field's place in the flat vectors (its index for a one-value field, its slice
# otherwise), one namedtuple per layout: the kernels take them as an argument, so one compiled
# specialisation serves every arm (the places' Numba type has no sizes in it). The field names
# are the same for every shape.
_SIX = RobotShape(tuple(f"j{i}" for i in range(6)))
StatePlaces = namedtuple("StatePlaces", [name for name, _ in state_fields(_SIX)])
RowPlaces = namedtuple("RowPlaces", [name for name, _ in row_fields(_SIX)])
ControllerPlaces = namedtuple("ControllerPlaces", [name for name, _ in controller_fields(_SIX)])
StepPlaces = namedtuple("StepPlaces", ["state", "row", "controller"])


@dataclass(frozen=True)
class StepLayout:
    """The step kernel's flat vectors for one robot shape: each layout, its slices by name
    (for Python) and its places (for the kernels)."""

    shape: RobotShape
    state_fields: Layout
    row_fields: Layout
    controller_fields: Layout

    @functools.cached_property
    def state(self) -> dict[str, slice]:
        return offsets(self.state_fields)

    @functools.cached_property
    def row(self) -> dict[str, slice]:
        return offsets(self.row_fields)

    @property
    def row_size(self) -> int:
        return sum(n for _, n in self.row_fields)

    @property
    def index(self) -> int:
        """This shape's places in :data:`STEP_PLACES`."""
        return self.shape.n - TASK_DOF

    @functools.cached_property
    def places(self) -> StepPlaces:
        return StepPlaces(places(StatePlaces, self.state_fields),
                          places(RowPlaces, self.row_fields),
                          places(ControllerPlaces, self.controller_fields))


@functools.lru_cache(maxsize=16)
def step_layout(shape: RobotShape) -> StepLayout:
    """The step's layouts for an arm of ``shape``."""
    if not TASK_DOF <= shape.n <= MAX_JOINTS:
        raise ValueError(f"{shape.n} arm joints: the step runs arms of {TASK_DOF} to "
                         f"{MAX_JOINTS}")
    return StepLayout(shape, state_fields(shape), row_fields(shape), controller_fields(shape))


# The places of every arm the step runs, by joint count, frozen into the kernels as one
# constant: the kernel takes the arm's index in it (``StepLayout.index``). Handed in from
# Python at each call, the places themselves (fifty-odd slices) cost Numba ~110 µs a call to
# type and unbox, half a step; an index costs nothing.
STEP_PLACES = tuple(
    step_layout(RobotShape(tuple(f"joint{i}" for i in range(n)))).places
    for n in range(TASK_DOF, MAX_JOINTS + 1))


# The bundles the kernels pass by name: the controller's parameters (flags as booleans), the
# carried state at the start of a step (all but ``dq``, which the step only writes), the task
# errors of eq. 14 and what the loops of one step return.
ControlParams = namedtuple("ControlParams", ControllerPlaces._fields)
StepState = namedtuple("StepState", [name for name in StatePlaces._fields if name != "dq"])
TaskErrors = namedtuple("TaskErrors", ["x_tilde", "J_x", "v_breve_des", "G_vc", "com_vel_err",
                                       "com_pos_err"])
LoopResult = namedtuple("LoopResult", ["v", "v_c", "v_breve", "integral", "x_tilde",
                                       "v_breve_des", "mu_max", "hit_acc", "hit_rate",
                                       "sat_v_c_acc", "sat_v_c_rate", "sat_v_max",
                                       "com_pos_err"])


@jit
def read_params(c, at):
    """The controller vector (``controller_fields``, places ``at``) by name. The arrays are
    copies: the step scales the gains in place."""
    return ControlParams(
        k=c[at.k].copy(), d=c[at.d].copy(), derate_gain=c[at.derate_gain] > 0.5,
        k_posture=c[at.k_posture], q_bar=c[at.q_bar].copy(), k_null=c[at.k_null],
        imex=c[at.imex] > 0.5, dt=c[at.dt], acc_bounds=c[at.acc_bounds].copy(),
        rate_bounds=c[at.rate_bounds].copy(), com_K=c[at.com_K], com_D=c[at.com_D],
        com_Ki=c[at.com_Ki], com_i_max=c[at.com_i_max], v_c_acc=c[at.v_c_acc],
        v_c_rate=c[at.v_c_rate], v_max=c[at.v_max], ramp_low=c[at.ramp_low],
        ramp_high=c[at.ramp_high], ramp_floor=c[at.ramp_floor], mass=c[at.mass],
        inverse_floor=c[at.inverse_floor], inverse_damping=c[at.inverse_damping])


@jit
def read_state(s, at):
    """The carried state (``state_fields``, places ``at``, but ``dq``) by name, as contiguous
    copies; ``gamma_vt`` as its square matrix."""
    nv = s[at.v].size
    return StepState(
        q=s[at.q].copy(), v=s[at.v].copy(), v_c=s[at.v_c].copy(),
        v_breve=s[at.v_breve].copy(), tau=s[at.tau], integral=s[at.integral].copy(),
        v_breve_des_prev=s[at.v_breve_des_prev].copy(), has_prev=s[at.has_prev] > 0.5,
        measure=s[at.measure] > 0.5, gamma_vt=s[at.gamma_vt].copy().reshape((nv, nv)),
        warm=s[at.warm] > 0.5)


@jit
def task_error_terms(R_tb, R_te, p_e, p_c, ref, gamma, v_c, n_breve):
    """x̃, J_x, v̆_des, G_vc, ẋ̃_c and the CoM position error against the references ``ref``
    (a ``Reference``) (eq. 14), as ``TaskErrors``, for a v̆ of ``n_breve`` components.

    x̃ = [2ε_b; p_e − p_e,des; 2ε_e], J_x = blockdiag(E_b, R_te, E_e),
    v̆_des = [R_bt γω_b,des; R_et γ(ṗ_e,des − ṗ_c,des); R_et γω_e,des; 0], G_vc = [0; R_et; 0; 0]
    (a redundant arm's null-space velocity has no reference: its rows are zero, eq. 37f).
    """
    x_b, E_b = attitude_error(R_tb, ref.R_b)
    x_o, E_e = attitude_error(R_te, ref.R_e)
    R_et = np.ascontiguousarray(R_te.T)
    R_bt = np.ascontiguousarray(R_tb.T)
    J_x = np.zeros((9, 9))
    J_x[0:3, 0:3] = E_b
    J_x[3:6, 3:6] = R_te
    J_x[6:9, 6:9] = E_e
    v_des = np.zeros(n_breve)
    v_des[0:3] = matvec(R_bt, gamma * ref.w_b)
    v_des[3:6] = matvec(R_et, gamma * (ref.v_e - ref.v_c))
    v_des[6:9] = matvec(R_et, gamma * ref.w_e)
    G_vc = np.zeros((n_breve, 3))
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
    n_breve = s.v_breve.size
    err = task_error_terms(pose.R_tb, pose.R_te, pose.p_e, tr.p_c, ref, gamma, s.v_c, n_breve)
    v_dot_des = ((err.v_breve_des - s.v_breve_des_prev) / p.dt if s.has_prev
                 else np.zeros(n_breve))
    M_breve = np.ascontiguousarray(tr.M_hat[3:, 3:])
    C_breve = np.ascontiguousarray(tr.C_hat[3:, 3:])
    rhs = bc.breve_rhs(M_breve, C_breve, tr.C_hat[3:, :3], tr.gamma_inv, s.v_breve, v_dot_des,
                       err, K_breve, D_breve, p.k_posture, s.q[Q.joints].copy(), p.q_bar,
                       p.k_null)
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
    nu = np.empty(3 + n_breve)
    nu[0:3] = v_c_new
    nu[3:] = v_b_new
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
def write_row(row, at, s, tr, gamma, dt, out, u, pointing, boresight, coverage):
    """Log row k (``row_fields``, places ``at``) by name: the state ``s`` at the start of the
    step, the transform's conditioning, γ, dt·μ_max, the loops' ``out`` (``LoopResult``), the
    commanded
    generalized force ``u`` (eq. 29; the plant of eq. 15 applies it as it is, the sampled-data
    plant overwrites ``u_applied`` and ``attitude_excursion_deg``), the pointing errors and the
    coverage fraction."""
    row[at.tau] = s.tau
    row[at.q] = s.q
    row[at.v] = s.v
    row[at.v_c] = s.v_c
    row[at.v_breve] = s.v_breve
    row[at.v_breve_des] = out.v_breve_des
    row[at.x_tilde] = out.x_tilde
    row[at.u_cmd] = u
    row[at.u_applied] = u
    row[at.s_min_G] = tr.s_min_G
    row[at.kappa_G] = tr.kappa_G
    row[at.s_min_J] = tr.s_min_J
    row[at.kappa_J] = tr.kappa_J
    row[at.gamma] = gamma
    row[at.dt_mu_max] = dt * out.mu_max
    row[at.pointing_err_deg] = pointing
    row[at.boresight_err_deg] = boresight
    row[at.com_err] = math.sqrt(dot(out.com_pos_err, out.com_pos_err))
    row[at.coverage] = coverage
    # The update of eq. 15 turns the bus at a constant rate over the step: no excursion from
    # the geodesic between the instants (eq. 32). The sampled-data plant overwrites it.
    row[at.attitude_excursion_deg] = 0.0
    # The limit flags (log_layout.limit_flags): each block's acceleration and rate bound, the
    # CoM loop's two and the v_max clip, then a redundant arm's null-space block's two.
    f = at.limit_flags.start
    for b in range(3):
        row[f + 2 * b] = 1.0 if out.hit_acc[b] else 0.0
        row[f + 2 * b + 1] = 1.0 if out.hit_rate[b] else 0.0
    row[f + 6] = 1.0 if out.sat_v_c_acc else 0.0
    row[f + 7] = 1.0 if out.sat_v_c_rate else 0.0
    row[f + 8] = 1.0 if out.sat_v_max else 0.0
    for b in range(3, out.hit_acc.size):
        row[f + 9 + 2 * (b - 3)] = 1.0 if out.hit_acc[b] else 0.0
        row[f + 10 + 2 * (b - 3)] = 1.0 if out.hit_rate[b] else 0.0


@jit
def controller_step(inputs, ref, ctrl, state, rows, k, coverage, shape_index):
    """Step k of the mission from the rigid-body terms at (q_k, v_k) (eq. 22's order).

    ``inputs`` is a ``DynamicsInputs``; ``ref``, ``ctrl`` and ``state`` are the flat vectors of
    ``REFERENCE_FIELDS``, ``controller_fields`` and ``state_fields`` of the arm whose places
    (and the row's) are ``STEP_PLACES[shape_index]``; ``coverage`` is a ``CoverageCounter``.
    Eqs. 2–9 and 19 (37 for a redundant arm, :func:`full_transform`), γ (eq. 20), both loops
    (:func:`loop_update`), the pointing errors and coverage (eq. 18); writes log row k
    (``row_fields``) and advances ``state`` in place to step k + 1, all but q: its increment
    v_{k+1} dt is left in the ``dq`` field for q ⊕ δ. Returns whether the new
    state is finite.
    """
    at = STEP_PLACES[shape_index]
    p = read_params(ctrl, at.controller)
    r = read_reference(ref)
    s = read_state(state, at.state)
    pose = inputs  # the rigid-body terms' own C-ordered arrays, fresh at every step
    # Γ's SVD from the step before's right vectors (eq. 19): two or three Jacobi sweeps
    # instead of seven or eight; the first step starts from the identity.
    start = s.gamma_vt if s.warm else np.empty((0, 0))
    tr = full_transform(pose, p.mass, p.inverse_floor, p.inverse_damping, s.v, start)
    st = at.state
    if s.measure:  # the sampled-data plant's state: the controller measures ν = Γ(q) v
        nu_measured = matvec(tr.gamma, s.v)
        state[st.v_c] = nu_measured[0:3]
        state[st.v_breve] = nu_measured[3:]
        state[st.measure] = 0.0
        s = read_state(state, st)
    gamma = scale_by_svd(tr.s_min_G, p.ramp_low, p.ramp_high, p.ramp_floor)
    if p.derate_gain:  # the bus block of K̆ and D̆ scales with γ (eq. 20)
        p.k[0:3] *= gamma
        p.d[0:3] *= gamma
    out = loop_update(pose, tr, r, p, s, gamma, np.diag(p.k), np.diag(p.d))
    nu = np.empty(3 + s.v_breve.size)
    nu[0:3] = s.v_c
    nu[3:] = s.v_breve
    nu_next = np.empty(nu.size)
    nu_next[0:3] = out.v_c
    nu_next[3:] = out.v_breve
    u = commanded_force(pose.M, pose.C, tr.gamma_inv, tr.gamma_dot, s.v, nu, nu_next, p.dt)
    pointing, boresight = pointing_errors(pose.R_tb, pose.p_b, pose.R_te, pose.p_e, r.aim)
    coverage.count[0] += mark_visible(coverage.points, coverage.normals, pose.p_e, pose.R_te,
                                      coverage.tan_half_fov, coverage.d_min, coverage.d_max,
                                      coverage.cos_max, coverage.seen)
    write_row(rows[k], at.row, s, tr, gamma, p.dt, out, u, pointing, boresight,
              coverage.count[0] / coverage.seen.size)

    state[st.v] = out.v
    state[st.v_c] = out.v_c
    state[st.v_breve] = out.v_breve
    state[st.tau] = s.tau + gamma * p.dt
    state[st.integral] = out.integral
    state[st.v_breve_des_prev] = out.v_breve_des
    state[st.has_prev] = 1.0
    state[st.gamma_vt] = tr.gamma_vt.ravel()
    state[st.warm] = 1.0
    state[st.dq] = out.v * p.dt
    return state_is_finite(s.q, out.v, out.v_breve, out.v_c)
