"""The claims' studies, run in the background: ``python -m pipeline montecarlo`` (or ``power``)
in a process of its own (its own Dask cluster), its kept records reused, waited for before
its result is read."""

from __future__ import annotations

import sys
from pathlib import Path

from pipeline.sweep.background import BackgroundJob


def start_montecarlo(path: Path, samples: int | None, logs: Path, out: Path,
                     workers: int = 2, stage: str = "montecarlo") -> BackgroundJob:
    """Start ``python -m pipeline montecarlo`` (or ``power``, the detector-power study) in the
    background, its output in ``<out>/<name>/<stage>.log``; the samples it finds kept are not
    run again."""
    name = Path(path).stem
    job = BackgroundJob(name, stage)
    cmd = [sys.executable, "-m", "pipeline", stage, str(path), "--logs", str(logs),
           "--out", str(out), "--workers", str(workers)]
    if samples is not None:
        cmd += ["--samples", str(samples)]
    # Its table and result beside its output.
    job.start(cmd, Path(out) / name / f"{stage}.log", f"{workers} workers")
    return job


def wait_study(job: BackgroundJob) -> None:
    """Wait for a Monte Carlo or power study started here (RunFailed if it failed); its
    result is then read as any other (:func:`pipeline.montecarlo.studies.study_result`)."""
    job.wait()
