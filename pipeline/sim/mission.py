"""The inspection mission: one controller step after another, logged per step (architecture
§2).

Order of one step k (the discrete map of eq. 22 follows exactly this order):
1. terms of (q_k, v_k); γ_k from s_min_G; references at guidance time τ_k;
2. breve loop: v̆_{k+1} from v̆_k (explicit or imex); CoM loop: v_c,{k+1} from v_c,k;
3. v_{k+1} = clip(Γ⁻¹(q_k) [v_c,{k+1}; v̆_{k+1}], ±v_max);  q_{k+1} = q_k ⊕ v_{k+1} dt;
4. τ_{k+1} = τ_k + γ_k dt.
Row k of the log holds the state at the start of step k and what step k computed from it.

The reduced plant's steps run in compiled code, a slice of steps per call
(:mod:`pipeline.sim.mission_loop`: the rigid-body terms, the references, the compiled
``controller_step`` of :mod:`pipeline.sim.control_step`, then q ⊕ v dt); the sampled-data
plant's step calls the same terms and controller from Python, then its plant (eq. 29).
:meth:`Mission.step` runs that same code on one ``LoopState``, for the linearisation and the
checks.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from pipeline.joint_ranges import JointRanges, outside
from pipeline.log_layout import (
    JOINT_EXCESS,
    OUTSIDE_JOINT_RANGE,
    SCALAR_COLUMNS,
    limit_flags,
    vector_columns,
)
from pipeline.logs import ROW_GROUP, concat_columns
from pipeline.shapes import Q
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.base_guidance import REFERENCE_SIZE, BaseGuidance, Reference
from pipeline.sim.breve_controller import damping_rates
from pipeline.sim.control_step import (
    StepLayout,
    TaskErrors,
    controller_step,
    step_layout,
    task_error_terms,
)
from pipeline.sim.forward_dynamics import rigid_tree
from pipeline.sim.layout import pack
from pipeline.sim.limits import breve_bounds
from pipeline.sim.linalg import matvec
from pipeline.sim.margins import (
    Latency,
    Requirement,
    RequirementFix,
    gain_margin,
    requirement_fixes,
)
from pipeline.sim.mission_loop import (
    DIVERGED,
    FLOWN,
    NOT_FINITE,
    ReducedLoop,
    fly_reduced,
    new_clip,
)
from pipeline.sim.plant import held_command, integrate_held, integrate_split, limit_bus_torque
from pipeline.sim.robot import GiordanoRobot, Terms
from pipeline.sim.robot_file import check_null_space, check_posture_limits
from pipeline.sim.rotations import quat_from_matrix
from pipeline.sim.sensors import Measurement
from pipeline.sim.stability import (
    critical_step,
    damping_modes,
    loop_stiffness,
    map_critical_step,
    position_jacobian,
)
from pipeline.sim.target import CoverageCounter, build_target
from pipeline.spec import Spec

# Divergence criterion (eq. 16): the v_max clip binding on this many consecutive steps. The
# clip is the last guard, far above any commanded motion (50 against rate limits below 1), so
# a velocity that stays on it has run away: the run ends there, marked ``diverged``, rather
# than going on as a finite but meaningless "complete" log.
DIVERGENCE_STEPS = 3
# Steps per call of the compiled loop: Python in between (the progress bar, the log's chunks)
# costs a few microseconds a call, nothing per step.
SLICE_STEPS = 256
# What a step's compiled kernels raise on a state they cannot take (a division by zero, a
# singular solve): the run ends there, ``failed``, with the exception's words.
STEP_ERRORS = (np.linalg.LinAlgError, FloatingPointError, ValueError, ZeroDivisionError)


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
    gamma_vt: np.ndarray | None = None  # where the step's SVD of Γ starts (None: identity)


@dataclass
class MissionResult:
    columns: dict[str, np.ndarray] | None  # None when the run wrote them to a sink
    status: str
    failed_step: int | None = None
    error: str = ""
    warnings: list[str] = field(default_factory=list)
    rows: int = 0  # the rows of the log


def task_errors(T: Terms, ref: Reference, gamma: float, v_c: np.ndarray) -> TaskErrors:
    """Task errors and desired reduced velocity against the references (eq. 14).

    x̃ = [2ε_b; p_e − p_e,des; 2ε_e], J_x = blockdiag(E_b, R_te, E_e),
    v̆_des = [R_bt γω_b,des; R_et γ(ṗ_e,des − ṗ_c,des); R_et γω_e,des; 0],
    G_vc = [0; R_et; 0; 0] (the null-space rows of a redundant arm zero, eq. 37f).
    """
    return task_error_terms(T.R_tb, T.R_te, T.p_e, T.p_c, ref, gamma, v_c,
                            T.M_hat.shape[0] - 3)


class Mission:
    """Robot, target and guidance of one spec, and the step that advances them."""

    def __init__(self, spec: Spec, robot: GiordanoRobot | None = None):
        self.spec = spec
        self.robot = robot or GiordanoRobot(spec)
        check_null_space(spec, self.robot.shape)
        check_posture_limits(spec, self.robot.model)
        self.ranges = JointRanges.of(self.robot.model)  # flagged in the log (eq. 42)
        self.target = build_target(spec.target)
        self.dt = spec.mission.dt
        self.layout: StepLayout = step_layout(self.robot.shape)
        # The row's place of the v_max clip's flag: the divergence test's (eq. 16).
        self._clip_flag = (self.layout.row["limit_flags"].start
                           + limit_flags(self.layout.shape).index("sat_v_max"))
        self._reference = np.zeros(REFERENCE_SIZE)
        self._zero_q = np.zeros(self.robot.model.nq)
        self._zero_v = np.zeros(self.robot.model.nv)
        # The sampled-data plant's own Pinocchio data and its held command (eq. 29).
        self._plant_data = self.robot.model.createData()
        self._tree = rigid_tree(self.robot.model)  # the compiled plant's model (eq. 29)
        self._held: list[np.ndarray] | None = None
        self._arrivals: np.random.Generator | None = None  # ξ_k of eq. 41
        # The sampled plant's own state, which the controller sees through its sensors
        # (eq. 40); None: the state the controller holds (no sensors, or the first step).
        self._true: tuple[np.ndarray, np.ndarray] | None = None
        self._sensors: Measurement | None = None
        q_start = self.robot.start_configuration()
        T0 = self.robot.terms(q_start, np.zeros(self.robot.model.nv), dynamics=False)
        self.guidance = BaseGuidance(spec.guidance, T0.p_e - T0.p_c, T0.R_te[:, 0])
        ref0 = self.guidance.reference(0.0)
        q0 = q_start.copy()
        q0[0:3] = ref0.p_c - matvec(ref0.R_b, T0.p_bc)
        q0[Q.quat_tb] = quat_from_matrix(ref0.R_b)
        self.q0 = q0
        # The CoM starts on the orbit at the orbit's speed (the bus was inserted into it),
        # with the arm and bus at rest relative to it.
        gamma0 = conditioning_scale(T0.s_min_G, spec.controller)
        self.v_c0 = gamma0 * ref0.v_c

    def initial_state(self) -> LoopState:
        nv = self.robot.model.nv
        T0 = self.robot.terms(self.q0, np.zeros(nv), dynamics=False)
        v_c0 = self.v_c0.copy()
        # The bus's rate at the start (mission.initial_omega_b; zero: at rest): ω_b is v̆'s
        # first block (eq. 13), the arm still relative to the bus.
        v_breve0 = np.zeros(self.robot.shape.n_breve)
        v_breve0[0:3] = self.spec.mission.initial_omega_b
        v0 = matvec(T0.gamma_inv, np.concatenate([v_c0, v_breve0]))
        return LoopState(q=self.q0.copy(), v=v0, v_c=v_c0, v_breve=v_breve0)

    def critical_steps(self, s: LoopState) -> tuple[float, float | None]:
        """(dt*_damping, dt*_map) at state ``s`` for the spec's integrator (eq. 24): 2/μ_max,
        and the step at which the spectral radius of the map of the loop as flown (eq. 34:
        stiffness, plant and delay included) reaches 1 (None if none below 1 s). The online
        guard evaluates them once, at the start."""
        M, D, K_x, J_x = self.linearised_loop(s)
        # C-ordered, as the step kernel passes it: one compiled specialisation (the kernel
        # makes the same contiguous copy itself).
        mu_max = float(damping_rates(np.ascontiguousarray(M), D)[-1])
        integrator, plant = self.spec.controller.integrator, self.spec.mission.plant
        delay, fraction = Latency.of(plant).worst  # the longest delay flown (eq. 41)
        return critical_step(mu_max), map_critical_step(
            M, D, K_x, J_x, integrator, plant=plant.model, delay=delay, fraction=fraction)

    def guard_fix(self, s: LoopState) -> tuple[str, str]:
        """(the fastest damping mode's name, what meets the spec's requirement on the loop as
        flown) at state ``s`` (eqs. 21, 35): the guard's messages, off the per-step path."""
        M, D, _, _ = self.linearised_loop(s)
        spec = self.spec
        delay, fraction = Latency.of(spec.mission.plant).worst
        fixes = requirement_fixes(M, D, self.dt, spec.controller.integrator, delay,
                                  Requirement(**spec.requirements.model_dump()), fraction)
        return damping_modes(M, D)[0].name, fix_text(fixes, requirement_words(spec))

    def linearised_loop(self, s: LoopState) -> tuple[np.ndarray, ...]:
        """(M̆, D̆, K_x, J_x) at state ``s``: the reduced inertia, the damping gains after the γ
        derate, the stiffness in the map's position coordinates (x̃, and a redundant arm's
        null-space η) and their rate per v̆ (eqs. 13, 21, 22, 37f)."""
        robot, ctrl, shape = self.robot, self.spec.controller, self.robot.shape
        T = robot.terms(s.q, s.v)
        gamma = conditioning_scale(T.s_min_G, ctrl)
        J_x = position_jacobian(
            task_errors(T, self.guidance.reference(s.tau, T.p_b), gamma, s.v_c).J_x,
            shape.n_breve)
        K, D = block_gains(ctrl, gamma, shape.null_space_dim)
        K_x = loop_stiffness(J_x, K, T.gamma_inv, ctrl)
        return np.asarray(T.reduced_inertia), D, K_x, J_x

    def controller_vector(self) -> np.ndarray:
        """The spec's controller and the robot's constants as the step kernel reads them
        (``controller_fields``); built per run, so a changed ``robot.q_bar`` is honoured."""
        ctrl, robot = self.spec.controller, self.robot
        lim, com, ramp, null = ctrl.limits, ctrl.com, ctrl.base.conditioning, ctrl.null_space
        K, D = block_gains(ctrl, 1.0, robot.shape.null_space_dim)
        return pack(self.layout.controller_fields, {
            "k": np.diag(K), "d": np.diag(D), "derate_gain": ctrl.base.derate.gain,
            "k_posture": ctrl.gains.posture, "q_bar": robot.q_bar,
            "k_null": 0.0 if null is None else null.K,
            "imex": ctrl.integrator == "imex", "dt": self.dt,
            "acc_bounds": breve_bounds(lim, "acc", null),
            "rate_bounds": breve_bounds(lim, "rate", null),
            "com_K": com.K, "com_D": com.D, "com_Ki": com.Ki, "com_i_max": com.i_max,
            "v_c_acc": lim.v_c_acc, "v_c_rate": lim.v_c_rate, "v_max": lim.v_max,
            "ramp_low": ramp.low, "ramp_high": ramp.high, "ramp_floor": ramp.floor,
            "mass": robot.mass, "inverse_floor": robot.floor, "inverse_damping": robot.damping})

    def _reduced_loop(self, ctrl: np.ndarray, coverage: CoverageCounter) -> ReducedLoop:
        """The compiled loop's bundle for this run's controller vector and coverage."""
        if not self.guidance.params.size:  # a fixed reference: the vector as it leaves it
            self.guidance.reference_into(self._reference, 0.0, np.zeros(3))
        return ReducedLoop(self.robot.bundle, self.guidance.params, ctrl, coverage,
                           self.layout.index, self._clip_flag, DIVERGENCE_STEPS)

    def _advance(self, k: int, state: np.ndarray, rows: np.ndarray, ctrl: np.ndarray,
                 coverage: CoverageCounter) -> bool:
        """Step k: the terms at (q_k, v_k), the references, one call of the step kernel (row k
        and the state of step k + 1, but q), then q_{k+1} = q_k ⊕ v_{k+1} dt (the compiled
        loop's one step), or the sampled-data plant's motion under the held command (eq. 29).
        Whether the new state is finite."""
        if self.spec.mission.plant.model != "sampled":
            status, _ = fly_reduced(self._reduced_loop(ctrl, coverage), self._reference,
                                    state, rows, k, k + 1, new_clip())
            return status != NOT_FINITE
        ref, at = self._reference, self.layout.state
        # what the plant is at: (q_k, v_k), not what its sensors read
        q_k, v_k = (self._true if self._true is not None else
                    (state[at["q"]].copy(), state[at["v"]].copy()))
        inputs = self.robot.dynamics_inputs(state[at["q"]], state[at["v"]])
        self.guidance.reference_into(ref, float(state[at["tau"].start]), inputs.p_b)
        finite = controller_step(inputs, ref, ctrl, state, rows, k, coverage,
                                 self.layout.index)
        return finite and self._hold(state, rows[k], q_k, v_k)

    def _fly(self, start: int, stop: int, state: np.ndarray, rows: np.ndarray,
             ctrl: np.ndarray, coverage: CoverageCounter,
             clip: np.ndarray) -> tuple[int, int, str]:
        """Rows ``start`` to ``stop`` − 1 (:func:`~pipeline.sim.mission_loop.fly_reduced`'s
        contract, for either plant): (how the slice ended, its last row, why a step failed)."""
        if self.spec.mission.plant.model != "sampled":
            try:
                status, i = fly_reduced(self._reduced_loop(ctrl, coverage), self._reference,
                                        state, rows, start, stop, clip)
            except STEP_ERRORS as exc:  # a compiled kernel divides by zero
                return NOT_FINITE, int(clip[1]), f"{type(exc).__name__}: {exc}"
            return status, i, "non-finite state"
        for i in range(start, stop):
            try:
                finite = self._advance(i, state, rows, ctrl, coverage)
            except STEP_ERRORS as exc:
                return NOT_FINITE, i, f"{type(exc).__name__}: {exc}"
            if not finite:
                return NOT_FINITE, i, "non-finite state"
            clip[0] = clip[0] + 1 if rows[i, self._clip_flag] > 0.5 else 0
            if clip[0] >= DIVERGENCE_STEPS:
                return DIVERGED, i, ""
        return FLOWN, stop, ""

    def _hold(self, state: np.ndarray, row: np.ndarray, q_k: np.ndarray,
              v_k: np.ndarray) -> bool:
        """The sampled-data plant (eq. 29): the step's commanded generalized force (the row's
        ``u_cmd``, from the kernel), held (``delay_steps`` late, the bus torque saturated to
        ``bus_torque_max``) while the robot's forward dynamics move it over dt; with
        ``timing`` (eq. 41) it arrives δ_k·dt into the step, the one before held until then.
        The row's ``u_applied`` is what the plant received (its mean over a split step), and
        the controller then measures ν = Γ(q) v. Whether the state is finite."""
        model, data, plant = self.robot.model, self._plant_data, self.spec.mission.plant
        at, row_at = self.layout.state, self.layout.row
        tau = row[row_at["u_cmd"]].copy()
        if not math.isfinite(tau @ self._zero_v):  # 0·x: NaN exactly when x is not finite
            return False
        # The commands computed and not yet wholly applied, oldest first: d of them, and with
        # a command arriving within the step (eq. 41) the one it replaces there.
        waiting = plant.delay_steps + (plant.timing is not None)
        if waiting:
            if self._held is None:  # before the first command: the one that holds v_0
                self._held = [held_command(model, data, q_k, v_k, np.zeros_like(v_k))] * waiting
            self._held.append(tau)
            tau = self._held.pop(0)
        tau, _ = limit_bus_torque(tau, plant.bus_torque_max)
        if plant.timing is None:
            row[row_at["u_applied"]] = tau
            q, v, excursion = integrate_held(self._tree, q_k, v_k, tau, self.dt,
                                             plant.substeps)
        else:  # τ_{k−d−1} until the arrival δ_k·dt, then τ_{k−d} (eq. 41)
            arrival = self._arrival()
            after, _ = limit_bus_torque(self._held[0], plant.bus_torque_max)
            if arrival == 0.0:  # at the instant: the whole hold, the same bits as no timing
                row[row_at["u_applied"]] = after
                q, v, excursion = integrate_held(self._tree, q_k, v_k, after, self.dt,
                                                 plant.substeps)
            else:
                row[row_at["u_applied"]] = arrival * tau + (1.0 - arrival) * after  # the mean
                q, v, excursion = integrate_split(self._tree, q_k, v_k, tau, after, self.dt,
                                                  arrival, plant.substeps)
        if not (math.isfinite(q @ self._zero_q) and math.isfinite(v @ v)):
            return False
        row[row_at["attitude_excursion_deg"].start] = math.degrees(excursion)
        if self._sensors is not None:  # the controller's view of the plant (eq. 40)
            self._true = (q, v)
            q, v = self._sensors.measure(q, v)
        # ν = Γ(q) v is measured by the next step's kernel, from the Γ it computes anyway.
        state[at["q"]], state[at["v"]], state[at["measure"].start] = q, v, 1.0
        return True

    def _start_sensors(self) -> None:
        """A fresh plant state, sensor stream (eq. 40) and arrival stream (eq. 41) for a run or
        a single step."""
        sensors, timing = self.spec.mission.plant.sensors, self.spec.mission.plant.timing
        self._true = None
        self._sensors = None if sensors is None else Measurement(sensors, self.dt)
        self._arrivals = (None if timing is None or not timing.jitter else
                          np.random.default_rng(np.random.SeedSequence([timing.seed])))

    def _arrival(self) -> float:
        """δ_k: where within this step its command reaches the plant, in steps (eq. 41)."""
        timing = self.spec.mission.plant.timing
        if self._arrivals is None:
            return timing.delay_fraction
        return timing.delay_fraction + timing.jitter * float(self._arrivals.random())

    def step(self, s: LoopState) -> tuple[LoopState, dict]:
        """One controller step from state ``s`` (eq. 22's update order, the limits of eq. 16,
        the guard's dt·μ_max of eq. 21): the next state and the row to log. The same code as
        :meth:`run`'s steps; the row's coverage counts this step's view alone."""
        layout = self.layout
        state = pack(layout.state_fields, {
            "q": s.q, "v": s.v, "v_c": s.v_c, "v_breve": s.v_breve, "tau": s.tau,
            "integral": s.integral, "has_prev": s.v_breve_des_prev is not None,
            "v_breve_des_prev": (np.zeros(s.v_breve.size) if s.v_breve_des_prev is None
                                 else s.v_breve_des_prev),
            "warm": s.gamma_vt is not None,
            "gamma_vt": np.zeros(s.v.size ** 2) if s.gamma_vt is None else s.gamma_vt.ravel()})
        rows = np.zeros((1, layout.row_size))
        self._start_sensors()
        self._advance(0, state, rows, self.controller_vector(),
                      CoverageCounter.start(self.target, self.spec.camera))
        if state[layout.state["measure"].start]:  # the sampled plant's: ν = Γ(q) v here
            q, v = state[layout.state["q"]], state[layout.state["v"]]
            nu = matvec(self.robot.gamma_matrices(q[None, :])[0], v)
            state[layout.state["v_c"]], state[layout.state["v_breve"]] = nu[:3], nu[3:]
        f = {name: state[sl].copy() for name, sl in layout.state.items()}
        nxt = LoopState(q=f["q"], v=f["v"], v_c=f["v_c"], v_breve=f["v_breve"],
                        tau=float(f["tau"][0]), integral=f["integral"],
                        v_breve_des_prev=f["v_breve_des_prev"],
                        gamma_vt=f["gamma_vt"].reshape(s.v.size, s.v.size))
        cols = log_columns(layout, rows, self.ranges)
        return nxt, {name: value[0] for name, value in cols.items() if name not in ("t", "step")}

    def run(self, progress: bool = False,
            sink: Callable[[dict[str, np.ndarray]], None] | None = None,
            chunk: int = ROW_GROUP) -> MissionResult:
        """Run every step. A non-finite state ends the run with status ``failed`` (its log
        holds the steps before it); the v_max clip binding on ``DIVERGENCE_STEPS`` consecutive
        steps ends it with status ``diverged`` (its log holds the steps up to that one).

        With a ``sink`` the log's columns are handed to it ``chunk`` steps at a time (the last
        chunk possibly shorter or empty) and memory stays at one chunk; the result then holds
        no columns. Without one they are returned whole.
        """
        n = self.spec.n_steps
        size = max(1, min(n, chunk)) if sink is not None else max(n, 1)
        layout = self.layout
        rows = np.zeros((size, layout.row_size))
        parts: list[dict[str, np.ndarray]] = []
        out = sink if sink is not None else parts.append
        first = 0  # the step of rows[0]

        def flush(count: int) -> None:
            # Copies: the buffer is reused for the next chunk.
            out({k: np.array(v) for k, v in log_columns(layout, rows[:count], self.ranges,
                                                        self.dt, first).items()})

        def result(status: str, rows_logged: int, step: int | None = None,
                   error: str = "") -> MissionResult:
            cols = None if sink is not None else concat_columns(parts, list(parts[0]))
            return MissionResult(cols, status, step, error, warned, rows=rows_logged)

        s0 = self.initial_state()
        state = pack(layout.state_fields, {"q": s0.q, "v": s0.v, "v_c": s0.v_c,
                                    "v_breve": s0.v_breve, "integral": s0.integral})
        ctrl = self.controller_vector()
        coverage = CoverageCounter.start(self.target, self.spec.camera)
        explicit = self.spec.controller.integrator == "explicit"
        self._held = None  # a run starts with no command held (eq. 29)
        self._start_sensors()
        warned: list[str] = []
        # The guard (eq. 24): the map's critical step at the start, once per run (a search
        # over 18×18 eigenvalue problems, too costly per step), then dt·μ_max at every step
        # (explicit).
        dt_damping, dt_map = self.critical_steps(s0)
        integrator = self.spec.controller.integrator
        delay, fraction = Latency.of(self.spec.mission.plant).worst
        # Forward Euler's bound on dt·μ with the plant's delay: g at a gain margin of 1 (eqs.
        # 35, 41), at the longest delay flown.
        bound = gain_margin(1.0, delay, fraction)[0]
        if dt_map is not None and self.dt >= dt_map:
            mode, fix = self.guard_fix(s0)
            warned.append(map_warning(self.dt, dt_map, dt_damping, integrator, mode, fix))
        clip = new_clip()
        dt_mu_at = layout.row["dt_mu_max"].start
        # Overflow shows as a non-finite state, caught at the step it happens.
        with np.errstate(all="ignore"), tqdm(total=n, disable=not progress, unit="step",
                                             mininterval=0.5, desc=self.spec.name) as bar:
            k = 0
            while k < n:
                start = k - first
                stop = min(size, n - first, start + SLICE_STEPS)
                status, i, why = self._fly(start, stop, state, rows, ctrl, coverage, clip)
                flown = i if status == NOT_FINITE else i + 1 if status == DIVERGED else stop
                if explicit and not warned:  # the guard's one message, at the first step past
                    past = np.flatnonzero(rows[start:flown, dt_mu_at] > bound)
                    if past.size:
                        j = start + int(past[0])
                        mode, fix = self.guard_fix(row_state(layout, rows[j]))
                        warned.append(stability_warning(first + j, float(rows[j, dt_mu_at]),
                                                        bound, delay + fraction, mode, fix))
                if status == NOT_FINITE:
                    flush(i)
                    return result("failed", first + i, first + i, f"step {first + i}: {why}")
                if status == DIVERGED:
                    flush(i + 1)
                    fix = self.guard_fix(row_state(layout, rows[i]))[1]
                    return result("diverged", first + i + 1, first + i, divergence_message(
                        first + i, float(rows[i, dt_mu_at]), self.dt, fix))
                k = first + stop
                bar.update(stop - start)
                if stop == size and k < n:
                    flush(size)
                    first = k
        flush(n - first)
        return result("complete", n)


