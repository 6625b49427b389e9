"""Where the pipeline's artefacts live: their file names and the paths built from them,
defined once (architecture §6). A run's log is ``<logs>/<spec name>/run.parquet``; its
analysis record ``<out>/<spec name>/analysis.json``, with the per-direction table beside it;
an evaluated claims register ``<out>/claims.json``. An imported log (pipeline.importer) lives
under ``<logs>/imported/<name>/``, its analysis under ``<out>/imported/<name>/``: its name is
the user's and must not clash with a spec's.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.errors import OutputError

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


def check_contained(root: Path | str, folder: Path | str) -> None:
    """OutputError unless ``folder`` (an artefact's folder under ``root``) stays under
    ``root`` once its symbolic links are followed: a link in the way (``logs/nominal`` or
    ``logs/imported/<name>`` pointing elsewhere) would write outside the output folder.
    ``root`` itself may be a link (a logs folder kept on another disk)."""
    real_root, real = Path(root).resolve(), Path(folder).resolve()
    if not real.is_relative_to(real_root):
        raise OutputError(f"{folder}: a symbolic link out of {root} (to {real}): refused, "
                          f"nothing written (remove the link, or give --out a folder of its own)")
