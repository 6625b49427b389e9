"""Budgets: work whose memory or time would exceed them is refused up front (exit 2).

Estimated from the spec alone, before anything is allocated:

- a mission holds its log in memory while it runs: steps × ``ROW_BYTES`` (the kernel's rows,
  the columns handed to Arrow, and the Parquet encoder's buffers, 3 copies of a row of
  ``ROW_SIZE`` floats), plus the target's points (7 numbers each);
- its time is steps × (``STEP_SECONDS`` + points × ``POINT_SECONDS``), the simulator's cost
  per step measured by ``make bench`` (about 90 µs, of which about 8 µs for 1,500 points),
  rounded up;
- a sweep is the product of its value lists (counted before any point is built), at most
  ``MAX_SWEEP_POINTS``, each point a mission within the budget, the time divided among the
  workers.

Memory: the least of half this machine's RAM, the memory limit of the process's cgroup, what
the address-space limit (``ulimit -v``, RLIMIT_AS, as cluster nodes set) leaves beyond the
address space the process has already reserved, and ``BREVE_MEMORY_BUDGET_GB`` if set
(:func:`memory_limit`). Time: 24 hours, or ``BREVE_TIME_BUDGET_H`` (documented in the README).

Files are read through :func:`pipeline.bounded_read.read_at_most`, which never reserves
more than the data read so far: a stream or a device (a FIFO, ``/dev/zero``) is read in
chunks and stops at its bound.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

from pipeline.errors import SpecError
from pipeline.log_layout import row_size
from pipeline.shapes import TASK_DOF, RobotShape

STEP_SECONDS = 1.5e-4  # s per step without the target (bench: ~8e-5), with margin
POINT_SECONDS = 1e-8  # s per target point and step (bench: ~5e-9), with margin
# The sampled-data plant (eq. 29) per RK4 substep, and its step's own work (measured: ~0.17 ms a
# substep of four ABA calls in Python; ~0.3 ms Γ of the new state and the attitude's excursion
# between the instants; 1.87 ms a step of 8 substeps in all), with margin.
SUBSTEP_SECONDS = 3e-4
HOLD_SECONDS = 5e-4
# The log row's width (pipeline/log_layout.py) for a six-joint arm: the budget is judged from
# the spec alone, before the robot file is read; each joint beyond six adds six floats and a
# redundant arm two limit flags (a seven-joint row is 8 % wider).
ROW_FLOATS = row_size(RobotShape(tuple(f"joint{i}" for i in range(TASK_DOF))))
ROW_BYTES = 3 * 8 * ROW_FLOATS
POINT_BYTES = 7 * 8
MAX_SWEEP_POINTS = 10_000
# The most samples a Monte Carlo or a power study may draw (counted before any is drawn): ten
# times the 10⁴ a cluster study is sized for (docs/montecarlo.md); p = 0.99999 at 90 % needs
# 230,258 (eq. 38b), which this refuses rather than draw for minutes and grow past memory.
MAX_SAMPLES = 100_000
DEFAULT_TIME_H = 24.0


@dataclass(frozen=True)
class Budget:
    memory_bytes: float
    seconds: float

    @classmethod
    def from_environment(cls) -> Budget:
        """The budget in force: the machine's and the process's limits (:func:`memory_limit`),
        lowered by the environment's override; the time budget or its override."""
        mem = _env_float("BREVE_MEMORY_BUDGET_GB")
        hours = _env_float("BREVE_TIME_BUDGET_H")
        limit = memory_limit()
        return cls(memory_bytes=min(limit, mem * 2**30) if mem is not None else limit,
                   seconds=3600.0 * (hours if hours is not None else DEFAULT_TIME_H))


@functools.cache
def memory_limit() -> float:
    """Bytes this process may use: the least of half the RAM, its cgroup's memory limit and
    what RLIMIT_AS leaves (the soft limit less the address space already reserved: Python,
    NumPy, LLVM and the libraries take some hundreds of MB of it before any data). Taken once
    per process, before its data: what the process reads later is inside the budget, not
    taken off it again."""
    import resource

    import psutil

    limits = [0.5 * psutil.virtual_memory().total]
    cgroup = cgroup_memory_limit()
    if cgroup is not None:
        limits.append(cgroup)
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        limits.append(max(soft - psutil.Process().memory_info().vms, 0))
    return float(min(limits))


