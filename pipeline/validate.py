"""``python -m pipeline validate SPEC``: check a spec and say what its run would cost.

The spec goes through the loader ``run`` uses (:func:`pipeline.spec.load_spec`), its robot
file through the simulator's loader (:func:`pipeline.sim.robot_file.load_robot_model`), and
its size through the budget ``run`` enforces (:func:`pipeline.budget.check_mission`); nothing
is simulated and nothing is written. A spec ``run`` would refuse is refused here with the same
one-line message (exit 2), so ``validate`` answers "will this start?" before a long run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pipeline.budget import ROW_FLOATS, Budget, Estimate, check_mission
from pipeline.sim.robot_file import RobotCard
from pipeline.sim.stability import DampingMode, ModeFixes
from pipeline.spec import Spec, load_spec

# The units of each gain block's damping gain (eq. 13).
GAIN_UNITS = {"bus": "N·m·s/rad", "cam_pos": "N·s/m", "cam_ori": "N·m·s/rad"}


@dataclass(frozen=True)
class Validation:
    """What ``validate`` found: the resolved spec, its cost, every damping mode at the start
    and the fixes of the fastest, and the robot card's closed forms (bus yaw, camera roll)."""

    spec: Spec
    estimate: Estimate
    budget: Budget
    log_bytes: int  # the log's rows before Parquet's compression (an upper bound on disk)
    card: RobotCard  # at q̄, with the spec's gains: μ_bus = D_b/I_zz,bus, μ_roll = D_o/I_roll
    modes: list[DampingMode]  # of M̆⁻¹D̆ at the start state, fastest first (eq. 21)
    fixes: ModeFixes  # of the fastest (eq. 24)

    @property
    def mu_bus(self) -> float:
        return self.card.mu_bus

    @property
    def dt_mu_bus(self) -> float:
        return self.spec.mission.dt * self.mu_bus


def validate_spec(spec_arg: str | Path, budget: Budget | None = None) -> Validation:
    """Load and check ``spec_arg`` as ``run`` would, without simulating; SpecError (exit 2)
    naming the field or file when ``run`` would refuse it."""
    from pipeline.sim.robot_file import load_robot_model

    spec = load_spec(spec_arg)
    model = load_robot_model(spec.robot_path, spec.robot.camera_frame,
                             spec.robot.bus_inertia_scale)
    import pinocchio as pin

    q = pin.neutral(model)
    q[7:] = spec.robot.q_bar
    budget = budget or Budget.from_environment()
    est = check_mission(spec, budget, str(spec_arg))
    from pipeline.sim.mission import Mission
    from pipeline.sim.stability import damping_modes, mode_fixes

    mission = Mission(spec)
    M, D, _, _ = mission.linearised_loop(mission.initial_state())
    return Validation(spec, est, budget, est.steps * ROW_FLOATS * 8, mission.robot.card(q),
                      damping_modes(M, D), mode_fixes(M, D, spec.mission.dt))


def _plant(p) -> str:
    """How the spec's plant moves between control instants (eq. 29)."""
    if p.model == "reduced":
        return "reduced (the simulator's update)"
    delay = f", {p.delay_steps} step of delay" if p.delay_steps else ""
    return f"sampled (forward dynamics under the held command, {p.substeps} RK4 steps{delay})"


def _size(x: float) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20)):
        if x >= scale:
            return f"{x / scale:.3g} {unit}"
    return f"{x / 2**10:.3g} KiB"


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.3g} s"
    if seconds < 7200:
        return f"{seconds / 60:.3g} min"
    return f"{seconds / 3600:.3g} h"


