"""Read t, q and v out of a foreign log: CSV, Parquet, NumPy ``.npz`` (ROS 2 bags and MCAP in
:mod:`pipeline.importer.bags`). Nothing is converted here but the time unit: the columns come
out as the file holds them, in its own conventions.

The time stamps' resolution is read from the file, for the time base's check
(:mod:`pipeline.importer.timebase`): half a unit of the last decimal a CSV prints, half a
tick of an integer stamp, the rounding of a float64 stamp (both ends of a difference).
"""

from __future__ import annotations

import hashlib
import io
import os
import re
import stat
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.bounded_read import read_at_most
from pipeline.budget import Budget
from pipeline.errors import SpecError
from pipeline.importer.mapping import TIME_UNITS, ImportMapping
from pipeline.importer.selection import parse_selection, select
from pipeline.shapes import RobotShape

# The import's peak memory over the size of the data it reads: measured 11x for a binary log
# (docs/importing.md, "Size and memory"); a CSV's text is larger than its numbers, so the same
# factor over its file size is conservative.
IMPORT_COPIES = 12


@dataclass(frozen=True)
class SourceBytes:
    """A log file's bytes, read once: what is parsed and what is hashed are the same bytes
    (a pipe's, or a file's that is replaced while the import runs)."""

    path: Path  # for messages
    data: bytes
    sha256: str


# A source that is not a regular file (a pipe, a device) has no size to judge before it is
# read: it is read up to this many bytes, then refused (a log that large is saved to a file).
STREAM_MAX_BYTES = 256 << 20


def read_bytes(source: Path) -> SourceBytes:
    """The file's bytes and their SHA-256, refused when they alone would not fit the memory
    budget: before they are read (a regular file, by its size) or as soon as they pass it (a
    pipe). What its data need once decoded is each format's check (:func:`check_size`)."""
    limit = int(Budget.from_environment().memory_bytes)
    try:
        with open(source, "rb") as fh:
            st = os.fstat(fh.fileno())
            regular = stat.S_ISREG(st.st_mode)
            if regular and st.st_size > limit:
                check_size(source, st.st_size, copies=1)
            # In chunks, so only what is there is held: a regular file up to the budget, a
            # stream or a device (a FIFO, /dev/zero) up to STREAM_MAX_BYTES as well.
            data = read_at_most(fh, limit if regular else min(STREAM_MAX_BYTES, limit))
    except IsADirectoryError:
        raise SpecError(f"{source}: a folder, not a log file (a ROS 2 bag's folder is "
                        f"--format rosbag)") from None
    except OSError as exc:
        raise SpecError(f"{source}: cannot read: {exc.strerror or exc}") from None
    check_size(source, len(data), copies=1)
    if not regular and len(data) > STREAM_MAX_BYTES:
        raise SpecError(f"{source}: not a regular file (a pipe or a device) and more than "
                        f"{STREAM_MAX_BYTES >> 20} MiB of it; save it to a file and import "
                        "that")
    return SourceBytes(source, data, hashlib.sha256(data).hexdigest())


@dataclass(frozen=True)
class RawLog:
    """A foreign log's columns as read, time in seconds."""

    t: np.ndarray | None  # N, seconds; None when the log has no time stamps
    t_resolution: np.ndarray | None  # N, seconds: how finely each stamp is written
    q: np.ndarray  # N×13 in the log's conventions
    v: np.ndarray  # N×12
    s_min_G: np.ndarray | None = None  # N: the source's own σ_min(Γ), where it logged one


def float_resolution(t: np.ndarray, accumulated: bool = True,
                     written: np.dtype | type = np.float64) -> np.ndarray:
    """How far stamps t_k written as floats of type ``written`` may lie from t_0 + k·dt
    though written from it, per row: two ulps of the largest stamp (its own rounding and that
    of t_0 + k·dt), and for stamps that may have been summed step by step (t += dt; not
    integer ticks) k + 1 roundings of at most an ulp of the time elapsed (t_k − t_0: a sum
    started at an epoch keeps its offset). The ulps are ``written``'s (float32's are 2²⁹
    float64's)."""
    if not len(t):
        return np.zeros(0)

    def ulp(x: float) -> float:
        return float(np.spacing(np.asarray(x, dtype=written)))

    base = 2 * ulp(float(np.max(np.abs(t))))
    if not accumulated:
        return np.full(len(t), base)
    return base + (np.arange(len(t)) + 1) * ulp(float(np.max(np.abs(t - t[0]))))


