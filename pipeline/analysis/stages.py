"""The analysis of one log (architecture §3): stages 1–6, and stage 7 for a pair of logs.

Window rule: the analysis window is [window_start, end) with window_start = half the mission
by default, so start-up transients are excluded. Theory is evaluated at the representative
step (:func:`representative_step`): the step of median s_min_G among the window's steps whose
s_min_J is at or above the damped inverse's floor, where Γ⁻¹ is exact and M̆ is the robot's
reduced inertia; below the floor the damping distorts M̆, so such steps are counted and
reported, not used.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import NamedTuple

import numpy as np

from pipeline.analysis import schema as rs
from pipeline.analysis import signals, theory
from pipeline.analysis.directions import project_directions, rebuild_gamma, singular_directions
from pipeline.analysis.harm import harm, roll_smear
from pipeline.analysis.joint_ranges import joint_range_record
from pipeline.analysis.ringing import MIN_STEPS as RING_MIN_STEPS
from pipeline.analysis.schema import value_at
from pipeline.analysis.verdict import judge, mode_loops
from pipeline.errors import CheckFailed, LogError, SpecError
from pipeline.joint_ranges import JointRanges
from pipeline.log_layout import JOINT_EXCESS, LIMIT_FLAGS, OUTSIDE_JOINT_RANGE, limit_flags
from pipeline.logs import VerifiedLog
from pipeline.provenance.keys import analysis_version
from pipeline.shapes import V
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.margins import Latency, period_steps, requirement_fixes, root_regime
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.stability import (
    BUS_YAW_AXIS,
    ModeFixes,
    damping_modes,
    loop_stiffness,
    mode_fixes,
    mode_stiffness,
    position_jacobian,
)
from pipeline.spec import Spec, spec_differences

REQUIRED = ["step", "t", "q", "v", "s_min_G", "kappa_G", "s_min_J", "x_tilde", "dt_mu_max",
            "pointing_err_deg", "boresight_err_deg", "coverage", "u_applied",
            "attitude_excursion_deg", *LIMIT_FLAGS, JOINT_EXCESS, OUTSIDE_JOINT_RANGE]
# The same Γ and the same chain of SVDs as the simulator's: 0 on a whole simulated log; a few
# ε ‖Γ‖ (1e-16) for another source's σ; more only when the log or the robot changed.
PROVENANCE_TOL = 1e-10


@dataclass
class Window:
    start: int
    stop: int
    rule: str


MIN_WINDOW = 3  # steps: a lag-1 (eq. 25) and a second difference need three


def choose_window(n: int, dt: float, window_start: float | None, source: str = "log"
                  ) -> Window:
    if window_start is None:
        if n - n // 2 < MIN_WINDOW:
            raise LogError(f"{source}: {n} steps: the analysis window (its second half) holds "
                           f"{n - n // 2}, fewer than the {MIN_WINDOW} its statistics need")
        return Window(n // 2, n, "second half of the mission (after start-up transients)")
    if not np.isfinite(window_start):
        raise SpecError(f"--window-start {window_start}: not a finite number of seconds")
    start = round(window_start / dt)
    if window_start < 0 or n - start < MIN_WINDOW:
        raise LogError(f"window start {window_start} s leaves fewer than 3 steps of a "
                       f"{n * dt:g} s log")
    return Window(start, n, f"from {window_start:g} s to the end")


def least_mission_steps(window_start: float | None, dt: float) -> int:
    """The fewest mission steps whose analysis window (:func:`choose_window`'s rule) holds
    ``MIN_STEPS``, what a ring's verdict needs (eq. 36): the second half's ⌈n/2⌉, or the
    steps from ``window_start`` to the end."""
    if window_start is None:
        return 2 * RING_MIN_STEPS - 1
    return round(window_start / dt) + RING_MIN_STEPS


@dataclass(frozen=True)
class Representative:
    """The representative step of a window (its index in the window) and how it was found."""

    index: int
    rule: str
    below_floor: int  # window steps with s_min_J below the damped inverse's floor
    above_floor: bool  # whether the chosen step is at or above it


def _above_floor(s_min_J: np.ndarray, floor: float) -> tuple[bool, int, np.ndarray]:
    """(any step at or above the damped inverse's floor, how many below it, the steps a
    representative step is chosen among: those above it, else all, flagged)."""
    ok = s_min_J >= floor
    pool = np.flatnonzero(ok) if ok.any() else np.arange(s_min_J.size)
    return bool(ok.any()), int(np.count_nonzero(~ok)), pool


def representative_step(s_min_G: np.ndarray, s_min_J: np.ndarray, floor: float
                        ) -> Representative:
    """The step of median s_min_G among the window's steps with s_min_J ≥ floor (the lower
    median for an even count, so it is a step of the window). If every step lies below the
    floor, the median over all of them, flagged: the theory there uses a damped M̆."""
    above, below, pool = _above_floor(s_min_J, floor)
    order = pool[np.argsort(s_min_G[pool], kind="stable")]
    k = int(order[(order.size - 1) // 2])
    if above:
        rule = (f"step of median s_min_G among the window's {pool.size} steps with s_min_J ≥ "
                f"the damped inverse's floor {floor:g}" + (f" ({below} steps below it "
                                                             f"left out)" if below else ""))
    else:
        rule = (f"every one of the window's {below} steps has s_min_J below the damped "
                f"inverse's floor {floor:g}: step of median s_min_G over all of them, where "
                f"M̆ is distorted by the damping")
    return Representative(k, rule, below, above)


def representative_nearest(s_min_G: np.ndarray, s_min_J: np.ndarray, floor: float,
                           target: float) -> Representative:
    """The step of the window whose s_min_G is nearest ``target`` among its steps with s_min_J
    ≥ floor (all of them, flagged, if none is): the seed note's regime, "a representative
    near-singular step (s_min_G ~ 0.032)", taken where a mission flies it (issue 50). Ties go
    to the earlier step."""
    above, below, pool = _above_floor(s_min_J, floor)
    k = int(pool[np.argmin(np.abs(s_min_G[pool] - target))])
    rule = (f"step of s_min_G nearest {target:.6g} among the window's {pool.size} steps"
            + (f" with s_min_J ≥ the damped inverse's floor {floor:g}" if above else
               f", every one below the damped inverse's floor {floor:g} (M̆ distorted there)")
            + (f" ({below} steps below it left out)" if below and above else ""))
    return Representative(k, rule, below, above)


def require_provenance(path, prov: rs.Provenance) -> None:
    """CheckFailed unless σ_min of the rebuilt Γ matches the logged s_min_G on every step."""
    if prov.max_abs_s_min_G > PROVENANCE_TOL:
        raise CheckFailed(f"{path}: provenance: rebuilt σ_min(Γ) differs from logged s_min_G "
                          f"by {prov.max_abs_s_min_G:.3e} at step {prov.worst_step} "
                          f"(tolerance {PROVENANCE_TOL:g})")


def analyze_log(log: VerifiedLog, window_start: float | None = None,
                check: bool = True, s_min_G_target: float | None = None) -> rs.AnalysisRecord:
    """All single-log stages; returns the analysis record (the content of analysis.json).
    ``log``: a verified log, as the artefact store hands it out
    (:meth:`pipeline.store.door.ArtefactStore.open_log`)."""
    path, meta, spec = log.path, log.meta, log.spec
    if meta.origin != "simulated":  # its spec holds no controller: pipeline.analysis.imported
        raise LogError(f"{path}: an {meta.origin} log: its data stages are analyze_imported's")
    if meta.status == "diverged":
        return divergence_record(log)
    if meta.status != "complete":
        raise LogError(f"{path}: log marked {meta.status} at step {meta.failed_step}: "
                       f"{meta.error}")
    log.require(REQUIRED)
    n = log.rows
    dt = spec.mission.dt
    win = choose_window(n, dt, window_start, str(path))
    robot = GiordanoRobot(spec)

    prov, directions, dominant, nu_breve = direction_stages(robot, log, win, check)

    # The window's columns, but not q and x̃: stages 1–4 read those by row group or by step.
    flags = limit_flags(robot.shape)
    skip = ("x_tilde", "kappa_G", JOINT_EXCESS, OUTSIDE_JOINT_RANGE, *flags)
    cols = log.columns([*(c for c in REQUIRED if c not in skip),
                        *flags], win.start, win.stop)
    rep = (representative_step(cols["s_min_G"], cols["s_min_J"], robot.floor)
           if s_min_G_target is None else
           representative_nearest(cols["s_min_G"], cols["s_min_J"], robot.floor,
                                  s_min_G_target))
    th = theory_at_step(robot, spec, log, win.start + rep.index)
    at_rep = replace(th.record, rule=rep.rule, window_steps_below_floor=rep.below_floor,
                     at_or_above_floor=rep.above_floor, s_min_G_target=s_min_G_target)
    card = robot.card(th.q)

    # Stages 5 and 6: alignment of theory and data directions, per-step velocity jump.
    data_dir = signals.dominant_step_direction(cols["v"])
    jumps = signals.velocity_jumps(cols["v"])
    return rs.CompleteRecord(
        **_identity(log),
        window=rs.Window(start_step=win.start, stop_step=win.stop, rule=win.rule),
        provenance=prov,
        directions=directions,
        dominant=dominant,
        theory=at_rep,
        alignment=rs.Alignment(abs_cos=signals.abs_cos(th.direction, data_dir),
                               theory_direction=th.direction.tolist(),
                               data_direction=data_dir.tolist()),
        velocity_jump=rs.VelocityJump(median=float(np.median(jumps)),
                                      max=float(np.max(jumps))),
        bus_rate=bus_rate_statistics(cols["v"][:, V.omega_b], dt,
                                     spec.controller.limits.omega_b_acc),
        metrics=mission_metrics(cols, flags),
        harm=harm(cols["u_applied"], cols["v"], cols["q"], cols["attitude_excursion_deg"], dt),
        camera_roll=roll_smear(nu_breve[:, 8], dt, spec.camera.resolution_px,
                               spec.camera.fov_deg),
        prediction=judge(th.record.modes, np.asarray(th.record.M_breve), nu_breve, dt,
                         th.record.delay_steps, spec.controller.limits,
                         th.record.spectral_radius, spec.controller.null_space,
                         least_mission_steps(window_start, dt)),
        versions=meta.versions,
        robot=card,
        # The bus-yaw damping mode (eq. 21): dt·μ_bus and the bus inertia at which it is 2.
        # The sweep's predicted crossing I_zz,bus = dt·D_b/2 is the closed form's: off the
        # axis the bus yaw mixes with the other modes as the inertia changes (which mode has
        # the largest ω_b,z share switches), and no crossing is predicted.
        bus_mode=rs.BusMode(dt_mu_bus=dt * card.mu_bus,
                            critical_I_zz=(dt * card.D_b / 2 if card.bus_closed_form_holds
                                           else None)),
        mu_max_log=mu_max_along(log, dt, card.mu_bus_closed_form, robot.floor),
        modes_along=fastest_modes_along(robot, spec, log),
        joint_ranges=joint_range_record(log, JointRanges.of(robot.model), dt),
    )


def direction_stages(robot: GiordanoRobot, log: VerifiedLog, win: Window, check: bool = True
                     ) -> tuple[rs.Provenance, list[rs.Direction], rs.Dominant, np.ndarray]:
    """Stages 1–3 from q and v alone: Γ rebuilt at every step with the provenance check, the
    velocity projected on its singular directions in the window (eq. 26), each direction's
    lag-1 (eq. 25) and the dominant one (most step-to-step energy); and the window's reduced
    velocity ν̆ = (Γ v)[3:] as the data say it, for the modes' judgement (eq. 36)."""
    prov, y, sigma, nu_breve = rebuild_and_project(robot, log, win)
    if check:
        require_provenance(log.path, prov)
    bad = np.flatnonzero(~np.isfinite(y).all(axis=1))
    if bad.size:
        raise CheckFailed(f"{log.path}: the per-direction projection is not finite at step "
                          f"{win.start + int(bad[0])} (Γ's SVD failed there)")
    lag1 = signals.lag1_or_none(y)
    srms = signals.step_rms(y)
    dom = int(np.argmax(srms))
    directions = [
        rs.Direction(direction=i, sigma=float(np.median(sigma[:, i])),
                     rms=float(signals.rms(y[:, i])), step_rms=float(srms[i]),
                     lag1=lag1[i])
        for i in range(y.shape[1])
    ]
    top = directions[dom]
    energy = float(np.sum(srms**2))
    return prov, directions, rs.Dominant(
        index=dom, sigma=top.sigma, lag1=top.lag1, step_rms=top.step_rms,
        step_energy_share=float(srms[dom] ** 2 / energy) if energy > 0 else None), nu_breve