def report_lines(v: Validation) -> list[str]:
    """The lines ``validate`` prints, every number computed from the spec and the budget."""
    s, est, m = v.spec, v.estimate, v.spec.mission
    integ = s.controller.integrator
    stable = ("explicit: stable in this mode only below 2" if integ == "explicit"
              else "imex: the damping is implicit, no step bound")
    c = v.card
    return [*_cost_lines(v, s, est, m, integ), *_mode_lines(v, m.dt, integ),
            f"  bus-yaw damping mode (closed form): μ_bus = D_b/I_zz,bus = {v.mu_bus:.4g} 1/s, "
            f"dt·μ_bus = {v.dt_mu_bus:.3g} ({stable})",
            f"  camera-roll damping mode (closed form): μ_roll = D_o/I_roll = {c.mu_roll:.4g} "
            f"1/s, dt·μ_roll = {m.dt * c.mu_roll:.3g} (I_roll = {c.I_roll:.4g} kg·m² about the "
            f"last joint's axis; its CoM {c.roll_axis_offset:.2g} m and the camera "
            f"{c.roll_camera_offset:.2g} m from the axis, boresight |cos| "
            f"{c.roll_boresight_cos:.6f}: exact when both offsets are 0 and |cos| = 1)"]


def _mode_lines(v: Validation, dt: float, integ: str) -> list[str]:
    """Every damping mode at the start, the fastest named with the gain that sets it, and its
    fixes: the largest step and gain, stable and with the margin dt·μ ≤ 1 (eqs. 21, 24)."""
    from pipeline.analysis.theory import regime

    f = v.fixes
    fast = f.mode
    listed = ", ".join(f"{m.mu:.4g} ({m.name})" for m in v.modes)
    gain = f"controller.gains.{f.gain_block}.D"
    unit = GAIN_UNITS[f.gain_block]
    lines = [
        f"  damping modes at the start, μ of M̆⁻¹D̆ in 1/s (eq. 21), fastest first: {listed}",
        f"  fastest: {fast.name}, μ = {fast.mu:.4g} 1/s, dt·μ = {f.dt_mu:.3g}, its rate set by "
        f"{gain} = {f.gain:.4g} {unit} (share {fast.shares[fast.block]:.3f}); "
        + (f"explicit: {regime(f.dt_mu)} (stable below 2)" if integ == "explicit"
           else "imex: the damping is implicit, no step bound from it"),
    ]
    if integ != "explicit":
        return lines

    def gain_text(g: float | None) -> str:
        if g is not None:
            return f"{gain} at most {g:.4g} {unit}"
        return (f"no value of {gain} (with it at 0 the fastest mode still has dt·μ = "
                f"{dt * f.mu_without:.3g})")

    lines += [
        f"  fixes (stable, dt·μ < 2): mission.dt below 2/μ = {f.dt_stable:.4g} s, or "
        f"{gain_text(f.gain_stable)} at dt = {dt:g} s, or controller.integrator: imex",
        f"  with a margin (dt·μ ≤ 1: half the bound, and the bound itself under one step of "
        f"computation delay, z² − z + dt·μ = 0): mission.dt at most {f.dt_margin:.4g} s, or "
        f"{gain_text(f.gain_margin)} at dt = {dt:g} s",
    ]
    return lines


def _cost_lines(v: Validation, s: Spec, est: Estimate, m, integ: str) -> list[str]:
    return [
        f"{s.name}: valid spec (hash {s.spec_hash[:12]}), robot {s.robot.file}, "
        f"integrator {integ}, plant {_plant(m.plant)}",
        f"  steps:  {est.steps:,} (duration {m.duration:g} s / dt {m.dt:g} s)",
        f"  log:    {est.steps:,} rows of {ROW_FLOATS} numbers, at most "
        f"{_size(v.log_bytes)} before compression -> logs/{s.name}/run.parquet",
        f"  memory: about {_size(est.memory_bytes)} while running "
        f"(budget {_size(v.budget.memory_bytes)}, BREVE_MEMORY_BUDGET_GB)",
        f"  time:   at most about {_duration(est.seconds)} of simulation "
        f"(budget {_duration(v.budget.seconds)}, BREVE_TIME_BUDGET_H), not counting the "
        f"one-time compile of the kernels",
    ]


def validate_command(spec_arg: str) -> int:
    for line in report_lines(validate_spec(spec_arg)):
        print(line)
    return 0
