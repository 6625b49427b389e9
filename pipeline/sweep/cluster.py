"""Where a sweep runs: an embedded LocalCluster, an existing scheduler, or SLURM workers.

- default: ``LocalCluster(n_workers=N, threads_per_worker=1, processes=True)``; a point whose
  worker dies is rescheduled, up to ``ALLOWED_FAILURES`` times;
- ``--scheduler ADDR`` or ``DASK_SCHEDULER_ADDRESS`` (or dask's ``scheduler-address``
  config): connect within ``CONNECT_TIMEOUT`` s or fail with one line (exit 2);
- ``--slurm``: a ``dask_jobqueue.SLURMCluster`` scaled to N one-worker jobs; the queue,
  account, walltime, … come from dask's ``jobqueue.slurm`` config (``jobqueue.yaml`` or
  ``DASK_JOBQUEUE__SLURM__*`` variables); see docs/sweeps.md.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import dask

from pipeline.errors import SpecError
from pipeline.paths import PROJECT_ROOT

CONNECT_TIMEOUT = 5.0  # s, for an existing scheduler
ALLOWED_FAILURES = 3  # worker deaths a point survives before it is a failed row


def scheduler_address(option: str | None) -> str | None:
    return (option or os.environ.get("DASK_SCHEDULER_ADDRESS")
            or dask.config.get("scheduler-address", None))


def connect(address: str, timeout: float = CONNECT_TIMEOUT):
    """A Client on an existing scheduler, or a one-line SpecError within ``timeout``."""
    from distributed import Client

    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SpecError(f"--scheduler {address}: no Dask scheduler reachable within "
                        f"{timeout:g} s ({why})") from None


def slurm_kwargs(log_dir: Path) -> dict:
    """SLURMCluster arguments: one single-threaded worker per job, started in this project
    with this interpreter; cores and memory default to 1 and 2 GiB unless configured."""
    cfg = dask.config.get("jobqueue.slurm", {})
    kw: dict = {
        "processes": 1,
        "python": cfg.get("python") or sys.executable,
        "job_name": "breve-sweep",
        "log_directory": cfg.get("log-directory") or str(log_dir),
        "job_script_prologue": [*(cfg.get("job-script-prologue") or []), f"cd {PROJECT_ROOT}"],
        "scheduler_options": {"dashboard_address": ":0", **(cfg.get("scheduler-options") or {})},
    }
    if cfg.get("cores") is None:
        kw["cores"] = 1
    if cfg.get("memory") is None:
        kw["memory"] = "2GiB"
    return kw


def slurm_cluster(log_dir: Path):
    """A SLURMCluster (no job submitted until it is scaled)."""
    try:
        from dask_jobqueue import SLURMCluster
    except ImportError:
        raise SpecError("--slurm needs dask-jobqueue: pip install -e '.[slurm]'") from None
    return SLURMCluster(**slurm_kwargs(log_dir))


@contextmanager
def open_client(scheduler: str | None, workers: int, slurm: bool,
                slurm_log_dir: Path) -> Iterator:
    """A connected Client for the sweep; clusters this opens are closed on exit."""
    from distributed import Client, LocalCluster

    address = scheduler_address(scheduler)
    if workers < 1:
        raise SpecError(f"--workers {workers}: needs at least 1")
    if address and slurm:
        raise SpecError("--slurm and --scheduler (or DASK_SCHEDULER_ADDRESS) exclude each other")
    if address:
        client = connect(address)
        try:
            yield client
        finally:
            client.close()
        return
    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES}):
        if slurm:
            cluster = slurm_cluster(slurm_log_dir)
            cluster.scale(jobs=workers)
        else:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0")
        with cluster, Client(cluster, set_as_default=False) as client:
            yield client
