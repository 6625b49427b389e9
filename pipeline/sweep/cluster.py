"""Where a sweep runs: an embedded LocalCluster, an existing scheduler, or SLURM workers.

- default: ``LocalCluster(n_workers=N, threads_per_worker=1, processes=True)``; a point whose
  worker dies is rescheduled, up to ``ALLOWED_FAILURES`` times;
- ``--scheduler ADDR`` or ``DASK_SCHEDULER_ADDRESS`` (or dask's ``scheduler-address``
  config): connect within ``CONNECT_TIMEOUT`` s or fail with one line (exit 2);
- ``--slurm``: a ``dask_jobqueue.SLURMCluster`` kept at N one-worker jobs by ``adapt``, each
  worker retiring (``--lifetime``) before its job's walltime; the queue, account, walltime, …
  come from dask's ``jobqueue.slurm`` config (``jobqueue.yaml`` or ``DASK_JOBQUEUE__SLURM__*``
  variables); see docs/sweeps.md.

Every worker runs its numerical libraries on one thread (``SINGLE_THREAD``), so N workers
use N cores. The sweep fails with one line (exit 2) when no worker joins within
``worker_timeout`` s, or as soon as ``sbatch`` refuses a worker job.
"""

from __future__ import annotations

import logging
import os
import re
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import dask

from pipeline.errors import SpecError

CONNECT_TIMEOUT = 5.0  # s, for an existing scheduler
ALLOWED_FAILURES = 3  # worker deaths a point survives before it is a failed row
WORKER_TIMEOUT = 300.0  # s a sweep waits for its first worker (a SLURM queue may be slow)
# One thread per worker for BLAS, OpenMP and Numba: the tasks are single-threaded by design
# (one mission per core), and a threaded BLAS in each of N workers would oversubscribe.
SINGLE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                 "NUMBA_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1",
                 "NUMEXPR_NUM_THREADS": "1"}


@dataclass(frozen=True)
class ClusterOptions:
    """Where and how the sweep's workers run (the CLI's sweep options)."""

    scheduler: str | None = None
    workers: int = 2
    slurm: bool = False
    slurm_log_dir: Path = Path("logs/sweeps/.slurm")
    worker_timeout: float = WORKER_TIMEOUT
    lifetime: float | None = None  # s a SLURM worker lives; None: from the walltime; 0: none


@dataclass
class Jobs:
    """The SLURM jobs a sweep submitted (ids in order) and the refusals of ``sbatch``."""

    ids: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)


@dataclass
class Session:
    """A connected Client, what kind of cluster it talks to, and its SLURM jobs if any."""

    client: object
    kind: str  # "local", "scheduler" or "slurm"
    workers: int  # the workers asked for (for an existing scheduler: those connected at start)
    jobs: Jobs | None = None
    startup_s: float = 0.0  # from the start of open_client to the first worker


def scheduler_address(option: str | None) -> str | None:
    return (option or os.environ.get("DASK_SCHEDULER_ADDRESS")
            or dask.config.get("scheduler-address", None))


def connect(address: str, timeout: float = CONNECT_TIMEOUT):
    """A Client on an existing scheduler, or a one-line SpecError within ``timeout``."""
    from distributed import Client
    from distributed.comm import get_address_host_port

    try:
        # A malformed address is refused before a Client is made: a Client that fails to
        # start leaves a half-made object whose __del__ waits 10 s at exit, then prints a
        # traceback after the one-line error. Other protocols (ucx://) are the Client's.
        if "://" not in address or address.split("://", 1)[0] in ("tcp", "tls"):
            get_address_host_port(address)
    except ValueError as exc:
        raise SpecError(f"--scheduler {address}: not a scheduler address such as "
                        f"tcp://10.0.0.5:8786 ({exc})") from None
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SpecError(f"--scheduler {address}: no Dask scheduler reachable within "
                        f"{timeout:g} s ({why})") from None


_WALLTIME = re.compile(r"^(?:(\d+)-)?(\d+)(?::(\d+))?(?::(\d+))?$")


def walltime_seconds(text: str) -> int:
    """SLURM's ``--time`` formats: ``M``, ``M:S``, ``H:M:S``, ``D-H``, ``D-H:M``, ``D-H:M:S``."""
    m = _WALLTIME.match(str(text).strip())
    if not m:
        raise SpecError(f"jobqueue.slurm.walltime {text!r}: not a SLURM time such as 01:30:00")
    d, a, b, c = m.groups()
    if d is not None:  # D-H[:M[:S]]
        return ((int(d) * 24 + int(a)) * 60 + int(b or 0)) * 60 + int(c or 0)
    if c is not None:
        return (int(a) * 60 + int(b)) * 60 + int(c)
    if b is not None:
        return int(a) * 60 + int(b)
    return int(a) * 60


