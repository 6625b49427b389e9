"""``python -m pipeline sweep``: plan the grid, run it on Dask, write the table, report."""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
import time
import uuid
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.artefact_paths import log_path
from pipeline.budget import Budget, check_mission, check_sweep_size, check_sweep_time
from pipeline.errors import OutputError, PipelineError, RunFailed
from pipeline.provenance.keys import analysis_version, sim_version
from pipeline.spec import Spec, load_spec
from pipeline.store.locks import clear_unheld
from pipeline.sweep.cluster import (
    ALLOWED_FAILURES,
    WORKER_TIMEOUT,
    ClusterOptions,
    open_client,
)
from pipeline.sweep.grid import Point, build_grid, parse_sets, sweep_name
from pipeline.sweep.point import figures, sweep_task
from pipeline.sweep.progress import Progress, Tracker
from pipeline.sweep.results import TABLE_NAME, make_table, summary_text, write_table

WATCH_EVERY = 2.0  # s between the watchdog's looks at the worker count


@dataclass(frozen=True)
class Sweep:
    name: str
    base: Spec
    axes: list[tuple[str, list[Any]]]
    points: list[Point]
    log_dir: Path  # absolute: workers may run elsewhere (shared file system)
    out_dir: Path

    @property
    def keys(self) -> list[str]:
        return [k for k, _ in self.axes]

    @property
    def table_path(self) -> Path:
        return self.out_dir / TABLE_NAME


def plan_sweep(spec: str | Path, sets: list[str], name: str | None = None,
               logs: Path | str = "logs/sweeps",
               out: Path | str = "generated_reports/sweeps", workers: int = 1) -> Sweep:
    """Parse and validate everything (SpecError on bad input); nothing runs, nothing is written.

    The grid is counted before it is built and refused over ``MAX_SWEEP_POINTS``; each point
    is a mission within the budget, and all of them on ``workers`` within the time budget."""
    base = load_spec(spec)
    axes = parse_sets(sets)
    sname = sweep_name(base.name, [k for k, _ in axes], name)
    check_sweep_size(math.prod(len(vals) for _, vals in axes), f"sweep {sname}")
    points = build_grid(base, axes)
    budget = Budget.from_environment()
    per_point = max((check_mission(p.spec, budget, f"sweep {sname}: point {p.name}").seconds
                     for p in points), default=0.0)
    check_sweep_time(per_point, len(points), workers, f"sweep {sname}", budget)
    return Sweep(sname, base, axes, points, Path(logs).resolve() / sname,
                 Path(out).resolve() / sname)


class Interrupted(PipelineError):
    """SIGINT or SIGTERM stopped the sweep: exit 128 + the signal number (130, 143)."""

    def __init__(self, message: str, signum: int) -> None:
        super().__init__(message)
        self.exit_code = 128 + signum


class _Stop(BaseException):  # raised by the SIGTERM handler in the driver's main thread
    def __init__(self, signum: int) -> None:
        self.signum = signum


def _failed_record(point: Point, error: str) -> dict:
    return {"point": point.name, "status": "failed", "error": error, "ran": False,
            "analysed": False, "n_steps": 0, "seconds": float("nan"), "worker": "",
            "spec_hash": point.spec.spec_hash, "log": "", **figures(None)}


def _outcome(fut, name: str, failed: Callable, why_cancelled: str) -> dict:
    """The record of a completed future. A ``lost`` one (its worker died, at a walltime say,
    between finishing and our taking the result) is computed again by Dask: wait for it."""
    from distributed.client import FutureCancelledError

    cancelled = ("task cancelled: "
                 f"{why_cancelled or 'the scheduler was lost or the sweep stopped'}")
    if fut.status == "cancelled":
        return failed(name, cancelled)
    try:
        return fut.result()
    except FutureCancelledError:
        return failed(name, cancelled)
    except Exception as exc:  # a bug, or KilledWorker: its workers died too many times
        text = str(exc).splitlines()[0] if str(exc) else ""
        return failed(name, f"{type(exc).__name__}: {text}")


