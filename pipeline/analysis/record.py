"""The analysis record on disk: ``<out>/<run>/analysis.json`` and ``directions.parquet``, a
pair written as a set and read back only when whole (architecture §3, §6).

``analysis.json`` carries a schema version (:data:`SCHEMA`); its fields and their types are
:mod:`pipeline.analysis.schema`'s, checked when it is written and when it is read: a reader
refuses a version it does not know, a file that is not JSON, and a record missing a field,
holding one it should not or one of the wrong type. It also carries the
SHA-256 of the ``directions.parquet`` written with it: the table is written first and the
record last, so a record whose table is missing or is another run's is caught on reading
(a writer killed between the two, a disk that filled up). And it carries the SHA-256 of its
own content (``record_sha256``, over the canonical JSON of every other field): a record edited
by hand after the analysis wrote it is refused on reading, by ``claims`` (which makes it again)
and ``report`` (exit 2), never believed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.analysis.schema import (
    AnalysisRecord,
    CompleteRecord,
    Direction,
    check_record,
    record_from_json,
    to_json,
)
from pipeline.artefact_paths import ANALYSIS_FILE, DIRECTIONS_FILE
from pipeline.atomic_files import atomic_write_bytes, atomic_write_text
from pipeline.errors import LogError

# /2: sim_version and analysis_version (was code_version); /3: theory.fastest_mode (every damping
# mode's fastest, named, with its fixes) and bus_rate.at_bound_share, which the reports read;
# /4: harm (the actuators' torque reversals and the bus attitude jitter, eqs. 30–32) and
# modes_along (the fastest damping mode named along the whole log, eq. 21); /6: a ring's growth
# (sustained or decaying), a held cycle checked against its estimate (HeldBy.explains) and the
# modes' stability checked against the map's (Prediction.theory_consistent); /7: a lag-1 and
# the dominant step-energy share may be null, undetermined (a series without motion); the
# record holds no NaN (it is written as strict JSON); /8: record_sha256, the record's own content
# hash, checked on reading; an imported log's provenance absent where the import rebuilt its σ;
# /9: joint_ranges, the run's time outside the arm's joint ranges (eq. 42), and
# theory.s_min_G_target where the step was chosen nearest a σ_min(Γ) (issue 50); /10:
# prediction.agrees null when undetermined (never false), with undetermined_why and
# least_mission_steps, and each ring's own reason (Ring.undetermined) (issue 51); /11: the
# short-period peak to peak of the bus torque (with its channel) and of the bus attitude (eq.
# 30b), and a comparison's mission_differs, its coverage difference null for another mission.
SCHEMA = "breve-analysis/11"
CONTENT_KEY = "record_sha256"
RECORD_NAME = ANALYSIS_FILE
TABLE_NAME = DIRECTIONS_FILE


def content_digest(record: dict) -> str:
    """SHA-256 of a record's canonical JSON (sorted keys, no spaces), its own hash left out: a
    float reads back from JSON to the same value, so the digest of what was written is the
    digest of what is read."""
    body = {k: v for k, v in record.items() if k != CONTENT_KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def _table_bytes(record: CompleteRecord) -> bytes:
    rows = record.directions
    table = pa.table({f.name: np.array([getattr(d, f.name) for d in rows])
                      for f in dataclasses.fields(Direction)})
    table = table.replace_schema_metadata({b"pipeline.log": record.log.encode()})
    buf = io.BytesIO()
    pq.write_table(table, buf, compression="zstd")
    return buf.getvalue()


def write_analysis(record: AnalysisRecord, out_dir: Path) -> Path:
    """Write ``out_dir/<spec name>/analysis.json`` and its ``directions.parquet`` as a set:
    the table first, then the record naming the table's hash (each atomically). If the
    record cannot be written, the new table is removed, so no record points at it."""
    folder = Path(out_dir) / record.spec_name
    table_path, path = folder / TABLE_NAME, folder / RECORD_NAME
    table = _table_bytes(record) if getattr(record, "directions", None) else None
    digest = hashlib.sha256(table).hexdigest() if table is not None else None
    record = dataclasses.replace(record, schema=SCHEMA, directions_sha256=digest,
                                 record_sha256=None)
    content = to_json(record)  # without record_sha256 (absent while None), then with it
    content[CONTENT_KEY] = content_digest(content)
    text = json.dumps(content, indent=1, allow_nan=False) + "\n"
    problem = check_record(json.loads(text))
    if problem is not None:  # the analysis code's own error: never written, never read back
        raise ValueError(f"analysis record of {record.spec_name} off its schema: {problem}")
    if table is not None:
        atomic_write_bytes(table_path, table)
    else:  # a diverged log has no per-direction stage: no stale table of an older run
        table_path.unlink(missing_ok=True)
    try:
        atomic_write_text(path, text)
    except BaseException:
        table_path.unlink(missing_ok=True)
        raise
    return path


def read_analysis(path: Path | str) -> AnalysisRecord:
    """A validated analysis record; LogError naming the file and the key otherwise."""
    path = Path(path)
    try:
        record = json.loads(path.read_text())
    except OSError as exc:
        raise LogError(f"{path}: cannot read the analysis record: {exc.strerror}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise LogError(f"{path}: not an analysis record (not JSON: {exc})") from None
    if not isinstance(record, dict):
        raise LogError(f"{path}: not an analysis record (not a JSON object)")
    schema = record.get("schema")
    if schema != SCHEMA:
        raise LogError(f"{path}: key schema: {schema!r} is not a version this code reads "
                       f"({SCHEMA})")
    problem = check_record(record)  # every field of its kind, typed (analysis/schema.py)
    if problem is not None:
        raise LogError(f"{path}: key {problem} (not the analysis record {SCHEMA})")
    # Whole and well-typed, but is it what the analysis wrote? Its own hash says.
    if record[CONTENT_KEY] != content_digest(record):
        raise LogError(f"{path}: key {CONTENT_KEY}: the record's content is not what the "
                       f"analysis wrote (edited since?): analyse its log again")
    digest = record.get("directions_sha256")
    table = path.parent / TABLE_NAME
    if digest is not None:
        try:
            have = hashlib.sha256(table.read_bytes()).hexdigest()
        except OSError:
            raise LogError(f"{path}: its {TABLE_NAME} is missing (written as a pair)") from None
        if have != digest:
            raise LogError(f"{path}: key directions_sha256: {TABLE_NAME} beside it is not the "
                           f"one written with it")
    return record_from_json(record)


def try_read_analysis(path: Path) -> AnalysisRecord | None:
    """The record if it reads whole (:func:`read_analysis`), else None: for caches."""
    try:
        return read_analysis(path)
    except LogError:
        return None