def log_columns(layout: StepLayout, rows: np.ndarray, ranges: JointRanges, dt: float = 0.0,
                first: int = 0) -> dict[str, np.ndarray]:
    """The log's columns (architecture §6, in the log's order) from the kernel's rows
    (``layout.row_fields``) of steps ``first``, ``first`` + 1, …; t = step·dt; and each arm
    joint's excess beyond its range with the step's flag (eq. 42)."""
    at = layout.row
    step = np.arange(first, first + len(rows), dtype=np.int64)
    cols = {c: rows[:, at[c]] for c in vector_columns(layout.shape)}
    cols |= {c: (step * dt if c == "t" else rows[:, at[c].start]) for c in SCALAR_COLUMNS}
    flags = at["limit_flags"].start
    cols |= {c: rows[:, flags + i] > 0.5 for i, c in enumerate(limit_flags(layout.shape))}
    cols[JOINT_EXCESS] = ranges.excess(cols["q"])
    cols[OUTSIDE_JOINT_RANGE] = outside(cols[JOINT_EXCESS])
    cols["step"] = step
    return cols


def row_state(layout: StepLayout, row: np.ndarray) -> LoopState:
    """The state at the start of a logged step, from its row (``layout.row_fields``)."""
    at = layout.row
    return LoopState(q=row[at["q"]].copy(), v=row[at["v"]].copy(), v_c=row[at["v_c"]].copy(),
                     v_breve=row[at["v_breve"]].copy(), tau=float(row[at["tau"].start]))


