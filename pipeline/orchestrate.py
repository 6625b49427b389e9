"""Runs, analyses and sweeps on demand, for the CLI and the claims: what is current is reused
(:mod:`pipeline.provenance.validity` decides), anything else is made, once.

- :func:`ensure_run`: the log of a spec, reused when current and ended as expected;
- :func:`ensure_analysis`: its analysis.json, reused when made from that log (and the same
  second log) by this analysis code;
- :func:`start_sweep` and :func:`finish_sweep`: a sweep's table, run as ``python -m pipeline
  sweep`` in a background process (its own Dask cluster) unless current, and its stability
  bracket once it is done.
"""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pipeline.analysis.record import write_analysis
from pipeline.analysis.stages import analyze_log, compare
from pipeline.artefact_paths import analysis_path
from pipeline.errors import RunFailed
from pipeline.logs import LogMeta, verify_log
from pipeline.paths import display_path
from pipeline.progress import interactive, say, stage
from pipeline.provenance.keys import analysis_version, sim_version
from pipeline.provenance.validity import current_analysis, current_log, current_sweep
from pipeline.sim.run import log_path, run_spec
from pipeline.spec import Spec

if TYPE_CHECKING:
    from pipeline.sweep.driver import Sweep


@dataclass(frozen=True)
class RunRecord:
    """A verified log ready for analysis and where it came from; ``spec`` is the spec its
    metadata records (the claims read run parameters from it, never from a spec file)."""

    spec: Spec
    path: Path
    meta: LogMeta
    reused: bool


def ensure_run(spec: Spec, logs_dir: Path, expect: str = "complete") -> RunRecord:
    """The log of ``spec``, reused or run; a run that does not end as ``expect`` (a
    ``complete`` one that diverges, or the reverse) is a RunFailed."""
    path = log_path(spec, logs_dir)
    meta = current_log(path, spec)
    if meta is not None and meta.status == expect:
        log = verify_log(path)
        return RunRecord(log.spec, path, log.meta, True)
    with stage(f"mission {spec.name}", f"({spec.n_steps} steps) -> {display_path(path)}") as st:
        out = run_spec(spec, logs_dir, progress=interactive(), raise_on_failure=False)
        st.done(out.status)
    if out.status != expect:
        raise RunFailed(f"{spec.name}: expected a {expect} run, got {out.status}"
                        + (f" at {out.error}" if out.error else "") + f"; log: {out.path}")
    for w in out.warnings:
        print(f"warning: {w}", file=sys.stderr)
    log = verify_log(out.path)
    return RunRecord(log.spec, out.path, log.meta, False)


def ensure_analysis(run: RunRecord, out_dir: Path, against: RunRecord | None = None,
                    against_record: dict | None = None) -> dict:
    """The analysis record of ``run`` (compared with ``against``), reused or recomputed."""
    path = analysis_path(out_dir, run.spec.name)
    old = current_analysis(path, run.path, run.meta,
                           None if against is None else (against.path, against.meta))
    if old is not None:
        return old
    with stage(f"analysis {run.spec.name}",
               f"(against {against.spec.name})" if against is not None else ""):
        record = analyze_log(run.path)
        if against is not None:
            other = against_record if against_record is not None else analyze_log(against.path)
            record["comparison"] = compare(record, other)
        write_analysis(record, out_dir)
    return record


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
    from pipeline.sweep.driver import plan_sweep

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
        job.process = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT)
    job.t0 = time.perf_counter()
    say(f"sweep {name}: started in the background ({len(plan.points)} points, {workers} "
        f"worker{'s' if workers != 1 else ''}) -> {display_path(job.log)}")
    return job


def finish_sweep(job: SweepJob, key: str = "mission.dt", lag: str = "dominant_lag1",
                 predicted: str = "dt_star_damping", unstable: str = "above"
                 ) -> tuple[dict, dict]:
    """Wait for the sweep (if it was started), then its stability bracket and provenance."""
    from pipeline.sweep.results import stability_bracket

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
