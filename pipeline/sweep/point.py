"""One sweep point as one Dask task: run the mission unless current, analyse it, return a
record.

Runs on a worker. The log goes to ``ROOT/<point>/run.parquet`` and the analysis beside it
(``analysis.json``, ``directions.parquet``), all written atomically, through the artefact
store (:class:`pipeline.store.door.ArtefactStore`): a current log is reused whether
``complete``, ``failed`` or ``diverged`` (the simulation is deterministic: the same spec on the
same code fails or diverges again at the same step), a current analysis too; what is made is
made under the point folder's lock, so two sweeps sharing a point (or a rescheduled task
meeting its predecessor) never simulate it twice at once (:mod:`pipeline.store.locks`).
"""

from __future__ import annotations

import math
import os
import socket
import time

from pipeline.analysis.schema import AnalysisRecord, value_at
from pipeline.errors import PipelineError
from pipeline.spec import Spec

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


def figures(analysis: AnalysisRecord | None) -> dict[str, float]:
    """The table's columns of a point's record (NaN where it has none: no record, a failed
    point, a field that is null)."""
    out = {}
    for col, path in FIGURES.items():
        try:
            node = value_at(analysis, path) if analysis is not None else None
        except KeyError:
            node = None
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
    from pipeline.store.door import ArtefactStore

    t0 = time.perf_counter()
    store = ArtefactStore(root)
    error = ""
    analysis = None
    analysed = False
    run = store.run(spec, expect=None, quiet=True)
    if run.meta.status == "complete":
        try:
            done = store.analysis(run.log, quiet=True)
        except PipelineError as exc:
            error = f"analysis: {exc}"
        else:
            analysis, analysed = done.record, not done.reused
    status = run.meta.status if not error else "failed"
    if run.meta.status != "complete":
        error = run.meta.error or f"log marked {run.meta.status}"
    return {
        "point": spec.name, "status": status, "error": error, "ran": not run.reused,
        "analysed": analysed, "n_steps": run.log.rows, "seconds": time.perf_counter() - t0,
        "worker": f"{socket.gethostname()}:{os.getpid()}", "spec_hash": spec.spec_hash,
        "log": str(run.path), **figures(analysis),
    }