def fastest_mode_record(fixes: ModeFixes) -> rs.FastestMode:
    """The fastest damping mode, the gain block that sets it and its fixes (eqs. 21, 24)."""
    return rs.FastestMode(
        name=fixes.mode.name, mu=fixes.mode.mu, dt_mu=fixes.dt_mu,
        axis=fixes.mode.axis, is_bus_yaw=fixes.mode.axis == BUS_YAW_AXIS,
        gain_block=fixes.gain_block, share=float(fixes.mode.shares[fixes.mode.block]),
        gain=fixes.gain, dt_stable=fixes.dt_stable, dt_margin=fixes.dt_margin,
        gain_stable=fixes.gain_stable, gain_margin=fixes.gain_margin)


def _identity(log: VerifiedLog) -> dict:
    """The fields every record opens with: which log, which code."""
    spec = log.spec
    return dict(spec_name=spec.name, log=str(log.path), log_sha256=log.sha256,
                spec_hash=log.meta.spec_hash, sim_version=log.meta.sim_version,
                analysis_version=analysis_version(), integrator=spec.controller.integrator,
                dt=spec.mission.dt, n_steps=log.rows)


GROWTH_FLOOR = 1e-3  # rad/s: a step of ω_b above the smooth motion's (~1e-5) and rounding