def requirement_words(spec: Spec) -> str:
    """The spec's requirement and the loop it is judged on (eq. 35), for messages."""
    r, plant = spec.requirements, spec.mission.plant
    loop = ("the simulator's update" if plant.model == "reduced" else
            f"the sampled-data plant with {Latency.of(plant).words()}")
    return (f"GM ≥ {r.gain_margin_db:g} dB, PM ≥ {r.phase_margin_deg:g}°, DM ≥ "
            f"{r.delay_margin_steps:g} step on {loop}")


def fix_text(fixes: list[RequirementFix], requirement: str) -> str:
    """What meets the requirement on the loop as flown, and what does not (eq. 35): the
    guard's and validate's fixes come from the theory the reports' fix tables read, so no
    message calls a change a fix that fails the requirement with the spec's delay."""
    if fixes[0].meets:
        return (f"The loop as flown meets the requirement ({requirement}): least GM "
                f"{fixes[0].gain_margin_db:.3g} dB, {fixes[0].worst_mode}")
    ok = [f.change for f in fixes[1:] if f.meets]
    short = [f"{f.change} (least GM {f.gain_margin_db:.3g} dB, {f.worst_mode})"
             for f in fixes[1:] if not f.meets]
    text = (f"Fix ({requirement}): " + "; or ".join(ok) if ok else
            f"No single change meets the requirement ({requirement})")
    return text + (f"; short of it: {'; '.join(short)}" if short else "")