_DECIMAL = re.compile(r"^[+-]?(\d*)(?:\.(\d*))?(?:[eE]([+-]?\d+))?$")


def printed_resolution(text: np.ndarray) -> np.ndarray:
    """How finely each printed stamp is written, per row, from the writer's habit read off all
    rows: every row with the same number of decimals is a fixed-decimal writer (``%.3f``: half
    a unit of the last decimal); a row with 15 significant digits or more is a writer of the
    shortest text that reads back the same float (Python's repr, pandas' default), whose rows
    are exact (0: the float's own rounding is :func:`float_resolution`'s); else a writer of S
    significant digits (``%g``), S the most any row has: half a unit of each row's S-th."""
    parts = [_DECIMAL.match(s) for s in text]
    if any(m is None for m in parts):
        k = next(i for i, m in enumerate(parts) if m is None)
        raise ValueError(f"row {k}: {text[k]!r} is not a number")
    decimals = np.array([len(m[2] or "") - int(m[3] or 0) for m in parts])
    if decimals.min() == decimals.max():
        return np.full(len(text), 0.5 * 10.0 ** -float(decimals[0]))
    digits = np.array([len((m[1] + (m[2] or "")).lstrip("0")) for m in parts])
    if digits.max() >= 15:
        return np.zeros(len(text))
    value = np.abs(np.array([float(s) for s in text]))
    exponent = np.floor(np.log10(np.where(value > 0, value, 1.0)))
    return np.where(value > 0, 0.5 * 10.0 ** (exponent - digits.max() + 1), 0.0)


def _real_numbers(source: Path, name: str, value: Any) -> np.ndarray:
    """``value`` as an array, refused when it holds complex numbers (NumPy would drop their
    imaginary parts with a warning), booleans (it would read them as 0 and 1) or text (it
    would parse it: a binary log's numbers are numbers). A CSV's text is parsed by its own
    reader before this."""
    try:
        x = np.asarray(value)
    except (TypeError, ValueError):
        raise SpecError(f"{source}: {name}: not numbers") from None
    if np.iscomplexobj(x):
        raise SpecError(f"{source}: {name}: complex numbers ({x.dtype}); a log's t, q and v "
                        f"are real")
    if x.dtype == bool:
        raise SpecError(f"{source}: {name}: booleans, not numbers")
    if x.dtype.kind in "USV":  # text or bytes in a binary format: not a number written
        raise SpecError(f"{source}: {name}: not numbers ({x.dtype}: text or bytes)")
    return x


def _matrix(source: Path, name: str, value: Any, width: int) -> np.ndarray:
    value = _real_numbers(source, name, value)
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"{source}: {name}: not numbers") from None
    if x.ndim != 2 or x.shape[1] != width:
        raise SpecError(f"{source}: {name}: shape {x.shape}, expected N×{width}")
    return x


def _vector(source: Path, field: str, spec: str | list[str], width: int, get,
            positional=None) -> np.ndarray:
    """One N×width array from a vector column or a selection of columns (``spec`` a text of
    :mod:`pipeline.importer.selection`) or ``width`` scalar columns named."""
    if isinstance(spec, str):
        return _matrix(source, f"{field} ({spec})", select(source, field, spec, get,
                                                           positional)[1], width)
    if len(spec) != width:
        raise SpecError(f"{source}: field {field}: {len(spec)} columns named, {width} needed")
    twice = [c for i, c in enumerate(spec) if c in spec[:i]]
    if twice:
        raise SpecError(f"{source}: field {field}: column {twice[0]!r} named twice (each of "
                        f"the {width} components is its own column)")
    return _matrix(source, field, np.column_stack([_real_numbers(source, c, get(c))
                                                   for c in spec]), width)


def _scalar(source: Path, field: str, spec: str | None, get, positional=None
            ) -> np.ndarray | None:
    """One column of N finite numbers (a selection of one), or None when not mapped."""
    if spec is None:
        return None
    x = _real_numbers(source, f"{field} ({spec})",
                      select(source, field, spec, get, positional)[1]).astype(float)
    if x.ndim != 1:
        raise SpecError(f"{source}: {field} ({spec}): shape {x.shape}, expected N")
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise SpecError(f"{source}: {field} ({spec}): row {bad[0]} is not finite")
    return x


