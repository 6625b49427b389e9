"""Sweeps on Dask (issue 6): grid, cache, failed points, killed workers, scheduler errors,
concurrent sweeps, the SLURM job script and the stability bracket.

The sweeps run as ``python -m pipeline sweep`` subprocesses (with warnings as errors, as the
CLI tests do) on very short missions (``short_nominal`` cut to 1–3 s), each on its own
embedded LocalCluster.
"""

from __future__ import annotations

import fcntl
import json
import os
import pty
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest
from sweep_helpers import sweep, sweep_argv, sweep_env, table

from pipeline.errors import LogError, SpecError
from pipeline.logs import num_rows, read_meta
from pipeline.paths import PROJECT_ROOT
from pipeline.spec import load_spec
from pipeline.store.locks import folder_lock, remove_stale_temps
from pipeline.sweep import build_grid, parse_sets, plan_sweep, point_name, stability_bracket
from pipeline.sweep.cluster import (
    default_lifetime,
    scheduler_address,
    slurm_kwargs,
    walltime_seconds,
)
from pipeline.sweep.grid import parse_value

SHORT = ["--set", "mission.duration=1.0"]
FOUR = [*SHORT, "--set", "mission.dt=0.02,0.03", "--set", "controller.gains.cam_ori.D=1.0,1.5"]
# huge limits (no saturation left to contain it) and a large damping gain at dt = 0.01 s:
# dt·μ_max ~ 1e6 ≫ 2: the explicit loop overflows within a few steps; D = 1 is stable.
DIVERGING_SPEC = """\
extends: short_nominal
mission: {duration: 1.0, dt: 0.01}
controller:
  limits: {omega_b_rate: 1.0e+300, omega_b_acc: 1.0e+300, nu_e_lin_rate: 1.0e+300,
           nu_e_lin_acc: 1.0e+300, nu_e_ang_rate: 1.0e+300, nu_e_ang_acc: 1.0e+300,
           v_c_rate: 1.0e+300, v_c_acc: 1.0e+300, v_max: 1.0e+300}
"""


def code_version_of(path: Path) -> str:
    import pyarrow.parquet as pq

    md = pq.read_schema(path).metadata
    return (md[b"pipeline.sim_version"] + b"/" + md[b"pipeline.analysis_version"]).decode()


def same_code(*paths: Path) -> None:
    """Other sessions may edit pipeline/ while the tests run: a new code version legitimately
    invalidates the cache, so the cache assertions only apply within one code version."""
    if len({code_version_of(p) for p in paths}) > 1:
        pytest.skip("pipeline/ changed while the test ran (new code version)")


def files_of(folder: Path) -> dict[str, tuple[int, int]]:
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in folder.iterdir()}


def assert_clean_valid(folder: Path, spec_hash: str) -> None:
    """One complete log of this spec, its analysis, and no temporary or lock file."""
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["analysis.json", "directions.parquet", "run.parquet"], (folder, names)
    meta = read_meta(folder / "run.parquet")
    assert (meta.status, meta.spec_hash) == ("complete", spec_hash), folder
    assert num_rows(folder / "run.parquet") == load_spec_rows(meta.spec)
    assert json.loads((folder / "analysis.json").read_text())["spec_hash"] == spec_hash


def load_spec_rows(spec: dict) -> int:
    return round(spec["mission"]["duration"] / spec["mission"]["dt"])


# -- grid ---------------------------------------------------------------------------------------

def test_values_are_yaml_scalars_and_lists_keep_their_commas():
    assert parse_sets(["mission.dt=0.01,2e-2, 1e300", "controller.integrator=imex,explicit",
                       "robot.q_bar=[0, -1.6, 1, -0.95, 1.5708, 0]"]) == [
        ("mission.dt", [0.01, 0.02, 1e300]),
        ("controller.integrator", ["imex", "explicit"]),
        ("robot.q_bar", [[0, -1.6, 1, -0.95, 1.5708, 0]]),
    ]
    assert parse_value("20") == 20 and parse_value("true") is True


