"""Never a confident wrong answer: a log is checked against its own metadata before it is
believed, and NaN is a failure, never "no difference" (issue 12).

Each tamper or damage class is written from a genuine short log with pyarrow, the way an
edit by hand or a broken copy would leave it, and must be refused with exit 1 (LogDamaged),
one line naming the file, the check and the first offending step, and nothing written.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import footer_metadata, run_cli, run_cli_in_process, sealed

from pipeline.analysis.stages import analyze_log
from pipeline.claims.baselines import compare_logs
from pipeline.errors import LogDamaged
from pipeline.log_layout import vector_columns
from pipeline.logs import MAY_BE_INFINITE, read_meta, verify_log
from pipeline.sim.robot_file import load_spec_robot, robot_shape
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides

DURATION = 3.0  # s: 100 steps


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    spec = with_overrides(load_spec("nominal"), {"mission.duration": DURATION}, name="t3")
    return run_spec(spec, tmp_path_factory.mktemp("trust")).path


def _rewrite(src: Path, dst: Path, table: pa.Table | None = None,
             meta: dict[str, str] | None = None) -> Path:
    t = pq.read_table(src) if table is None else table
    md = footer_metadata(src)
    md.update({k.encode(): v.encode() for k, v in (meta or {}).items()})
    dst.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(sealed(t, md), dst)
    return dst


def _with_nan(t: pa.Table, name: str, row: int) -> pa.Table:
    col = t.column(name).combine_chunks()
    if pa.types.is_fixed_size_list(col.type):
        width = col.type.list_size
        flat = col.flatten().to_numpy(zero_copy_only=False).copy()
        flat[row * width + width - 1] = np.nan
        new = pa.FixedSizeListArray.from_arrays(pa.array(flat), width)
    else:
        x = col.to_numpy(zero_copy_only=False).copy()
        x[row] = np.nan
        new = pa.array(x)
    return t.set_column(t.schema.get_field_index(name), name, new)


def _edited_dt(src: Path) -> dict[str, str]:
    spec = read_meta(src).spec
    spec["mission"]["dt"] = 0.01  # the hash left alone
    return {"pipeline.spec": json.dumps(spec, sort_keys=True)}


def _cases(src: Path, tmp: Path) -> dict[str, tuple[Path, str]]:
    t = pq.read_table(src)
    n = t.num_rows
    wrong_hash = {"pipeline.robot_hash": "0" * 64}
    return {
        "metadata edited without rehash": (
            _rewrite(src, tmp / "a" / "run.parquet", meta=_edited_dt(src)), "spec hash"),
        "rows removed": (
            _rewrite(src, tmp / "b" / "run.parquet", t.slice(0, n // 2)), "row count"),
        "rows removed, count edited": (
            _rewrite(src, tmp / "c" / "run.parquet", t.slice(0, n // 2),
                     {"pipeline.rows": str(n // 2)}), "row count"),
        "rows duplicated": (
            _rewrite(src, tmp / "d" / "run.parquet", pa.concat_tables([t, t])), "row count"),
        "a row duplicated in place": (
            _rewrite(src, tmp / "e" / "run.parquet",
                     pa.concat_tables([t.slice(0, 10), t.slice(9, n - 10)])),
            "step column: row 10 holds step 9"),
        "wrong robot hash": (
            _rewrite(src, tmp / "f" / "run.parquet", meta=wrong_hash), "robot file"),
        "t not step·dt": (
            _rewrite(src, tmp / "g" / "run.parquet", t.set_column(
                t.schema.get_field_index("t"), "t",
                pa.array(t.column("t").to_numpy() * 1.5))), "t column: step 1"),
    }


@pytest.mark.parametrize("case", ["metadata edited without rehash", "rows removed",
                                  "rows removed, count edited", "rows duplicated",
                                  "a row duplicated in place", "wrong robot hash",
                                  "t not step·dt"])
def test_a_tampered_log_is_refused_with_exit_1_and_nothing_written(log, tmp_path, case):
    path, needle = _cases(log, tmp_path)[case]
    with pytest.raises(LogDamaged, match="tampered or damaged"):
        verify_log(path)
    r = run_cli_in_process("analyze", str(path), "--out", str(tmp_path / "out"))
    assert r.returncode == 1, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and needle in lines[0], lines
    assert not (tmp_path / "out").exists()


def _numeric_columns(path: Path) -> list[str]:
    schema = pq.read_schema(path)
    out = []
    for f in schema:
        typ = f.type.value_type if pa.types.is_fixed_size_list(f.type) else f.type
        if pa.types.is_floating(typ):
            out.append(f.name)
    return out


def test_every_numeric_column_is_covered(log):
    cols = set(_numeric_columns(log))
    widths = vector_columns(robot_shape(load_spec_robot(load_spec("nominal"))))
    assert {"t", "tau", "s_min_G", "kappa_G", "dt_mu_max", "coverage", *widths} <= cols


def test_a_nan_in_any_numeric_column_is_refused_at_its_step(log, tmp_path):
    """One NaN at step 37, column by column: each refused, naming the column and the step."""
    t = pq.read_table(log)
    for name in _numeric_columns(log):
        path = _rewrite(log, tmp_path / name / "run.parquet", _with_nan(t, name, 37))
        needle = ("t column: step 37" if name == "t"  # t = step·dt is checked first
                  else rf"column {name}: step 37 is not finite")
        with pytest.raises(LogDamaged, match=needle):
            verify_log(path)


def test_condition_numbers_may_be_inf_but_not_nan_or_minus_inf(log, tmp_path):
    t = pq.read_table(log)
    for name in MAY_BE_INFINITE:
        x = t.column(name).to_numpy().copy()
        x[5] = np.inf
        ok = _rewrite(log, tmp_path / f"{name}_inf" / "run.parquet",
                      t.set_column(t.schema.get_field_index(name), name, pa.array(x)))
        verify_log(ok)  # +inf: a condition number at an exact singularity
        x[5] = -np.inf
        bad = _rewrite(log, tmp_path / f"{name}_minf" / "run.parquet",
                       t.set_column(t.schema.get_field_index(name), name, pa.array(x)))
        with pytest.raises(LogDamaged, match=rf"column {name}: step 5"):
            verify_log(bad)


def test_a_genuine_log_passes_and_records_what_the_checks_need(log):
    v = verify_log(log)
    assert v.meta.rows == 100 and v.meta.status == "complete"
    assert set(v.meta.versions) == {"python", "numpy", "scipy", "pinocchio", "numba", "pyarrow"}
    assert v.spec.mission.duration == DURATION


def test_the_analysis_reads_dt_from_the_verified_log_only(log, tmp_path):
    """The classic tamper of issue 12: dt edited in the metadata (hash left alone) was analysed
    with exit 0 and dt·μ_max for the wrong dt; now it never reaches the analysis."""
    path = _rewrite(log, tmp_path / "x" / "run.parquet", meta=_edited_dt(log))
    with pytest.raises(LogDamaged, match="spec hash"):
        analyze_log(verify_log(path))


def test_nan_is_never_no_difference_in_the_baselines(log, tmp_path):
    t = pq.read_table(log)
    nan = _rewrite(log, tmp_path / "n" / "run.parquet", _with_nan(t, "s_min_G", 3))
    r = compare_logs(nan, nan)  # NaN against the very same NaN
    assert r["max_abs_diff"] == np.inf and any("NaN at row 3" in n for n in r["notes"])
    assert compare_logs(log, log)["max_abs_diff"] == 0.0


# -- reports refuse what they cannot render (issue 12, item 5) ---------------------------------

@pytest.fixture(scope="module")
def analysed(log, tmp_path_factory) -> Path:
    from pipeline.analysis.record import write_analysis

    out = tmp_path_factory.mktemp("analysed")
    write_analysis(analyze_log(verify_log(log)), out)
    return out


def _set(record: dict, path: tuple[str, ...], value) -> dict:
    """The record with the field at ``path`` set to ``value`` (a damage by hand)."""
    node = record
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    return record


def _copy_reports(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


@pytest.mark.parametrize("damage,needle", [
    (lambda p: p.write_text('{"schema": "breve-analysis/1", "spec_name": "t3"'), "not JSON"),
    (lambda p: p.write_text(json.dumps({**json.loads(p.read_text()), "schema": "v0"})),
     "key schema"),
    (lambda p: p.write_text(json.dumps({k: v for k, v in json.loads(p.read_text()).items()
                                        if k != "theory"})), "key theory: missing"),
    (lambda p: p.write_text(json.dumps(_set(json.loads(p.read_text()), ("dominant", "lag1"),
                                            "-0.99"))), "key dominant.lag1: '-0.99' is not a"),
    (lambda p: p.write_text(json.dumps(_set(json.loads(p.read_text()), ("theory", "mu_max2"),
                                            1.0))), "key theory.mu_max2: not a field"),
    # Whole and well-typed, but not what the analysis wrote: a number edited by hand.
    (lambda p: p.write_text(json.dumps(_set(json.loads(p.read_text()), ("dominant", "lag1"),
                                            0.99))), "key record_sha256: the record's content"),
    (lambda p: p.write_text(json.dumps({k: v for k, v in json.loads(p.read_text()).items()
                                        if k != "record_sha256"})), "key record_sha256: missing"),
    (lambda p: (p.parent / "directions.parquet").unlink(), "directions.parquet is missing"),
    (lambda p: (p.parent / "directions.parquet").write_bytes(b"PAR1 another table"),
     "key directions_sha256"),
])
def test_report_refuses_a_damaged_analysis_with_exit_2(analysed, tmp_path, damage, needle):
    out = _copy_reports(analysed, tmp_path / "rep")
    damage(out / "t3" / "analysis.json")
    r = run_cli_in_process("report", "--out", str(out))
    assert r.returncode == 2, r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert "analysis.json" in line and needle in line, line
    assert not (out / "index.html").exists()


def test_report_refuses_an_empty_or_missing_folder(tmp_path):
    (tmp_path / "empty").mkdir()
    r = run_cli("report", "--out", str(tmp_path / "empty"))
    assert r.returncode == 2 and "nothing to report" in r.stderr
    r = run_cli("report", "--out", str(tmp_path / "typo"))
    assert r.returncode == 2 and "report folder not found" in r.stderr
    assert not (tmp_path / "typo").exists()


def test_report_removes_the_outputs_of_a_run_that_is_gone(analysed, tmp_path):
    from pipeline.reports.render import render_all

    out = _copy_reports(analysed, tmp_path / "rep")
    (out / "gone").mkdir()
    for name in ("mechanism.md", "mechanism.html"):
        (out / "gone" / name).write_text("an old report of a run without analysis")
    (out / "figures").mkdir()
    (out / "figures" / "eig_gone.png").write_bytes(b"old")
    render_all(out)
    assert not (out / "gone" / "mechanism.md").exists()
    assert not (out / "figures" / "eig_gone.png").exists()
    assert (out / "figures" / "eig_t3.png").is_file()


def test_analysis_files_are_a_pair(analysed):
    from pipeline.analysis.record import SCHEMA, read_analysis

    rec = read_analysis(analysed / "t3" / "analysis.json")
    assert rec.schema == SCHEMA and len(rec.directions_sha256) == 64


# -- bounded resources, refused up front (issue 12, item 6) ------------------------------------

@pytest.mark.parametrize("yaml_text,env,needle", [
    ("extends: nominal\nmission: {duration: 1.0e9}\n", {},
     "field mission.duration: the mission would need about"),
    ("extends: nominal\ntarget: {n_points: 1000000000}\n", {},
     "field target.n_points: the mission would need about"),
    ("extends: nominal\nmission: {duration: 3600.0}\n", {"BREVE_TIME_BUDGET_H": "0.001"},
     "field mission.duration: the mission would take about"),
])
def test_a_mission_over_budget_is_refused_before_any_work(tmp_path, monkeypatch, yaml_text,
                                                          env, needle):
    import time as _time

    for k, v in env.items():
        monkeypatch.setenv(k, v)
    spec = tmp_path / "big.yaml"
    spec.write_text(yaml_text)
    t0 = _time.perf_counter()
    r = run_cli_in_process("run", str(spec), "--out", str(tmp_path / "out"))
    took = _time.perf_counter() - t0
    assert r.returncode == 2, r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert needle in line and "budget" in line, line
    assert not (tmp_path / "out").exists()
    assert took < 30  # an interpreter start; the estimate itself allocates nothing


def test_the_estimate_allocates_nothing_and_answers_fast():
    import time as _time
    import tracemalloc

    from pipeline.budget import Budget, check_mission
    from pipeline.errors import SpecError

    spec = with_overrides(load_spec("nominal"), {"mission.duration": 1.0e9})
    tracemalloc.start()
    t0 = _time.perf_counter()
    with pytest.raises(SpecError, match="memory budget"):
        check_mission(spec, Budget(memory_bytes=8 * 2**30, seconds=3600.0))
    took = _time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert took < 1.0 and peak < 10 * 2**20


def test_a_sweep_of_a_million_points_is_refused_before_its_grid_is_built(tmp_path):
    values = ",".join(f"{0.001 + 1e-6 * i:.6f}" for i in range(1000))
    gains = ",".join(f"{1 + i}" for i in range(1000))
    r = run_cli("sweep", "nominal", "--set", f"mission.dt={values}",
                "--set", f"controller.gains.bus.D={gains}", "--logs", str(tmp_path / "l"),
                "--out", str(tmp_path / "o"))
    assert r.returncode == 2, r.stderr
    assert "1,000,000 points, over the limit of 10,000" in r.stderr
    assert not (tmp_path / "l").exists() and not (tmp_path / "o").exists()


def test_the_budget_row_width_is_the_logs():
    from pipeline.budget import ROW_FLOATS
    from pipeline.sim.mission import Mission

    # a six-joint arm's kernel row ends where the budget says a row does, and the fields
    # tile it
    row = Mission(load_spec("nominal")).layout.row
    assert ROW_FLOATS == max(sl.stop for sl in row.values())
    assert sum(sl.stop - sl.start for sl in row.values()) == ROW_FLOATS


def test_budget_overrides_are_validated(monkeypatch):
    from pipeline.budget import Budget
    from pipeline.errors import SpecError

    monkeypatch.setenv("BREVE_MEMORY_BUDGET_GB", "0.5")
    monkeypatch.setenv("BREVE_TIME_BUDGET_H", "2")
    b = Budget.from_environment()
    assert b.memory_bytes == 0.5 * 2**30 and b.seconds == 7200.0
    monkeypatch.setenv("BREVE_TIME_BUDGET_H", "nan")
    with pytest.raises(SpecError, match="BREVE_TIME_BUDGET_H"):
        Budget.from_environment()


# -- output folders that cannot be written (issue 12, item 8) ----------------------------------

def test_an_output_folder_that_is_a_file_is_exit_2_naming_the_path(tmp_path):
    blocker = tmp_path / "out"
    blocker.write_text("a file where the log folder should be")
    r = run_cli("run", "short_nominal", "--out", str(blocker))
    assert r.returncode == 2, r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert str(blocker) in line and "cannot write" in line
    assert blocker.read_text() == "a file where the log folder should be"


def test_a_full_disk_leaves_nothing_partial(tmp_path, monkeypatch):
    import errno
    import os

    import pipeline.atomic_files as atomic
    from pipeline.errors import OutputError

    target = tmp_path / "x.json"
    target.write_text("old")

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(atomic.os, "fsync", full)
    with pytest.raises(OutputError, match="No space left on device"):
        atomic.atomic_write_text(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["x.json"]  # no temporary file left


def test_an_analysis_pair_is_written_whole_or_not_at_all(log, tmp_path, monkeypatch):
    """The record is the commit: if it cannot be written, the new table goes too."""
    import pipeline.analysis.record as record
    from pipeline.errors import OutputError

    rec = analyze_log(verify_log(log))

    def full(path, text):
        raise OutputError(f"{path}: cannot write: No space left on device")

    monkeypatch.setattr(record, "atomic_write_text", full)
    with pytest.raises(OutputError):
        record.write_analysis(rec, tmp_path)
    assert not (tmp_path / "t3" / "directions.parquet").exists()
    assert not (tmp_path / "t3" / "analysis.json").exists()


def test_a_sweep_whose_log_folder_is_a_file_is_exit_2_and_creates_nothing(tmp_path):
    blocker = tmp_path / "logs"
    blocker.write_text("a file")
    r = run_cli("sweep", "short_nominal", "--set", "mission.dt=0.03", "--logs", str(blocker),
                "--out", str(tmp_path / "o"))
    assert r.returncode == 2, r.stderr
    assert "is a file, not a folder" in r.stderr and str(blocker) in r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("value", ["nan", "inf", "-1"])
def test_a_window_start_that_is_not_a_time_is_exit_2(log, tmp_path, value):
    r = run_cli_in_process("analyze", log, "--window-start", value, "--out", tmp_path / "o")
    assert r.returncode == 2, r.stderr
    assert "window" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_a_log_hashed_before_the_inert_fields_left_the_hash_still_verifies(log, tmp_path):
    """A log written when the spec hash covered every field (config_sampling.low/high/floor
    included) is whole, not damaged; a hash of neither form is still refused."""
    from pipeline.spec import canonical_hash

    content = {k: v for k, v in read_meta(log).spec.items() if k not in ("name", "description")}
    legacy = canonical_hash(content)
    assert legacy != read_meta(log).spec_hash  # the two forms differ
    old = _rewrite(log, tmp_path / "old" / "run.parquet", meta={"pipeline.spec_hash": legacy})
    assert verify_log(old).meta.spec_hash == legacy
    bad = _rewrite(log, tmp_path / "bad" / "run.parquet",
                   meta={"pipeline.spec_hash": canonical_hash({**content, "x": 1})})
    with pytest.raises(LogDamaged, match="spec hash"):
        verify_log(bad)
