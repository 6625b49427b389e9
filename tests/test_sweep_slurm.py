"""Sweeps on a live single-node SLURM (issue 13): ``--slurm`` end to end with the cache, jobs
reaching their walltime mid-sweep (graceful retirement, and SLURM's hard kill), and a refused
``sbatch``.

SLURM comes from ``scripts/slurm-local.sh`` (Debian's munge, slurmctld, slurmd on localhost);
``.ci/run`` (in a folder of its own, ``BREVE_SLURM_DIR``) and ``make slurm-up`` (this
checkout's folder) start it, and the ``slurm_up`` fixture, when neither answers, starts one of
its own in a fresh folder with its own ports (and stops it again). Without the packages or
root the tests skip, saying why; under ``CI=true`` such a skip fails the run
(tests/conftest.py).

SLURM's walltime is whole minutes (1 minute is the shortest: a limit in seconds is rounded up
to one), checked by slurmctld every 30 s, and its kill waits ``KillWait`` (5 s here) between
SIGTERM and SIGKILL: a job of a 1-minute limit is killed 60 to 90 s after it starts (measured
here: 65 and 72 s for two jobs of one check). The hard-kill test therefore gives its two
one-core jobs about two and a half minutes of work, measured in seconds on the machine that
runs it (``_point_duration``), so that every first job is killed mid-sweep. The
retirement test does not need SLURM's clock: its workers retire after ``--lifetime 15`` (the
default for a 1-minute walltime, 40 ± 3 s, is ``default_lifetime``'s, tested in
tests/test_sweep.py), long before the limit, on about 36 s of work each.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import pytest
from sweep_helpers import sweep, table

from pipeline.paths import PROJECT_ROOT
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides

pytestmark = pytest.mark.slurm
SCRIPT = PROJECT_ROOT / "scripts" / "slurm-local.sh"
# scheduler and workers on the loopback interface: nothing listens beyond localhost
LOCAL = {"DASK_JOBQUEUE__SLURM__INTERFACE": "lo"}


def _script(*args: str, env: dict[str, str], timeout: float = 30
            ) -> subprocess.CompletedProcess:
    return subprocess.run([str(SCRIPT), *args], capture_output=True, text=True, env=env,
                          timeout=timeout)


@pytest.fixture(scope="module")
def slurm_up():
    """A running local SLURM, or a skip that says why. The cluster of ``BREVE_SLURM_DIR`` if
    set, else this checkout's (``make slurm-up``), when it answers; else, as root, one of this
    test run's own, in a fresh folder with its own ports, stopped and removed afterwards, so
    that no other run's cluster is used or stopped. The sweeps find it by ``SLURM_CONF``."""
    missing = [c for c in ("munged", "slurmctld", "slurmd", "sbatch") if not shutil.which(c)]
    if missing:
        pytest.skip(f"SLURM packages missing ({', '.join(missing)} not found): "
                    "apt-get install munge slurmctld slurmd slurm-client, or make slurm-up")
    env = dict(os.environ)
    started, own = False, None
    if _script("status", env=env).returncode != 0:
        if os.geteuid() != 0:
            pytest.skip("local SLURM not running and not root to start it: make slurm-up as root")
        if not env.get("BREVE_SLURM_DIR"):
            own = tempfile.mkdtemp(prefix="breve-slurm.")
            env["BREVE_SLURM_DIR"] = own
        started = True
        r = _script("up", env=env, timeout=120)
        if r.returncode != 0:
            _script("down", env=env, timeout=120)
            pytest.fail(f"scripts/slurm-local.sh up failed: {r.stderr.strip()}")
    saved = os.environ.get("SLURM_CONF")
    # the sweeps' sbatch, squeue and scancel talk to this cluster, whatever /etc/slurm says
    os.environ["SLURM_CONF"] = _script("conf", env=env).stdout.strip()
    yield
    if saved is None:
        os.environ.pop("SLURM_CONF", None)
    else:
        os.environ["SLURM_CONF"] = saved
    if started:
        _script("down", env=env, timeout=120)
        if own is not None:
            shutil.rmtree(own, ignore_errors=True)


def _jobs(stdout: str) -> list[str]:
    m = re.search(r"^slurm: (\d+) worker jobs submitted .*?: ?(.*)$", stdout, re.M)
    assert m, stdout
    return m.group(2).split()


