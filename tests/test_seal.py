"""A simulated log is sealed like an imported one (issue 49): the SHA-256 of its columns'
values, written by the simulator's writer and checked on every read, reuse included.

Each damage is made from a genuine short log the way an edit or a broken copy would leave it
(the metadata kept whole): the log must be refused by ``verify_log``, ``analyze`` (exit 1, one
line naming the file) and ``read_log_table``, and made again by ``run``.
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import footer_metadata, run_cli_in_process

from pipeline.errors import LogDamaged
from pipeline.logs import SEAL_KEY, file_metadata, verify_log
from pipeline.spec import load_spec, with_overrides
from pipeline.store.door import ArtefactStore
from pipeline.store.table import read_log_table

SPEC = with_overrides(load_spec("nominal"), {"mission.duration": 3.0}, name="sealed")


@pytest.fixture(scope="module")
def genuine(tmp_path_factory) -> Path:
    logs = tmp_path_factory.mktemp("seal") / "logs"
    return ArtefactStore(logs).run(SPEC).path


def _copy(src: Path, tmp_path: Path) -> Path:
    """A copy of the genuine log in a logs folder of its own, as ``run`` would find it."""
    dst = tmp_path / "logs" / SPEC.name / "run.parquet"
    dst.parent.mkdir(parents=True)
    shutil.copyfile(src, dst)
    return dst


def _edited(src: Path, dst: Path, edit) -> None:
    """The log rewritten with ``edit`` applied to its table, every metadata key kept (the old
    seal among them)."""
    pq.write_table(edit(pq.read_table(src)).replace_schema_metadata(footer_metadata(src)), dst)


def _sign_flipped_v(t: pa.Table) -> pa.Table:
    """v with every other step's sign flipped: a smooth signal turned into a period-2 one."""
    v = t.column("v").combine_chunks()
    flat = v.flatten().to_numpy().reshape(len(v), -1).copy()
    flat[1::2] *= -1.0
    col = pa.FixedSizeListArray.from_arrays(pa.array(flat.ravel()), v.type.list_size)
    return t.set_column(t.schema.get_field_index("v"), "v", col)


def _q_float32(t: pa.Table) -> pa.Table:
    q = t.column("q").combine_chunks()
    col = pa.FixedSizeListArray.from_arrays(q.flatten().cast(pa.float32()), q.type.list_size)
    return t.set_column(t.schema.get_field_index("q"), "q", col)


def _bytes_damaged(path: Path) -> None:
    """64 random bytes written over the middle of the data pages (the footer left whole)."""
    data = bytearray(path.read_bytes())
    footer = int.from_bytes(data[-8:-4], "little") + 8
    middle = (len(data) - footer) // 2
    data[middle:middle + 64] = np.random.default_rng(49).bytes(64)
    path.write_bytes(bytes(data))


def test_the_seal_is_the_sha256_of_the_columns_values(genuine):
    """Computed here from the file's columns with hashlib: each column's values as
    little-endian bytes in row order (a vector column's flattened), by column name, then one
    SHA-256 over the names and the columns' digests."""
    table = pq.read_table(genuine)
    top = hashlib.sha256()
    for name in sorted(table.column_names):
        col = table.column(name).combine_chunks()
        if pa.types.is_fixed_size_list(col.type):
            col = col.flatten()
        x = col.to_numpy(zero_copy_only=False)
        top.update(name.encode() + b"\0" + hashlib.sha256(
            x.astype(x.dtype.newbyteorder("<")).tobytes()).digest())
    assert file_metadata(genuine)[SEAL_KEY] == top.hexdigest()


@pytest.mark.parametrize("damage", ["v sign-flipped", "q as float32", "v removed",
                                    "64 bytes damaged"])
def test_a_damaged_simulated_log_is_refused_by_every_reader_and_made_again_by_run(
        genuine, tmp_path, damage):
    path = _copy(genuine, tmp_path)
    if damage == "64 bytes damaged":
        _bytes_damaged(path)
    else:
        edit = {"v sign-flipped": _sign_flipped_v, "q as float32": _q_float32,
                "v removed": lambda t: t.drop_columns(["v"])}[damage]
        _edited(genuine, path, edit)
    with pytest.raises(LogDamaged, match="tampered or damaged") as refused:
        verify_log(path)
    assert str(path) in str(refused.value)
    with pytest.raises(LogDamaged, match=str(path)):
        read_log_table(path)
    r = run_cli_in_process("analyze", path, "--out", tmp_path / "out")
    assert r.returncode == 1, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0], lines
    assert not (tmp_path / "out").exists()
    # run: not "up to date", made again, the simulator's bits back.
    again = ArtefactStore(tmp_path / "logs").run(SPEC, quiet=True)
    assert not again.reused
    verify_log(path)
    assert file_metadata(path)[SEAL_KEY] == file_metadata(genuine)[SEAL_KEY]


def test_an_edit_the_seal_catches_is_named_as_the_seal(genuine, tmp_path):
    """v edited where no other check looks (finite, steps and times whole): only the seal
    sees it, and says so."""
    path = _copy(genuine, tmp_path)
    _edited(genuine, path, _sign_flipped_v)
    with pytest.raises(LogDamaged, match=f"{SEAL_KEY}: the columns' values are not the ones "
                                         "the simulator wrote"):
        verify_log(path)


def test_a_log_without_a_seal_is_refused_and_made_again(genuine, tmp_path):
    """A log written before logs carried a seal (or with the key removed)."""
    path = _copy(genuine, tmp_path)
    md = {k: v for k, v in footer_metadata(genuine).items() if k != SEAL_KEY.encode()}
    pq.write_table(pq.read_table(genuine).replace_schema_metadata(md), path)
    with pytest.raises(LogDamaged, match="without the seal of its columns"):
        verify_log(path)
    assert not ArtefactStore(tmp_path / "logs").run(SPEC, quiet=True).reused
    verify_log(path)


def test_a_column_named_twice_is_refused_in_one_line(genuine, tmp_path):
    """A file with two columns of one name (possible in Parquet) is damaged, not a
    traceback of the seal's digest."""
    path = _copy(genuine, tmp_path)
    t = pq.read_table(genuine)
    twice = pa.Table.from_arrays([*t.columns, t.column("t")], names=[*t.column_names, "t"])
    pq.write_table(twice.replace_schema_metadata(footer_metadata(genuine)), path)
    with pytest.raises(LogDamaged, match="column t: named twice"):
        verify_log(path)