def test_grid_is_the_product_with_deterministic_safe_names():
    base = load_spec("short_nominal")
    axes = parse_sets(["mission.dt=0.01,0.02,1e-2", "mission.duration=1,2"])
    points = build_grid(base, axes)
    assert len(points) == 4  # 1e-2 is 0.01: the same point once
    assert points[0].name == "short_nominal__mission.dt=0.01__mission.duration=1.0"
    assert points[0].spec.mission.duration == 1.0 and points[0].spec.name == points[0].name
    # the name depends on the point only, not on the order of --set or the rest of the grid
    swapped = build_grid(base, parse_sets(["mission.duration=2,1", "mission.dt=0.02"]))
    assert {p.name for p in swapped} <= {p.name for p in points}
    # unsafe or long values get a cleaned name with a hash suffix; distinct values stay distinct
    a = point_name("x", {"robot.urdf": "robots/a b.urdf"})
    b = point_name("x", {"robot.urdf": "robots/a:b.urdf"})
    assert a != b and "/" not in a and " " not in a and a.startswith("x__robot.urdf=robots-a-b")
    assert len(point_name("x", {"k": "v" * 500})) <= 150


@pytest.mark.parametrize(("sets", "words"), [
    (["mission.dtt=0.01"], ["mission.dtt", "unknown key"]),
    (["mission.dt=0.01,-1"], ["mission.dt", "greater than 0"]),
    (["mission.dt=0.01,fast"], ["mission.dt"]),
    (["mission.dt"], ["--set mission.dt", "KEY=V1,V2"]),
    (["mission.dt=0.01,"], ["empty value"]),
    ([], ["at least one --set"]),
])
def test_bad_grid_fails_before_anything_runs(tmp_path, sets, words):
    with pytest.raises(SpecError) as exc:
        plan_sweep("short_nominal", sets, logs=tmp_path / "logs", out=tmp_path / "out")
    for w in words:
        assert w in str(exc.value)
    assert not (tmp_path / "logs").exists()


def test_bad_value_is_exit_2_one_line_and_nothing_written(tmp_path):
    r = sweep(tmp_path, "short_nominal", "--set", "mission.dt=0.02,0.0", timeout=60)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "field mission.dt" in r.stderr
    assert not (tmp_path / "logs").exists() and not (tmp_path / "out").exists()


# -- running, caching, resuming --------------------------------------------------------------

@pytest.mark.slow
def test_four_points_then_nothing_reruns_then_only_what_is_missing(tmp_path):
    r = sweep(tmp_path, "short_nominal", *FOUR, "--workers", "2")
    assert r.returncode == 0, r.stderr
    t1 = table(tmp_path)
    assert len(t1) == 4 and (t1["status"] == "complete").all()
    assert t1["ran"].all() and t1["analysed"].all()
    assert sorted(zip(t1["mission.dt"], t1["controller.gains.cam_ori.D"], strict=True)) == [
        (0.02, 1.0), (0.02, 1.5), (0.03, 1.0), (0.03, 1.5)]
    assert t1[["dominant_lag1", "dt_mu_max", "dt_star_damping", "eig_real", "spectral_radius"]
              ].notna().all().all()
    # dt·μ_max is linear in dt at fixed gains
    d1 = t1[t1["controller.gains.cam_ori.D"] == 1.0].sort_values("mission.dt")["dt_mu_max"]
    assert d1.iloc[1] / d1.iloc[0] == pytest.approx(1.5, rel=0.02)
    assert "4 points: 4 complete, 0 failed; 4 simulated now" in r.stdout
    assert "point/s" not in r.stderr and "\r" not in r.stderr  # no progress bar off a terminal
    # but one line per change of the counts, ending with all four done
    progress = [ln for ln in r.stderr.splitlines() if ln.startswith("sweep s: ")]
    assert progress[-1] == "sweep s: 4/4 finished (4 done, 0 failed), 0 running"
    assert len(progress) == len(set(progress)) and len(progress) >= 5
    folders = {p: tmp_path / "logs" / "s" / p for p in t1["point"]}
    for p, f in folders.items():
        assert_clean_valid(f, t1.set_index("point").loc[p, "spec_hash"])
    before = {p: files_of(f) for p, f in folders.items()}
    table_path = tmp_path / "out" / "s" / "sweep.parquet"
    v1 = code_version_of(table_path)

    r = sweep(tmp_path, "short_nominal", *FOUR, "--workers", "2")
    assert r.returncode == 0, r.stderr
    if code_version_of(table_path) != v1:
        pytest.skip("pipeline/ changed while the test ran (new code version)")
    t2 = table(tmp_path)
    assert not t2["ran"].any() and not t2["analysed"].any()
    assert {p: files_of(f) for p, f in folders.items()} == before  # same inodes, same mtimes
    assert "0 simulated now, 4 from cache" in r.stdout

    # an interrupted sweep: one log never written, one analysis never written
    p_log, p_ana, *rest = list(folders)
    old_log = (folders[p_log] / "run.parquet").read_bytes()
    (folders[p_log] / "run.parquet").unlink()
    (folders[p_ana] / "analysis.json").unlink()
    (folders[p_log] / ".run.parquet.dead.tmp").write_bytes(b"torn")  # a killed writer's leftover
    r = sweep(tmp_path, "short_nominal", *FOUR, "--workers", "2")
    assert r.returncode == 0, r.stderr
    if code_version_of(table_path) != v1:
        pytest.skip("pipeline/ changed while the test ran (new code version)")
    t3 = table(tmp_path).set_index("point")
    assert t3["ran"].to_dict() == {p: p == p_log for p in folders}
    # the re-run log is the same bytes (deterministic), so its analysis, keyed on the log's
    # content, is still current; the missing analysis is made again
    assert (folders[p_log] / "run.parquet").read_bytes() == old_log
    assert t3["analysed"].to_dict() == {p: p == p_ana for p in folders}
    for p in rest:
        assert files_of(folders[p]) == before[p]
    for p, f in folders.items():
        assert_clean_valid(f, t3.loc[p, "spec_hash"])