def _job_logs(tmp: Path) -> dict[str, str]:
    """The worker jobs' stderr files (``breve-sweep-<jobid>.err``), by job id."""
    return {p.stem.rsplit("-", 1)[1]: p.read_text(errors="replace")
            for p in (tmp / "logs" / ".slurm").glob("breve-sweep-*.err")}


def test_slurm_sweep_end_to_end_with_cache(slurm_up, tmp_path, record_property):
    args = ["short_nominal", "--set", "mission.duration=1.0", "--set", "mission.dt=0.02,0.03",
            "--slurm", "--workers", "2"]
    env = {**LOCAL, "DASK_JOBQUEUE__SLURM__WALLTIME": "00:10:00"}
    t0 = time.monotonic()
    r = sweep(tmp_path, *args, timeout=300, **env)
    assert r.returncode == 0, r.stderr[-3000:]
    t = table(tmp_path)
    assert len(t) == 2 and (t["status"] == "complete").all() and t["ran"].all()
    assert "2 points: 2 complete, 0 failed; 2 simulated now" in r.stdout
    jobs = _jobs(r.stdout)
    assert len(jobs) >= 1 and set(_job_logs(tmp_path)) >= set(jobs)  # real SLURM jobs ran
    # progress off a terminal: one line per change, ending with everything finished
    assert "sweep s: 2/2 finished (2 done, 0 failed), 0 running" in r.stderr
    r2 = sweep(tmp_path, *args, timeout=300, **env)
    assert r2.returncode == 0, r2.stderr[-3000:]
    assert "0 simulated now, 2 from cache" in r2.stdout
    assert not table(tmp_path)["ran"].any()
    record_property("wall_s", round(time.monotonic() - t0, 1))


POINT_SECONDS = 3.0  # the work of one point of the walltime sweeps, on this machine


def _point_duration(tmp: Path) -> float:
    """The mission duration (s) whose run costs about POINT_SECONDS here, measured: the
    walltime tests need a given amount of work in seconds, whatever the processor's speed (a
    fixed duration of 250 s was 2.5 s of work on the machine it was written on and 1.7 s on a
    faster one, where the hard-kill sweep then ended before SLURM's limit). 300-step runs of
    the sweep's spec at its mean step, kernels warm, give the cost of a step: the least of
    three, in CPU time, which other work on the machine does not inflate (in wall time a
    loaded machine made the missions too short and the retirement sweep ended before the
    workers' lifetime)."""
    spec = with_overrides(load_spec("short_nominal"), {"mission.duration": 7.65,
                                                       "mission.dt": 0.0255})
    run_spec(spec, tmp / "calibration")  # loads the kernels
    costs = []
    for _ in range(3):
        t0 = time.process_time()
        run_spec(spec, tmp / "calibration")
        costs.append((time.process_time() - t0) / 300)
    return round(POINT_SECONDS / min(costs) * 0.0255, 1)


def _walltime_sweep(tmp: Path, gains: int, lifetime: list[str], record_property
                    ) -> tuple[list[str], dict]:
    """12 × ``gains`` points on two jobs of a 1-minute walltime: every point must complete
    although the first jobs end mid-sweep (``lifetime``: the sweep's ``--lifetime`` option).
    A point is a mission at dt ≈ 0.025 s of about POINT_SECONDS of work on an idle core
    (its duration measured by :func:`_point_duration`): well below a worker's lifetime even
    on a loaded host, so that a retiring worker hands back little work."""
    dts = ",".join(f"{0.02 + 0.001 * i:.3f}" for i in range(12))
    ds = ",".join(f"{1.0 + 0.25 * i:g}" for i in range(gains))
    duration = _point_duration(tmp)
    record_property("point_duration_s", duration)
    t0 = time.monotonic()
    r = sweep(tmp, "short_nominal", "--set", f"mission.duration={duration}",
              "--set", f"mission.dt={dts}",
              "--set", f"controller.gains.cam_ori.D={ds}", "--slurm", "--workers", "2",
              *lifetime, timeout=900, **LOCAL, DASK_JOBQUEUE__SLURM__WALLTIME="00:01:00")
    wall = time.monotonic() - t0
    assert r.returncode == 0, r.stderr[-3000:]
    t = table(tmp)
    assert len(t) == 12 * gains and (t["status"] == "complete").all(), \
        t.loc[t["status"] != "complete", ["point", "error"]]
    jobs = _jobs(r.stdout)
    assert len(jobs) > 2, f"no job was replaced: {jobs}"
    record_property("wall_s", round(wall, 1))
    record_property("points", len(t))
    record_property("jobs", len(jobs))
    record_property("replaced", len(jobs) - 2)
    record_property("retried_points", int((t["attempts"] > 1).sum()))
    return jobs, _job_logs(tmp)


