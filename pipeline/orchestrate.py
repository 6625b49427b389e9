"""Runs, analyses and sweeps on demand, for the CLI and the claims: what is current is reused
(:mod:`pipeline.provenance.validity` decides), anything else is made, once.

- :func:`ensure_run`: the log of a spec, reused when current and ended as expected;
- :func:`ensure_analysis`: its analysis.json, reused when made from that log (and the same
  second log) by this analysis code;
- :func:`ensure_sweep`: a sweep's table, run as ``python -m pipeline sweep`` in a subprocess
  (its own Dask cluster) unless current, and its stability bracket.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from pipeline.analysis.record import write_analysis
from pipeline.analysis.stages import analyze_log, compare
from pipeline.errors import RunFailed
from pipeline.logs import LogMeta, verify_log
from pipeline.paths import display_path
from pipeline.progress import interactive, stage
from pipeline.provenance.keys import analysis_version, sim_version
from pipeline.provenance.validity import current_analysis, current_log, current_sweep
from pipeline.sim.run import log_path, run_spec
from pipeline.spec import Spec


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
    path = Path(out_dir) / run.spec.name / "analysis.json"
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


def ensure_sweep(spec: str, sets: list[str], name: str, logs: Path, out: Path,
                 workers: int = 2, key: str = "mission.dt", lag: str = "dominant_lag1",
                 predicted: str = "dt_star_damping", unstable: str = "above"
                 ) -> tuple[dict, dict]:
    """The stability bracket of the sweep and its provenance, running the sweep if needed."""
    from pipeline.sweep.driver import plan_sweep
    from pipeline.sweep.results import stability_bracket

    plan = plan_sweep(spec, sets, name, logs, out)
    if not current_sweep(plan.table_path, plan.base.spec_hash, [p.name for p in plan.points]):
        cmd = [sys.executable, "-m", "pipeline", "sweep", spec, "--name", name,
               "--logs", str(logs), "--out", str(out), "--workers", str(workers)]
        for s in sets:
            cmd += ["--set", s]
        # Its stderr is ours: on a terminal the sweep draws its own bar, and its one-line
        # error, if any, shows above the failure.
        with stage(f"sweep {name}", f"({len(plan.points)} points, {workers} workers)"):
            r = subprocess.run(cmd, stdout=sys.stderr)
            if r.returncode != 0:
                raise RunFailed(f"sweep {name} failed (exit {r.returncode}); its message is "
                                f"above")
    bracket = stability_bracket(plan.table_path, key, lag, predicted, unstable)
    prov = {"source": "sweep", "version": f"sim {sim_version()}, analysis {analysis_version()}",
            "file": display_path(plan.table_path)}
    return bracket, prov
