"""The importer's round-three cases (issue 49 item 6): each refused in one line naming the
file and the field, or read as written; nothing read wrongly.

- text in a binary format's q or t column (Parquet strings, lists of strings, an npz of
  text) is not parsed into numbers: binary formats write numbers as numbers;
- float32 stamps are judged at float32's resolution, not float64's;
- a column named twice in a list (q12 never read) is refused;
- a selection past the file's columns (``--time '[5]'``) is refused, not a traceback;
- a corrupt npz member (a bad CRC-32) is refused, not a traceback.
"""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import run_cli_in_process

from pipeline.errors import SpecError
from pipeline.importer.mapping import load_mapping
from pipeline.logs import verify_log
from pipeline.store.door import import_log


@pytest.fixture(scope="module")
def cols(short_logs):
    return verify_log(short_logs["short_nominal"]).columns(["t", "q", "v"])


def _mapping(**fields):
    return load_mapping(None, {"robot": "short_nominal", **fields})


def _parquet(path, **columns):
    pq.write_table(pa.table(columns), path)
    return path


def test_text_in_a_parquet_column_is_refused_not_parsed(cols, tmp_path):
    text_t = _parquet(tmp_path / "t.parquet", t=[repr(x) for x in cols["t"]],
                      q=list(cols["q"]), v=list(cols["v"]))
    with pytest.raises(SpecError, match=r"column 't': string values, not numbers"):
        import_log(text_t, _mapping(), "t", tmp_path / "logs")
    text_q = _parquet(tmp_path / "q.parquet", t=cols["t"],
                      q=[[repr(x) for x in row] for row in cols["q"]], v=list(cols["v"]))
    with pytest.raises(SpecError, match=r"column 'q': string values, not numbers"):
        import_log(text_q, _mapping(), "q", tmp_path / "logs")
    assert not (tmp_path / "logs").exists()


def test_text_in_an_npz_column_named_in_a_list_is_refused(cols, tmp_path):
    arrays = {"t": cols["t"], "v": cols["v"]}
    arrays |= {f"q{i}": cols["q"][:, i].astype(str) for i in range(13)}
    src = tmp_path / "x.npz"
    np.savez(src, **arrays)
    with pytest.raises(SpecError, match=r"q0: not numbers \(<U"):
        import_log(src, _mapping(q=[f"q{i}" for i in range(13)]), "x", tmp_path / "logs")


def test_a_column_named_twice_is_refused(cols, tmp_path):
    names = [f"q{i}" for i in range(12)] + ["q11"]
    src = tmp_path / "x.npz"
    np.savez(src, t=cols["t"], v=cols["v"], **{f"q{i}": cols["q"][:, i] for i in range(13)})
    with pytest.raises(SpecError, match=r"field q: column 'q11' named twice"):
        import_log(src, _mapping(q=names), "x", tmp_path / "logs")


def test_float32_stamps_are_judged_at_their_own_resolution(cols, tmp_path):
    """Stamps written as float32 from k·dt lie up to float32's half-ulp off it (about 1e-7 s
    at 3 s): within their resolution, taken; the same offsets in float64 stamps are jitter."""
    t32 = cols["t"].astype(np.float32)
    assert np.max(np.abs(t32.astype(float) - cols["t"])) > 1e-9  # not float64's exactness
    src = _parquet(tmp_path / "f32.parquet", t=pa.array(t32, type=pa.float32()),
                   q=list(cols["q"]), v=list(cols["v"]))
    done = import_log(src, _mapping(), "f32", tmp_path / "logs")
    time = verify_log(done.path).meta.imported["time"]
    assert time["resolution"] >= float(np.spacing(np.float32(t32.max())))


def test_a_positional_selection_past_the_columns_is_one_line(cols, tmp_path):
    src = _parquet(tmp_path / "x.parquet", t=cols["t"], q=list(cols["q"]), v=list(cols["v"]))
    r = run_cli_in_process("import", src, "--robot", "short_nominal", "--time", "[5]",
                           "--out", tmp_path / "logs")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "field time" in lines[0] and "column 5" in lines[0], lines
    assert not (tmp_path / "logs").exists()


def test_a_corrupt_npz_member_is_one_line(cols, tmp_path):
    buf = io.BytesIO()
    np.savez(buf, t=cols["t"], q=cols["q"], v=cols["v"])
    data = bytearray(buf.getvalue())
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as z:
        info = z.getinfo("q.npy")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 200
    data[start:start + 8] = b"\xff" * 8  # stored (not compressed): only the CRC can tell
    src = tmp_path / "crc.npz"
    src.write_bytes(bytes(data))
    r = run_cli_in_process("import", src, "--robot", "short_nominal", "--out",
                           tmp_path / "logs")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "crc.npz" in lines[0] and "'q'" in lines[0], lines


def test_a_bags_column_options_are_refused_not_recorded(tmp_path):
    """A bag's t, q and v come from its topics: --q given with a bag was ignored and yet
    recorded in the imported log's mapping as if it had been read."""
    from pipeline.importer.bags import read_bag

    mapping = load_mapping(None, {"robot": "short_nominal", "q": "states.x[:, 0:13]",
                                  "topics": {"odometry": "/odom", "joints": "/joints"}})
    with pytest.raises(SpecError, match="field q: a rosbag log's t, q and v come from its "
                                        "topics"):
        read_bag(tmp_path / "bag", mapping, "rosbag", [])


def test_a_timestamp_time_column_imports_as_before(cols, tmp_path):
    """pandas writes a time column as timestamp[ns]: a time, not text; it imports (its
    ticks in the unit --time-unit names, as before the Arrow types were checked)."""
    ns = (cols["t"] * 1e9).round().astype("int64")
    src = _parquet(tmp_path / "ts.parquet", t=pa.array(ns, pa.timestamp("ns")),
                   q=list(cols["q"]), v=list(cols["v"]))
    done = import_log(src, _mapping(time_unit="ns"), "ts", tmp_path / "logs")
    assert verify_log(done.path).rows == len(cols["t"])