@pytest.mark.slow
def test_diverging_point_is_a_failed_row_and_exit_1_naming_it(tmp_path):
    spec = tmp_path / "diverge.yaml"
    spec.write_text(DIVERGING_SPEC)
    # stderr on a pseudo-terminal: the progress bar shows, with the failed count
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 120, 0, 0))  # 120 columns
    proc = subprocess.Popen(sweep_argv(tmp_path, str(spec), "--set",
                                  "controller.gains.cam_ori.D=1.0,1e6", "--workers", "2"),
                            cwd=PROJECT_ROOT, stdout=subprocess.PIPE, stderr=slave, text=True,
                            env=sweep_env())
    os.close(slave)
    chunks: list[bytes] = []
    reader = threading.Thread(target=_drain, args=(master, chunks), daemon=True)
    reader.start()
    out, _ = proc.communicate(timeout=180)
    reader.join(timeout=10)
    err = b"".join(chunks).decode(errors="replace")
    assert proc.returncode == 1, err
    t = table(tmp_path).set_index("controller.gains.cam_ori.D")
    assert t.loc[1.0, "status"] == "complete" and np.isfinite(t.loc[1.0, "dominant_lag1"])
    bad = t.loc[1e6]
    assert bad["status"] == "failed" and bad["error"].startswith("step ")
    assert "overflow" in bad["error"] or "non-finite" in bad["error"]
    assert np.isnan(bad["dominant_lag1"])
    assert read_meta(Path(bad["log"])).status == "failed"  # its log is kept, marked failed
    last = err.strip().splitlines()[-1]
    assert last.startswith("error: ") and bad["point"] in last and bad["error"] in last
    assert "failed 1" in err and "point" in err  # the progress bar on the terminal
    assert "1 complete, 1 failed" in out


def _drain(fd: int, chunks: list[bytes]) -> None:
    while True:
        try:
            data = os.read(fd, 4096)
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
    os.close(fd)