def read_csv(src: SourceBytes, mapping: ImportMapping, shape: RobotShape) -> RawLog:
    source = src.path
    check_size(source, len(src.data))  # a CSV's text is larger than its numbers: conservative
    try:
        df = pd.read_csv(io.BytesIO(src.data), dtype=str, skipinitialspace=True,
                         keep_default_na=False)
    except pd.errors.EmptyDataError:
        raise SpecError(f"{source}: empty: no header and no rows") from None
    except (OSError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise SpecError(f"{source}: not a readable CSV file ({str(exc).splitlines()[0]})"
                        ) from None
    if df.empty:
        raise SpecError(f"{source}: no rows (a header of {len(df.columns)} columns only)")

    def get(name: str) -> np.ndarray:
        if name not in df.columns:
            raise SpecError(f"{source}: no column {name!r} (columns: "
                            f"{', '.join(map(str, df.columns[:20]))})")
        try:
            return df[name].astype(float).to_numpy()
        except ValueError:
            raise SpecError(f"{source}: column {name!r} holds something that is not a "
                            f"number") from None

    def positional(cols: slice | int) -> np.ndarray:
        names = df.columns[cols]
        return get(names) if isinstance(cols, int) else np.column_stack(
            [get(c) for c in names]) if len(names) else np.zeros((len(df), 0))

    t = res = None
    if mapping.time is not None:
        scale = TIME_UNITS[mapping.time_unit]
        name = _csv_time_column(source, mapping.time, df.columns)
        t = _finite_stamps(source, mapping.time, get(name) * scale)
        try:
            res = (printed_resolution(df[name].str.strip().to_numpy()) * scale
                   + float_resolution(t))
        except ValueError as exc:
            raise SpecError(f"{source}: column {name!r}: {exc}") from None
    return RawLog(t, res, _vector(source, "q", mapping.q, shape.nq, get, positional),
                  _vector(source, "v", mapping.v, shape.nv, get, positional),
                  _scalar(source, "s_min_G", mapping.s_min_G, get, positional))


def _csv_time_column(source: Path, text: str, columns: pd.Index) -> str:
    """The name of a CSV's time column: named, or one column by position (``[0]``)."""
    sel = parse_selection(text, "time")
    if sel.cols is None:
        return sel.path
    if sel.path or not isinstance(sel.cols, int):
        raise SpecError(f"{source}: field time: {text!r}: a CSV's time is one of its columns, "
                        f"by name or by position ([0])")
    if not -len(columns) <= sel.cols < len(columns):
        raise SpecError(f"{source}: field time: {text!r}: the file has {len(columns)} columns")
    return str(columns[sel.cols])


# Bytes per value of a Parquet physical type once decoded (a boolean becomes a byte).
_PHYSICAL_WIDTH = {"BOOLEAN": 1, "INT32": 4, "FLOAT": 4, "INT64": 8, "DOUBLE": 8, "INT96": 12}


def parquet_decoded_size(meta: pq.FileMetaData) -> int:
    """The bytes a Parquet file's values take once decoded, from its footer, before a row is
    read: each column chunk's value count times its type's width (a text or byte column's
    uncompressed size). Not the footer's ``total_byte_size``: that is the *encoded* size, and
    run-length and dictionary encoding make it a hundredth of the data (10⁷ rows of a robot
    at rest: 158 MB encoded, 2.1 GB decoded)."""
    total = 0
    for i in range(meta.num_row_groups):
        rg = meta.row_group(i)
        for j in range(rg.num_columns):
            c = rg.column(j)
            width = _PHYSICAL_WIDTH.get(c.physical_type)
            total += c.num_values * width if width else c.total_uncompressed_size
    return total


def _numpy_column(col: pa.ChunkedArray) -> np.ndarray:
    if pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type) \
            or pa.types.is_large_list(col.type):
        return np.array(col.to_pylist(), dtype=float)
    return col.to_numpy()


def _arrow_numbers(source: Path, name: str, typ: pa.DataType) -> None:
    """SpecError unless a binary column holds numbers (integers or floats, or lists of them;
    timestamps and durations, as pandas writes a time column): text is not parsed, booleans
    are not 0 and 1."""
    inner = typ
    while pa.types.is_list(inner) or pa.types.is_fixed_size_list(inner) \
            or pa.types.is_large_list(inner):
        inner = inner.value_type
    if not (pa.types.is_integer(inner) or pa.types.is_floating(inner)
            or pa.types.is_timestamp(inner) or pa.types.is_duration(inner)):
        raise SpecError(f"{source}: column {name!r}: {inner} values, not numbers (a binary "
                        f"format's numbers are written as numbers)")