class _Watchdog(threading.Thread):
    """Cancels what is left when the sweep has had no worker for ``timeout`` s (a SLURM
    queue that stopped starting jobs, an sbatch that now fails): the sweep then ends with
    failed rows instead of waiting forever. A liveness check, not a look at the results."""

    def __init__(self, client, futures: set, timeout: float, jobs) -> None:
        super().__init__(daemon=True, name="sweep-watchdog")
        self.client, self.futures, self.timeout, self.jobs = client, futures, timeout, jobs
        self.stop = threading.Event()
        self.reason = ""

    def run(self) -> None:
        alone_since = None
        while not self.stop.wait(WATCH_EVERY):
            try:
                n = len(self.client.scheduler_info()["workers"])
            except Exception:  # the client is closing: nothing left to watch
                return
            if n:
                alone_since = None
                continue
            alone_since = alone_since or time.monotonic()
            if time.monotonic() - alone_since > self.timeout:
                why = f"no Dask worker for {self.timeout:g} s"
                if self.jobs is not None and self.jobs.errors:
                    why += f" (sbatch: {self.jobs.errors[-1]})"
                self.reason = why
                self.client.cancel(list(self.futures.copy()))  # the main thread edits it
                return


def execute(sweep: Sweep, client, progress: bool = False, worker_timeout: float = 300.0,
            jobs=None) -> list[dict]:
    """Submit one task per point and collect the records as they complete (grid order);
    see :func:`execute_tasks`."""
    points = {p.name: p for p in sweep.points}

    def submit(name: str, topic: str, key: str):
        return client.submit(sweep_task, points[name].spec, str(sweep.log_dir), topic,
                             pure=False, key=key)

    return execute_tasks(sweep.name, list(points), submit,
                         lambda name, error: _failed_record(points[name], error),
                         lambda rec: rec["status"] == "complete", client, progress,
                         worker_timeout, jobs)


def execute_tasks(title: str, names: list[str], submit: Callable, failed: Callable,
                  ok: Callable[[dict], bool], client, progress: bool = False,
                  worker_timeout: float = 300.0, jobs=None, kind: str = "sweep",
                  unit: str = "point") -> list[dict]:
    """Submit one task per name (``submit(name, topic, key)`` returns its future) and collect
    the records as they complete, in the order of ``names``; a task that raised, was cancelled
    or whose workers died gets ``failed(name, error)``; ``ok(record)`` counts it done or
    failed in the progress.

    Each record gets ``attempts``, the starts of its task that the driver saw (more than
    one: a worker died or retired under it and Dask ran it again; tasks announce their start
    on the topic, :func:`pipeline.sweep.progress.announce_start`), and for a task the
    scheduler gave up on (KilledWorker) the starts its rule implies."""
    from distributed import as_completed

    tag = uuid.uuid4().hex[:8]
    topic = f"breve-sweep-{tag}"
    shown = Progress(title, len(names), terminal=progress, kind=kind, unit=unit)
    tracker = Tracker(names, shown)
    client.subscribe_topic(topic, tracker.started)
    futures = {submit(name, topic, f"{kind}-{name}-{tag}"): name for name in names}
    pending = set(futures)
    watchdog = _Watchdog(client, pending, worker_timeout, jobs)
    watchdog.start()
    records: dict[str, dict] = {}
    try:
        for fut in as_completed(list(futures), loop=client.loop):
            name = futures.pop(fut)
            rec = _outcome(fut, name, failed, watchdog.reason)
            # Release the result at once: a result the client still refers to is recomputed
            # when the worker holding it dies or retires (a walltime), so every finished task
            # would run again each time a job ends.
            pending.discard(fut)
            fut.release()
            rec["received"] = time.perf_counter()  # for the throughput (not in the table)
            records[name] = rec
            tracker.finished(name, ok(rec))
    except BaseException:
        client.cancel(list(pending))  # what is queued never starts
        raise
    finally:
        watchdog.stop.set()
        shown.close()
        with suppress(Exception):
            client.unsubscribe_topic(topic)
    for name in names:
        # The starts the driver saw; a start announced by a worker killed at once may never
        # arrive (under load). A KilledWorker is the scheduler's own count: the task's worker
        # died ALLOWED_FAILURES + 1 times, so it started that often.
        seen = tracker.attempts(name)
        killed = str(records[name].get("error", "")).startswith("KilledWorker")
        records[name]["attempts"] = max(seen, ALLOWED_FAILURES + 1) if killed else seen
    return [records[name] for name in names]


