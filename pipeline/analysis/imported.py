"""The data stages of an imported log (``pipeline.origin = imported``): what t, q and v
alone say, and the damping theory only where the user declares the controller.

Run on every imported log: Γ rebuilt from q (stage 1; its provenance check only against a
σ_min(Γ) the source logged itself, else not applicable: the import rebuilt the σ columns
from the same q), the per-direction projection, lag-1 and the dominant direction
(stages 2–3), the per-step velocity jump (stage 6), the bus rate's statistics and the
conditioning along the log. Run only with ``--controller SPEC`` (the gains, the integrator and
the step of the loop that flew the log): the damping modes at the representative step, dt·μ_max
and dt* (eqs. 21–23), the fastest mode, every mode's loop as the declared controller flew it
with its margins (eq. 35), and each mode's prediction against its own coordinate in the data
(eq. 36). Never run: the
18×18 map Φ (it needs the task error x̃ the controller held, which no imported log has), the
alignment (it needs Φ's mode), the mission metrics and the actuators' harm (their columns are
the simulator's). A prediction is never made from gains the log did not have.
"""

from __future__ import annotations

import numpy as np

from pipeline.analysis import schema as rs
from pipeline.analysis import signals, theory
from pipeline.analysis.joint_ranges import joint_range_record
from pipeline.analysis.stages import (
    bus_rate_data,
    choose_window,
    direction_stages,
    fastest_mode_record,
    least_mission_steps,
    representative_step,
)
from pipeline.analysis.verdict import judge, mode_loops
from pipeline.errors import SpecError
from pipeline.joint_ranges import JointRanges
from pipeline.log_layout import JOINT_EXCESS, OUTSIDE_JOINT_RANGE
from pipeline.logs import S_MIN_G_REBUILT, S_MIN_G_SOURCE, VerifiedLog
from pipeline.provenance.keys import analysis_version, file_digest
from pipeline.shapes import V
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.margins import Latency
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.stability import mode_fixes, mode_stiffness
from pipeline.spec import Spec

IMPORTED_COLUMNS = ["step", "t", "q", "v", "s_min_G", "kappa_G", "s_min_J", JOINT_EXCESS,
                    OUTSIDE_JOINT_RANGE]
UNDECLARED = "undeclared"


def controller_key(controller: Spec) -> str:
    """What a declared controller is, for reuse: its spec's hash and its robot file's."""
    return f"{controller.spec_hash}:{file_digest(controller.robot_path)[:16]}"


def check_controller(log: VerifiedLog, controller: Spec) -> None:
    """SpecError unless the declared controller flew this robot (its spec's robot file, camera
    frame and bus inertia are the log's) at the log's step, to the resolution the time base
    was checked to (the step from the end stamps, each within its resolution r and the
    jitter allowed J·dt: within 2(r + J·dt)/(N − 1))."""
    if (file_digest(controller.robot_path) != log.meta.robot_hash
            or controller.robot.camera_frame != log.spec.robot.camera_frame
            or controller.robot.bus_inertia_scale != log.spec.robot.bus_inertia_scale):
        raise SpecError(f"--controller {controller.name}: field robot: the spec's robot "
                        f"({controller.robot.file}, camera frame {controller.robot.camera_frame!r}"
                        f", bus inertia × {controller.robot.bus_inertia_scale:g}) is not the "
                        f"log's ({log.meta.robot_file}): not the loop that flew it")
    dt = log.spec.mission.dt
    time = log.meta.imported.get("time", {})
    res = float(time.get("resolution") or 0.0) + float(time.get("jitter_bound") or 0.0) * dt
    tol = max(2 * res / max(log.rows - 1, 1), 4 * np.finfo(float).eps * dt)
    if abs(controller.mission.dt - dt) > tol:
        raise SpecError(f"--controller {controller.name}: field mission.dt: "
                        f"{controller.mission.dt:g} s is not the log's step {dt:.9g} s: a "
                        f"prediction from another loop's step would not be this log's")


def analyze_imported(log: VerifiedLog, controller: Spec | None = None,
                     window_start: float | None = None) -> rs.ImportedRecord:
    """The data stages of an imported log, and with ``controller`` the damping theory."""
    log.require(IMPORTED_COLUMNS)
    if controller is not None:
        check_controller(log, controller)
    n, dt = log.rows, log.spec.mission.dt
    win = choose_window(n, dt, window_start, str(log.path))
    robot = GiordanoRobot(log.spec)
    # The provenance check is one only against a σ the source logged itself: σ columns the
    # import rebuilt from this q would agree with Γ rebuilt from it by construction.
    own_sigma = log.meta.imported.get("s_min_G_from") == S_MIN_G_SOURCE
    prov, directions, dominant, nu_breve = direction_stages(robot, log, win, check=own_sigma)
    cols = log.columns(["v", "s_min_G", "s_min_J", "kappa_G"], win.start, win.stop)
    jumps = signals.velocity_jumps(cols["v"])
    damping, prediction = None, None
    if controller is not None:
        rep = representative_step(cols["s_min_G"], cols["s_min_J"], robot.floor)
        damping = damping_theory(robot, log, controller, win.start + rep.index, rep.rule)
        prediction = judge(damping.modes, np.asarray(damping.M_breve), nu_breve, dt,
                           damping.delay_steps, controller.controller.limits, None,
                           controller.controller.null_space,
                           least_mission_steps(window_start, dt))
    imp = log.meta.imported
    return rs.ImportedRecord(
        spec_name=log.spec.name, log=str(log.path), log_sha256=log.sha256,
        spec_hash=log.meta.spec_hash, sim_version=log.meta.sim_version,
        analysis_version=analysis_version(),
        integrator=controller.controller.integrator if controller else UNDECLARED,
        dt=dt, n_steps=n,
        origin=rs.Origin(source=imp["source"], source_sha256=imp["source_sha256"],
                         format=imp["format"], robot_from=imp["robot_from"],
                         robot_file=log.meta.robot_file, robot_sha256=log.meta.robot_hash,
                         conventions=imp["conventions"],
                         consistency_median_ratio=imp["consistency"]["median_ratio"]),
        stages=stages_run(controller, own_sigma),
        window=rs.Window(start_step=win.start, stop_step=win.stop, rule=win.rule),
        provenance=prov if own_sigma else None, directions=directions, dominant=dominant,
        velocity_jump=rs.VelocityJump(median=float(np.median(jumps)), max=float(np.max(jumps))),
        bus_rate=bus_rate_data(cols["v"][:, V.omega_b]),
        conditioning=conditioning_along(log, robot.floor),
        damping=damping, prediction=prediction,
        versions=log.meta.versions or {},
        joint_ranges=joint_range_record(log, JointRanges.of(robot.model), dt),
    )