@pytest.mark.slow
def test_killed_worker_does_not_lose_the_sweep(tmp_path):
    args = ["short_nominal", "--set", "mission.duration=3.0",
            "--set", "mission.dt=0.005,0.006,0.007,0.008", "--workers", "2"]
    proc = subprocess.Popen(sweep_argv(tmp_path, *args), cwd=PROJECT_ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=sweep_env())
    killed = None
    deadline = time.monotonic() + 120
    try:
        while killed is None and proc.poll() is None and time.monotonic() < deadline:
            for lock in (tmp_path / "logs" / "s").glob("*/.lock"):
                try:
                    pid = int(lock.read_text().split()[0])
                except (OSError, ValueError, IndexError):
                    continue  # not yet written, or just released
                family = {c.pid for c in psutil.Process(proc.pid).children(recursive=True)}
                if pid in family:  # a worker of this sweep, in the middle of this point
                    try:
                        psutil.Process(pid).send_signal(signal.SIGKILL)
                    except psutil.NoSuchProcess:
                        continue
                    killed = (pid, lock.parent.name)
                    break
            time.sleep(0.02)
        out, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert killed is not None, "no point was seen running: nothing to kill"
    assert proc.returncode == 0, err
    t = table(tmp_path).set_index("point")
    assert len(t) == 4 and (t["status"] == "complete").all()
    assert not t.loc[killed[1], "worker"].endswith(f":{killed[0]}")  # redone elsewhere
    assert t.loc[killed[1], "attempts"] == 2
    assert f"retried {killed[1]}: 2 attempts" in out and "; 1 retried ->" in out
    for p in t.index:
        assert_clean_valid(tmp_path / "logs" / "s" / p, t.loc[p, "spec_hash"])


@pytest.mark.slow
def test_two_overlapping_sweeps_at_once_share_each_point_once(tmp_path):
    grids = {"a": "0.01,0.015,0.02", "b": "0.015,0.02,0.025"}
    procs = {k: subprocess.Popen(
        sweep_argv(tmp_path, "short_nominal", "--set", "mission.duration=2.0", "--set",
              f"mission.dt={g}", "--workers", "2", name="overlap", out=f"out_{k}"),
        cwd=PROJECT_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=sweep_env()) for k, g in grids.items()}
    results = {k: p.communicate(timeout=240) for k, p in procs.items()}
    for k, p in procs.items():
        assert p.returncode == 0, results[k][1]
    ta, tb = (table(tmp_path, "overlap", f"out_{k}") for k in grids)
    same_code(*(tmp_path / f"out_{k}" / "overlap" / "sweep.parquet" for k in grids))
    assert len(ta) == len(tb) == 3
    assert (ta["status"] == "complete").all() and (tb["status"] == "complete").all()
    shared = sorted(set(ta["point"]) & set(tb["point"]))
    assert len(shared) == 2
    ran = pd.concat([ta, tb]).groupby("point")["ran"].sum()
    assert (ran == 1).all(), ran  # every point, shared or not, simulated exactly once
    root = tmp_path / "logs" / "overlap"
    assert sorted(p.name for p in root.iterdir()) == sorted(set(ta["point"]) | set(tb["point"]))
    for p in shared:
        a, b = ta.set_index("point").loc[p], tb.set_index("point").loc[p]
        assert a["dominant_lag1"] == b["dominant_lag1"] and a["log"] == b["log"]
        assert_clean_valid(root / p, a["spec_hash"])
    assert not list(root.rglob("*.tmp")) and not list(root.rglob(".lock"))


# -- the per-point lock -------------------------------------------------------------------------

