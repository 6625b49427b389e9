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
from pipeline.spec import Spec, load_spec


@dataclass(frozen=True)
class Validation:
    """What ``validate`` found: the resolved spec, its cost and the bus-yaw mode's step."""

    spec: Spec
    estimate: Estimate
    budget: Budget
    log_bytes: int  # the log's rows before Parquet's compression (an upper bound on disk)
    mu_bus: float  # 1/s, D_b / I_zz,bus of the spec's robot (eq. 21)

    @property
    def dt_mu_bus(self) -> float:
        return self.spec.mission.dt * self.mu_bus


def validate_spec(spec_arg: str | Path, budget: Budget | None = None) -> Validation:
    """Load and check ``spec_arg`` as ``run`` would, without simulating; SpecError (exit 2)
    naming the field or file when ``run`` would refuse it."""
    from pipeline.sim.robot_file import load_robot_model, robot_card

    spec = load_spec(spec_arg)
    model = load_robot_model(spec.robot_path, spec.robot.camera_frame,
                             spec.robot.bus_inertia_scale)
    import pinocchio as pin

    q = pin.neutral(model)
    q[7:] = spec.robot.q_bar
    card = robot_card(model, q, spec.controller.gains.bus.D)
    budget = budget or Budget.from_environment()
    est = check_mission(spec, budget, str(spec_arg))
    return Validation(spec, est, budget, est.steps * ROW_FLOATS * 8, card.mu_bus)


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
    return [
        f"{s.name}: valid spec (hash {s.spec_hash[:12]}), robot {s.robot.file}, "
        f"integrator {integ}",
        f"  steps:  {est.steps:,} (duration {m.duration:g} s / dt {m.dt:g} s)",
        f"  log:    {est.steps:,} rows of {ROW_FLOATS} numbers, at most "
        f"{_size(v.log_bytes)} before compression -> logs/{s.name}/run.parquet",
        f"  memory: about {_size(est.memory_bytes)} while running "
        f"(budget {_size(v.budget.memory_bytes)}, BREVE_MEMORY_BUDGET_GB)",
        f"  time:   at most about {_duration(est.seconds)} of simulation "
        f"(budget {_duration(v.budget.seconds)}, BREVE_TIME_BUDGET_H), not counting the "
        f"one-time compile of the kernels",
        f"  bus-yaw damping mode: μ_bus = D_b/I_zz,bus = {v.mu_bus:.4g} 1/s, "
        f"dt·μ_bus = {v.dt_mu_bus:.3g} ({stable})",
    ]


def validate_command(spec_arg: str) -> int:
    for line in report_lines(validate_spec(spec_arg)):
        print(line)
    return 0
