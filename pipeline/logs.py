"""The run log: one Parquet file per run, the contract between ``sim`` and ``analysis``.

Per-step columns (architecture §6), vector columns as fixed-size lists of float64, and schema
metadata under ``pipeline.*`` keys. Files are written atomically: a temporary file in the
same folder, fsynced, then renamed over the target.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic_files import atomic_target, cannot_write
from pipeline.errors import LogDamaged, LogError, SpecError
from pipeline.paths import find_on_search_path
from pipeline.platform import fingerprint
from pipeline.provenance.keys import SIM_LIBRARIES, file_digest, library_versions
from pipeline.spec import Spec, build_spec, canonical_hash, spec_hash_of

META_KEYS = ("spec", "spec_hash", "sim_version", "robot_file", "robot_hash", "status", "rows",
             "versions")
# Columns that may hold +inf: a condition number at an exact singularity (eq. 19). Every other
# numeric column of a log must be finite.
MAY_BE_INFINITE = ("kappa_G", "kappa_J")
# What an imported log's pipeline.import record holds (pipeline/importer/run.py writes it).
IMPORT_KEYS = ("source", "source_sha256", "format", "mapping", "robot_from", "import_key",
               "s_min_G_from", "conventions", "time", "quat_norm_error", "consistency")
# Where an imported log's s_min_G came from (its record's ``s_min_G_from``): the source's own
# column (the mapping's s_min_G), which the analysis' provenance check compares with Γ rebuilt
# from q; or rebuilt from q on import, which that check would compare with itself.
S_MIN_G_SOURCE, S_MIN_G_REBUILT = "source", "rebuilt from q on import"
ROW_GROUP = 65_536


@dataclass(frozen=True)
class LogMeta:
    spec: dict
    spec_hash: str
    sim_version: str  # the simulator's code and libraries (pipeline.provenance)
    robot_file: str
    robot_hash: str
    status: str
    failed_step: int | None
    error: str
    rows: int = -1  # the number of rows written, as the writer counted them
    versions: dict | None = None  # Python's and the numerical libraries' versions
    # The platform it ran on (pipeline.platform.Platform.to_dict()); None in a log written
    # before logs recorded it: an unknown platform.
    platform: dict | None = None
    # Where the log came from: None for the simulator's; for a log the importer wrote, its
    # ``pipeline.import`` record (the source file, its hash and format, the mapping, the
    # conventions, the time base and the consistency check; pipeline.importer).
    imported: dict | None = None

    @property
    def origin(self) -> str:
        return "simulated" if self.imported is None else "imported"

    @property
    def name(self) -> str:
        return self.spec["name"]


# An imported log's own hashes (JSON {"table", "record"}): the SHA-256 of its columns' values
# and of its pipeline.import text, checked on every read.
IMPORT_HASH_KEY = "pipeline.import_sha256"
# A simulated log's seal: the SHA-256 of its columns' values (:class:`TableDigest`), checked
# on every read, reuse included. Its spec would make it again, bitwise, but only if someone
# knew to: without the seal an edited or byte-damaged log whose metadata is intact would be
# analysed (and reused by ``run``) as if it were the simulator's.
SEAL_KEY = "pipeline.table_sha256"


class TableDigest:
    """SHA-256 of a table's values, column by column in name order, each column's values as
    little-endian bytes in row order (a list column's flattened): the same for the table as
    written and as read back row group by row group, whatever the chunking."""

    def __init__(self, names: list[str]):
        self._h = {n: hashlib.sha256() for n in sorted(names)}

    def update(self, table: pa.Table) -> None:
        for name, h in self._h.items():
            for chunk in table.column(name).chunks:
                listed = pa.types.is_list(chunk.type) or pa.types.is_fixed_size_list(chunk.type)
                values = chunk.flatten() if listed else chunk
                x = values.to_numpy(zero_copy_only=False)
                h.update(np.ascontiguousarray(x, dtype=x.dtype.newbyteorder("<")).tobytes())

    def hexdigest(self) -> str:
        top = hashlib.sha256()
        for name, h in self._h.items():
            top.update(name.encode() + b"\0" + h.digest())
        return top.hexdigest()


def _arrow_column(values: np.ndarray) -> pa.Array:
    values = np.ascontiguousarray(values)
    if values.ndim == 1:
        return pa.array(values)
    flat = pa.array(values.reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, values.shape[1])


def seal_keys(metadata: dict[str, str], digest: TableDigest) -> dict[str, str]:
    """The keys that seal a log whose columns hashed to ``digest``: an imported log's own
    hashes (IMPORT_HASH_KEY: its columns and its import record), a simulated log's SEAL_KEY."""
    if "pipeline.import" in metadata:
        return {IMPORT_HASH_KEY: json.dumps({
            "table": digest.hexdigest(),
            "record": hashlib.sha256(metadata["pipeline.import"].encode()).hexdigest()})}
    return {SEAL_KEY: digest.hexdigest()}


def write_table(path: Path, columns: dict[str, np.ndarray], metadata: dict[str, str]) -> None:
    """Write columns (1-D, or 2-D as fixed-size lists) and metadata to Parquet, atomically,
    sealed (:func:`seal_keys`)."""
    path = Path(path)
    table = pa.table({k: _arrow_column(v) for k, v in columns.items()})
    digest = TableDigest(table.column_names)
    digest.update(table)
    metadata = metadata | seal_keys(metadata, digest)
    table = table.replace_schema_metadata({k.encode(): v.encode() for k, v in metadata.items()})
    tmp = atomic_target(path)
    try:
        pq.write_table(table, tmp, row_group_size=ROW_GROUP, compression="zstd")
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:  # pyarrow's IOError on a full disk is an OSError too
        raise cannot_write(path, exc) from None
    finally:
        tmp.unlink(missing_ok=True)


class LogWriter:
    """A log written row group by row group into a temporary file beside ``path``, so a long
    run's memory stays at one row group; :meth:`close` puts the keys known only at the end
    (status, failed step, error, row count) and the seal of the columns written
    (:func:`seal_keys`) into the Parquet footer, then fsyncs and renames: a run killed before
    that leaves no file that looks complete (architecture §6).

    Use as a context manager: leaving it without :meth:`close` removes the temporary file.
    """

    def __init__(self, path: Path, metadata: dict[str, str]):
        self.path = Path(path)
        self.metadata = metadata
        self.rows = 0
        self._tmp = atomic_target(self.path)
        self._writer: pq.ParquetWriter | None = None
        self._digest: TableDigest | None = None

    def write(self, columns: dict[str, np.ndarray]) -> None:
        """Append one row group (every column, same length)."""
        table = pa.table({k: _arrow_column(v) for k, v in columns.items()})
        try:
            if self._writer is None:
                schema = table.schema.with_metadata(
                    {k.encode(): v.encode() for k, v in self.metadata.items()})
                self._writer = pq.ParquetWriter(self._tmp, schema, compression="zstd")
                self._digest = TableDigest(table.column_names)
            self._writer.write_table(table, row_group_size=ROW_GROUP)
            self._digest.update(table)
        except OSError as exc:
            raise cannot_write(self.path, exc) from None
        self.rows += table.num_rows

    def close(self, final: dict[str, str]) -> Path:
        """Write the footer with ``final`` keys and move the file into place."""
        if self._writer is None:
            raise ValueError("a log needs at least one write, even of zero rows")
        try:
            self._writer.add_key_value_metadata(
                {**self.metadata, **final, **seal_keys(self.metadata, self._digest)})
            self._writer.close()
            with open(self._tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.replace(self._tmp, self.path)
        except OSError as exc:
            raise cannot_write(self.path, exc) from None
        return self.path

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, *exc) -> None:
        if self._writer is not None and exc[0] is not None:
            with contextlib.suppress(Exception):
                self._writer.close()
        self._tmp.unlink(missing_ok=True)


def static_metadata(meta: LogMeta) -> dict[str, str]:
    """The keys of a log known before it runs (the spec, the code, the robot, the versions)."""
    return {k: v for k, v in log_metadata(meta).items() if k not in FINAL_KEYS}


FINAL_KEYS = ("pipeline.status", "pipeline.failed_step", "pipeline.error", "pipeline.rows")


def log_metadata(meta: LogMeta) -> dict[str, str]:
    return {
        "pipeline.spec": json.dumps(meta.spec, sort_keys=True),
        "pipeline.spec_hash": meta.spec_hash,
        "pipeline.sim_version": meta.sim_version,
        "pipeline.robot_file": meta.robot_file,
        "pipeline.robot_hash": meta.robot_hash,
        "pipeline.status": meta.status,
        "pipeline.failed_step": "" if meta.failed_step is None else str(meta.failed_step),
        "pipeline.error": meta.error,
        "pipeline.rows": str(meta.rows),
        "pipeline.versions": json.dumps(meta.versions or library_versions(SIM_LIBRARIES),
                                        sort_keys=True),
        "pipeline.platform": json.dumps(meta.platform or fingerprint().to_dict(),
                                        sort_keys=True),
    } | ({} if meta.imported is None else {
        "pipeline.origin": "imported",
        "pipeline.import": json.dumps(meta.imported, sort_keys=True)})


def _open(path: Path, handle=None) -> pq.ParquetFile:
    """The Parquet file at ``path`` (read through ``handle`` when one is open on it)."""
    path = Path(path)
    if handle is None and not path.is_file():
        raise LogError(f"{path}: log file not found")
    try:
        return pq.ParquetFile(path if handle is None else handle)
    except (pa.ArrowInvalid, OSError) as exc:
        raise LogError(f"{path}: not a readable Parquet log ({str(exc).splitlines()[0]})") from None


def file_metadata(path: Path) -> dict[str, str]:
    """The key-value metadata of a Parquet file's footer (where :class:`LogWriter` puts the
    keys it learns at the end of a run), without Arrow's own schema key."""
    return _footer(_open(path))


def _footer(pf: pq.ParquetFile) -> dict[str, str]:
    md = pf.metadata.metadata or {}
    return {k.decode(): v.decode() for k, v in md.items() if k != b"ARROW:schema"}


def read_meta(path: Path) -> LogMeta:
    """The log's metadata; a missing key is a LogError naming it."""
    return _meta(Path(path), _open(path))


def _meta(path: Path, pf: pq.ParquetFile) -> LogMeta:
    md = _footer(pf)
    for key in META_KEYS:
        if f"pipeline.{key}" not in md:
            raise LogError(f"{path}: metadata key pipeline.{key} missing")
    try:
        spec = json.loads(md["pipeline.spec"])
    except json.JSONDecodeError:
        raise LogError(f"{path}: metadata key pipeline.spec is not JSON") from None
    failed = md.get("pipeline.failed_step", "")
    try:
        rows = int(md["pipeline.rows"])
        failed_step = int(failed) if failed else None
        versions = json.loads(md["pipeline.versions"])
    except (ValueError, json.JSONDecodeError):
        raise LogError(f"{path}: metadata keys pipeline.rows, pipeline.failed_step or "
                       f"pipeline.versions are not what the writer writes") from None
    if not isinstance(spec, dict) or not isinstance(versions, dict):
        raise LogError(f"{path}: metadata key pipeline.spec or pipeline.versions is not a "
                       f"mapping")
    return LogMeta(spec, md["pipeline.spec_hash"], md["pipeline.sim_version"],
                   md["pipeline.robot_file"], md["pipeline.robot_hash"], md["pipeline.status"],
                   failed_step, md.get("pipeline.error", ""), rows, versions,
                   _platform(path, md.get("pipeline.platform")), _imported(path, md))


def _imported(path: Path, md: dict[str, str]) -> dict | None:
    """The import record of a log the importer wrote; None for the simulator's."""
    origin = md.get("pipeline.origin", "simulated")
    if origin == "simulated":
        return None
    if origin != "imported" or "pipeline.import" not in md:
        raise LogError(f"{path}: metadata key pipeline.origin: {origin!r} without the "
                       f"pipeline.import record of an imported log")
    try:
        record = json.loads(md["pipeline.import"])
    except json.JSONDecodeError:
        raise LogError(f"{path}: metadata key pipeline.import is not JSON") from None
    if not isinstance(record, dict):
        raise LogError(f"{path}: metadata key pipeline.import is not a mapping")
    missing = [k for k in IMPORT_KEYS if k not in record]
    if missing:
        raise LogError(f"{path}: metadata key pipeline.import: no {missing[0]!r} (the import "
                       f"record holds {', '.join(IMPORT_KEYS)})")
    return record


def _platform(path: Path, text: str | None) -> dict | None:
    """The recorded platform; None (unknown) for a log written before logs recorded one."""
    if text is None:
        return None
    try:
        record = json.loads(text)
    except json.JSONDecodeError:
        raise LogError(f"{path}: metadata key pipeline.platform is not JSON") from None
    if not isinstance(record, dict):
        raise LogError(f"{path}: metadata key pipeline.platform is not a mapping")
    return record


def num_rows(path: Path) -> int:
    return _open(path).metadata.num_rows


def read_footer(path: Path) -> tuple[LogMeta, int]:
    """The log's metadata and its row count, from one read of its footer."""
    pf = _open(path)
    return _meta(Path(path), pf), pf.metadata.num_rows


def _to_numpy(col: pa.ChunkedArray | pa.Array) -> np.ndarray:
    """A column as an array: a vector column (a fixed-size list, as the logs are written) as
    N×width, its width from its type."""
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_fixed_size_list(col.type):
        return col.flatten().to_numpy(zero_copy_only=False).reshape(-1, col.type.list_size)
    if pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
        raise LogError(f"a vector column of variable length ({col.type}); the logs' vectors "
                       "are fixed-size lists")
    return col.to_numpy(zero_copy_only=False)


def require_columns(path: Path, columns: list[str]) -> None:
    """A LogError naming the first of ``columns`` the log lacks."""
    _check_columns(path, _open(path), columns)


def _check_columns(path: Path, pf: pq.ParquetFile, columns: list[str]) -> None:
    all_names = pf.schema_arrow.names
    twice = sorted({n for n in all_names if all_names.count(n) > 1})
    if twice:
        raise _damaged(path, f"column {twice[0]}", "named twice in the file")
    names = set(all_names)
    for c in columns:
        if c not in names:
            raise LogError(f"{path}: required column {c!r} missing")


def read_columns(path: Path, columns: list[str], start: int = 0,
                 stop: int | None = None) -> dict[str, np.ndarray]:
    """Columns for rows [start, stop) as arrays (vectors as N×k), read by row group."""
    return concat_columns(iter_columns(path, columns, start, stop), columns)


def iter_columns(path: Path, columns: list[str], start: int = 0,
                 stop: int | None = None) -> Iterator[dict[str, np.ndarray]]:
    """Yield the columns row group by row group, clipped to [start, stop)."""
    return _row_groups(path, _open(path), columns, start, stop)


def _row_groups(path: Path, pf: pq.ParquetFile, columns: list[str], start: int,
                stop: int | None) -> Iterator[dict[str, np.ndarray]]:
    _check_columns(path, pf, columns)
    stop = pf.metadata.num_rows if stop is None else stop
    offset, read = 0, False
    for rg in range(pf.num_row_groups):
        n = pf.metadata.row_group(rg).num_rows
        lo, hi = max(start - offset, 0), min(stop - offset, n)
        if hi > lo:
            t = pf.read_row_group(rg, columns=columns)
            yield {c: _to_numpy(t.column(c))[lo:hi] for c in columns}
            read = True
        offset += n
        if offset >= stop:
            break
    if not read:  # no rows in range: empty columns of the file's types (vectors 0×width)
        schema = pf.schema_arrow
        yield {c: _to_numpy(pa.array([], type=schema.field(c).type)) for c in columns}


def concat_columns(chunks: Iterable[dict[str, np.ndarray]], columns: list[str]
                   ) -> dict[str, np.ndarray]:
    """Chunks of the same columns joined along time (at least one chunk: a file's reader
    yields empty columns of its types when no row is in range)."""
    parts = list(chunks)
    return {c: np.concatenate([p[c] for p in parts]) for c in columns}


@dataclass(frozen=True)
class VerifiedLog:
    """A log that passed :func:`verify_log`: its metadata, the spec it records, the SHA-256 of
    the bytes that were verified, and its table, read lazily by row group through the file
    the verification opened (the same file, even if the path is replaced meanwhile)."""

    path: Path
    meta: LogMeta
    spec: Spec
    sha256: str = ""
    rows: int = 0
    _file: pq.ParquetFile | None = field(default=None, repr=False, compare=False)

    def _parquet(self) -> pq.ParquetFile:
        if self._file is None:  # unpickled in another process: the same bytes, or nothing
            handle, sha = _hashed(self.path)
            if sha != self.sha256:
                raise _damaged(self.path, "content", "the file changed after it was verified")
            object.__setattr__(self, "_file", _open(self.path, handle))
        return self._file

    def __getstate__(self) -> dict:
        """Pickled (to a worker of the report) without its open file: a worker reads the
        table by path."""
        return {**self.__dict__, "_file": None}

    def column_names(self) -> list[str]:
        """The table's columns, in the file's order."""
        return list(self._parquet().schema_arrow.names)

    def require(self, columns: list[str]) -> None:
        """A LogError naming the first of ``columns`` the log lacks."""
        _check_columns(self.path, self._parquet(), columns)

    def iter_columns(self, columns: list[str], start: int = 0,
                     stop: int | None = None) -> Iterator[dict[str, np.ndarray]]:
        """The columns row group by row group, clipped to [start, stop)."""
        return _row_groups(self.path, self._parquet(), columns, start, stop)

    def columns(self, columns: list[str], start: int = 0,
                stop: int | None = None) -> dict[str, np.ndarray]:
        """Columns for rows [start, stop) as arrays (vectors as N×k)."""
        return concat_columns(self.iter_columns(columns, start, stop), columns)


def _damaged(path: Path, check: str, detail: str) -> LogDamaged:
    return LogDamaged(f"{path}: {check}: {detail} (tampered or damaged; nothing written)")


def verify_log(path: Path | str, digest: Callable[[Path], str] = file_digest
               ) -> VerifiedLog:
    """Check a log against its own metadata before anything believes it (architecture §6).

    - the metadata spec hashes, canonically, to ``pipeline.spec_hash`` and is a valid spec;
    - the row count is the recorded one, and fits the status: every step of a ``complete``
      run, the steps before the failing one of a ``failed`` run, up to and including the
      divergence step of a ``diverged`` one;
    - ``step`` is 0, 1, …, n − 1 and ``t`` is step·dt, as the simulator writes them;
    - a robot file on disk hashes to ``pipeline.robot_hash``: the analysis rebuilds Γ from it.
      It is looked for at the recorded ``pipeline.robot_file``, then as the spec's
      ``robot.file`` beside the log and on the spec search path (logs move between machines);
    - every numeric column is finite, but the condition numbers (``MAY_BE_INFINITE``), which
      may be +inf at an exact singularity and never NaN;
    - the columns' values hash to the seal their writer recorded (SEAL_KEY for a simulated
      log, IMPORT_HASH_KEY for an imported one): a value edited, a column removed or cast, a
      byte damaged where it still decodes.

    ``digest``: how a robot file is hashed (the artefact store's, which hashes each once).

    A missing or unreadable file or metadata key is a LogError (exit 2); a failed check is a
    LogDamaged (exit 1) naming the file, the check and the first offending step. Reads the log
    by row group: memory stays bounded by one row group.
    """
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: log file not found")
    # One open file for the hash and the checks: what is verified is what was hashed, and the
    # table is read later through it (the same bytes, even if the path is replaced
    # meanwhile). pyarrow's file, not Python's: nothing to close by hand; read, not mapped:
    # a long log's pages do not stay in the process's memory.
    handle, sha = _hashed(path)
    pf = _open(path, handle)
    meta = _meta(path, pf)
    spec = _verified_spec(path, meta, pf.metadata.num_rows)
    spec._robot_path = _recorded_robot(path, meta, spec, digest)
    imported = meta.imported is not None
    sealed = _import_hashes(path, pf)["table"] if imported else _seal(path, pf)
    table = TableDigest(pf.schema_arrow.names)
    try:
        _check_rows(path, pf, spec.mission.dt, table)
    except (OSError, pa.ArrowException) as exc:  # a data page that does not decode
        raise _damaged(path, "data", f"a row group does not read "
                       f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
                       ) from None
    if table.hexdigest() != sealed:
        raise _damaged(path, IMPORT_HASH_KEY if imported else SEAL_KEY,
                       "the columns' values are not the ones the "
                       + ("import wrote (changed after the import)" if imported else
                          "simulator wrote (changed or damaged since the run)"))
    return VerifiedLog(path, meta, spec, sha, pf.metadata.num_rows, pf)


def _hashed(path: Path) -> tuple[pa.NativeFile, str]:
    """The file opened for reading and the SHA-256 of its bytes, read through that handle
    (rewound): what is read later through it is what was hashed."""
    try:
        handle = pa.OSFile(str(path))
        sha = hashlib.sha256()
        while chunk := handle.read(1 << 22):
            sha.update(chunk)
        handle.seek(0)
    except (pa.ArrowInvalid, OSError) as exc:
        raise LogError(f"{path}: not a readable Parquet log ({str(exc).splitlines()[0]})"
                       ) from None
    return handle, sha.hexdigest()


def _verified_spec(path: Path, meta: LogMeta, n: int) -> Spec:
    """The spec the metadata records, checked against its hash, and the row count against
    the status. A log written before the inert fields left the spec hash
    (``pipeline.spec.INERT_FIELDS``) records the hash of all its content: that is as good a
    check of its metadata, so it is accepted too."""
    content = {k: v for k, v in meta.spec.items() if k not in ("name", "description")}
    try:
        digest = spec_hash_of(content)
        whole = canonical_hash(content)
    except (TypeError, ValueError):
        raise _damaged(path, "spec hash", "the metadata spec is not canonical JSON") from None
    if meta.spec_hash not in (digest, whole):
        raise _damaged(path, "spec hash", f"the metadata spec hashes to {digest[:12]}…, the "
                       f"log records {meta.spec_hash[:12]}…")
    try:
        spec = build_spec(str(meta.spec.get("name", path.parent.name)), content, path,
                          find_robot=False)
    except SpecError as exc:
        raise _damaged(path, "spec", f"the metadata spec is not a valid spec ({exc})") from None
    expected = {"complete": spec.n_steps,
                "failed": meta.failed_step, "diverged": None if meta.failed_step is None
                else meta.failed_step + 1}
    if meta.status not in expected:
        raise _damaged(path, "status", f"unknown status {meta.status!r}")
    if n != meta.rows:
        raise _damaged(path, "row count", f"{n} rows, the writer recorded {meta.rows}")
    if expected[meta.status] is None or n != expected[meta.status]:
        raise _damaged(path, "row count", f"{n} rows for a {meta.status} run (expected "
                       f"{expected[meta.status]}: {spec.n_steps} steps, failed step "
                       f"{meta.failed_step})")
    return spec


def _recorded_robot(path: Path, meta: LogMeta, spec: Spec,
                    digest: Callable[[Path], str]) -> Path:
    """The robot file this log was run with, found by its content hash."""
    recorded = Path(meta.robot_file)
    candidates = [recorded] if recorded.is_absolute() else [Path.cwd() / recorded]
    candidates.append(find_on_search_path(spec.robot.file, path.parent))
    found = [c for c in candidates if c is not None and c.is_file()]
    for cand in found:
        if digest(cand) == meta.robot_hash:
            return cand.resolve()
    if not found:
        raise LogError(f"{path}: its robot file {meta.robot_file} is not on disk")
    raise _damaged(path, "robot file", f"{found[0]} on disk is not the robot this log was run "
                   f"with (its hash differs from pipeline.robot_hash)")


def _import_hashes(path: Path, pf: pq.ParquetFile) -> dict:
    """An imported log's own hashes, the import record's checked against its text."""
    md = {k.decode(): v.decode() for k, v in (pf.schema_arrow.metadata or {}).items()}
    try:
        hashes = json.loads(md[IMPORT_HASH_KEY])
        table, record = hashes["table"], hashes["record"]
    except (KeyError, TypeError, json.JSONDecodeError):
        raise _damaged(path, IMPORT_HASH_KEY, "an imported log without its own hashes "
                       "(written before imports carried them, or edited): import it again"
                       ) from None
    if not (isinstance(table, str) and isinstance(record, str)):
        raise _damaged(path, IMPORT_HASH_KEY, "not two hashes")
    if hashlib.sha256(md["pipeline.import"].encode()).hexdigest() != record:
        raise _damaged(path, "metadata key pipeline.import", "the import record is not the "
                       "one the import wrote (edited after the import)")
    return hashes


def _seal(path: Path, pf: pq.ParquetFile) -> str:
    """A simulated log's seal (SEAL_KEY): the SHA-256 its writer recorded of its columns."""
    seal = _footer(pf).get(SEAL_KEY, "")
    if len(seal) != 64:
        raise _damaged(path, SEAL_KEY, "a simulated log without the seal of its columns "
                       "(written before logs carried one, or edited): run it again")
    return seal


def _check_rows(path: Path, pf: pq.ParquetFile, dt: float, digest: TableDigest | None = None
                ) -> None:
    """Steps numbered 0…n−1, t = step·dt, and finite values, row group by row group; each
    row group into ``digest`` when given (the log's seal)."""
    names = pf.schema_arrow.names
    _check_columns(path, pf, ["step", "t"])
    offset = 0
    for rg in range(pf.num_row_groups):
        t = pf.read_row_group(rg)
        if digest is not None:
            digest.update(t)
        k = np.arange(offset, offset + t.num_rows)
        step = t.column("step").to_numpy()
        bad = np.flatnonzero(step != k)
        if bad.size:
            raise _damaged(path, "step column", f"row {k[bad[0]]} holds step "
                           f"{int(step[bad[0]])}: steps are not 0, 1, … once each")
        tt = t.column("t").to_numpy()
        bad = np.flatnonzero(tt != k * dt)
        if bad.size:
            raise _damaged(path, "t column", f"step {k[bad[0]]}: t = {float(tt[bad[0]])!r}, "
                           f"not step·dt = {float(k[bad[0]] * dt)!r}")
        for name in names:
            col = t.column(name)
            typ = col.type.value_type if pa.types.is_fixed_size_list(col.type) else col.type
            if not pa.types.is_floating(typ):
                continue
            x = _to_numpy(col)
            ok = (~np.isnan(x) & (x != -np.inf)) if name in MAY_BE_INFINITE else np.isfinite(x)
            if x.ndim > 1:
                ok = ok.all(axis=1)
            bad = np.flatnonzero(~ok)
            if bad.size:
                raise _damaged(path, f"column {name}", f"step {k[bad[0]]} is not finite")
        offset += t.num_rows
