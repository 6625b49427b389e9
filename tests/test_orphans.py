"""kill -9 of a command leaves no worker behind (issue 36, item 6; pipeline/orphans.py)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import psutil
import pytest
from report_fixtures import built

from pipeline.paths import PROJECT_ROOT

GRACE_S = 5.0  # the watch looks every 0.2 s; a loaded 2-core machine may take longer


def _cmdline(p: psutil.Process) -> str:
    """A process's command line; empty for one that has ended (a zombie, or gone)."""
    try:
        return " ".join(p.cmdline())
    except psutil.Error:
        return ""


def _gone_within(procs: list[psutil.Process], seconds: float) -> list[psutil.Process]:
    """The processes still alive after ``seconds``."""
    _, alive = psutil.wait_procs(procs, timeout=seconds)
    return [p for p in alive if _running(p)]


def _running(p: psutil.Process) -> bool:
    try:
        return p.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def test_a_worker_ends_with_the_process_that_started_it(tmp_path):
    """A parent starts a worker that calls exit_with_parent and sleeps for a minute; the
    parent is killed with SIGKILL (no clean-up runs): the worker is gone within seconds. Without
    the watch it would sleep on (the control: a worker that does not call it)."""
    code = textwrap.dedent("""
        import os, subprocess, sys, time
        watch = sys.argv[1] == "watch"
        child = ("from pipeline.orphans import exit_with_parent; import time; "
                 f"exit_with_parent({os.getpid()}) if {watch} else None; time.sleep(60)")
        p = subprocess.Popen([sys.executable, "-c", child])
        print(p.pid, flush=True)
        time.sleep(60)
    """)
    alive = {}
    for mode in ("watch", "control"):
        parent = subprocess.Popen([sys.executable, "-c", code, mode], stdout=subprocess.PIPE,
                                  text=True, cwd=PROJECT_ROOT)
        worker = psutil.Process(int(parent.stdout.readline()))
        time.sleep(1.0)  # the worker has imported and started its watch
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        alive[mode] = _gone_within([worker], GRACE_S if mode == "watch" else 1.0)
        for p in alive[mode]:
            p.kill()
    assert alive["watch"] == [] and len(alive["control"]) == 1


def _workers_left_after_kill_9(cmd: list[str], what: str, **popen) -> list[psutil.Process]:
    """Start ``cmd``, wait until two spawned worker processes of it run, kill -9 the command
    and return the workers still running GRACE_S later (killed then, so none outlives the
    test)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, **popen)
    me = psutil.Process(proc.pid)
    deadline = time.monotonic() + 120
    workers: list[psutil.Process] = []
    while time.monotonic() < deadline and proc.poll() is None:
        workers = [c for c in me.children(recursive=True) if "spawn_main" in _cmdline(c)]
        if len(workers) >= 2:
            break
        time.sleep(0.1)
    assert len(workers) >= 2, f"the {what} never started"
    time.sleep(1.0)  # at work
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    left = _gone_within(workers, GRACE_S)
    for p in left:
        p.kill()
    return left


@pytest.mark.slow
def test_kill_9_of_report_leaves_no_figure_process(tmp_path):
    out = tmp_path / "rep"
    shutil.copytree(built().reports, out)
    cmd = [sys.executable, "-m", "pipeline", "report", "--out", str(out), "--force"]
    left = _workers_left_after_kill_9(cmd, "figure processes",
                                      env={**os.environ, "PYTHONPATH": str(PROJECT_ROOT)})
    assert left == [], [_cmdline(p) for p in left]


@pytest.mark.slow
def test_kill_9_of_a_sweep_leaves_no_dask_worker(tmp_path):
    """Dask's worker processes end when the process that holds their nanny dies (distributed
    watches its parent); measured here, not assumed."""
    cmd = [sys.executable, "-m", "pipeline", "sweep", "nominal", "--set",
           "mission.dt=0.02,0.021,0.022,0.023", "--workers", "2", "--logs",
           str(tmp_path / "logs"), "--out", str(tmp_path / "out")]
    left = _workers_left_after_kill_9(cmd, "sweep's workers", cwd=PROJECT_ROOT)
    assert left == [], [_cmdline(p) for p in left]
