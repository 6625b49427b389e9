"""``python -m pipeline sweep``: plan the grid, run it on Dask, write the table, report."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from pipeline.budget import Budget, check_mission, check_sweep_size, check_sweep_time
from pipeline.errors import OutputError, RunFailed
from pipeline.provenance.keys import analysis_version, sim_version
from pipeline.spec import Spec, load_spec
from pipeline.sweep.cluster import open_client
from pipeline.sweep.grid import Point, build_grid, parse_sets, sweep_name
from pipeline.sweep.point import figures, run_point
from pipeline.sweep.results import TABLE_NAME, make_table, summary_text, write_sweep_table

POLL = 0.2  # s between looks at the futures
PROCESSING_EVERY = 1.0  # s between asks to the scheduler for the running count


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


def _failed_record(point: Point, error: str) -> dict:
    return {"point": point.name, "status": "failed", "error": error, "ran": False,
            "analysed": False, "n_steps": 0, "seconds": float("nan"), "worker": "",
            "spec_hash": point.spec.spec_hash, "log": "", **figures(None)}


def _outcome(fut, point: Point) -> dict:
    if fut.status == "finished":
        return fut.result()
    if fut.status == "error":  # a bug, or KilledWorker: its workers died too many times
        exc = fut.exception()
        text = str(exc).splitlines()[0] if str(exc) else ""
        return _failed_record(point, f"{type(exc).__name__}: {text}")
    return _failed_record(point, f"task {fut.status}: the scheduler was lost or the sweep stopped")


def execute(sweep: Sweep, client, progress: bool = False) -> list[dict]:
    """Submit one task per point, collect the records (grid order), with a progress bar."""
    tag = uuid.uuid4().hex[:8]
    futures = {client.submit(run_point, p.spec, str(sweep.log_dir), pure=False,
                             key=f"sweep-{p.name}-{tag}"): p for p in sweep.points}
    keys = {f.key for f in futures}
    records: dict[str, dict] = {}
    pending = set(futures)
    n_failed, running, asked = 0, 0, 0.0
    with tqdm(total=len(futures), disable=not progress, unit="point", desc=sweep.name,
              file=sys.stderr) as bar:
        while pending:
            done = {f for f in pending if f.done()}
            if not done and client.status == "closed":  # the scheduler is gone for good
                for f in pending:
                    records[futures[f].name] = _failed_record(futures[f], "scheduler lost")
                n_failed += len(pending)
                break
            pending -= done
            for f in done:
                rec = _outcome(f, futures[f])
                records[rec["point"]] = rec
                n_failed += rec["status"] != "complete"
            if progress and time.monotonic() - asked > PROCESSING_EVERY:
                asked = time.monotonic()
                running = sum(len(keys.intersection(ks)) for ks in client.processing().values())
            bar.set_postfix_str(f"done {len(records) - n_failed}, failed {n_failed}, "
                                f"running {min(running, len(pending))}", refresh=False)
            bar.update(len(done))
            if pending and not done:
                time.sleep(POLL)
    return [records[p.name] for p in sweep.points]


def run_sweep(sweep: Sweep, client, progress: bool = False):
    """Run the sweep on ``client`` and write its table; returns (table, path)."""
    records = execute(sweep, client, progress)
    df = make_table(sweep.keys, [p.overrides for p in sweep.points], records)
    meta = {"pipeline.sweep": sweep.name, "pipeline.spec": sweep.base.name,
            "pipeline.base_spec_hash": sweep.base.spec_hash,
            # the driver's keys; each worker checked its own logs and analyses against its own
            "pipeline.sim_version": sim_version(), "pipeline.analysis_version": analysis_version(),
            "pipeline.keys": ",".join(sweep.keys), "pipeline.log_dir": str(sweep.log_dir)}
    return df, write_sweep_table(df, sweep.table_path, meta)


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


def sweep_command(args: argparse.Namespace) -> int:
    sweep = plan_sweep(args.spec, args.set, args.name, args.logs, args.out, args.workers)
    for folder in (sweep.log_dir, sweep.out_dir):
        check_writable(folder)
    progress = sys.stderr.isatty()
    t0 = time.perf_counter()
    with open_client(args.scheduler, args.workers, args.slurm,
                     sweep.log_dir.parent / ".slurm") as client:
        df, path = run_sweep(sweep, client, progress)
    print(summary_text(df, sweep.keys, path))
    print(f"sweep {sweep.name}: {time.perf_counter() - t0:.1f} s wall")
    failed = df[df["status"] != "complete"]
    if len(failed):
        names = "; ".join(f"{r.point} ({r.error})" for r in failed.itertuples())
        raise RunFailed(f"sweep {sweep.name}: {len(failed)} of {len(df)} points failed: {names}")
    return 0