def read_parquet(src: SourceBytes, mapping: ImportMapping, shape: RobotShape) -> RawLog:
    source = src.path
    try:
        pf = pq.ParquetFile(pa.BufferReader(src.data))
        meta = pf.metadata
        check_size(source, parquet_decoded_size(meta), "decoded")
        if meta.num_rows == 0:
            raise SpecError(f"{source}: no rows")
        table = pf.read()
    except (OSError, pa.ArrowInvalid) as exc:
        raise SpecError(f"{source}: not a readable Parquet file ({str(exc).splitlines()[0]})"
                        ) from None

    def get(name: str) -> np.ndarray:
        if name not in table.column_names:
            raise SpecError(f"{source}: no column {name!r} (columns: "
                            f"{', '.join(table.column_names[:20])})")
        _arrow_numbers(source, name, table.schema.field(name).type)
        try:
            return _numpy_column(table.column(name))
        except (ValueError, TypeError):  # a list of another length, or a null, in a row
            raise SpecError(f"{source}: column {name!r}: rows of different lengths or "
                            f"nulls") from None

    def positional(cols: slice | int) -> np.ndarray:
        names = table.column_names[cols]
        return get(names) if isinstance(cols, int) else np.column_stack(
            [get(c) for c in names]) if names else np.zeros((meta.num_rows, 0))

    return RawLog(*_stamps(source, mapping, get, positional),
                  _vector(source, "q", mapping.q, shape.nq, get, positional),
                  _vector(source, "v", mapping.v, shape.nv, get, positional),
                  _scalar(source, "s_min_G", mapping.s_min_G, get, positional))


def _stamps(source: Path, mapping: ImportMapping, get, positional=None
            ) -> tuple[np.ndarray | None, float | None]:
    """Time stamps in seconds and their resolution, from a binary column or key (or a
    selection of one column, :mod:`pipeline.importer.selection`)."""
    if mapping.time is None:
        return None, None
    raw = _real_numbers(source, f"time ({mapping.time})",
                        select(source, "time", mapping.time, get, positional)[1])
    if raw.ndim != 1:
        raise SpecError(f"{source}: time ({mapping.time}): shape {raw.shape}, expected N")
    scale = TIME_UNITS[mapping.time_unit]
    if np.issubdtype(raw.dtype, np.integer) and len(raw):
        # Exact to the tick, then one rounding: ticks counted from the earliest stamp in the
        # stamps' own type (every difference is ≥ 0 and fits it: a uint64 at or above 2⁶³ cast
        # to int64 would wrap to a negative time), as a bag's stamps are. An epoch in seconds
        # would keep only ~2 µs at 10⁹ s; the log's t starts at 0 in any case.
        t = (raw - raw.min()).astype(np.float64) * scale
        return t, 0.5 * scale + float_resolution(t, accumulated=False)
    try:
        t = _finite_stamps(source, mapping.time, raw.astype(float) * scale)
    except (TypeError, ValueError):
        raise SpecError(f"{source}: time ({mapping.time}): not numbers") from None
    if raw.dtype.kind == "f" and raw.dtype.itemsize < 8:  # written coarser than float64
        return t, (float_resolution(raw.astype(float), written=raw.dtype) * scale
                   + float_resolution(t))
    return t, float_resolution(t)


def _finite_stamps(source: Path, name: str, t: np.ndarray) -> np.ndarray:
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise SpecError(f"{source}: time ({name}): row {bad[0]} is not a finite time")
    return t


