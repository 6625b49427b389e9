"""One Monte Carlo sample: run its mission, judge it against the requirement, keep the record
(eq. 39).

The requirement a sample passes (every part from the mission spec and the Monte Carlo file):
- the run completes (a failed or diverged run fails);
- the map of the loop as flown (eq. 34: the sample's integrator, plant and delay, the longest
  when its command arrives within the step, eq. 41) has every eigenvalue inside the unit
  circle at the analysis' representative step, and with a jittered arrival the loop is stable
  in mean square (eq. 41c);
- every damping mode meets the spec's gain, phase and delay margins there (eq. 35);
- ω_b's period-2 amplitude (eq. 30, the largest of its three components) over the analysis
  window is at most ``ripple_max``.

The theory is the analysis' own (:func:`pipeline.analysis.stages.sample_theory`: the numbers
of ``theory_at_step`` a verdict reads, without its fix searches and critical step, at the
step :func:`representative_step` picks in the window :func:`choose_window` picks), on the log
the sample made, held in memory: a Monte Carlo of hundreds of missions keeps a small record
per sample, not its log. The record holds the log's digest (SHA-256 of its columns), so a
sample re-run alone (``montecarlo … --sample I``, which writes the log) is shown to make the
same bits.
"""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from pipeline.analysis.harm import period2_amplitude
from pipeline.analysis.stages import (
    bus_rate_data,
    choose_window,
    representative_step,
    sample_theory,
)
from pipeline.shapes import V
from pipeline.spec import Spec


@dataclass(frozen=True)
class SampleRecord:
    """What one sample did and whether it meets the requirement (eq. 39)."""

    sample: str
    index: int
    seed: list[int]
    spec_hash: str
    status: str  # the run's end: complete, failed, diverged
    error: str
    steps: int
    passes: bool
    fails: list[str]  # the parts of the requirement it misses
    step: int  # the step the theory is taken at (-1: none)
    spectral_radius: float
    mean_square_radius: float  # a jittered loop's (eq. 41c); NaN without jitter
    dt_mu_max: float
    gain_margin_db: float  # the least over the damping modes
    phase_margin_deg: float  # the least; -inf where a mode has no gain crossover
    delay_margin_steps: float  # the least, in steps of the sample's dt
    worst_mode: str  # the mode of least gain margin
    ripple: float  # rad/s: ω_b's period-2 amplitude over the window (NaN: no window)
    bus_rate_lag1: float  # NaN: undetermined
    log_digest: str
    seconds: float
    draws: dict[str, float]


class ColumnsLog:
    """A log's columns held in memory, read as a verified log is (``columns``)."""

    def __init__(self, columns: dict[str, np.ndarray]) -> None:
        self._columns = columns
        self.rows = len(columns["step"])

    def columns(self, names: list[str], start: int = 0, stop: int | None = None
                ) -> dict[str, np.ndarray]:
        return {n: self._columns[n][start:stop] for n in names}


def log_digest(columns: dict[str, np.ndarray]) -> str:
    """SHA-256 of a log's columns, in order: each name, dtype, shape and bytes."""
    h = hashlib.sha256()
    for name, values in columns.items():
        a = np.ascontiguousarray(values)
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode() + b"\0")
        h.update(a.tobytes())
    return h.hexdigest()


def run_sample(spec: Spec, index: int, seed: list[int], draws: dict[str, float],
               ripple_max: float) -> SampleRecord:
    """Run the sample's mission in memory and judge it (module docstring)."""
    from pipeline.sim.mission import Mission

    t0 = time.perf_counter()
    mission = Mission(spec)
    result = mission.run()
    return evaluate(spec, index, seed, draws, result.columns, result.status, result.error,
                    ripple_max, mission.robot, t0)


def judge_columns(sample, cols: dict[str, np.ndarray], status: str, error: str,
                  ripple_max: float) -> SampleRecord:
    """A sample's record from its log's columns (a log written by ``--sample I``)."""
    from pipeline.sim.robot import GiordanoRobot

    return evaluate(sample.spec, sample.index, list(sample.seed), sample.draws, cols, status,
                    error, ripple_max, GiordanoRobot(sample.spec), time.perf_counter())


def evaluate(spec: Spec, index: int, seed: list[int], draws: dict[str, float],
             cols: dict[str, np.ndarray], status: str, error: str, ripple_max: float, robot,
             t0: float) -> SampleRecord:
    """The record of a sample's run (module docstring)."""
    fails: list[str] = [] if status == "complete" else [f"run {status}"]
    nan = math.nan
    figures = dict(step=-1, spectral_radius=nan, mean_square_radius=nan, dt_mu_max=nan,
                   gain_margin_db=nan, phase_margin_deg=nan, delay_margin_steps=nan,
                   worst_mode="", ripple=nan, bus_rate_lag1=nan)
    if status == "complete":
        figures = judge_log(robot, spec, cols, fails, ripple_max)
    return SampleRecord(
        sample=spec.name, index=index, seed=list(seed), spec_hash=spec.spec_hash,
        status=status, error=error, steps=len(cols["step"]), passes=not fails,
        fails=fails, **figures, log_digest=log_digest(cols), seconds=time.perf_counter() - t0,
        draws=dict(draws))


def judge_log(robot, spec: Spec, cols: dict[str, np.ndarray], fails: list[str],
              ripple_max: float) -> dict:
    """The theory at the representative step and the data's ripple (module docstring);
    appends what the requirement misses to ``fails``."""
    log = ColumnsLog(cols)
    dt = spec.mission.dt
    win = choose_window(log.rows, dt, None, spec.name)
    rep = representative_step(cols["s_min_G"][win.start:win.stop],
                              cols["s_min_J"][win.start:win.stop], robot.floor)
    th = sample_theory(robot, spec, log, win.start + rep.index)
    if th.spectral_radius >= 1.0:
        fails.append("unstable mode")
    if th.latency is not None and not th.latency.mean_square_radius < 1.0:  # eq. 41c
        fails.append("unstable in mean square")
    gm = min(m.margins.gain_margin_db for m in th.modes)
    pms = [m.margins.phase_margin_deg for m in th.modes]
    pm = -math.inf if any(p is None for p in pms) else min(pms)
    dm = min(m.margins.delay_margin_s for m in th.modes) / dt
    for part, ok in (("gain margin", all(m.margins.meets_gain for m in th.modes)),
                     ("phase margin", all(m.margins.meets_phase for m in th.modes)),
                     ("delay margin", all(m.margins.meets_delay for m in th.modes))):
        if not ok:
            fails.append(part)
    w_b = cols["v"][win.start:win.stop, V.omega_b]
    ripple = float(np.max(period2_amplitude(w_b)))
    if not ripple <= ripple_max:  # NaN fails
        fails.append("ripple")
    lag1 = bus_rate_data(w_b).lag1
    worst = min(th.modes, key=lambda m: m.margins.gain_margin_db)
    jittered = th.latency is not None and th.latency.jitter_steps > 0
    return dict(step=th.step, spectral_radius=th.spectral_radius,
                mean_square_radius=th.latency.mean_square_radius if jittered else math.nan,
                dt_mu_max=th.dt_mu_max,
                gain_margin_db=gm, phase_margin_deg=pm, delay_margin_steps=dm,
                worst_mode=worst.name, ripple=ripple,
                bus_rate_lag1=math.nan if lag1 is None else lag1)


def record_dict(rec: SampleRecord) -> dict:
    return asdict(rec)
