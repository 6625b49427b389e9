"""Runs and analyses on demand: reuse a finished log of the same spec and code, else run.

A log is reused when it is complete, its spec hash and code version equal the spec's and the
package's, and it has the spec's number of steps. An analysis.json is reused when it was made
from that same log (path, spec hash, code version) and against the same second log.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from pipeline.analysis.record import try_read_analysis, write_analysis
from pipeline.analysis.stages import analyze_log, compare
from pipeline.errors import LogError, RunFailed
from pipeline.logs import LogMeta, num_rows, read_meta, verify_log
from pipeline.sim.run import log_path, run_spec
from pipeline.spec import PROJECT_ROOT, Spec
from pipeline.version import code_version


@dataclass(frozen=True)
class RunRecord:
    """A verified log ready for analysis and where it came from; ``spec`` is the spec its
    metadata records (the claims read run parameters from it, never from a spec file)."""

    spec: Spec
    path: Path
    meta: LogMeta
    reused: bool


def display_path(path: Path | str) -> str:
    """A path relative to the project root when it is inside it."""
    p = Path(path)
    try:
        return p.resolve().relative_to(PROJECT_ROOT).as_posix()
    except ValueError:
        return str(p)


def reusable(spec: Spec, path: Path, expect: str = "complete") -> LogMeta | None:
    """The log's metadata if it is a finished run of this spec under this code that ended as
    ``expect`` (``complete`` with every step, or ``diverged``), else None."""
    if not path.is_file():
        return None
    try:
        meta = read_meta(path)
        rows = num_rows(path)
    except LogError:
        return None
    ok = (meta.status == expect and meta.spec_hash == spec.spec_hash
          and meta.code_version == code_version()
          and (rows == spec.n_steps if expect == "complete" else True))
    return meta if ok else None


def ensure_run(spec: Spec, logs_dir: Path, expect: str = "complete") -> RunRecord:
    """The log of ``spec``, reused or run; a run that does not end as ``expect`` (a
    ``complete`` one that diverges, or the reverse) is a RunFailed."""
    path = log_path(spec, logs_dir)
    if reusable(spec, path, expect) is not None:
        log = verify_log(path)
        return RunRecord(log.spec, path, log.meta, True)
    print(f"running {spec.name} ({spec.n_steps} steps) -> {display_path(path)}", file=sys.stderr)
    out = run_spec(spec, logs_dir, progress=sys.stderr.isatty(), raise_on_failure=False)
    if out.status != expect:
        raise RunFailed(f"{spec.name}: expected a {expect} run, got {out.status}"
                        + (f" at {out.error}" if out.error else "") + f"; log: {out.path}")
    for w in out.warnings:
        print(f"warning: {w}", file=sys.stderr)
    log = verify_log(out.path)
    return RunRecord(log.spec, out.path, log.meta, False)


def _same_log(record: dict, run: RunRecord) -> bool:
    return (Path(record.get("log", "")).resolve() == run.path.resolve()
            and record.get("spec_hash") == run.meta.spec_hash
            and record.get("code_version") == run.meta.code_version)


def ensure_analysis(run: RunRecord, out_dir: Path, against: RunRecord | None = None,
                    against_record: dict | None = None) -> dict:
    """The analysis record of ``run`` (compared with ``against``), reused or recomputed."""
    path = Path(out_dir) / run.spec.name / "analysis.json"
    old = try_read_analysis(path)  # a cache: a damaged or foreign record is recomputed
    if old is not None and _same_log(old, run):
        comp = old.get("comparison")
        if against is None and comp is None:
            return old
        if against is not None and comp is not None and _same_log(comp.get("other", {}),
                                                                  against):
            return old
    print(f"analysing {run.spec.name}" + (f" against {against.spec.name}" if against else ""),
          file=sys.stderr)
    record = analyze_log(run.path)
    if against is not None:
        other = against_record if against_record is not None else analyze_log(against.path)
        record["comparison"] = compare(record, other)
    write_analysis(record, out_dir)
    return record