def cgroup_memory_limit() -> float | None:
    """The least memory limit on this process's cgroup and its ancestors (v2 ``memory.max``
    of each level; v1 ``hierarchical_memory_limit``, which includes the parents', else
    ``memory.limit_in_bytes``), looked for under the cgroup's path and at the mount's root (a
    container's namespace shows its own cgroup there); None where there is none or it cannot
    be read."""
    from pathlib import Path

    try:
        lines = Path("/proc/self/cgroup").read_text().splitlines()
    except OSError:
        return None
    found: list[float] = []

    def number(text: str) -> float | None:
        text = text.strip()
        return float(text) if text.isdigit() and int(text) < 2**60 else None  # v1: "none" huge

    for line in lines:
        _, controllers, where = [*line.split(":", 2), "", ""][:3]
        parts = [p for p in where.strip("/").split("/") if p]
        if controllers == "":  # v2: one unified hierarchy, each level's memory.max
            root = Path("/sys/fs/cgroup")
            for k in range(len(parts), -1, -1):
                try:
                    x = number((root.joinpath(*parts[:k]) / "memory.max").read_text())
                except OSError:
                    continue
                if x is not None:
                    found.append(x)
        elif "memory" in controllers.split(","):
            root = Path("/sys/fs/cgroup/memory")
            for folder in (root.joinpath(*parts), root):
                try:
                    stat = (folder / "memory.stat").read_text()
                    x = next((number(ln.split()[1]) for ln in stat.splitlines()
                              if ln.startswith("hierarchical_memory_limit ")), None)
                    x = x if x is not None else number(
                        (folder / "memory.limit_in_bytes").read_text())
                except (OSError, IndexError):
                    continue
                if x is not None:
                    found.append(x)
                break
    return min(found) if found else None


def _env_float(name: str) -> float | None:
    text = os.environ.get(name)
    if text is None or text == "":
        return None
    try:
        value = float(text)
    except ValueError:
        raise SpecError(f"environment {name}={text!r}: not a number") from None
    if not math.isfinite(value) or value <= 0:
        raise SpecError(f"environment {name}={text!r}: must be a positive number")
    return value


@dataclass(frozen=True)
class Estimate:
    steps: int
    memory_bytes: float
    seconds: float


def mission_estimate(duration: float, dt: float, n_points: int, substeps: int = 0
                     ) -> Estimate:
    """Memory and time of one mission, from its duration, step, target size and the sampled
    plant's RK4 substeps per step (0: the simulator's update, no plant)."""
    steps = round(duration / dt)
    plant = HOLD_SECONDS + substeps * SUBSTEP_SECONDS if substeps else 0.0
    return Estimate(steps, steps * ROW_BYTES + n_points * POINT_BYTES,
                    steps * (STEP_SECONDS + n_points * POINT_SECONDS + plant))


def _gb(x: float) -> str:
    return f"{x / 2**30:.3g} GiB"


def _h(x: float) -> str:
    return f"{x / 3600:.3g} h"


def check_mission(spec, budget: Budget | None = None, where: str = "") -> Estimate:
    """SpecError naming the field when one mission of ``spec`` exceeds the budget."""
    budget = budget or Budget.from_environment()
    m, t = spec.mission, spec.target
    est = mission_estimate(m.duration, m.dt, t.n_points,
                           m.plant.substeps if m.plant.model == "sampled" else 0)
    src = where or spec.name
    if est.memory_bytes > budget.memory_bytes:
        field = ("target.n_points" if t.n_points * POINT_BYTES > est.steps * ROW_BYTES
                 else "mission.duration")
        raise SpecError(f"{src}: field {field}: the mission would need about "
                        f"{_gb(est.memory_bytes)} ({est.steps:,} steps, {t.n_points:,} target "
                        f"points), over the memory budget of {_gb(budget.memory_bytes)} "
                        f"(BREVE_MEMORY_BUDGET_GB)")
    if est.seconds > budget.seconds:
        field = ("target.n_points" if t.n_points * POINT_SECONDS > STEP_SECONDS
                 else "mission.duration")
        raise SpecError(f"{src}: field {field}: the mission would take about "
                        f"{_h(est.seconds)} ({est.steps:,} steps, {t.n_points:,} target "
                        f"points), over the time budget of {_h(budget.seconds)} "
                        f"(BREVE_TIME_BUDGET_H)")
    return est


def check_sweep_size(n_points: int, what: str) -> None:
    """SpecError when a sweep's grid has more points than ``MAX_SWEEP_POINTS``."""
    if n_points > MAX_SWEEP_POINTS:
        raise SpecError(f"{what}: the grid has {n_points:,} points, over the limit of "
                        f"{MAX_SWEEP_POINTS:,} a sweep may have")


def check_samples(n: int, what: str) -> None:
    """SpecError when a study would draw more than ``MAX_SAMPLES`` samples."""
    if n > MAX_SAMPLES:
        raise SpecError(f"{what}: {n:,} samples, over the limit of {MAX_SAMPLES:,} a study may "
                        "draw (the N a target implies grows as ln(1 − C)/ln p, eq. 38b)")


def check_study_time(seconds: float, n: int, workers: int, what: str,
                     budget: Budget | None = None, unit: str = "samples") -> None:
    """SpecError when ``n`` tasks (``unit``) estimated at ``seconds`` in all, shared among
    ``workers``, exceed the time budget."""
    budget = budget or Budget.from_environment()
    total = seconds / max(workers, 1)
    if total > budget.seconds:
        raise SpecError(f"{what}: {n:,} {unit} on {workers} workers would take about "
                        f"{_h(total)}, over the time budget of {_h(budget.seconds)} "
                        f"(BREVE_TIME_BUDGET_H)")


def check_sweep_time(per_point_seconds: float, n_points: int, workers: int, what: str,
                     budget: Budget | None = None) -> None:
    """SpecError when the sweep's points, shared among ``workers``, exceed the time budget."""
    check_study_time(per_point_seconds * n_points, n_points, workers, what, budget, "points")
