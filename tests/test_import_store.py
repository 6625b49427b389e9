"""Imports under the store's rules, and a source hashed as it was read (issue 36, items 2 and 6).

The import's origin hash is of the bytes it parsed (a pipe's, not the empty file's; a bag
changed while it was read is refused); a name holds one import (the same again is reused,
another refused unless --force, two at once never lose one silently); a killed import's
temporary files go at the next one; no log is written through a link out of the logs folder.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import threading
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import run_cli_in_process

from pipeline.errors import OutputError, SpecError
from pipeline.importer.mapping import load_mapping
from pipeline.logs import verify_log
from pipeline.shapes import RobotShape
from pipeline.store.door import import_log


@pytest.fixture(scope="module")
def cols(short_logs):
    return verify_log(short_logs["short_nominal"]).columns(["t", "q", "v"])


def _parquet(path: Path, cols, rows: slice = slice(None)) -> Path:
    pq.write_table(pa.table({"t": cols["t"][rows], "q": list(cols["q"][rows]),
                             "v": list(cols["v"][rows])}), path)
    return path


def _csv_bytes(cols) -> bytes:
    head = ",".join(["t", *(f"q{i}" for i in range(13)), *(f"v{i}" for i in range(12))])
    rows = [",".join(repr(float(x)) for x in (t, *q, *v))
            for t, q, v in zip(cols["t"], cols["q"], cols["v"], strict=True)]
    return ("\n".join([head, *rows]) + "\n").encode()


def _csv_mapping(**fields):
    return load_mapping(None, {"robot": "short_nominal", "format": "csv",
                               "q": [f"q{i}" for i in range(13)],
                               "v": [f"v{i}" for i in range(12)], **fields})


def _mapping(**fields):
    return load_mapping(None, {"robot": "short_nominal", **fields})


# -- item 2: the origin is the bytes read ------------------------------------------------------

def test_a_pipe_is_hashed_as_read_not_as_the_empty_file(cols, tmp_path):
    data = _csv_bytes(cols)
    fifo = tmp_path / "stream"
    os.mkfifo(fifo)

    def feed():
        with open(fifo, "wb") as fh:
            fh.write(data)

    writer = threading.Thread(target=feed)
    writer.start()
    done = import_log(fifo, _csv_mapping(), "piped", tmp_path / "logs")
    writer.join()
    record = verify_log(done.path).meta.imported
    assert record["source_sha256"] == hashlib.sha256(data).hexdigest()
    assert record["source_sha256"] != hashlib.sha256(b"").hexdigest()
    assert done.rows == len(cols["t"])


def test_the_origin_hash_is_of_the_bytes_parsed(cols, tmp_path, monkeypatch):
    """The file is replaced right after it is read: the record keeps the hash of what was
    parsed, not of the replacement (the old code hashed the file again after reading)."""
    import pipeline.importer.run as run_module

    src = _parquet(tmp_path / "a.parquet", cols)
    first = hashlib.sha256(src.read_bytes()).hexdigest()
    real = run_module.read_bytes

    def read_then_replace(path):
        got = real(path)
        _parquet(path, cols, slice(0, 50))  # another file under the same name
        return got

    monkeypatch.setattr(run_module, "read_bytes", read_then_replace)
    done = import_log(src, _mapping(), "replaced", tmp_path / "logs")
    record = verify_log(done.path).meta.imported
    assert record["source_sha256"] == first != hashlib.sha256(src.read_bytes()).hexdigest()
    assert done.rows == len(cols["t"])


def test_a_bag_changed_while_it_is_read_is_refused(tmp_path, monkeypatch):
    """A bag is read by its reader from the file (it seeks): hashed before and after, and
    refused when a recorder still writes it."""
    import pipeline.importer.run as run_module

    bag = tmp_path / "x.mcap"
    bag.write_bytes(b"first")

    def read_while_recording(source, *args):
        with open(source, "ab") as fh:
            fh.write(b" more")

    monkeypatch.setattr(run_module, "read_bag", read_while_recording)
    with pytest.raises(SpecError, match="changed while it was read"):
        run_module.read_source(bag, _mapping(topics={"odometry": "/o", "joints": "/j"}),
                               "mcap", RobotShape(()))


# -- item 6: one import per name ---------------------------------------------------------------

def test_the_same_import_again_is_reused_and_another_refused_unless_forced(cols, tmp_path):
    logs = tmp_path / "logs"
    src = _parquet(tmp_path / "a.parquet", cols)
    done = import_log(src, _mapping(), "run1", logs)
    assert not done.reused
    inode = done.path.stat().st_ino
    again = import_log(src, _mapping(), "run1", logs)
    assert again.reused and again.rows == done.rows and again.path.stat().st_ino == inode
    other = _parquet(tmp_path / "b.parquet", cols, slice(0, 100))
    with pytest.raises(SpecError, match=r"--name run1: .*holds an import of .*a\.parquet.*"
                                        r"--force"):
        import_log(other, _mapping(), "run1", logs)
    assert verify_log(done.path).rows == len(cols["t"])  # the first import is kept whole
    # Imported the same way but read otherwise (a declared unit) is another import too.
    with pytest.raises(SpecError, match="--force"):
        import_log(src, _mapping(angle_unit="deg"), "run1", logs)
    forced = import_log(other, _mapping(), "run1", logs, force=True)
    assert not forced.reused and verify_log(forced.path).rows == 100


def test_the_command_says_up_to_date_and_refuses_another_in_one_line(cols, tmp_path):
    logs = tmp_path / "logs"
    a = _parquet(tmp_path / "a.parquet", cols)
    b = _parquet(tmp_path / "b.parquet", cols, slice(0, 100))
    base = ["--robot", "short_nominal", "--name", "n", "--out", logs]
    assert run_cli_in_process("import", a, *base).returncode == 0
    r = run_cli_in_process("import", a, *base)
    assert r.returncode == 0 and "up to date" in r.stdout, r.stdout + r.stderr
    r = run_cli_in_process("import", b, *base)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--force" in r.stderr
    assert "Traceback" not in r.stderr
    r = run_cli_in_process("import", b, *base, "--force")
    assert r.returncode == 0 and "100 rows" in r.stdout, r.stderr


def test_two_imports_of_one_name_at_once_never_lose_one_silently(cols, tmp_path):
    """Two processes import different sources under one name at the same moment: one writes
    it, the other waits for the lock and is then refused (exit 2): the log is the one whose
    command said it was written."""
    logs = tmp_path / "logs"
    srcs = [_parquet(tmp_path / "a.parquet", cols),
            _parquet(tmp_path / "b.parquet", cols, slice(0, 100))]
    procs = [subprocess.Popen([sys.executable, "-m", "pipeline", "import", str(s), "--robot",
                               "short_nominal", "--name", "same", "--out", str(logs)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for s in srcs]
    outs = [p.communicate(timeout=120) for p in procs]
    codes = [p.returncode for p in procs]
    assert sorted(codes) == [0, 2], outs
    winner = codes.index(0)
    assert "--force" in outs[1 - winner][1]
    rows = verify_log(logs / "imported" / "same" / "run.parquet").rows
    assert rows == (len(cols["t"]), 100)[winner]


def test_a_killed_imports_temporary_file_goes_at_the_next_import(cols, tmp_path):
    folder = tmp_path / "logs" / "imported" / "k"
    folder.mkdir(parents=True)
    stale = folder / ".run.parquet.abc123.tmp"
    stale.write_bytes(b"half a log")
    import_log(_parquet(tmp_path / "a.parquet", cols), _mapping(), "k", tmp_path / "logs")
    assert not stale.exists()
    assert sorted(p.name for p in folder.iterdir()) == ["run.parquet"]


def test_no_import_or_run_writes_through_a_link_out_of_its_folder(cols, tmp_path):
    logs, elsewhere = tmp_path / "logs", tmp_path / "elsewhere"
    (logs / "imported").mkdir(parents=True)
    elsewhere.mkdir()
    (logs / "imported" / "linked").symlink_to(elsewhere)
    with pytest.raises(OutputError, match="a symbolic link out of"):
        import_log(_parquet(tmp_path / "a.parquet", cols), _mapping(), "linked", logs)
    assert list(elsewhere.iterdir()) == []
    (logs / "short_nominal").symlink_to(elsewhere)
    r = run_cli_in_process("run", "short_nominal", "--out", logs)
    assert r.returncode == 2 and "a symbolic link out of" in r.stderr, r.stderr
    assert r.stderr.count("\n") == 1 and list(elsewhere.iterdir()) == []
    # A logs folder that is itself a link (kept on another disk) is fine.
    (tmp_path / "linked_logs").symlink_to(elsewhere)
    done = import_log(_parquet(tmp_path / "b.parquet", cols), _mapping(), "ok",
                      tmp_path / "linked_logs")
    assert (elsewhere / "imported" / "ok" / "run.parquet").is_file() and done.rows