def default_lifetime(walltime_s: float) -> tuple[float, float]:
    """(lifetime, stagger) in s for a job of ``walltime_s``: the worker retires gracefully
    (its tasks go elsewhere, and adapt submits a replacement job) before SLURM kills it.

    The margin is a tenth of the walltime and at least 20 s, the time a worker needs to hand
    over and close; the stagger (±) keeps the N workers from retiring at the same moment."""
    margin = max(20.0, 0.1 * walltime_s)
    lifetime = max(walltime_s - margin, 0.5 * walltime_s)
    return lifetime, min(0.05 * walltime_s, 0.25 * margin)


def slurm_kwargs(log_dir: Path, lifetime: float | None = None) -> dict:
    """SLURMCluster arguments: one single-threaded worker per job, started in this project
    with this interpreter, retiring before the walltime; cores and memory default to 1 and
    2 GiB unless configured. ``lifetime`` 0 turns retirement off; a ``--lifetime`` in the
    config's ``worker-extra-args`` wins."""
    cfg = dask.config.get("jobqueue.slurm", {})
    extra = list(cfg.get("worker-extra-args") or [])
    if lifetime is None:
        life, stagger = default_lifetime(walltime_seconds(cfg.get("walltime") or "00:30:00"))
    else:
        life, stagger = lifetime, min(0.1 * lifetime, 5.0)
    if life > 0 and "--lifetime" not in extra:
        extra += ["--lifetime", f"{life:.0f}s", "--lifetime-stagger", f"{stagger:.0f}s"]
    kw: dict = {
        "processes": 1,
        "python": cfg.get("python") or sys.executable,
        "job_name": "breve-sweep",
        "log_directory": cfg.get("log-directory") or str(log_dir),
        "job_script_prologue": [*(cfg.get("job-script-prologue") or []),
                                *(f"export {k}={v}" for k, v in SINGLE_THREAD.items()),
                                # the driver's folder: relative paths mean the same
                                f"cd {Path.cwd()}"],
        "worker_extra_args": extra,
        "scheduler_options": {"dashboard_address": ":0", **(cfg.get("scheduler-options") or {})},
    }
    if cfg.get("cores") is None:
        kw["cores"] = 1
    if cfg.get("memory") is None:
        kw["memory"] = "2GiB"
    return kw


def _sbatch_error(exc: BaseException) -> str:
    """The ``sbatch: error: …`` lines of a failed submission, else its first line."""
    text = str(exc)
    lines = [ln.strip() for ln in text.splitlines() if "error" in ln.lower() and ":" in ln]
    lines = [ln for ln in lines if not ln.startswith("Command exited")] or text.splitlines()[:1]
    return "; ".join(lines) or type(exc).__name__


