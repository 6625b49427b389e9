"""The claims' sweeps, run in the background: a sweep's table, made by ``python -m pipeline
sweep`` in a process of its own (its own Dask cluster) unless current
(:func:`pipeline.store.validity.current_sweep`), and its stability bracket once it is done.
"""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import RunFailed
from pipeline.orphans import child_environment
from pipeline.paths import display_path
from pipeline.progress import say
from pipeline.provenance.keys import analysis_version, sim_version
from pipeline.store.validity import current_sweep
from pipeline.sweep.driver import Sweep, plan_sweep
from pipeline.sweep.results import stability_bracket


@dataclass
class BackgroundJob:
    """A ``python -m pipeline STAGE`` process of the claims, running in the background (a
    sweep, a Monte Carlo, a power study), its output in ``log``."""

    name: str
    stage: str
    process: subprocess.Popen | None = None
    log: Path | None = None
    t0: float = 0.0

    def start(self, cmd: list[str], log: Path, what: str) -> None:
        """Run ``cmd`` in the background, its output (both streams) in ``log``, and say so
        (``what``: its size in words). The process ends with the command that started it,
        kill -9 included (:mod:`pipeline.orphans`)."""
        self.log = log
        log.parent.mkdir(parents=True, exist_ok=True)
        with open(log, "wb") as f:
            self.process = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT,
                                            env=child_environment())
        self.t0 = time.perf_counter()
        say(f"{self.stage} {self.name}: started in the background ({what}) -> "
            f"{display_path(log)}")

    def stop(self) -> None:
        """End the process if still running (the claims failed before they needed it)."""
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait()

    def wait(self, summary: str = "") -> None:
        """Wait for the process, if one was started: RunFailed with its last line unless it
        ended well, else say it is done (with the first line of its output holding
        ``summary``)."""
        if self.process is None:
            return
        rc = self.process.wait()
        lines = self.log.read_text(errors="replace").strip().splitlines() or ["(no output)"]
        took = time.perf_counter() - self.t0
        if rc != 0:
            say(f"{self.stage} {self.name}: failed after {took:.1f} s")
            raise RunFailed(f"{self.stage} {self.name} failed (exit {rc}): {lines[-1]} (all of "
                            f"its output: {display_path(self.log)})")
        line = next((ln for ln in lines if summary and summary in ln), "")
        say(f"{self.stage} {self.name}: done in {took:.1f} s"
            + (f" ({line.split(' -> ')[0]})" if line else ""))
        self.process = None


@dataclass
class SweepJob(BackgroundJob):
    """A sweep of the claims: its plan and, unless its table was current, the ``python -m
    pipeline sweep`` process making it in the background."""

    plan: Sweep | None = None


def start_sweep(spec: str, sets: list[str], name: str, logs: Path, out: Path,
                workers: int = 2) -> SweepJob:
    """Plan the sweep and, unless its table is current, start it in a process of its own (its
    own Dask cluster), in the background: the claims' missions and checks run meanwhile. Its
    output goes to ``<out>/<name>/sweep.log`` (lines of two sweeps and the missions would
    interleave, their bars collide)."""
    plan = plan_sweep(spec, sets, name, logs, out)
    job = SweepJob(name, "sweep", plan=plan)
    if current_sweep(plan.table_path, plan.base.spec_hash, [p.name for p in plan.points]):
        return job
    cmd = [sys.executable, "-m", "pipeline", "sweep", spec, "--name", name,
           "--logs", str(logs), "--out", str(out), "--workers", str(workers)]
    for s in sets:
        cmd += ["--set", s]
    job.start(cmd, plan.table_path.parent / "sweep.log",
              f"{len(plan.points)} points, {workers} worker{'s' if workers != 1 else ''}")
    return job


def finish_sweep(job: SweepJob, key: str = "mission.dt", lag: str = "dominant_lag1",
                 predicted: str = "dt_star_damping", unstable: str = "above"
                 ) -> tuple[dict, dict]:
    """Wait for the sweep (if it was started), then its stability bracket and provenance."""
    job.wait(summary=" points: ")
    bracket = stability_bracket(job.plan.table_path, key, lag, predicted, unstable)
    prov = {"source": "sweep", "version": f"sim {sim_version()}, analysis {analysis_version()}",
            "file": display_path(job.plan.table_path)}
    return bracket, prov
