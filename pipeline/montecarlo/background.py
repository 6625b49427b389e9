"""The claims' Monte Carlos, run in the background: ``python -m pipeline montecarlo`` in a
process of its own (its own Dask cluster), its kept records reused, and its verdict read once
it is done."""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from pipeline.errors import RunFailed
from pipeline.montecarlo.verdict import TABLE_NAME, VERDICT_NAME, read_verdict
from pipeline.orphans import child_environment
from pipeline.paths import display_path
from pipeline.progress import say
from pipeline.provenance.keys import sample_version


@dataclass
class MonteCarloJob:
    name: str
    out: Path  # the folder of its table and verdict
    stage: str = "montecarlo"
    process: subprocess.Popen | None = None
    log: Path | None = None
    t0: float = 0.0

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait()


def start_montecarlo(path: Path, samples: int | None, logs: Path, out: Path,
                     workers: int = 2, stage: str = "montecarlo") -> MonteCarloJob:
    """Start ``python -m pipeline montecarlo`` (or ``power``, the detector-power study) in the
    background, its output in ``<out>/<name>/<stage>.log``; the samples it finds kept are not
    run again."""
    name = Path(path).stem
    job = MonteCarloJob(name, Path(out) / name, stage=stage)
    cmd = [sys.executable, "-m", "pipeline", stage, str(path), "--logs", str(logs),
           "--out", str(out), "--workers", str(workers)]
    if samples is not None:
        cmd += ["--samples", str(samples)]
    job.out.mkdir(parents=True, exist_ok=True)
    job.log = job.out / f"{stage}.log"
    with open(job.log, "wb") as f:
        job.process = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT,
                                       env=child_environment())
    job.t0 = time.perf_counter()
    say(f"{stage} {name}: started in the background ({workers} workers) -> "
        f"{display_path(job.log)}")
    return job


def _wait(job: MonteCarloJob) -> None:
    if job.process is not None:
        rc = job.process.wait()
        lines = job.log.read_text(errors="replace").strip().splitlines() or ["(no output)"]
        if rc != 0:
            say(f"{job.stage} {job.name}: failed after {time.perf_counter() - job.t0:.1f} s")
            raise RunFailed(f"{job.stage} {job.name} failed (exit {rc}): {lines[-1]} (all of "
                            f"its output: {display_path(job.log)})")
        say(f"{job.stage} {job.name}: done in {time.perf_counter() - job.t0:.1f} s")
        job.process = None


def finish_power(job: MonteCarloJob) -> tuple[dict, dict, list[Path]]:
    """Wait for the detector-power study, then its result (as a mapping), provenance, files."""
    from pipeline.montecarlo.power import RESULT_NAME, TABLE_NAME, read_power

    _wait(job)
    result = job.out / RESULT_NAME
    prov = {"source": "power", "version": f"samples {sample_version()}",
            "file": display_path(result)}
    return asdict(read_power(result)), prov, [job.out / TABLE_NAME, result]


def finish_montecarlo(job: MonteCarloJob) -> tuple[dict, dict, list[Path]]:
    """Wait for the Monte Carlo, then its verdict (as a mapping), provenance and files."""
    _wait(job)
    verdict = job.out / VERDICT_NAME
    prov = {"source": "montecarlo", "version": f"samples {sample_version()}",
            "file": display_path(verdict)}
    return asdict(read_verdict(verdict)), prov, [job.out / TABLE_NAME, verdict]
