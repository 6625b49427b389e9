"""The time base of a foreign log: a fixed step, checked to the stamps' own resolution, or
resampled on request (recorded), never silently.

A log is evenly sampled when every stamp lies within its resolution of t_0 + k·dt, with
dt = (t_{N−1} − t_0)/(N − 1): jitter, a dropped row (a gap of two steps) and a repeated stamp
all break it, and the first row that does is named. The imported log's ``t`` column is then
k·dt exactly, and t_0, dt and the largest deviation are recorded.

Resampling (``--resample DT``) puts the log on t_0 + k·DT: q by geodesic interpolation on the
configuration manifold (``pin.interpolate``) and v linearly between the bracketing rows. It
changes the data: a period-2 ripple at the source's step is not one at another step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.budget import Budget
from pipeline.errors import SpecError
from pipeline.importer.readers import IMPORT_COPIES

GAP_STEPS = 1.5  # a step this many times dt or longer is rows missing, not jitter
# Jitter of a quarter step or more lets a step of one row reach 1.5·dt, a dropped row's
# 2·dt − 2·jitter come down to it: the two could not be told apart.
MAX_JITTER = 0.25


@dataclass(frozen=True)
class TimeBase:
    t0: float  # s, the first stamp (the imported t column starts at 0)
    dt: float  # s
    max_deviation: float  # s, the largest |t_k − t_0 − k·dt|
    resolution: float  # s, how finely the stamps are written (the coarsest row's)
    resampled_from: int | None = None  # the source's row count, when resampled
    jitter_bound: float = 0.0  # the stamps' allowed jitter beyond their resolution, × dt
    rms_deviation: float = 0.0  # s, the RMS of |t_k − t_0 − k·dt|

    def record(self) -> dict:
        return {"t0": self.t0, "dt": self.dt, "max_deviation": self.max_deviation,
                "resolution": self.resolution, "resampled_from": self.resampled_from,
                "jitter_bound": self.jitter_bound, "rms_deviation": self.rms_deviation}


def even_time_base(t: np.ndarray, resolution: float | np.ndarray, what: str,
                   jitter: float = 0.0) -> TimeBase:
    """The log's fixed step, or a SpecError naming the first row off it. ``resolution``: how
    finely each stamp is written; row k may lie its own, t_0's and t_{N−1}'s resolution off
    t_0 + k·dt (dt is drawn from those two), and 2·``jitter``·dt more (a telemetry's stamps,
    each published late or early by up to jitter·dt, the line through the end stamps too: one
    row per step still, analysed at its own instants). A step over GAP_STEPS·dt (rows
    missing) or under the shortest a jittered step may be (a row too many) is refused
    whatever the resolution: a step of one row lies within (1 ± 2·jitter)·dt, the short bound
    dt/GAP_STEPS, or (1 − 2·jitter)·dt when the jitter allows shorter (above a sixth of a
    step); a row too many is also far off the line of the others (its deviation check)."""
    if not 0.0 <= jitter < MAX_JITTER:
        raise SpecError(f"--max-jitter {jitter:g}: a fraction of the step in [0, {MAX_JITTER:g})"
                        f": beyond it a jittered step cannot be told from a dropped row")
    n = len(t)
    if n < 3:
        raise SpecError(f"{what}: {n} rows: an analysis needs at least 3")
    if not np.all(np.isfinite(t)):
        raise SpecError(f"{what}: time stamp of row {int(np.argmin(np.isfinite(t)))} is not "
                        f"finite")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise SpecError(f"{what}: time stamps not increasing at row {k} ({t[k - 1]!r} then "
                        f"{t[k]!r})")
    dt = (t[-1] - t[0]) / (n - 1)
    res = np.broadcast_to(np.asarray(resolution, dtype=float), t.shape)
    # Jitter as the resolution: row k's own, and t_0's and t_{N−1}'s through the reference
    # line, ε_k − (1 − f) ε_0 − f ε_{N−1} with f = k/(N − 1): at most 2·jitter·dt.
    tol = res + res[0] + res[-1] + 2 * jitter * dt
    dev = np.abs(t - t[0] - np.arange(n) * dt)
    worst = float(dev.max())
    gap = steps / dt
    slack = (res[1:] + res[:-1]) / dt  # a step is known to its two stamps' resolutions
    shortest = min(1 / GAP_STEPS, 1 - 2 * jitter)
    odd = np.flatnonzero((gap > GAP_STEPS + slack) | (gap < shortest - slack))
    if odd.size or np.any(dev > tol):
        k = int(np.argmax(dev > tol))
        if odd.size:
            label = "a gap of" if gap[odd[0]] > 1 else "a row too many: a step of"
            detail = f"{label} {gap[odd[0]]:.3g} steps before row {odd[0] + 1}"
        else:  # no step out of range: the stamps wander, beyond their own resolution
            allowed = (f" and the jitter allowed ({jitter:g}·dt)" if jitter else
                       " (--max-jitter FRACTION analyses it at its own instants)")
            detail = (f"jitter: row {k} is {t[k] - t[0] - k * dt:+.3g} s off t0 + k·dt, "
                      f"beyond the stamps' resolution{allowed}")
        raise SpecError(f"{what}: uneven time base: {detail} (dt {dt:.6g} s, stamps written "
                        f"to {float(res.max()):.2g} s; steps from {steps.min():.6g} to "
                        f"{steps.max():.6g} s): give --resample DT to resample (recorded), "
                        f"nothing is resampled silently")
    return TimeBase(float(t[0]), float(dt), worst, float(res.max()), None, jitter,
                    float(np.sqrt(np.mean(dev**2))))


def resample(model: pin.Model, t: np.ndarray, q: np.ndarray, v: np.ndarray, dt: float,
             resolution: float | np.ndarray = 0.0) -> tuple[TimeBase, np.ndarray, np.ndarray]:
    """(q, v) on t_0 + k·dt for every k within the log (to the stamps' ``resolution``): q
    geodesically, v linearly."""
    if not dt > 0:
        raise SpecError(f"--resample {dt}: not a positive step")
    if np.any(np.diff(t) <= 0):
        raise SpecError("resample: time stamps not increasing")
    last = float(np.broadcast_to(np.asarray(resolution, dtype=float), t.shape)[-1])
    rows = int((t[-1] - t[0] + last) // dt) + 1  # counted before anything is allocated
    if rows < 3:
        raise SpecError(f"--resample {dt:g}: the log's {t[-1] - t[0]:.6g} s give {rows} "
                        f"row(s) at that step; an analysis needs at least 3")
    need = rows * (q.shape[1] + v.shape[1]) * 8 * IMPORT_COPIES  # the import's copies of q, v
    budget = Budget.from_environment().memory_bytes
    if need > budget:
        raise SpecError(f"--resample {dt:g}: {rows:,} rows ({t[-1] - t[0]:.6g} s at that step, "
                        f"the log's own is {np.median(np.diff(t)):.3g} s) need about "
                        f"{need / 2**30:.3g} GiB, over the memory budget of "
                        f"{budget / 2**30:.3g} GiB (BREVE_MEMORY_BUDGET_GB)")
    grid = t[0] + np.arange(rows) * dt
    grid = grid[grid <= t[-1] + last]
    j = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 2)
    lam = np.clip((grid - t[j]) / (t[j + 1] - t[j]), 0.0, 1.0)
    q_new = np.array([pin.interpolate(model, q[a], q[a + 1], float(w))
                      for a, w in zip(j, lam, strict=True)])
    v_new = v[j] + lam[:, None] * (v[j + 1] - v[j])
    return TimeBase(float(t[0]), float(dt), 0.0, 0.0, len(t)), q_new, v_new
