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

from pipeline.budget import Budget, Estimate, check_mission
from pipeline.shapes import Q
from pipeline.sim.margins import Latency, dominant_root, gain_margin, loop_gain, root_regime
from pipeline.sim.robot_file import RobotCard
from pipeline.sim.stability import GAIN_FIELDS, DampingMode, ModeFixes
from pipeline.spec import Spec, load_spec

# The units of each gain block's damping gain (eq. 13).
GAIN_UNITS = {"bus": "N·m·s/rad", "cam_pos": "N·s/m", "cam_ori": "N·m·s/rad",
              "null_space": "N·m·s/rad"}


@dataclass(frozen=True)
class Validation:
    """What ``validate`` found: the resolved spec, its cost, every damping mode at the start
    and the fixes of the fastest, and the robot card's closed forms (bus yaw, camera roll)."""

    spec: Spec
    estimate: Estimate
    budget: Budget
    row_floats: int  # the log row's width for this robot (pipeline/log_layout.py)
    log_bytes: int  # the log's rows before Parquet's compression (an upper bound on disk)
    card: RobotCard  # at q̄, with the spec's gains: μ_bus = D_b/I_zz,bus, μ_roll = D_o/I_roll
    modes: list[DampingMode]  # of M̆⁻¹D̆ at the start state, fastest first (eq. 21)
    fixes: ModeFixes  # of the fastest (eq. 24)
    fix: str  # what meets the spec's requirement on the loop as flown (eq. 35)

    @property
    def mu_bus(self) -> float:
        return self.card.mu_bus

    @property
    def dt_mu_bus(self) -> float:
        return self.spec.mission.dt * self.mu_bus


def validate_spec(spec_arg: str | Path, budget: Budget | None = None) -> Validation:
    """Load and check ``spec_arg`` as ``run`` would, without simulating; SpecError (exit 2)
    naming the field or file when ``run`` would refuse it."""
    from pipeline.sim.robot_file import load_spec_robot

    spec = load_spec(spec_arg)
    model = load_spec_robot(spec)
    import pinocchio as pin

    q = pin.neutral(model)
    q[Q.joints] = spec.robot.q_bar
    budget = budget or Budget.from_environment()
    est = check_mission(spec, budget, str(spec_arg))
    from pipeline.sim.mission import Mission
    from pipeline.sim.stability import damping_modes, mode_fixes

    mission = Mission(spec)
    s0 = mission.initial_state()
    M, D, _, _ = mission.linearised_loop(s0)
    row = mission.layout.row_size
    return Validation(spec, est, budget, row, est.steps * row * 8, mission.robot.card(q),
                      damping_modes(M, D), mode_fixes(M, D, spec.mission.dt),
                      mission.guard_fix(s0)[1])


def _plant(p) -> str:
    """How the spec's plant moves between control instants (eq. 29)."""
    if p.model == "reduced":
        return "reduced (the simulator's update)"
    latency = Latency.of(p)
    delay = f", {latency.words()}" if latency != Latency() else ""
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
    stable = _loop_words(integ, Latency.of(m.plant), m.dt * v.mu_bus)
    c = v.card
    return [*_cost_lines(v, s, est, m, integ), *_mode_lines(v, m.dt, integ),
            f"  bus-yaw damping mode: μ_bus = {v.mu_bus:.4g} 1/s at the start, "
            f"dt·μ_bus = {v.dt_mu_bus:.3g} ({stable}), from the {c.mu_bus_rule}; the bus body "
            f"is {', '.join(c.bus_links)} ({c.bus_mass:.4g} kg, I_zz,bus {c.I_zz_bus:.4g} "
            f"kg·m² about the first joint's axis: every link welded to the free joint)",
            f"  camera-roll damping mode (closed form): μ_roll = D_o/I_roll = {c.mu_roll:.4g} "
            f"1/s, dt·μ_roll = {m.dt * c.mu_roll:.3g} (I_roll = {c.I_roll:.4g} kg·m² about the "
            f"last joint's axis; its CoM {c.roll_axis_offset:.2g} m and the camera "
            f"{c.roll_camera_offset:.2g} m from the axis, boresight |cos| "
            f"{c.roll_boresight_cos:.6f}: exact when both offsets are 0 and |cos| = 1)",
            *([f"  continuous joints (no range; flown as one unwrapped angle each): "
               f"{', '.join(c.continuous_joints)}"] if c.continuous_joints else []),
            *([f"  warning: {c.light_bus}"] if c.light_bus else [])]