def divergence_message(step: int, dt_mu_max: float, dt: float, fix: str) -> str:
    """Why a run was stopped as diverged, with the bound and the fixes (eqs. 16, 21, 35)."""
    return (f"step {step}: the velocity stayed on the v_max clip for {DIVERGENCE_STEPS} "
            f"consecutive steps; dt·μ_max = {dt_mu_max:.3g}, dt*_damping = 2/μ_max = "
            f"{2 * dt / dt_mu_max:.4g} s. {fix}")


def map_warning(dt: float, dt_map: float, dt_damping: float, integrator: str, mode: str,
                fix: str) -> str:
    """The online guard's message when mission.dt is past the map's critical step (eq. 24),
    naming the fastest damping mode and what meets the requirement on this loop (eq. 35)."""
    return (f"step 0: mission.dt = {dt:.4g} s is at or above the critical step dt*_map = "
            f"{dt_map:.4g} s (the spectral radius of the map of the loop as flown, eq. 34: "
            f"stiffness, plant and delay included, reaches 1; the damping-only bound "
            f"dt*_damping = 2/μ_max = {dt_damping:.4g} s, μ_max the {mode} mode's) under the "
            f"{integrator} integrator: the loop is unstable. {fix}")


def stability_warning(step: int, dt_mu_max: float, bound: float, delay: float, mode: str,
                      fix: str) -> str:
    """The online guard's one message (eqs. 21, 35): the mode at that step, forward Euler's
    bound with the plant's delay, and what meets the requirement."""
    return (f"step {step}: dt·μ_max = {dt_mu_max:.3g} > {bound:.3g} (forward Euler's bound "
            f"with {delay:g} step(s) of delay, eq. 35): the {mode} mode's velocity damping is "
            f"unstable. {fix}")
