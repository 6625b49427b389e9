"""The claims' Monte Carlos, run in the background: ``python -m pipeline montecarlo`` in a
process of its own (its own Dask cluster), its kept records reused, and its verdict read once
it is done."""

from __future__ import annotations

import sys
from dataclasses import asdict
from pathlib import Path

from pipeline.montecarlo.verdict import TABLE_NAME, VERDICT_NAME, read_verdict
from pipeline.paths import display_path
from pipeline.provenance.keys import sample_version
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


def finish_power(job: BackgroundJob) -> tuple[dict, dict, list[Path]]:
    """Wait for the detector-power study, then its result (as a mapping), provenance, files."""
    from pipeline.montecarlo import power

    return _finish(job, power.RESULT_NAME, power.TABLE_NAME, power.read_power)


def finish_montecarlo(job: BackgroundJob) -> tuple[dict, dict, list[Path]]:
    """Wait for the Monte Carlo, then its verdict (as a mapping), provenance and files."""
    return _finish(job, VERDICT_NAME, TABLE_NAME, read_verdict)


def _finish(job: BackgroundJob, result_name: str, table_name: str, read
            ) -> tuple[dict, dict, list[Path]]:
    job.wait()
    folder = job.log.parent
    result = folder / result_name
    prov = {"source": job.stage, "version": f"samples {sample_version()}",
            "file": display_path(result)}
    return asdict(read(result)), prov, [folder / table_name, result]
