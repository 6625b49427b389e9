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
class SweepJob:
    """A sweep of the claims: its plan and, unless its table was current, the ``python -m
    pipeline sweep`` process making it in the background."""

    name: str
    plan: Sweep
    process: subprocess.Popen | None = None
    log: Path | None = None
    t0: float = 0.0

    def stop(self) -> None:
        """End a sweep still running (the claims failed before they needed it)."""
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait()


def start_sweep(spec: str, sets: list[str], name: str, logs: Path, out: Path,
                workers: int = 2) -> SweepJob:
    """Plan the sweep and, unless its table is current, start it in a process of its own (its
    own Dask cluster), in the background: the claims' missions and checks run meanwhile. Its
    output goes to ``<out>/<name>/sweep.log`` (lines of two sweeps and the missions would
    interleave, their bars collide)."""
    plan = plan_sweep(spec, sets, name, logs, out)
    job = SweepJob(name, plan)
    if current_sweep(plan.table_path, plan.base.spec_hash, [p.name for p in plan.points]):
        return job
    cmd = [sys.executable, "-m", "pipeline", "sweep", spec, "--name", name,
           "--logs", str(logs), "--out", str(out), "--workers", str(workers)]
    for s in sets:
        cmd += ["--set", s]
    job.log = plan.table_path.parent / "sweep.log"
    job.log.parent.mkdir(parents=True, exist_ok=True)
    with open(job.log, "wb") as f:
        # The sweep ends with this command (kill -9 included): pipeline.orphans.
        job.process = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT,
                                       env=child_environment())
    job.t0 = time.perf_counter()
    say(f"sweep {name}: started in the background ({len(plan.points)} points, {workers} "
        f"worker{'s' if workers != 1 else ''}) -> {display_path(job.log)}")
    return job


def finish_sweep(job: SweepJob, key: str = "mission.dt", lag: str = "dominant_lag1",
                 predicted: str = "dt_star_damping", unstable: str = "above"
                 ) -> tuple[dict, dict]:
    """Wait for the sweep (if it was started), then its stability bracket and provenance."""
    if job.process is not None:
        rc = job.process.wait()
        lines = job.log.read_text(errors="replace").strip().splitlines() or ["(no output)"]
        if rc != 0:
            say(f"sweep {job.name}: failed after {time.perf_counter() - job.t0:.1f} s")
            raise RunFailed(f"sweep {job.name} failed (exit {rc}): {lines[-1]} (all of its "
                            f"output: {display_path(job.log)})")
        summary = next((ln for ln in lines if " points: " in ln), "")
        say(f"sweep {job.name}: done in {time.perf_counter() - job.t0:.1f} s"
            + (f" ({summary.split(' -> ')[0]})" if summary else ""))
        job.process = None
    bracket = stability_bracket(job.plan.table_path, key, lag, predicted, unstable)
    prov = {"source": "sweep", "version": f"sim {sim_version()}, analysis {analysis_version()}",
            "file": display_path(job.plan.table_path)}
    return bracket, prov