def _loop_words(integrator: str, latency: Latency, dt_mu: float) -> str:
    """A mode's loop as flown (eqs. 35, 41): its root's behaviour and the bound on dt·μ that
    keeps it stable with the plant's delay, the longest flown (g = dt·μ explicit,
    dt·μ/(1 + dt·μ) imex, below B)."""
    delay, fraction = latency.worst
    bound = gain_margin(1.0, delay, fraction)[0]
    z = dominant_root(loop_gain(dt_mu, integrator), delay, fraction)
    if integrator == "explicit":
        limit = f"stable below {bound:.3g}"
    else:
        limit = ("stable at any step" if bound >= 1.0 else
                 f"stable below {bound / (1.0 - bound):.3g}")
    return f"{integrator}, {latency.words()}: {root_regime(z)} ({limit})"


def _mode_lines(v: Validation, dt: float, integ: str) -> list[str]:
    """Every damping mode at the start, the fastest named with the gain that sets it, and what
    meets the spec's requirement on the loop as flown, its plant and delay (eqs. 21, 35)."""
    f = v.fixes
    fast = f.mode
    listed = ", ".join(f"{m.mu:.4g} ({m.name})" for m in v.modes)
    gain = GAIN_FIELDS[f.gain_block]
    unit = GAIN_UNITS[f.gain_block]
    lines = [
        f"  damping modes at the start, μ of M̆⁻¹D̆ in 1/s (eq. 21), fastest first: {listed}",
        f"  fastest: {fast.name}, μ = {fast.mu:.4g} 1/s, dt·μ = {f.dt_mu:.3g}, its rate set by "
        f"{gain} = {f.gain:.4g} {unit} (share {fast.shares[fast.block]:.3f}); "
        + _loop_words(integ, Latency.of(v.spec.mission.plant), f.dt_mu),
    ]
    return [*lines, "  " + v.fix]


def _cost_lines(v: Validation, s: Spec, est: Estimate, m, integ: str) -> list[str]:
    return [
        f"{s.name}: valid spec (hash {s.spec_hash[:12]}), robot {s.robot.file}, "
        f"integrator {integ}, plant {_plant(m.plant)}",
        f"  steps:  {est.steps:,} (duration {m.duration:g} s / dt {m.dt:g} s)",
        f"  log:    {est.steps:,} rows of {v.row_floats} numbers, at most "
        f"{_size(v.log_bytes)} before compression -> logs/{s.name}/run.parquet",
        f"  memory: about {_size(est.memory_bytes)} while running "
        f"(budget {_size(v.budget.memory_bytes)}, BREVE_MEMORY_BUDGET_GB)",
        f"  time:   at most about {_duration(est.seconds)} of simulation "
        f"(budget {_duration(v.budget.seconds)}, BREVE_TIME_BUDGET_H), not counting the "
        f"one-time compile of the kernels",
    ]


def explain_lines(spec_arg: str | Path) -> list[str]:
    """Where each key of the merged spec came from (``validate --explain``): the spec itself
    or an ``extends`` ancestor (JSON Merge Patch, RFC 7386), and what a ``null`` deleted."""
    from pipeline.spec import key_sources, resolve_spec_path

    path = resolve_spec_path(spec_arg)
    sources, deleted = key_sources(path)
    by_source: dict[str, list[str]] = {}
    for key, name in sources.items():
        by_source.setdefault(name, []).append(key)
    own = path.stem
    lines = [f"keys of {own} as merged (extends: JSON Merge Patch, RFC 7386; a key left out "
             f"takes its default):"]
    for name, keys in by_source.items():
        where = "set here" if name == own else f"inherited from {name}"
        lines.append(f"  {where}: {', '.join(keys)}")
    for key, name in deleted.items():
        lines.append(f"  deleted by {name} (null): {key}")
    return lines


def validate_command(spec_arg: str, explain: bool = False) -> int:
    for line in report_lines(validate_spec(spec_arg)):
        print(line)
    if explain:
        for line in explain_lines(spec_arg):
            print(line)
    return 0