def divergence_record(log: VerifiedLog) -> rs.DivergedRecord:
    """The divergence stage, the only one a ``diverged`` log gets (eqs. 22, 23): the growth
    of ω_b per step before the v_max clip, against Φ's dominant eigenvalue.

    The log is read up to its divergence step. x_k is ω_b along its direction of most
    step-to-step energy and d_k = x_{k+1} − x_k. The fit covers the steps with |d_k| at or
    above ``GROWTH_FLOOR`` whose update no clip has touched (before the first ``sat_v_max``);
    the measured factor is exp(slope) of log|d_k| by least squares, negative when d_k
    alternates in sign. Φ (both update orders) is evaluated at the fit's first step.
    """
    path, meta, spec = log.path, log.meta, log.spec
    log.require(REQUIRED)
    n = log.rows
    robot = GiordanoRobot(spec)
    prov, _, _, _ = rebuild_and_project(robot, log, Window(0, n, "the whole diverged log"))
    require_provenance(path, prov)
    flags = limit_flags(robot.shape)
    cols = log.columns(["v_breve", *flags])
    bound = np.zeros(n, dtype=bool)
    for f in flags:
        bound |= cols[f]
    first = int(np.argmax(bound)) if bound.any() else n - 1
    w_b = cols["v_breve"][: first + 1, 0:3]
    direction = signals.dominant_step_direction(w_b)
    d = np.diff(w_b @ direction)
    fit = np.flatnonzero(np.abs(d) >= GROWTH_FLOOR)
    if fit.size < 3 or np.any(np.diff(fit) != 1):
        raise LogError(f"{path}: diverged log without 3 consecutive steps of ω_b growing above "
                       f"{GROWTH_FLOOR:g} rad/s before a limit bound (step {first}): no growth "
                       f"factor to measure")
    k = fit.astype(float)
    slope = np.polyfit(k, np.log(np.abs(d[fit])), 1)[0]
    alternating = bool(np.all(np.sign(d[fit][1:]) != np.sign(d[fit][:-1])))
    factor = float(np.exp(slope) * (-1.0 if alternating else 1.0))
    th = theory_at_step(robot, spec, log, int(fit[0]))
    sim = th.record.eig_dominant.real
    note = th.record.note_order.eig_dominant.real
    return rs.DivergedRecord(
        **_identity(log), status="diverged", diverged_step=meta.failed_step, error=meta.error,
        note=f"a diverged log, read up to its divergence step {meta.failed_step}: only "
             f"the divergence stage runs on it",
        provenance=prov,
        divergence=rs.Divergence(
            rule="ω_b along its dominant step direction; |Δx| ≥ "
                 f"{GROWTH_FLOOR:g} rad/s before the first limit flag; log-linear fit",
            direction=direction.tolist(), first_limit_step=first,
            fit_steps=[int(fit[0]), int(fit[-1]) + 1], alternating=alternating,
            growth_factor=factor, predicted=sim, predicted_note_order=note,
            ratio=factor / sim, ratio_note_order=factor / note),
        joint_ranges=joint_range_record(log, JointRanges.of(robot.model), spec.mission.dt),
        theory=th.record,
        robot=robot.card(th.q),
    )