def _check_npz(src: SourceBytes) -> None:
    """The archive checked from its zip directory and its members' headers before an array is
    read: one that is not a whole zip is refused as such (numpy would try it as a pickle and
    say so), one whose decompressed size is over the memory budget is refused, and so is a
    member whose header claims more bytes than the member holds."""
    source = src.path
    if not zipfile.is_zipfile(io.BytesIO(src.data)):
        raise SpecError(f"{source}: not a .npz file (not a zip archive: empty, truncated or "
                        f"another format)")
    try:
        with zipfile.ZipFile(io.BytesIO(src.data)) as z:
            infos = {i.filename.removesuffix(".npy"): i for i in z.infolist()}
            check_size(source, sum(i.file_size for i in infos.values()), "decompressed")
            for key, info in infos.items():
                with z.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    shape, _, dtype = (np.lib.format.read_array_header_1_0(f) if version ==
                                       (1, 0) else np.lib.format.read_array_header_2_0(f))
                claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if not dtype.hasobject and claimed > info.file_size:
                    raise SpecError(f"{source}: key {key!r}: its header claims shape {shape} "
                                    f"({claimed:,} bytes), the member holds {info.file_size:,}: "
                                    f"damaged")
    except (zipfile.BadZipFile, ValueError, EOFError, OSError) as exc:
        raise SpecError(f"{source}: not a readable .npz file ({str(exc).splitlines()[0]})"
                        ) from None


def read_npz(src: SourceBytes, mapping: ImportMapping, shape: RobotShape) -> RawLog:
    source = src.path
    _check_npz(src)
    try:
        archive = np.load(io.BytesIO(src.data), allow_pickle=mapping.allow_pickle)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise SpecError(f"{source}: not a readable .npz file ({str(exc).splitlines()[0]})"
                        ) from None
    with archive:
        cache: dict[str, Any] = {}

        def get(path: str) -> Any:
            key, *rest = path.split(".")
            if key not in archive.files:
                raise SpecError(f"{source}: no key {key!r} (" + (
                    f"keys: {', '.join(archive.files)})" if archive.files else
                    "the archive holds no arrays)"))
            if key not in cache:
                try:
                    cache[key] = archive[key]
                except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
                    why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                    raise SpecError(f"{source}: key {key!r}: a damaged member of the archive "
                                    f"({why})") from None
                except ValueError:  # an object array: numpy refuses it without pickles
                    raise SpecError(f"{source}: key {key!r} holds a pickled object; loading a "
                                    f"pickle runs code from the file: give --allow-pickle "
                                    f"if you trust it") from None
            node = cache[key]
            for part in rest:
                node = node.item() if isinstance(node, np.ndarray) and node.dtype == object \
                    and node.ndim == 0 else node
                if isinstance(node, dict) and part in node:
                    node = node[part]
                elif hasattr(node, part):
                    node = getattr(node, part)
                else:
                    raise SpecError(f"{source}: {path}: no {part!r} in key {key!r} (it holds "
                                    f"{_holds(node)})")
            return node

        return RawLog(*_stamps(source, mapping, get),
                      _vector(source, "q", mapping.q, shape.nq, get),
                      _vector(source, "v", mapping.v, shape.nv, get),
                      _scalar(source, "s_min_G", mapping.s_min_G, get))


def _holds(node: Any) -> str:
    """What an object read from a file holds, for a message: its keys or attributes, each with
    its shape (an array's) or type."""
    if isinstance(node, np.ndarray):
        return f"an array of shape {node.shape}"
    items = node if isinstance(node, dict) else getattr(node, "__dict__", None)
    if not isinstance(items, dict):
        return f"a {type(node).__name__}"

    def what(x: Any) -> str:
        return f"shape {np.shape(x)}" if isinstance(x, (np.ndarray, list)) else type(x).__name__

    kind = "keys" if isinstance(node, dict) else "attributes"
    return f"{kind} " + ", ".join(f"{k} ({what(x)})" for k, x in list(items.items())[:20])


def check_size(source: Path, nbytes: int, what: str = "", copies: int = IMPORT_COPIES) -> None:
    """Refuse a file whose data would not fit the memory budget of ``run`` (pipeline.budget),
    before it is read: the import holds about IMPORT_COPIES copies of the data at its peak
    (measured, docs/importing.md); the file's own bytes, read once, are one copy."""
    budget = Budget.from_environment().memory_bytes
    if nbytes * copies > budget:
        need = (f"importing it needs about {copies}× that" if copies > 1 else
                "the file alone is")
        raise SpecError(f"{source}: {nbytes / 2**20:,.0f} MiB {what + ' ' if what else ''}of "
                        f"data; {need}, over the memory budget of {budget / 2**30:.3g} GiB "
                        f"(BREVE_MEMORY_BUDGET_GB)")


READERS = {"csv": read_csv, "parquet": read_parquet, "npz": read_npz}
