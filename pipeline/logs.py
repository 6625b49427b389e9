"""The run log: one Parquet file per run, the contract between ``sim`` and ``analysis``.

Per-step columns (DESIGN §6), vector columns as fixed-size lists of float64, and schema
metadata under ``pipeline.*`` keys. Files are written atomically: a temporary file in the
same folder, fsynced, then renamed over the target.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.errors import LogError

VECTOR_COLUMNS = {
    "q": 13, "v": 12, "v_c": 3, "v_breve": 9, "v_breve_des": 9, "x_tilde": 9,
}
SCALAR_COLUMNS = (
    "t", "tau", "s_min_G", "kappa_G", "s_min_J", "kappa_J", "gamma", "dt_mu_max",
    "pointing_err_deg", "boresight_err_deg", "com_err", "coverage",
)
META_KEYS = ("spec", "spec_hash", "code_version", "robot_file", "robot_hash", "status")
ROW_GROUP = 65_536
_UMASK = os.umask(0)
os.umask(_UMASK)


@dataclass(frozen=True)
class LogMeta:
    spec: dict
    spec_hash: str
    code_version: str
    robot_file: str
    robot_hash: str
    status: str
    failed_step: int | None
    error: str

    @property
    def name(self) -> str:
        return self.spec["name"]


def _atomic_target(path: Path) -> Path:
    """A fresh temporary file beside ``path``, readable as an ordinary file would be."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.fchmod(fd, 0o666 & ~_UMASK)  # mkstemp makes 0600; the final file should not be
    os.close(fd)
    return Path(tmp)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write bytes to ``path`` atomically (temporary file, fsync, rename)."""
    path = Path(path)
    tmp = _atomic_target(path)
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def _arrow_column(values: np.ndarray) -> pa.Array:
    values = np.ascontiguousarray(values)
    if values.ndim == 1:
        return pa.array(values)
    flat = pa.array(values.reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, values.shape[1])


def write_table(path: Path, columns: dict[str, np.ndarray], metadata: dict[str, str]) -> None:
    """Write columns (1-D, or 2-D as fixed-size lists) and metadata to Parquet, atomically."""
    path = Path(path)
    table = pa.table({k: _arrow_column(v) for k, v in columns.items()})
    table = table.replace_schema_metadata({k.encode(): v.encode() for k, v in metadata.items()})
    tmp = _atomic_target(path)
    try:
        pq.write_table(table, tmp, row_group_size=ROW_GROUP, compression="zstd")
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def log_metadata(meta: LogMeta) -> dict[str, str]:
    return {
        "pipeline.spec": json.dumps(meta.spec, sort_keys=True),
        "pipeline.spec_hash": meta.spec_hash,
        "pipeline.code_version": meta.code_version,
        "pipeline.robot_file": meta.robot_file,
        "pipeline.robot_hash": meta.robot_hash,
        "pipeline.status": meta.status,
        "pipeline.failed_step": "" if meta.failed_step is None else str(meta.failed_step),
        "pipeline.error": meta.error,
    }


def _open(path: Path) -> pq.ParquetFile:
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: log file not found")
    try:
        return pq.ParquetFile(path)
    except (pa.ArrowInvalid, OSError) as exc:
        raise LogError(f"{path}: not a readable Parquet log ({str(exc).splitlines()[0]})") from None


def read_meta(path: Path) -> LogMeta:
    """The log's metadata; a missing key is a LogError naming it."""
    md = _open(path).schema_arrow.metadata or {}
    md = {k.decode(): v.decode() for k, v in md.items()}
    for key in META_KEYS:
        if f"pipeline.{key}" not in md:
            raise LogError(f"{path}: metadata key pipeline.{key} missing")
    try:
        spec = json.loads(md["pipeline.spec"])
    except json.JSONDecodeError:
        raise LogError(f"{path}: metadata key pipeline.spec is not JSON") from None
    failed = md.get("pipeline.failed_step", "")
    return LogMeta(spec, md["pipeline.spec_hash"], md["pipeline.code_version"],
                   md["pipeline.robot_file"], md["pipeline.robot_hash"], md["pipeline.status"],
                   int(failed) if failed else None, md.get("pipeline.error", ""))


def num_rows(path: Path) -> int:
    return _open(path).metadata.num_rows


def _to_numpy(col: pa.ChunkedArray | pa.Array, width: int | None) -> np.ndarray:
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if width is None:
        return col.to_numpy(zero_copy_only=False)
    return col.flatten().to_numpy(zero_copy_only=False).reshape(-1, width)


def require_columns(path: Path, columns: list[str]) -> None:
    """A LogError naming the first of ``columns`` the log lacks."""
    _check_columns(path, _open(path), columns)


def _check_columns(path: Path, pf: pq.ParquetFile, columns: list[str]) -> None:
    names = set(pf.schema_arrow.names)
    for c in columns:
        if c not in names:
            raise LogError(f"{path}: required column {c!r} missing")


def read_columns(path: Path, columns: list[str], start: int = 0,
                 stop: int | None = None) -> dict[str, np.ndarray]:
    """Columns for rows [start, stop) as arrays (vectors as N×k), read by row group."""
    return _concat(iter_columns(path, columns, start, stop), columns)


def iter_columns(path: Path, columns: list[str], start: int = 0,
                 stop: int | None = None) -> Iterator[dict[str, np.ndarray]]:
    """Yield the columns row group by row group, clipped to [start, stop)."""
    pf = _open(path)
    _check_columns(path, pf, columns)
    stop = pf.metadata.num_rows if stop is None else stop
    offset = 0
    for rg in range(pf.num_row_groups):
        n = pf.metadata.row_group(rg).num_rows
        lo, hi = max(start - offset, 0), min(stop - offset, n)
        if hi > lo:
            t = pf.read_row_group(rg, columns=columns)
            yield {c: _to_numpy(t.column(c), VECTOR_COLUMNS.get(c))[lo:hi] for c in columns}
        offset += n
        if offset >= stop:
            break


def _concat(chunks: Iterator[dict[str, np.ndarray]], columns: list[str]) -> dict[str, np.ndarray]:
    parts = list(chunks)
    if not parts:
        return {c: np.empty((0, VECTOR_COLUMNS[c]) if c in VECTOR_COLUMNS else 0) for c in columns}
    return {c: np.concatenate([p[c] for p in parts]) for c in columns}
