"""One sweep point as one Dask task: run the mission unless cached, analyse it, return a record.

Runs on a worker. The log goes to ``ROOT/<point>/run.parquet`` and the analysis beside it
(``analysis.json``, ``directions.parquet``), all written atomically.

Cache: a log that :func:`pipeline.provenance.validity.current_log` accepts (this spec, robot
and simulator) is reused, whether ``complete``, ``failed`` or ``diverged`` (the simulation is
deterministic: the same spec on the same code fails or diverges again at the same step). An
``analysis.json`` is reused when ``current_analysis`` accepts it (made from that log by this
analysis code).

Concurrency: the simulate-and-analyse part runs under an exclusive ``flock`` on
``ROOT/<point>/.lock``, so two sweeps sharing a point (or a rescheduled task meeting its
predecessor) never simulate it twice at once; the second waits, then finds the cache. The
kernel drops the lock of a killed process, so a stale lock cannot block. Holding the lock, a
task removes the temporary files a killed writer of this point left behind.
"""

from __future__ import annotations

import errno
import fcntl
import math
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from pipeline.artefact_paths import ANALYSIS_FILE, LOG_FILE
from pipeline.errors import PipelineError
from pipeline.logs import num_rows, read_meta
from pipeline.provenance.validity import current_analysis, current_log
from pipeline.spec import Spec

LOCK_NAME = ".lock"

# record column → path in analysis.json
FIGURES: dict[str, tuple[str, ...]] = {
    "dominant_lag1": ("dominant", "lag1"),
    "dominant_sigma": ("dominant", "sigma"),
    "dt_mu_max": ("theory", "dt_mu_max"),
    "mu_max": ("theory", "mu_max"),
    "dt_star_damping": ("theory", "dt_star_damping"),
    "dt_star_map": ("theory", "dt_star_map"),
    "eig_real": ("theory", "eig_dominant", "real"),
    "eig_imag": ("theory", "eig_dominant", "imag"),
    "spectral_radius": ("theory", "spectral_radius"),
    "abs_cos": ("alignment", "abs_cos"),
    "velocity_jump_median": ("velocity_jump", "median"),
    "pointing_err_deg_max": ("metrics", "pointing_err_deg_max"),
    "coverage_final": ("metrics", "coverage_final"),
    "bus_rate_lag1": ("bus_rate", "lag1"),
    "bus_rate_alternating_rms": ("bus_rate", "alternating_rms"),
    "I_zz_bus": ("robot", "I_zz_bus"),
    "mu_bus": ("robot", "mu_bus"),
    "bus_critical_I_zz": ("bus_mode", "critical_I_zz"),
}


@contextmanager
def point_lock(folder: Path) -> Iterator[None]:
    """Exclusive lock on ``folder/.lock`` (``flock``; released by the kernel if we die).

    The lock file is removed on release; a waiter that then holds a lock on the removed file
    notices (inode changed) and locks the new one. On a file system without ``flock`` the
    point runs unlocked (the atomic rename still rules out a torn log).
    """
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    while True:
        fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.ENOLCK, errno.ENOSYS, errno.EOPNOTSUPP, errno.EINVAL):
                yield
                return
            raise
        try:
            st = os.stat(path)
            held = (st.st_ino, st.st_dev) == (os.fstat(fd).st_ino, os.fstat(fd).st_dev)
        except FileNotFoundError:
            held = False
        if held:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
        yield
    finally:
        with suppress(FileNotFoundError):
            os.unlink(path)
        os.close(fd)


def remove_stale_temps(folder: Path) -> list[str]:
    """Delete the ``.*.tmp`` files of a dead writer (call only while holding the lock)."""
    gone = []
    for p in folder.glob(".*.tmp"):
        with suppress(FileNotFoundError):
            p.unlink()
            gone.append(p.name)
    return gone


def clear_unheld(folder: Path) -> list[str]:
    """After a stopped sweep: if no live process holds ``folder``'s lock, delete the temporary
    files a killed writer left and the stale lock file; a point still held (its task runs on
    a worker that outlives the sweep) is left to its holder. Returns what was deleted."""
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:
        return remove_stale_temps(folder) if folder.is_dir() else []
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return []  # held by a live task, or no flock here: not ours to touch
        gone = remove_stale_temps(folder)
        with suppress(FileNotFoundError):
            os.unlink(path)
        return [*gone, LOCK_NAME]
    finally:
        os.close(fd)


def figures(analysis: dict | None) -> dict[str, float]:
    out = {}
    for col, path in FIGURES.items():
        node = analysis
        for p in path:
            node = node.get(p) if isinstance(node, dict) else None
        out[col] = float(node) if isinstance(node, int | float) else math.nan
    return out


def sweep_task(spec: Spec, root: str, topic: str) -> dict:
    """The task the driver submits: announce the start on ``topic`` (the driver counts
    retries and running points from it), then ``run_point``."""
    from pipeline.sweep.progress import announce_start

    announce_start(topic, spec.name)
    return run_point(spec, root)


def run_point(spec: Spec, root: str) -> dict:
    """The Dask task of one point (see the module docstring); returns a small record."""
    from pipeline.analysis.record import write_analysis
    from pipeline.analysis.stages import analyze_log
    from pipeline.sim.run import run_spec

    t0 = time.perf_counter()
    folder = Path(root) / spec.name
    log, analysis_path = folder / LOG_FILE, folder / ANALYSIS_FILE
    ran = analysed = False
    error = ""
    analysis = None
    meta = current_log(log, spec)
    if meta is not None and meta.status == "complete":
        analysis = current_analysis(analysis_path, log, meta)
    if meta is None or (meta.status == "complete" and analysis is None):
        with point_lock(folder):
            remove_stale_temps(folder)
            meta = current_log(log, spec)  # another sweep may have finished it meanwhile
            if meta is None:
                run_spec(spec, root, raise_on_failure=False)
                ran = True
                meta = read_meta(log)
            if meta.status == "complete":
                analysis = current_analysis(analysis_path, log, meta)
                if analysis is None:
                    try:
                        analysis = analyze_log(log)
                    except PipelineError as exc:
                        error = f"analysis: {exc}"
                    else:
                        write_analysis(analysis, Path(root))
                        analysed = True
    status = meta.status if not error else "failed"
    if meta.status != "complete":
        error = meta.error or f"log marked {meta.status}"
    return {
        "point": spec.name, "status": status, "error": error, "ran": ran, "analysed": analysed,
        "n_steps": num_rows(log), "seconds": time.perf_counter() - t0,
        "worker": f"{socket.gethostname()}:{os.getpid()}", "spec_hash": spec.spec_hash,
        "log": str(log), **figures(analysis),
    }