def run_sweep(sweep: Sweep, client, progress: bool = False, worker_timeout: float = 300.0,
              jobs=None):
    """Run the sweep on ``client`` and write its table; returns (table, path)."""
    records = execute(sweep, client, progress, worker_timeout, jobs)
    df = make_table(sweep.keys, [p.overrides for p in sweep.points], records)
    meta = {"pipeline.sweep": sweep.name, "pipeline.spec": sweep.base.name,
            "pipeline.base_spec_hash": sweep.base.spec_hash,
            # the driver's keys; each worker checked its own logs and analyses against its own
            "pipeline.sim_version": sim_version(), "pipeline.analysis_version": analysis_version(),
            "pipeline.keys": ",".join(sweep.keys), "pipeline.log_dir": str(sweep.log_dir)}
    return df, write_table(df, sweep.table_path, meta)


def check_writable(folder: Path) -> None:
    """OutputError (exit 2) if ``folder`` could not be created and written, found without
    creating anything: its nearest existing ancestor must be a writable folder."""
    p = folder
    while not p.exists() and p != p.parent:
        p = p.parent
    if not p.is_dir():
        raise OutputError(f"{folder}: cannot write: {p} is a file, not a folder")
    if not os.access(p, os.W_OK | os.X_OK):
        raise OutputError(f"{folder}: cannot write: {p} is not writable")


def _raise_stop(signum, _frame):
    # Further signals are ignored from here on, so that closing the cluster and clearing
    # the leftovers of killed writers finish.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise _Stop(signum)


def _finished_points(sweep: Sweep) -> int:
    return sum(log_path(sweep.log_dir, p.name).is_file() for p in sweep.points)


def sweep_command(args: argparse.Namespace) -> int:
    sweep = plan_sweep(args.spec, args.set, args.name, args.logs, args.out, args.workers)
    for folder in (sweep.log_dir, sweep.out_dir):
        check_writable(folder)
    options = ClusterOptions(
        scheduler=args.scheduler, workers=args.workers, slurm=args.slurm,
        slurm_log_dir=sweep.log_dir.parent / ".slurm",
        worker_timeout=getattr(args, "worker_timeout", None) or WORKER_TIMEOUT,
        lifetime=getattr(args, "lifetime", None))
    t0 = time.perf_counter()
    # SIGTERM (scancel of a driver job, a batch system's kill) stops the sweep like Ctrl-C:
    # queued points are cancelled, finished ones are kept, nothing is half-written.
    previous = {s: signal.signal(s, _raise_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with open_client(options) as session:
            df, path = run_sweep(sweep, session.client, sys.stderr.isatty(),
                                 options.worker_timeout, session.jobs)
    except _Stop as stop:
        _stop_cleanly(sweep, stop.signum)
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    print(summary_text(df, sweep.keys, path))
    if session.jobs is not None:
        ids = session.jobs.ids
        print(f"slurm: {len(ids)} worker jobs submitted for {session.workers} workers "
              f"({len(ids) - session.workers if len(ids) > session.workers else 0} "
              f"replacements): {' '.join(ids)}")
    print(f"sweep {sweep.name}: {time.perf_counter() - t0:.1f} s wall "
          f"({session.startup_s:.1f} s to the first worker)")
    failed = df[df["status"] != "complete"]
    for point in failed["point"]:  # a point whose last worker was killed mid-write
        clear_unheld(sweep.log_dir / point)
    if len(failed):
        names = "; ".join(f"{r.point} ({r.error})" for r in failed.itertuples())
        raise RunFailed(f"sweep {sweep.name}: {len(failed)} of {len(df)} points failed: {names}")
    return 0


def _stop_cleanly(sweep: Sweep, signum: int) -> None:
    """After the cluster is closed: clear the leftovers of the points killed mid-write, then
    raise Interrupted (the handler ignores a second signal meanwhile)."""
    for p in sweep.points:
        clear_unheld(sweep.log_dir / p.name)
    name = signal.Signals(signum).name
    raise Interrupted(f"sweep {sweep.name}: stopped by {name}: queued points cancelled; "
                      f"{_finished_points(sweep)} of {len(sweep.points)} points have a "
                      f"finished log in {sweep.log_dir}, which the same command reuses; "
                      "no table written", signum) from None