BATCH = 8192  # steps per batched SVD: its ~8 temporaries of 12×12 per step stay near 10 MB


def _batches(chunks, size: int = BATCH):
    """Split each row group's columns into batches of at most ``size`` steps."""
    for chunk in chunks:
        n = len(chunk["step"])
        for lo in range(0, n, size):
            yield {k: a[lo:lo + size] for k, a in chunk.items()}


def rebuild_and_project(robot: GiordanoRobot, log: VerifiedLog, win: Window
                        ) -> tuple[rs.Provenance, np.ndarray, np.ndarray, np.ndarray]:
    """Stages 1–2, streamed by row group: provenance over every step, and the projections
    y (eq. 26), the singular values of Γ and the reduced velocity ν̆ = (Γ v)[3:] over the
    window. Every step's SVD starts from the step before's vectors, the first from the identity
    (about a third of the sweeps of a start from the identity): the simulator's own chain of
    SVDs, so on a whole simulated log (or an import's rebuilt σ) the rebuilt σ_min and κ are
    the logged ones to the bit."""
    worst, worst_step, worst_kappa = 0.0, -1, 0.0
    ys, sigmas, nus, V_prev, Vt_last = [], [], [], None, None
    for chunk in _batches(log.iter_columns(["step", "q", "v", "s_min_G", "kappa_G"])):
        gamma = rebuild_gamma(robot, chunk["q"])
        keep = (chunk["step"] >= win.start) & (chunk["step"] < win.stop)
        # Every step's SVD, each started from the step before's (one sequence over the log).
        sigma, Vt = singular_directions(gamma, Vt_last)
        if len(Vt):
            Vt_last = Vt[-1]
        if keep.any():
            part = project_directions(sigma[keep], Vt[keep], chunk["v"][keep], V_prev)
            V_prev = part.V_last
            ys.append(part.y)
            sigmas.append(part.sigma)
            nus.append(np.einsum("kij,kj->ki", gamma[keep][:, 3:, :], chunk["v"][keep]))
        # A NaN on either side is the worst difference there is, never "no difference".
        diff = np.abs(sigma[:, -1] - chunk["s_min_G"])
        diff[np.isnan(diff)] = np.inf
        if diff.size and diff.max() > worst:
            worst, worst_step = float(diff.max()), int(chunk["step"][np.argmax(diff)])
        with np.errstate(invalid="ignore", divide="ignore"):
            rel_k = np.abs(sigma[:, 0] / sigma[:, -1] - chunk["kappa_G"]) / chunk["kappa_G"]
        rel_k[np.isnan(rel_k)] = np.inf
        worst_kappa = max(worst_kappa, float(rel_k.max(initial=0.0)))
    if not ys:
        raise LogError(f"{log.path}: no row's step lies in the analysis window "
                       f"[{win.start}, {win.stop}): the step column is not 0, 1, …")
    prov = rs.Provenance(max_abs_s_min_G=worst, worst_step=worst_step,
                         max_rel_kappa_G=worst_kappa, tolerance=PROVENANCE_TOL)
    return prov, np.concatenate(ys), np.concatenate(sigmas), np.concatenate(nus)


