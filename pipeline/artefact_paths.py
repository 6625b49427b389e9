"""Where the pipeline's artefacts live: their file names and the paths built from them,
defined once (architecture §6). A run's log is ``<logs>/<spec name>/run.parquet``; its
analysis record ``<out>/<spec name>/analysis.json``, with the per-direction table beside it;
an evaluated claims register ``<out>/claims.json``. An imported log (pipeline.importer) lives
under ``<logs>/imported/<name>/``, its analysis under ``<out>/imported/<name>/``: its name is
the user's and must not clash with a spec's.
"""

from __future__ import annotations

from pathlib import Path

LOG_FILE = "run.parquet"
ANALYSIS_FILE = "analysis.json"
DIRECTIONS_FILE = "directions.parquet"
CLAIMS_FILE = "claims.json"
IMPORTED_FOLDER = "imported"


def log_path(logs_dir: Path | str, name: str) -> Path:
    """The log of the run of spec ``name`` under ``logs_dir``."""
    return Path(logs_dir) / name / LOG_FILE


def analysis_path(out_dir: Path | str, name: str) -> Path:
    """The analysis record of the run of spec ``name`` under ``out_dir``."""
    return Path(out_dir) / name / ANALYSIS_FILE