def test_slurm_walltime_workers_retire_before_the_limit(slurm_up, tmp_path, record_property):
    """Worker lifetime 15 ± 2 s, a quarter of the 1-minute walltime: each worker retires
    gracefully before SLURM's limit and adapt submits a replacement job."""
    # 24 points, ~72 s of work, ~36 s on two workers: past the first retirements at ~15 s
    jobs, logs = _walltime_sweep(tmp_path, 2, ["--lifetime", "15"], record_property)
    assert set(logs) <= set(jobs)
    assert any("worker-lifetime-reached" in text for text in logs.values()), logs
    assert not any("DUE TO TIME LIMIT" in text for text in logs.values())


def test_slurm_walltime_hard_kill_is_survived(slurm_up, tmp_path, record_property):
    """No lifetime: SLURM kills the jobs at the walltime (SIGTERM, SIGKILL KillWait s later),
    mid-task; the points they ran are rescheduled and the killed jobs replaced."""
    # 96 points, ~290 s of work, ~145 s on two workers: past SLURM's kill 60–95 s after start
    jobs, logs = _walltime_sweep(tmp_path, 8, ["--lifetime", "0"], record_property)
    assert set(logs) <= set(jobs)
    assert any("DUE TO TIME LIMIT" in text for text in logs.values()), logs
    assert not any("worker-lifetime-reached" in text for text in logs.values())


def test_slurm_refused_sbatch_is_exit_2_in_seconds(slurm_up, tmp_path):
    """An unknown partition: sbatch refuses the worker job, and the sweep ends within 60 s
    with one line naming sbatch's reason, instead of waiting for workers that never come."""
    r = sweep(tmp_path, "short_nominal", "--set", "mission.duration=1.0", "--slurm",
              "--workers", "1", timeout=60, **LOCAL,
              DASK_JOBQUEUE__SLURM__QUEUE="no_such_partition")
    assert r.returncode == 2, r.stderr[-3000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("error: --slurm: sbatch refused") and "partition" in lines[0]
    assert not (tmp_path / "out").exists()


MONTECARLO = """\
mission: omega_ripple_sampled_delay_dt0035
set: {mission.duration: 1.0}
seed: 3
ripple_max: 1.0e-4
dispersions:
  controller.gains.bus.D: {dist: uniform, rel: 0.1}
  mission.plant.delay_steps: {dist: choice, values: [0, 1]}
"""


def test_slurm_montecarlo(slurm_up, tmp_path):
    """A small Monte Carlo (issue 35) on SLURM workers: every sample judged, a verdict, the
    worker jobs real, and the records reused by a second run."""
    import subprocess as sp
    import sys

    from sweep_helpers import sweep_env

    from pipeline.montecarlo.verdict import read_table, read_verdict

    (tmp_path / "mc.yaml").write_text(MONTECARLO)
    argv = [sys.executable, "-m", "pipeline", "montecarlo", str(tmp_path / "mc.yaml"),
            "--samples", "4", "--slurm", "--workers", "2", "--logs", str(tmp_path / "logs"),
            "--out", str(tmp_path / "out")]
    env = sweep_env(**LOCAL, DASK_JOBQUEUE__SLURM__WALLTIME="00:10:00")
    r = sp.run(argv, cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    v = read_verdict(tmp_path / "out" / "mc" / "verdict.json")
    assert v.samples == 4 and v.errored == 0 and v.simulated == 4
    assert list(tmp_path.glob("logs/.slurm/*.err")), "no SLURM worker job wrote its log"
    again = sp.run(argv, cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert again.returncode == 0, again.stderr[-3000:]
    assert not read_table(tmp_path / "out" / "mc" / "montecarlo.parquet")["ran"].any()