class TheoryAtStep(NamedTuple):
    record: rs.Theory
    direction: np.ndarray  # the dominant mode's velocity direction, for the alignment
    q: np.ndarray  # the step's configuration


def _spectrum(m: theory.MapSpectrum) -> rs.SpectrumRecord:
    return rs.SpectrumRecord(eig_dominant=rs.Complex.of(m.dominant),
                          spectral_radius=m.spectral_radius,
                          eigenvalues=rs.Eigenvalues(real=m.eigenvalues.real.tolist(),
                                                     imag=m.eigenvalues.imag.tolist()))


class FlownLoop(NamedTuple):
    """The loop as flown at one logged step (eqs. 13, 21, 34, 41): what each theory of it
    reads."""

    T: object  # the robot's terms at the step (``Terms``)
    q: np.ndarray
    gamma: float
    K: np.ndarray
    D: np.ndarray
    M_b: np.ndarray
    J_x: np.ndarray
    K_x: np.ndarray
    mu: np.ndarray  # the damping rates, ascending (eq. 21)
    latency: Latency
    delay: int  # the longest delay flown (eq. 41): each margin falls as the delay grows
    fraction: float
    requirement: rs.Requirement


def flown_loop(robot: GiordanoRobot, spec: Spec, log: VerifiedLog, k: int) -> FlownLoop:
    """The loop at step k from the log's q, v and x̃ (eqs. 13, 21): M̆, the gains after the γ
    derate, the stiffness in the map's coordinates, the damping rates and the delay."""
    row = log.columns(["q", "v", "x_tilde", "s_min_G"], k, k + 1)
    T = robot.terms(row["q"][0], row["v"][0])
    gamma = conditioning_scale(T.s_min_G, spec.controller)
    ctrl, shape = spec.controller, robot.shape
    K, D = block_gains(ctrl, gamma, shape.null_space_dim)
    M_b = T.reduced_inertia
    J_x = position_jacobian(theory.task_jacobian(row["x_tilde"][0], T.R_te), shape.n_breve)
    K_x = loop_stiffness(J_x, K, T.gamma_inv, ctrl)
    mu = theory.damping_rates(np.ascontiguousarray(M_b), D)  # the step kernel's layout
    latency = Latency.of(spec.mission.plant)
    delay, fraction = latency.worst
    return FlownLoop(T, row["q"][0], gamma, K, D, M_b, J_x, K_x, mu, latency, delay, fraction,
                     rs.Requirement(**spec.requirements.model_dump()))


class SampleTheory(NamedTuple):
    """What a Monte Carlo sample's verdict reads of the theory at its step (eq. 39): the
    flown map's spectral radius, dt·μ_max, every mode's loop with its margins and the latency
    record; the same numbers as :func:`theory_at_step`'s, without its fix searches and
    critical step, which no sample's verdict reads."""

    step: int
    spectral_radius: float
    dt_mu_max: float
    modes: list
    latency: rs.LatencyRecord | None


def sample_theory(robot: GiordanoRobot, spec: Spec, log: VerifiedLog, k: int) -> SampleTheory:
    """:class:`SampleTheory` at step k (eqs. 34, 35, 41c)."""
    L = flown_loop(robot, spec, log, k)
    dt, integ, plant = spec.mission.dt, spec.controller.integrator, spec.mission.plant.model
    own = theory.spectrum(theory.flown_map(L.M_b, L.D, L.K_x, L.J_x, dt, integ, plant, L.delay,
                                           L.fraction))
    modes = mode_loops(L.M_b, L.D, dt, integ, L.delay, L.requirement,
                       mode_stiffness(L.K, spec.controller, robot.shape), L.fraction)
    return SampleTheory(k, own.spectral_radius, float(dt * L.mu[-1]), modes,
                        latency_record(L.M_b, L.D, L.K_x, L.J_x, dt, integ, L.latency,
                                       own.spectral_radius))


