"""Sweep and Monte Carlo throughput for ``make bench``: tasks per second and the per-task
overhead of Dask, so a user can size a study for a cluster (docs/montecarlo.md).

The same 32-point grid (8 values of ``mission.dt`` × 4 of the bus damping gain, 20-s missions
of the seed nominal) runs in three settings, each into a fresh log folder (nothing cached):
``inprocess`` (the tasks called one after the other in this process, no Dask), ``local2``
(a 2-worker LocalCluster) and ``slurm2`` (2 one-core jobs on the local SLURM; skipped, with
the reason, when no SLURM answers).

Start-up (cluster, job submission, workers up and their imports done) is ``startup_s``. The
steady state starts when as many points have finished as there are workers (every worker
has then been busy once; the first task on a worker pays for loading the compiled kernels):
``steady_s_per_point`` = (last finish − that finish) / the points in between. The per-point
overhead is ``steady_s_per_point × workers − task_s``, where ``task_s`` is the median time a
task spent simulating and analysing (its own clock), and ``overhead_ratio`` = overhead /
``task_s``. Target: below 1.

The Monte Carlo's (:func:`montecarlo_throughput`) are the same figures for its first
:data:`MC_SAMPLES` samples (a sample's task: its flight, its verdict and its kept record;
``task_s`` its own clock of the flight and the verdict), in the same three settings.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

DTS = "0.005,0.01,0.015,0.0175,0.02,0.025,0.03,0.04"
BUS_D = "1.0,1.5,2.0,2.5"
SETS = [f"mission.dt={DTS}", f"controller.gains.bus.D={BUS_D}", "mission.duration=20"]
SLURM_WALLTIME = "00:20:00"
# The Monte Carlo's throughput: the first samples of the bench's 852-sample Monte Carlo (60 s
# sampled-data missions with one step of delay), as many as fill two workers several times.
MC_FILE = "bench_sampled_delay"
MC_SAMPLES = 24


@dataclass(frozen=True)
class Throughput:
    """One setting's figures (NaN and ``skipped`` set when it could not run)."""

    setting: str
    workers: int
    points: int = 0
    complete: int = 0
    startup_s: float = float("nan")
    wall_s: float = float("nan")  # start-up included
    steady_s_per_point: float = float("nan")
    task_s: float = float("nan")  # median per-point simulation and analysis time
    points_per_s: float = float("nan")  # steady state
    overhead_s: float = float("nan")  # per point
    overhead_ratio: float = float("nan")
    # The grid's points differ in length (dt from 0.005 to 0.04 s), so the median task time
    # is not the mean one; the overhead against the mean task time of the points finished
    # within the steady state compares like with like (in process, with no Dask at all, the
    # median-based overhead is mostly that gap).
    task_s_mean: float = float("nan")
    overhead_ratio_mean: float = float("nan")
    skipped: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def throughput_of(setting: str, workers: int, startup: float, wall: float, records: list[dict]
             ) -> Throughput:
    done = sorted(r["received"] for r in records)
    task = float(np.median([r["seconds"] for r in records]))
    k = min(workers, len(done)) - 1  # index of the finish that starts the steady state
    steady = (done[-1] - done[k]) / max(len(done) - 1 - k, 1)
    overhead = steady * workers - task
    mean = float(np.mean([r["seconds"] for r in records if r["received"] > done[k]]
                         or [task]))
    return Throughput(setting, workers, len(records),
                      sum(r["status"] == "complete" for r in records), startup, wall, steady,
                      task, 1.0 / steady, overhead, overhead / task, mean,
                      (steady * workers - mean) / mean)


def _warm_here(root: Path) -> None:
    """Imports and compiled kernels loaded in this process: a 10-step mission."""
    from pipeline.sim.run import run_spec
    from pipeline.spec import load_spec, with_overrides
    from pipeline.sweep.progress import worker_id

    spec = load_spec("nominal")
    run_spec(with_overrides(spec, {"mission.duration": 10 * spec.mission.dt},
                            name=f"warm_{worker_id().replace(':', '_')}"), root / "warm")


def _warm(client, root: Path) -> None:
    """The same on every worker (part of the start-up)."""
    client.run(_warm_here, root)


def slurm_ready() -> str:
    """Why the local SLURM cannot be used ("" when it can)."""
    if not shutil.which("sbatch") or not shutil.which("sinfo"):
        return "no SLURM client (sbatch, sinfo) on PATH: make slurm-up"
    try:
        r = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True,
                           timeout=20)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"sinfo failed: {exc}"
    states = r.stdout.split()
    if r.returncode != 0 or not any(s in ("idle", "mix") for s in states):
        why = (r.stderr.strip().splitlines() or [f"node states {states}"])[0]
        return f"no idle SLURM node ({why}): make slurm-up"
    return ""