class _DropRecorded(logging.Filter):
    """Drops the logged traceback of a job submission that ``Jobs`` already recorded (tornado
    logs the failed callback; the driver reports sbatch's reason in one line instead)."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return not getattr(exc, "breve_recorded", False)


_DROP_RECORDED = _DropRecorded()


def slurm_cluster(log_dir: Path, lifetime: float | None = None, jobs: Jobs | None = None):
    """A SLURMCluster (no job submitted until it is scaled or adapted); each job it submits
    is recorded in ``jobs`` (its id, or ``sbatch``'s refusal)."""
    try:
        from dask_jobqueue import SLURMCluster
        from dask_jobqueue.slurm import SLURMJob
    except ImportError:
        raise SpecError("--slurm needs dask-jobqueue: pip install -e '.[slurm]'") from None
    record = jobs if jobs is not None else Jobs()

    class RecordedJob(SLURMJob):
        # A refused sbatch surfaces in dask only as a logged callback error while the client
        # waits; recording it here lets the driver fail at once, naming sbatch's reason.
        async def start(self):
            try:
                await super().start()
            except Exception as exc:
                record.errors.append(_sbatch_error(exc))
                exc.breve_recorded = True  # the driver reports it: no logged traceback
                raise
            record.ids.append(str(self.job_id))

    return SLURMCluster(job_cls=RecordedJob, **slurm_kwargs(log_dir, lifetime))


# SLURM workers when the cluster does not say how many CPUs it has (``sinfo``).
MAX_SLURM_WORKERS = 10_000


def check_workers(options: ClusterOptions, address: str | None = None) -> None:
    """SpecError (one line) for a worker count the cluster cannot give: below 1; above this
    machine's cores for the embedded cluster (more workers than cores only share them, each
    with its copy of the libraries); above the SLURM cluster's CPUs (``sinfo``), or
    ``MAX_SLURM_WORKERS`` where it does not answer. An existing scheduler's workers are its
    own."""
    n = options.workers
    if n < 1:
        raise SpecError(f"--workers {n}: needs at least 1")
    if address:
        return
    if options.slurm:
        cpus = slurm_cpus()
        cap, where = ((cpus, f"the SLURM cluster's {cpus} CPUs (sinfo)") if cpus else
                      (MAX_SLURM_WORKERS, f"{MAX_SLURM_WORKERS:,}, the most this asks SLURM for"))
    else:
        cores = usable_cores()
        if cores is None:  # not known here: nothing to judge against
            return
        # The default of 2 stays usable on a one-core machine (two workers share it).
        cap = max(cores, 2)
        where = f"this machine's {cores} usable cores (the embedded cluster; --slurm or " \
                "--scheduler for more)"
    if n > cap:
        raise SpecError(f"--workers {n}: more than {where}")


def usable_cores() -> int | None:
    """The cores this process may run on (its CPU affinity: a cpuset or taskset sees fewer
    than the machine has), None when not known."""
    try:
        return len(os.sched_getaffinity(0)) or None
    except (AttributeError, OSError):
        return os.cpu_count()


def slurm_cpus() -> int | None:
    """The SLURM cluster's CPUs (``sinfo -h -o %C``: allocated/idle/other/total), None when
    it does not answer."""
    import subprocess

    try:
        r = subprocess.run(["sinfo", "-h", "-o", "%C"], capture_output=True, text=True,
                           timeout=20)
        return int(r.stdout.split("/")[-1]) if r.returncode == 0 else None
    except (OSError, subprocess.TimeoutExpired, ValueError):
        return None


def wait_for_workers(client, n: int, timeout: float, what: str, jobs: Jobs | None = None
                     ) -> None:
    """Return once ``n`` workers are connected; SpecError (one line) after ``timeout`` s, or
    as soon as ``sbatch`` refuses a job."""
    deadline = time.monotonic() + timeout
    while True:
        if jobs is not None and jobs.errors:
            raise SpecError(f"{what}: sbatch refused the worker job: {jobs.errors[-1]}")
        if len(client.scheduler_info()["workers"]) >= n:
            return
        if time.monotonic() > deadline:
            raise SpecError(f"{what}: no Dask worker joined within {timeout:g} s "
                            "(raise --worker-timeout if the queue is slow)")
        try:  # blocks until the count is reached or 0.5 s have passed
            client.wait_for_workers(n, timeout=0.5)
        except TimeoutError:
            pass


@contextmanager
def open_client(options: ClusterOptions) -> Iterator[Session]:
    """A connected Session for the sweep, with at least one worker; clusters this opens are
    closed on exit (their SLURM jobs cancelled)."""
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    address = scheduler_address(options.scheduler)
    check_workers(options, address)
    if options.worker_timeout <= 0:
        raise SpecError(f"--worker-timeout {options.worker_timeout:g}: must be positive")
    if address and options.slurm:
        raise SpecError("--slurm and --scheduler (or DASK_SCHEDULER_ADDRESS) exclude each other")
    if address:
        client = connect(address)
        try:
            wait_for_workers(client, 1, options.worker_timeout, f"--scheduler {address}")
            yield Session(client, "scheduler", len(client.scheduler_info()["workers"]),
                          startup_s=time.perf_counter() - t0)
        finally:
            client.close()
        return
    config = {"distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
              "distributed.nanny.pre-spawn-environ": {
                  **dask.config.get("distributed.nanny.pre-spawn-environ", {}),
                  **SINGLE_THREAD}}
    with dask.config.set(config):
        jobs = None
        if options.slurm:
            jobs = Jobs()
            for name in ("tornado.application", "distributed.deploy.adaptive_core",
                         "distributed.deploy.adaptive", "distributed.utils"):
                logging.getLogger(name).addFilter(_DROP_RECORDED)
            cluster = slurm_cluster(options.slurm_log_dir, options.lifetime, jobs)
            # adapt, not scale: with scale(jobs=N) a job that ends (walltime, lifetime, a
            # node failure) is never replaced; adapt resubmits to keep N jobs.
            cluster.adapt(minimum_jobs=options.workers, maximum_jobs=options.workers)
        else:
            cluster = LocalCluster(n_workers=options.workers, threads_per_worker=1,
                                   processes=True, dashboard_address="127.0.0.1:0")
        try:
            with Client(cluster, set_as_default=False) as client:
                what = "--slurm" if options.slurm else "LocalCluster"
                wait_for_workers(client, 1, options.worker_timeout, what, jobs)
                yield Session(client, "slurm" if options.slurm else "local", options.workers,
                              jobs, time.perf_counter() - t0)
        finally:
            _close(cluster, jobs)


def _close(cluster, jobs: Jobs | None) -> None:
    """Close the cluster (cancelling its jobs). A job that sbatch refused was never started,
    and SpecCluster's close then trips on its state: that error would hide sbatch's reason,
    which is already the sweep's error."""
    try:
        cluster.close()
    except Exception:
        if not (jobs and jobs.errors):
            raise
        # Closed as far as it goes: without this, the cluster's finaliser warns "unclosed
        # cluster" at exit, a second stderr line after the sweep's one-line error.
        from distributed.core import Status

        cluster.status = Status.closed