def theory_at_step(robot: GiordanoRobot, spec: Spec, log: VerifiedLog, k: int) -> TheoryAtStep:
    """Stage 4 at step k: μ, dt·μ_max, dt*, the map of the loop as flown for both integrators
    (eq. 34: the log's plant and delay), its dominant eigenvalue, every damping mode's loop with
    its margins (eq. 35), and the dominant mode's velocity direction for the alignment
    (eq. 27)."""
    L = flown_loop(robot, spec, log, k)
    T, gamma, K, D, M_b, J_x, K_x, mu = L.T, L.gamma, L.K, L.D, L.M_b, L.J_x, L.K_x, L.mu
    ctrl, shape = spec.controller, robot.shape
    dt, integ = spec.mission.dt, spec.controller.integrator
    plant, latency, delay, fraction = spec.mission.plant.model, L.latency, L.delay, L.fraction
    maps = {i: theory.spectrum(theory.flown_map(M_b, D, K_x, J_x, dt, i, plant, delay,
                                                fraction))
            for i in ("explicit", "imex")}
    own = maps[integ]
    # The same integrator under the note's fully explicit update order (eq. 22): the order
    # the seed note's published eigenvalue matches; no loop flies it.
    note_map = theory.spectrum(theory.discrete_map(M_b, D, K_x, J_x, dt, integ, "note"))
    e = own.dominant_vector[shape.n_breve:2 * shape.n_breve]
    e = np.real(e * np.exp(-1j * np.angle(e[np.argmax(np.abs(e))])))  # real direction
    direction = T.gamma_inv @ np.concatenate([np.zeros(3), e])
    dt_map = theory.map_critical_step(M_b, D, K_x, J_x, "explicit", plant=plant,
                                      delay=delay, fraction=fraction)
    req = L.requirement
    fixes = mode_fixes(M_b, D, dt)
    record = rs.Theory(
        rule="the given step",
        step=k, t=k * dt, s_min_G=T.s_min_G, gamma=gamma,
        mu=mu.tolist(), mu_max=float(mu[-1]), dt_mu_max=float(dt * mu[-1]),
        # Two critical steps (eq. 24): the damping-only bound 2/μ_max, and the flown map's
        # (explicit, stiffness, plant and delay included), where its spectral radius reaches 1.
        dt_star_damping=theory.critical_step(mu[-1]), dt_star_map=dt_map,
        regime=root_regime(own.dominant),
        eig_dominant=rs.Complex.of(own.dominant),
        spectral_radius=own.spectral_radius,
        period_steps=period_steps(own.dominant),
        update_order=flown_order(plant, latency),
        note_order=rs.NoteOrder(rule="note: x̃ advances with the old velocity e (fully explicit)",
                                eig_dominant=rs.Complex.of(note_map.dominant),
                                spectral_radius=note_map.spectral_radius),
        maps=rs.Maps(explicit=_spectrum(maps["explicit"]), imex=_spectrum(maps["imex"])),
        # The fastest damping mode named, the gain block that sets it and its fixes (eqs. 21,
        # 24): on the servicer the camera roll, not the bus yaw of the card's closed form.
        fastest_mode=fastest_mode_record(fixes),
        integrator=integ, dt=dt, plant=plant, delay_steps=latency.steps, requirement=req,
        modes=mode_loops(M_b, D, dt, integ, delay, req, mode_stiffness(K, ctrl, shape),
                         fraction),
        requirement_fixes=requirement_fixes(M_b, D, dt, integ, delay, req, fraction),
        M_breve=M_b.tolist(), D_breve=D.tolist(), K_breve=K.tolist(),
        J_x=J_x.tolist(), K_x=K_x.tolist(),
        latency=latency_record(M_b, D, K_x, J_x, dt, integ, latency, own.spectral_radius),
    )
    return TheoryAtStep(record, direction, L.q)


def flown_order(plant: str, latency: Latency) -> str:
    """The update the flown map follows (eqs. 22, 34, 41), in words."""
    if plant == "reduced":
        return "simulator's update: x̃ advances with the updated velocity e⁺ (eq. 22)"
    delay = latency.steps
    if latency.fraction or latency.jitter:
        judged = (f", judged at the longest ({sum(latency.worst):.3g} steps)"
                  if latency.jitter else "")
        return ("sampled-data plant: the command held over the step (zero-order hold), "
                f"arriving with {latency.words()}{judged}: the command before it held until "
                "then, x̃ advancing by the integral of e (eqs. 34, 41)")
    late = f", applied {delay} step{'s' if delay > 1 else ''} late" if delay else ""
    return ("sampled-data plant: the command held over the step (zero-order hold)" + late +
            ", x̃ advancing by the trapezoid of e (eq. 34)")


def latency_record(M_b: np.ndarray, D: np.ndarray, K_x: np.ndarray, J_x: np.ndarray,
                   dt: float, integrator: str, latency: Latency, worst_radius: float
                   ) -> rs.LatencyRecord | None:
    """A command arriving within the step, jittered or not (eq. 41): the map's radius at the
    earliest and the longest delay, and the mean-square radius of the loop whose arrival is
    drawn afresh each step (eq. 41c); None without one."""
    if not latency.fraction and not latency.jitter:
        return None
    low, high = latency.fraction, latency.fraction + latency.jitter
    terms = theory.split_map_terms(M_b, D, K_x, J_x, dt, integrator, latency.steps)
    earliest = theory.spectrum(terms[0] + low * terms[1] + low**2 * terms[2]).spectral_radius
    ms = theory.mean_square_radius(terms, low, high) if latency.jitter else worst_radius
    word = "stable" if ms < 1.0 else "unstable"
    verdict = (f"{word} in mean square: ρ_ms = {ms:.6g} with the arrival uniform on "
               f"[{low:.3g}, {high:.3g}) of a step after {latency.steps} step(s)"
               if latency.jitter else f"{word}: ρ = {ms:.6g} at {sum(latency.worst):.3g} "
               f"steps of delay")
    return rs.LatencyRecord(
        delay_fraction=latency.fraction, jitter_steps=latency.jitter,
        judged_delay_steps=latency.steps + high, earliest_radius=earliest,
        mean_square_radius=ms, verdict=verdict,
        rule="Φ(δ) = A₀ + δA₁ + δ²A₂ (eq. 41); ρ_ms = √ρ(E[Φ ⊗ Φ]) (eq. 41c), δ uniform")


