"""Run one spec into its Parquet log: ``DIR/<spec name>/run.parquet`` (architecture §6)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from pipeline import artefact_paths
from pipeline.budget import check_mission
from pipeline.errors import RunFailed
from pipeline.logs import (
    FINAL_KEYS,
    LogMeta,
    LogWriter,
    log_metadata,
    static_metadata,
)
from pipeline.paths import display_path
from pipeline.provenance.keys import SIM_LIBRARIES, file_digest, library_versions, sim_version
from pipeline.sim.mission import Mission
from pipeline.spec import Spec


@dataclass(frozen=True)
class RunOutcome:
    path: Path
    status: str
    n_steps: int
    warnings: list[str]
    error: str = ""


def log_path(spec: Spec, out_dir: Path) -> Path:
    return artefact_paths.log_path(out_dir, spec.name)


def run_spec(spec: Spec, out_dir: Path | str = "logs", progress: bool = False,
             raise_on_failure: bool = True) -> RunOutcome:
    """Simulate ``spec`` and write its log atomically, marked ``complete``, ``failed`` (a
    non-finite state) or ``diverged`` (the v_max clip held, see ``DIVERGENCE_STEPS``).

    Raises RunFailed (after writing the log) unless ``raise_on_failure`` is false.
    """
    check_mission(spec)  # refused up front, before anything is allocated
    mission = Mission(spec)
    meta = LogMeta(
        spec=spec.model_dump(mode="json"), spec_hash=spec.spec_hash,
        sim_version=sim_version(), robot_file=display_path(spec.robot_path),
        robot_hash=file_digest(spec.robot_path), status="", failed_step=None, error="",
        versions=library_versions(SIM_LIBRARIES),
    )
    path = log_path(spec, Path(out_dir))
    # Row group by row group: a long run's memory stays at one group; the status and the
    # row count go into the footer when the file is closed and renamed into place.
    with LogWriter(path, static_metadata(meta)) as writer:
        result = mission.run(progress=progress, sink=writer.write)
        final = replace(meta, status=result.status, failed_step=result.failed_step,
                        error=result.error, rows=writer.rows)
        writer.close({k: v for k, v in log_metadata(final).items() if k in FINAL_KEYS})
    outcome = RunOutcome(path, result.status, writer.rows, result.warnings, result.error)
    if result.status != "complete" and raise_on_failure:
        raise RunFailed(f"{spec.name}: run {result.status} at {result.error}; log marked "
                        f"{result.status}: {path}")
    return outcome