def test_folder_lock_excludes_and_survives_a_killed_holder(tmp_path):
    order: list[str] = []
    inside = threading.Event()

    def hold():
        with folder_lock(tmp_path / "p"):
            inside.set()
            time.sleep(0.3)
            order.append("first out")

    t = threading.Thread(target=hold)
    t.start()
    inside.wait(5)
    with folder_lock(tmp_path / "p"):
        order.append("second in")
    t.join()
    assert order == ["first out", "second in"]
    assert not (tmp_path / "p" / ".lock").exists()

    # a holder killed with the lock: the kernel releases it; the next holder cleans up
    code = ("import sys, time; from pathlib import Path; from pipeline.store.locks import "
            "folder_lock\nwith folder_lock(Path(sys.argv[1])):\n"
            "    (Path(sys.argv[1]) / '.run.parquet.x.tmp').write_text('torn')\n"
            "    print('held', flush=True); time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "q")],
                              cwd=PROJECT_ROOT, stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    holder.kill()
    holder.wait(10)
    assert (tmp_path / "q" / ".lock").exists()  # stale file left behind ...
    t0 = time.monotonic()
    with folder_lock(tmp_path / "q"):  # ... but not a stale lock
        assert remove_stale_temps(tmp_path / "q") == [".run.parquet.x.tmp"]
    assert time.monotonic() - t0 < 2
    assert list((tmp_path / "q").iterdir()) == []


# -- where it runs ------------------------------------------------------------------------------

@pytest.mark.slow
def test_unreachable_scheduler_is_exit_2_within_seconds(tmp_path):
    t0 = time.monotonic()
    r = sweep(tmp_path, "short_nominal", *SHORT, "--set", "mission.dt=0.02",
              "--scheduler", "tcp://127.0.0.1:1", timeout=60)
    elapsed = time.monotonic() - t0
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --scheduler tcp://127.0.0.1:1")
    assert elapsed < 20
    assert not (tmp_path / "logs").exists()


def test_scheduler_address_from_environment(monkeypatch):
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://10.0.0.1:8786")
    assert scheduler_address(None) == "tcp://10.0.0.1:8786"
    assert scheduler_address("tcp://h:1") == "tcp://h:1"


def test_slurm_job_script(tmp_path):
    pytest.importorskip("dask_jobqueue")
    from pipeline.sweep.cluster import slurm_cluster

    kw = slurm_kwargs(tmp_path)
    assert kw["processes"] == 1 and kw["python"] == sys.executable
    cluster = slurm_cluster(tmp_path)
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    lines = script.splitlines()
    assert lines[0].startswith("#!") and "#SBATCH -J breve-sweep" in lines
    assert "#SBATCH --cpus-per-task=1" in lines and "#SBATCH --mem=2G" in lines
    assert f"#SBATCH -o {tmp_path}/breve-sweep-%J.out" in lines
    assert f"cd {Path.cwd()}" in lines
    assert "export OMP_NUM_THREADS=1" in lines and "export NUMBA_NUM_THREADS=1" in lines
    worker = lines[-1]
    assert worker.startswith(f"{sys.executable} -m distributed.cli.dask_worker tcp://")
    assert "--nthreads 1" in worker and "--nanny" in worker
    # retire before the default 30-minute walltime: 27 min ± 45 s
    assert worker.endswith("--lifetime 1620s --lifetime-stagger 45s")
    assert kw["worker_extra_args"] == ["--lifetime", "1620s", "--lifetime-stagger", "45s"]
    assert "--lifetime" not in slurm_kwargs(tmp_path, lifetime=0)["worker_extra_args"]


@pytest.mark.parametrize(("text", "seconds"), [
    ("30", 1800), ("1:30", 90), ("00:01:00", 60), ("2-00", 172800), ("1-02:03", 93780),
    ("1-02:03:04", 93784)])
def test_walltime_formats(text, seconds):
    assert walltime_seconds(text) == seconds


def test_worker_lifetime_leaves_a_margin_before_the_walltime():
    assert default_lifetime(60) == (40, 3)
    life, stagger = default_lifetime(7200)
    assert life + stagger < 7200 - 500 and stagger > 0
    with pytest.raises(SpecError, match="walltime"):
        walltime_seconds("soon")


# -- the stability bracket (claim C12) ----------------------------------------------------------

def _dt_table(dts, lags, stars, status=None):
    return pd.DataFrame({"point": [f"p{i}" for i in range(len(dts))], "mission.dt": dts,
                         "status": status or ["complete"] * len(dts),
                         "dominant_lag1": lags, "dt_star_damping": stars})


def test_stability_bracket():
    dts = [0.04, 0.005, 0.01, 0.02, 0.0225, 0.03]  # unsorted on purpose
    lags = [-0.9, 0.99, 0.98, 0.95, -0.6, -0.8]
    b = stability_bracket(_dt_table(dts, lags, [0.0204, 0.0203, 0.0205, 0.0204, 0.0204, 0.0204]))
    assert b["measured"] == (0.02, 0.0225) and b["predicted"] == (0.02, 0.0225)
    assert b["holds"] and b["dt_star"] == pytest.approx(0.0204)
    # a flip one interval too early: measured and predicted brackets differ
    b = stability_bracket(_dt_table(dts, [-0.9, 0.99, 0.98, -0.2, -0.6, -0.8], [0.0204] * 6))
    assert b["measured"] == (0.01, 0.02) and not b["holds"]
    # two flips: no single measured flip
    b = stability_bracket(_dt_table(dts, [-0.9, 0.99, -0.1, 0.95, -0.6, -0.8], [0.0204] * 6))
    assert len(b["flips"]) == 3 and b["measured"] is None and not b["holds"]
    # failed rows are left out; the bracket is found across the gap
    b = stability_bracket(_dt_table(dts, [np.nan, 0.99, 0.98, np.nan, -0.6, -0.8], [0.0204] * 6,
                                    ["failed", "complete", "complete", "failed", "complete",
                                     "complete"]))
    assert b["measured"] == (0.01, 0.0225) and b["holds"] and b["n_complete"] == 4
    with pytest.raises(LogError, match=r"mission\.duration"):
        stability_bracket(_dt_table(dts, lags, [0.02] * 6), key="mission.duration")


def test_the_bracket_judges_points_far_from_their_crossing_and_lists_the_near_ones():
    """Issue 12: the prediction (period-2 above dt*) against the lag-1 sign, point by point,
    more than 10 % from the crossing; nearer points are reported, not judged."""
    dts = [0.005, 0.01, 0.015, 0.0175, 0.02, 0.03]
    stars = [0.0156] * 6
    lags = [0.99, 0.98, 0.97, -0.9, -0.95, -0.99]  # 0.015 (−3.8 %) and 0.0175 (+12 %)
    b = stability_bracket(_dt_table(dts, lags, stars))
    assert b["far_agree"] and b["n_far"] == 5 and [p["x"] for p in b["near"]] == [0.015]
    # a far point measured smooth where period-2 is predicted: disagreement, named
    b = stability_bracket(_dt_table(dts, [0.99, 0.98, 0.97, -0.9, -0.95, 0.5], stars))
    assert not b["far_agree"] and b["far_disagree"] == [0.03]
    # the other side: a bus inertia rings below its crossing
    table = pd.DataFrame({"point": ["a", "b", "c"], "I_zz_bus": [0.0156, 0.0315, 1.0],
                          "status": ["complete"] * 3, "bus_rate_lag1": [-0.99, 0.99, 0.99],
                          "bus_critical_I_zz": [0.03] * 3})
    b = stability_bracket(table, "I_zz_bus", "bus_rate_lag1", "bus_critical_I_zz", "below")
    assert b["holds"] and b["far_agree"] and b["n_far"] == 2


def test_a_nan_lag1_is_no_evidence_and_no_bracket_holds_on_it():
    dts = [0.005, 0.01, 0.015, 0.0175, 0.02, 0.03]
    lags = [0.99, 0.98, 0.97, -0.9, float("nan"), -0.99]
    b = stability_bracket(_dt_table(dts, lags, [0.0156] * 6))
    assert b["undefined_lag1"] == [0.02] and not b["holds"] and not b["far_agree"]


def test_throughput_figures_take_the_steady_state_after_each_worker_has_finished_once():
    """``make bench``'s sweep figures (pipeline.sweep.throughput), on made-up finish times:
    two workers, the first two finishes slow (start-up), then one finish every 0.3 s with
    tasks of 0.5 s: 0.3 s × 2 workers − 0.5 s = 0.1 s of overhead per point."""
    from pipeline.sweep.throughput import throughput_of

    records = [{"received": t, "seconds": 0.5, "status": "complete"}
               for t in (4.0, 4.5, 4.8, 5.1, 5.4, 5.7)]
    f = throughput_of("local2", 2, 3.0, 6.0, records)
    assert f.steady_s_per_point == pytest.approx(0.3)
    assert f.points_per_s == pytest.approx(1 / 0.3)
    assert f.overhead_s == pytest.approx(0.1) and f.overhead_ratio == pytest.approx(0.2)
    assert (f.points, f.complete, f.startup_s) == (6, 6, 3.0)