# A step "at the bound" moves ω_b by dt·a_max within 1 %: the tolerance claim C16 gives the
# median step's ratio to dt·a_max.
AT_BOUND_REL = 0.01


def bus_rate_data(w_b: np.ndarray) -> rs.BusRateData:
    """The bus angular rate ω_b alone (eq. 25): lag-1 of its dominant step-to-step component
    x (ω_b projected on its direction of most step-to-step energy), its spread, and its
    alternating part a = (x_k − 2x_{k+1} + x_{k+2})/4 (exact for a period-2 signal), compared
    with its standard deviation to say how much of ω_b the ripple is; the median step
    ‖ω_b,k+1 − ω_b,k‖."""
    x = w_b @ signals.dominant_step_direction(w_b)
    alt = (x[:-2] - 2 * x[1:-1] + x[2:]) / 4
    steps = np.linalg.norm(np.diff(w_b, axis=0), axis=1)
    return rs.BusRateData(lag1=signals.lag1_or_none(x)[0], std=float(x.std()),
                          step_rms=float(signals.step_rms(x)),
                          alternating_rms=float(signals.rms(alt)),
                          step_median=float(np.median(steps)))


def bus_rate_statistics(w_b: np.ndarray, dt: float, acc_bound: float) -> rs.BusRate:
    """:func:`bus_rate_data`, and the step of ω_b against the acceleration saturation's
    dt·a_max (eq. 16). When the acceleration saturation binds (and the rate one does not),
    each step moves ω_b by exactly dt·a_max: a limit cycle held by that limit has
    step_ratio = 1.

    at_bound_share is the share of steps that move ω_b by dt·a_max within AT_BOUND_REL: the
    steps at the acceleration bound. The log's flag sat_omega_b_acc (‖request‖ > a_max) cannot
    tell them apart: a limit cycle held by the bound rides on it, and on some steps the request
    falls short of a_max by a few parts in 10⁷ (measured on the seed robot), the step then at
    the bound but the flag clear.
    """
    data = bus_rate_data(w_b)
    steps = np.linalg.norm(np.diff(w_b, axis=0), axis=1)
    bound = dt * acc_bound
    return rs.BusRate(**asdict(data), step_bound=bound, step_ratio=data.step_median / bound,
                      at_bound_share=float(np.mean(steps >= (1.0 - AT_BOUND_REL) * bound)))


def mu_max_along(log: VerifiedLog, dt: float, mu_bus: float, floor: float
                 ) -> rs.MuMaxAlong:
    """μ_max = dt_mu_max/dt over every logged step against the closed form μ_bus = D_b/I_zz,bus
    (eq. 21): its range, the largest relative deviation, and how near the log came to the
    singularity (the smallest s_min_J and s_min_G, and the damped inverse's floor, eq. 6)."""
    c = log.columns(["dt_mu_max", "s_min_J", "s_min_G"])
    mu = c["dt_mu_max"] / dt
    dev = np.abs(mu / mu_bus - 1.0)
    return rs.MuMaxAlong(min=float(mu.min()), max=float(mu.max()), closed_form=mu_bus,
                         max_rel_dev=float(dev.max()), worst_step=int(np.argmax(dev)),
                         steps=int(mu.size), s_min_J_min=float(c["s_min_J"].min()),
                         s_min_G_min=float(c["s_min_G"].min()), floor=floor,
                         steps_below_floor=int(np.sum(c["s_min_J"] < floor)))


MODE_SAMPLES = 60  # steps, evenly spaced over the log, at which every damping mode is named


def fastest_modes_along(robot: GiordanoRobot, spec: Spec, log: VerifiedLog,
                        samples: int = MODE_SAMPLES) -> rs.ModesAlong:
    """The fastest damping mode of M̆⁻¹D̆ named at ``samples`` steps spread evenly over the
    whole log (eq. 21), M̆ rebuilt from the logged (q, v), D̆ from the gains and the logged γ:
    how often each mode is the fastest, and the largest dt·μ_max with its step and mode. The
    online guard logs dt·μ_max at every step but not whose it is."""
    c = log.columns(["q", "v", "gamma"])
    n, dt = len(c["gamma"]), spec.mission.dt
    steps = np.unique(np.linspace(0, n - 1, min(samples, n)).round().astype(int))
    names, dt_mus = [], []
    for k in steps:
        T = robot.terms(c["q"][k], c["v"][k])
        _, D = block_gains(spec.controller, float(c["gamma"][k]), robot.shape.null_space_dim)
        fastest = damping_modes(T.reduced_inertia, D)[0]
        names.append(fastest.name)
        dt_mus.append(dt * fastest.mu)
    worst = int(np.argmax(dt_mus))
    return rs.ModesAlong(
        samples=int(steps.size),
        share={name: names.count(name) / len(names) for name in dict.fromkeys(names)},
        dt_mu_max=float(dt_mus[worst]), step_of_max=int(steps[worst]),
        name_at_max=names[worst], dt_mu_min=float(min(dt_mus)))