def stages_run(controller: Spec | None, own_sigma: bool) -> list[rs.StageRun]:
    """Which stages ran on the imported log, and why (the report shows it)."""
    data = "from t, q and v, which the log has"
    provenance = ("against the source's own σ_min(Γ) column (mapping field s_min_G)"
                  if own_sigma else
                  f"not applicable: the log's σ columns were {S_MIN_G_REBUILT}, so Γ rebuilt "
                  f"from the same q would agree by construction; a check needs the source's "
                  f"own σ_min(Γ) (mapping field s_min_G)")
    declared = (f"from the controller declared with --controller ({controller.name}: its "
                f"gains, integrator and step)" if controller is not None else
                "not run: no controller declared (--controller SPEC); a prediction is never "
                "made from gains the log did not have")
    no_x = "not run: Φ needs the task error x̃ the controller held, which the log does not have"
    return [
        rs.StageRun(stage="1 provenance (Γ rebuilt from q)", ran=own_sigma, why=provenance),
        rs.StageRun(stage="2–3 directions, lag-1, dominant direction", ran=True, why=data),
        rs.StageRun(stage="6 per-step velocity jump", ran=True, why=data),
        rs.StageRun(stage="bus rate statistics and conditioning", ran=True, why=data),
        rs.StageRun(stage="4 damping modes, dt·μ_max, dt* (eqs. 21–23)",
                    ran=controller is not None, why=declared),
        rs.StageRun(stage="4 the discrete map Φ (eq. 22)", ran=False, why=no_x),
        rs.StageRun(stage="5 mode alignment", ran=False, why="not run: it needs Φ's mode"),
        rs.StageRun(stage="mission metrics and the actuators' harm", ran=False,
                    why="not run: their columns are the simulator's, not in an imported log"),
    ]


def damping_theory(robot: GiordanoRobot, log: VerifiedLog, controller: Spec, k: int,
                   rule: str) -> rs.DampingTheory:
    """The damping modes at step k from the logged q and the declared gains (eqs. 21–23):
    D̆ at the γ the declared ramp gives at the rebuilt s_min_G."""
    row = log.columns(["q", "v"], k, k + 1)
    T = robot.terms(row["q"][0], row["v"][0])
    gamma = conditioning_scale(T.s_min_G, controller.controller)
    ctrl, shape = controller.controller, robot.shape
    K, D = block_gains(ctrl, gamma, shape.null_space_dim)
    M_b = T.reduced_inertia
    mu = theory.damping_rates(np.ascontiguousarray(M_b), D)
    dt, integ = log.spec.mission.dt, controller.controller.integrator
    latency = Latency.of(controller.mission.plant)
    delay, fraction = latency.worst  # the longest delay the declared loop flies (eq. 41)
    req = rs.Requirement(**controller.requirements.model_dump())
    return rs.DampingTheory(
        controller=controller.name, controller_hash=controller_key(controller), rule=rule,
        step=k,
        t=k * dt, s_min_G=T.s_min_G, gamma=gamma, mu=mu.tolist(), mu_max=float(mu[-1]),
        dt_mu_max=float(dt * mu[-1]), dt_star_damping=theory.critical_step(mu[-1]),
        fastest_mode=fastest_mode_record(mode_fixes(M_b, D, dt)),
        plant=controller.mission.plant.model, delay_steps=latency.steps, requirement=req,
        modes=mode_loops(M_b, D, dt, integ, delay, req, mode_stiffness(K, ctrl, shape),
                         fraction),
        M_breve=M_b.tolist(), D_breve=D.tolist())


def conditioning_along(log: VerifiedLog, floor: float) -> rs.Conditioning:
    """σ_min and κ of Γ and σ_min of J⊕ over the whole log (eq. 19), and the steps below the
    damped inverse's floor (eq. 6)."""
    c = log.columns(["s_min_G", "kappa_G", "s_min_J"])
    return rs.Conditioning(
        s_min_G_min=float(c["s_min_G"].min()), s_min_G_median=float(np.median(c["s_min_G"])),
        kappa_G_max=float(c["kappa_G"].max()), s_min_J_min=float(c["s_min_J"].min()),
        floor=floor, steps_below_floor=int(np.sum(c["s_min_J"] < floor)))
