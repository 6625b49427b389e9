"""One predicate per artefact kind: may this stored artefact be reused? (architecture §9)

Each predicate reads only what the artefact records about itself and compares it with the
keys of :mod:`pipeline.provenance.keys`; an artefact that cannot be read is not current (it
is made again, never believed).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from pathlib import Path

import pyarrow.parquet as pq

from pipeline.analysis.record import try_read_analysis
from pipeline.analysis.schema import AnalysisRecord, DivergedRecord, ImportedRecord
from pipeline.artefact_paths import (
    ANALYSIS_FILE,
    CLAIMS_FILE,
    DIRECTIONS_FILE,
    IMPORTED_FOLDER,
    log_path,
)
from pipeline.errors import LogError
from pipeline.logs import LogMeta, VerifiedLog, read_footer
from pipeline.platform import platform_key
from pipeline.provenance.keys import (
    ANALYSIS_LIBRARIES,
    REPORT_LIBRARIES,
    SIM_LIBRARIES,
    analysis_version,
    file_digest,
    library_versions,
    report_version,
    sim_version,
    source_version,
)
from pipeline.spec import Spec

FINISHED = ("complete", "failed", "diverged")  # a run that ended (a failed one fails again)


def current_log(path: Path, spec: Spec, digest: Callable[[Path], str] = file_digest
                ) -> LogMeta | None:
    """The log's metadata if it is a finished run of this spec (content hash), this robot
    file (content hash) and this simulator (sources and libraries), else None. A
    ``complete`` log must hold every step.

    The platform it ran on (``pipeline.platform``) is recorded but is not part of the key: a
    log made on another processor is still this code's valid result, equal to what this one
    would make within the contract's tolerances (docs/reproducibility.md), and re-simulating
    every log on every machine that reads a shared logs folder would buy nothing but churn.
    What does depend on the platform, the verdict of the pinned baselines, is keyed on it
    (:func:`current_baselines`, and the claims through their key). ``digest``: how the robot
    file is hashed (the artefact store's, once per store)."""
    try:
        meta, rows = read_footer(path)
    except LogError:
        return None
    return meta if log_is_current(meta, rows, spec, digest) else None


def log_is_current(meta: LogMeta, rows: int, spec: Spec,
                   digest: Callable[[Path], str] = file_digest) -> bool:
    """:func:`current_log`'s key on a log's metadata and row count (the footer read, or a
    verified log's: the door checks the file it hands out, not only the one it looked at)."""
    return (meta.spec_hash == spec.spec_hash and meta.sim_version == sim_version()
            and meta.status in FINISHED and meta.robot_hash == digest(spec.robot_path)
            and (meta.status != "complete" or rows == spec.n_steps))


def import_is_current(log: VerifiedLog, key: str) -> bool:
    """Whether the imported log is the import keyed ``key`` (the same source bytes, mapping,
    robot, resampling and importer: :func:`pipeline.importer.run.import_key`)."""
    return (log.meta.imported or {}).get("import_key") == key


def _made_from(record: AnalysisRecord, log: VerifiedLog) -> bool:
    """The record names this log, and its content: a log re-run bitwise keeps its analysis,
    a log changed in any byte does not."""
    return (Path(record.log).resolve() == Path(log.path).resolve()
            and record.spec_hash == log.meta.spec_hash
            and record.sim_version == log.meta.sim_version
            and record.log_sha256 == log.sha256)


def current_analysis(path: Path, log: VerifiedLog, against: VerifiedLog | None = None,
                     controller_hash: str | None = None,
                     s_min_G_target: float | None = None) -> AnalysisRecord | None:
    """The analysis record at ``path`` if it was made from this log by this analysis code, over
    the default window, compared with ``against`` exactly when one is given, for an imported
    log with the controller of ``controller_hash`` exactly when one is, and with its theory at
    the step nearest ``s_min_G_target`` exactly when one is (else at the median's), else
    None."""
    record = try_read_analysis(path)
    if (record is None or record.analysis_version != analysis_version()
            or not _made_from(record, log)):
        return None
    # A record whose theory was taken at another rule is not this one.
    if getattr(getattr(record, "theory", None), "s_min_G_target", None) != s_min_G_target:
        return None
    # A record of another window (``analyze --window-start``) is not the default analysis,
    # nor is a comparison whose second run was analysed over another window.
    if not _default_window(record, log):
        return None
    if isinstance(record, ImportedRecord):
        declared = record.damping.controller_hash if record.damping is not None else None
        return record if against is None and declared == controller_hash else None
    comparison = getattr(record, "comparison", None)
    if against is None:
        return record if comparison is None else None
    if (comparison is None or not _made_from(comparison.other, against)
            or not _default_window(comparison.other, against)):
        return None
    return record


def _default_window(record: AnalysisRecord, log: VerifiedLog) -> bool:
    """The record's window is the default one of its log (a diverged log's has none)."""
    from pipeline.analysis.stages import choose_window

    if isinstance(record, DivergedRecord):
        return True
    default = choose_window(log.rows, log.spec.mission.dt, None, str(log.path))
    return ((record.window.start_step, record.window.stop_step)
            == (default.start, default.stop))


def current_sweep(table: Path, base_spec_hash: str, points: Iterable[str]) -> bool:
    """A sweep table of this grid whose every point is complete, made by this simulator and
    analysis code (each point was itself checked by the predicates above when it ran)."""
    try:
        t = pq.read_table(table)
    except OSError:
        return False
    md = {k.decode(): v.decode() for k, v in (t.schema.metadata or {}).items()}
    df = t.to_pandas()
    return (md.get("pipeline.sim_version") == sim_version()
            and md.get("pipeline.analysis_version") == analysis_version()
            and md.get("pipeline.base_spec_hash") == base_spec_hash
            and list(df["point"]) == list(points)
            and bool((df["status"] == "complete").all()))


def current_baselines(path: Path, names: list[str], pinned_dir: Path,
                      tolerances: Path | None = None) -> dict | None:
    """``baselines.json`` if it re-ran these baselines with this simulator, on this platform
    (its verdict, bitwise or within tolerance, is about the platform it ran on), against these
    pinned files and this tolerances file (by hash; None: absent), else None."""
    tol = None if tolerances is None or not Path(tolerances).is_file() else file_digest(
        tolerances)
    try:
        old = json.loads(Path(path).read_text())
        ok = (old["sim_version"] == sim_version() and sorted(old["baselines"]) == names
              and old["platform_key"] == platform_key() and old["tolerances_sha256"] == tol
              and all(file_digest(log_path(pinned_dir, n))
                      == old["baselines"][n].get("pinned_sha256") for n in names))
    except (OSError, KeyError, json.JSONDecodeError, TypeError, AttributeError):
        return None
    return old if ok else None


def report_inputs(out: Path) -> list[Path]:
    """The files the reports under ``out`` are rendered from (not the reports themselves)."""
    out = Path(out)
    patterns = (f"*/{ANALYSIS_FILE}", f"*/{DIRECTIONS_FILE}", CLAIMS_FILE, "bench.json",
                "baselines.json", "sweeps/*/sweep.parquet", "montecarlo/*/montecarlo.parquet",
                "montecarlo/*/verdict.json", "montecarlo/*/search-*.json",
                "montecarlo/*/fixes.json", "power/*/power.json",
                f"{IMPORTED_FOLDER}/*/{ANALYSIS_FILE}", f"{IMPORTED_FOLDER}/*/{DIRECTIONS_FILE}")
    return sorted(p for pat in patterns for p in out.glob(pat))


def report_key(out: Path) -> str:
    """The key of the reports under ``out``: the renderer's version and every input's hash,
    and the size and time of the log each analysis names (a log re-made is a changed record;
    a log deleted or replaced since is flagged on its pages, so it changes the key too)."""
    inputs = report_inputs(out)
    parts = {p.relative_to(out).as_posix(): file_digest(p) for p in inputs}
    logs = {}
    for p in inputs:
        if p.name == ANALYSIS_FILE:
            try:
                log = Path(json.loads(p.read_text())["log"])
                st = log.stat()
                logs[str(log)] = [st.st_size, st.st_mtime_ns, st.st_ino]
            except (OSError, ValueError, KeyError, TypeError):
                logs[p.relative_to(out).as_posix()] = None  # gone, or not a record
    return json.dumps({"report_version": report_version(), "inputs": parts, "logs": logs},
                      sort_keys=True)


REPORT_KEY_FILE = ".report-key"  # in a report folder: the key of its last complete rendering


def current_report(out: Path, stamp: Path) -> bool:
    """Whether the reports under ``out`` were rendered from these inputs by this code."""
    try:
        return Path(stamp).read_text() == report_key(out)
    except OSError:
        return False


CLAIMS_KEY_FILE = ".claims-key"  # in a report folder: the key of its last claims evaluation


def claims_key(sources: dict[str, str], files: Iterable[Path]) -> str:
    """The key of an evaluated register: what it is made from (``sources``: the register,
    its specs and robots, :func:`pipeline.claims.register.register_sources`), the bytes of
    every artefact the evaluation read or wrote (logs, analyses, sweep tables, baselines, the
    cross-check and equations, claims.json and the CLAIMS pages), the package's sources (the
    cross-check inspects them all), the libraries and the platform."""
    libraries = library_versions(dict.fromkeys(SIM_LIBRARIES + ANALYSIS_LIBRARIES
                                               + REPORT_LIBRARIES))
    # The platform too: the baselines' verdict (claim C8) is about the platform it ran on.
    return json.dumps({"source_version": source_version(), "libraries": libraries,
                       "platform": platform_key(),
                       "sources": sources,
                       "files": {str(Path(p).resolve()): file_digest(p) for p in files}},
                      sort_keys=True, indent=1)


def current_claims(stamp: Path, sources: dict[str, str]) -> bool:
    """Whether the claims beside ``stamp`` were evaluated from these sources, by this code,
    and every file that evaluation read or wrote is still byte for byte as it left it (a
    file that is gone or changed, or a stamp that cannot be read: not current)."""
    try:
        text = Path(stamp).read_text()
        files = [Path(p) for p in json.loads(text)["files"]]
        return text == claims_key(sources, files)
    except (OSError, KeyError, json.JSONDecodeError, TypeError, AttributeError):
        return False