def mission_metrics(cols: dict[str, np.ndarray], flags: tuple[str, ...] = LIMIT_FLAGS
                    ) -> rs.Metrics:
    """Window metrics: pointing and boresight errors, coverage, and how often each limit
    (``flags``, the log's) bound."""
    return rs.Metrics(
        pointing_err_deg_max=float(cols["pointing_err_deg"].max()),
        boresight_err_deg_max=float(cols["boresight_err_deg"].max()),
        coverage_final=float(cols["coverage"][-1]),
        dt_mu_max_window_max=float(cols["dt_mu_max"].max()),
        limit_share={f: float(cols[f].mean()) for f in flags},
    )


COMPARE_ROWS = (
    ("dominant lag-1", ("dominant", "lag1")),
    ("dominant direction σ", ("dominant", "sigma")),
    ("dt·μ_max", ("theory", "dt_mu_max")),
    ("dt*_damping = 2/μ_max (s)", ("theory", "dt_star_damping")),
    ("dt*_map: spectral radius of Φ reaches 1 (s)", ("theory", "dt_star_map")),
    ("discrete-map dominant eigenvalue (real)", ("theory", "eig_dominant", "real")),
    ("discrete-map dominant eigenvalue (imag)", ("theory", "eig_dominant", "imag")),
    ("spectral radius", ("theory", "spectral_radius")),
    ("alignment |cos|", ("alignment", "abs_cos")),
    ("median ‖Δv‖ (m/s, rad/s mixed: v is [v_b; ω_b; q̇])", ("velocity_jump", "median")),
    ("bus rate ω_b: lag-1 of its dominant component", ("bus_rate", "lag1")),
    ("bus rate ω_b: alternating RMS (rad/s)", ("bus_rate", "alternating_rms")),
    ("provenance max |Δσ_min|", ("provenance", "max_abs_s_min_G")),
    ("bus torque: RMS (N·m)", ("harm", "bus_torque", "rms")),
    ("bus torque: period-2 amplitude (N·m)", ("harm", "bus_torque", "period2_amplitude")),
    ("bus torque: short-period peak to peak (N·m)",
     ("harm", "bus_torque", "short_period_peak_to_peak")),
    ("bus torque: reversals per second", ("harm", "bus_torque", "reversals_per_s")),
    ("joint torque: period-2 amplitude (N·m)", ("harm", "joint_torque", "period2_amplitude")),
    ("joint rate: reversals per second", ("harm", "joint_rate", "reversals_per_s")),
    ("bus attitude jitter (deg)", ("harm", "attitude", "jitter_deg")),
    ("bus attitude: short-period peak to peak (deg)",
     ("harm", "attitude", "short_period_peak_to_peak_deg")),
    ("max pointing error (deg)", ("metrics", "pointing_err_deg_max")),
    ("final coverage", ("metrics", "coverage_final")),
)


# What a causal test varies between its two runs (eq. 24's step, eq. 15's integrator); any
# other difference of their specs makes the other run another mission.
CAUSAL_KNOBS = ("mission.dt", "controller.integrator")


def compare(a: rs.CompleteRecord, b: rs.CompleteRecord, spec_a: dict, spec_b: dict
            ) -> rs.Comparison:
    """Stage 7: the two runs side by side, the lag-1 flip and the amplitude ratio, and what
    else their resolved specs ``spec_a`` and ``spec_b`` (the logs') differ in. ``b`` is kept
    whole, as analysed (the fields only a written record has are dropped)."""
    la, lb = a.dominant.lag1, b.dominant.lag1
    differs = [k for k in spec_differences(spec_a, spec_b) if k not in CAUSAL_KNOBS]
    return rs.Comparison(
        against=b.spec_name, against_log=b.log,
        # An undetermined lag-1 flips nothing: the sign of no motion is no evidence.
        lag1_flip=la is not None and lb is not None and bool(np.sign(la) != np.sign(lb)),
        amplitude_ratio=a.velocity_jump.median / b.velocity_jump.median,
        mission_differs=differs,
        coverage_diff_pp=(100 * abs(a.metrics.coverage_final - b.metrics.coverage_final)
                          if rs.same_mission(a, b, differs) else None),
        table=[{"quantity": label, a.spec_name: value_at(a, p), b.spec_name: value_at(b, p)}
               for label, p in COMPARE_ROWS],
        other=replace(b, schema=None, record_sha256=None, directions_sha256=None,
                      comparison=None),
    )
