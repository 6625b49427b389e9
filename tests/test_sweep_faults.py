"""Sweeps that meet faults (issue 13): a point whose worker dies on every attempt, SIGINT and
SIGTERM to the driver, and a real ``dask scheduler`` with two ``dask worker`` processes that
outlive the sweep. (A worker killed once is in tests/test_sweep.py.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from sweep_helpers import sweep, sweep_argv, sweep_env, table

from pipeline.paths import PROJECT_ROOT
from pipeline.sweep.cluster import ALLOWED_FAILURES


def _holder(lock: Path) -> int | None:
    try:
        return int(lock.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None  # not there, not yet written, or just released


def _family(pid: int) -> set[int]:
    try:
        return {c.pid for c in psutil.Process(pid).children(recursive=True)}
    except psutil.NoSuchProcess:
        return set()


@pytest.mark.slow
def test_a_point_whose_worker_always_dies_is_named_and_the_others_complete(tmp_path):
    args = ["short_nominal", "--set", "mission.duration=4.0",
            "--set", "mission.dt=0.01,0.02,0.03", "--workers", "2"]
    proc = subprocess.Popen(sweep_argv(tmp_path, *args), cwd=PROJECT_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=sweep_env())
    victim = "short_nominal__mission.dt=0.01__mission.duration=4.0"
    lock = tmp_path / "logs" / "s" / victim / ".lock"
    killed: list[int] = []
    try:
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline:
            pid = _holder(lock)
            if pid and pid not in killed and pid in _family(proc.pid):
                psutil.Process(pid).kill()  # every attempt at this point dies with its worker
                killed.append(pid)
            time.sleep(0.05)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1, err
    assert len(killed) == ALLOWED_FAILURES + 1, killed
    t = table(tmp_path).set_index("point")
    assert t.loc[victim, "status"] == "failed"
    assert t.loc[victim, "error"].startswith("KilledWorker")
    assert (t.drop(victim)["status"] == "complete").all()
    last = err.strip().splitlines()[-1]
    assert last.startswith("error: sweep s: 1 of 3 points failed") and victim in last
    assert "KilledWorker" in last
    assert f"retried {victim}: {ALLOWED_FAILURES + 1} attempts" in out
    assert not list((tmp_path / "logs" / "s").rglob("*.tmp"))


@pytest.mark.slow
@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_cancels_the_queue_keeps_what_finished_and_writes_nothing_half(
        tmp_path, signum, code):
    dts = "0.010,0.011,0.012,0.013,0.014,0.015,0.016,0.017"
    args = ["short_nominal", "--set", "mission.duration=3.0", "--set", f"mission.dt={dts}",
            "--workers", "2"]
    proc = subprocess.Popen(sweep_argv(tmp_path, *args), cwd=PROJECT_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=sweep_env())
    root = tmp_path / "logs" / "s"
    workers: set[int] = set()
    try:
        deadline = time.monotonic() + 240
        # wait until one point is finished and another is being simulated
        while proc.poll() is None and time.monotonic() < deadline:
            workers |= _family(proc.pid)
            held = [lk for lk in root.glob("*/.lock") if _holder(lk) in workers]
            if list(root.glob("*/analysis.json")) and held:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the sweep ended before it could be interrupted"
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == code, err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"error: sweep s: stopped by {signal.Signals(signum).name}"), err
    assert not (tmp_path / "out").exists()  # no table: it would not cover the grid
    finished = 0
    for folder in root.iterdir():
        names = {p.name for p in folder.iterdir()}
        # only finished files: no temporary file of a killed writer, no stale lock (a point
        # stopped during its analysis keeps its finished log; a rerun redoes the analysis)
        assert names <= {"analysis.json", "directions.parquet", "run.parquet"}, names
        assert not names or "run.parquet" in names, names
        finished += "run.parquet" in names
    assert 1 <= finished < 8
    time.sleep(1)
    assert not [p for p in workers if psutil.pid_exists(p)
                and psutil.Process(p).status() != psutil.STATUS_ZOMBIE]  # no orphan worker
    # the same command resumes: the finished points come from the cache
    r = sweep(tmp_path, *args, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"{8 - finished} simulated now, {finished} from cache" in r.stdout


@pytest.mark.slow
def test_sweep_on_a_real_scheduler_that_outlives_it(tmp_path):
    info = tmp_path / "scheduler.json"
    env = sweep_env()
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler",
                               "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(info)], cwd=PROJECT_ROOT, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(info.read_text())["address"]
        procs += [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker",
                                    address, "--nthreads", "1", "--name", f"w{i}",
                                    "--no-dashboard", "--host", "127.0.0.1"],
                                   cwd=PROJECT_ROOT, env=env, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL) for i in range(2)]
        r = sweep(tmp_path, "short_nominal", "--set", "mission.duration=1.0",
                  "--set", "mission.dt=0.02,0.025,0.03", "--scheduler", address, timeout=300)
        assert r.returncode == 0, r.stderr
        t = table(tmp_path)
        assert len(t) == 3 and (t["status"] == "complete").all()
        worker_pids = set().union(*(_family(p.pid) | {p.pid} for p in procs[1:]))
        assert {int(w.rsplit(":", 1)[1]) for w in t["worker"]} <= worker_pids
        # the cluster outlives the sweep: all three processes run, both workers still there
        assert all(p.poll() is None for p in procs)
        from distributed import Client

        with Client(address, timeout=10) as client:
            assert len(client.scheduler_info()["workers"]) == 2
    finally:
        for p in reversed(procs):
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()


def test_workers_run_their_numerical_libraries_single_threaded():
    from pipeline.sweep.cluster import SINGLE_THREAD, ClusterOptions, open_client

    def threads() -> dict:
        return {k: os.environ.get(k) for k in SINGLE_THREAD}

    with open_client(ClusterOptions(workers=2)) as session:
        seen = session.client.run(threads)
    assert len(seen) == 2 and all(v == SINGLE_THREAD for v in seen.values()), seen