def measure(setting: str, root: Path) -> Throughput:
    """Run the grid in ``setting`` into ``root`` (a fresh folder) and measure it."""
    from pipeline.sweep.driver import execute, plan_sweep
    from pipeline.sweep.point import run_point

    sweep = plan_sweep("nominal", SETS, name=f"bench_{setting}", logs=root / "logs",
                       out=root / "out", workers=2)
    return _timed(setting, root,
                  lambda: (run_point(p.spec, str(sweep.log_dir)) for p in sweep.points),
                  lambda client, timeout, jobs: execute(sweep, client, worker_timeout=timeout,
                                                        jobs=jobs))


def measure_montecarlo(setting: str, root: Path, samples: int = MC_SAMPLES) -> Throughput:
    """The first ``samples`` samples of the bench's Monte Carlo (:data:`MC_FILE`) in
    ``setting``, their records kept under ``root`` (a fresh folder: every sample flies)."""
    from pipeline.montecarlo.driver import run_montecarlo
    from pipeline.montecarlo.plan import plan_montecarlo
    from pipeline.montecarlo.task import sample_task

    mc = plan_montecarlo(MC_FILE, samples)
    records = root / "records"
    ripple = mc.config.ripple_max
    return _timed(setting, root,
                  lambda: (sample_task(s.spec, s.index, list(s.seed), s.draws, ripple,
                                       str(records), "bench") for s in mc.samples),
                  lambda client, timeout, jobs: run_montecarlo(mc, records, client, False,
                                                               timeout, jobs))


def _timed(setting: str, root: Path, here, on_cluster) -> Throughput:
    """Start-up, then the tasks: ``here()``, a generator of their calls, one after the other
    in this process (each record stamped as it returns), or ``on_cluster(client,
    worker_timeout, jobs)`` on the setting's 2 workers (the driver stamps them)."""
    import dask

    from pipeline.sweep.cluster import ClusterOptions, open_client

    t0 = time.perf_counter()
    if setting == "inprocess":
        _warm_here(root)
        startup = time.perf_counter() - t0
        records = [{**rec, "received": time.perf_counter()} for rec in here()]
        return throughput_of(setting, 1, startup, time.perf_counter() - t0, records)
    slurm = setting.startswith("slurm")
    if slurm and (why := slurm_ready()):
        return Throughput(setting, 2, skipped=why)
    options = ClusterOptions(workers=2, slurm=slurm, slurm_log_dir=root / "slurm")
    if slurm:
        # dask-jobqueue adds its defaults to Dask's config when first imported: imported
        # inside the set below, they would leave with it, and the next SLURM cluster of this
        # process would find no jobqueue.slurm.shared-temp-directory.
        import dask_jobqueue  # noqa: F401
    # the local SLURM: scheduler and workers on the loopback interface
    local = {"jobqueue.slurm.walltime": SLURM_WALLTIME, "jobqueue.slurm.interface": "lo"}
    with dask.config.set(local), \
            open_client(options) as session:
        session.client.wait_for_workers(2, timeout=options.worker_timeout)
        _warm(session.client, root)
        startup = time.perf_counter() - t0
        records = on_cluster(session.client, options.worker_timeout, session.jobs)
        wall = time.perf_counter() - t0
    return throughput_of(setting, 2, startup, wall, records)


SETTINGS = ("inprocess", "local2", "slurm2")


def _each_setting(measure_in, what: str, settings: tuple[str, ...], progress
                  ) -> dict[str, Throughput]:
    """``measure_in(setting, folder)`` for each setting, each in a fresh folder."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for s in settings:
            progress(f"{what}: {s}")
            out[s] = measure_in(s, Path(tmp) / s)
    return out


def sweep_throughput(settings: tuple[str, ...] = SETTINGS, progress=print
                     ) -> dict[str, Throughput]:
    return _each_setting(measure, "sweep throughput, 32 points", settings, progress)


def montecarlo_throughput(settings: tuple[str, ...] = SETTINGS, progress=print
                          ) -> dict[str, Throughput]:
    return _each_setting(measure_montecarlo, f"Monte Carlo throughput, {MC_SAMPLES} samples "
                         f"of {MC_FILE}", settings, progress)
