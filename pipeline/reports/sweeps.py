"""Sweeps for the claims: reuse a finished sweep table of this code and grid, else run it.

The sweep runs as ``python -m pipeline sweep`` in a subprocess (its own Dask cluster, which
caches finished points by spec hash and code version); the claims read the stability bracket
of its table (:func:`pipeline.sweep.results.stability_bracket`).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq

from pipeline.errors import RunFailed
from pipeline.reports.runs import display_path
from pipeline.spec import PROJECT_ROOT
from pipeline.sweep.driver import plan_sweep
from pipeline.sweep.results import stability_bracket
from pipeline.version import code_version


def _fresh(table: Path, plan) -> bool:
    """A complete table of this code, base spec and grid."""
    if not table.is_file():
        return False
    try:
        t = pq.read_table(table)
    except OSError:
        return False
    md = {k.decode(): v.decode() for k, v in (t.schema.metadata or {}).items()}
    df = t.to_pandas()
    return (md.get("pipeline.code_version") == code_version()
            and md.get("pipeline.base_spec_hash") == plan.base.spec_hash
            and list(df["point"]) == [p.name for p in plan.points]
            and bool((df["status"] == "complete").all()))


def ensure_sweep(spec: str, sets: list[str], name: str, logs: Path, out: Path,
                 workers: int = 2, key: str = "mission.dt", lag: str = "dominant_lag1",
                 predicted: str = "dt_star_damping", unstable: str = "above"
                 ) -> tuple[dict, dict]:
    """The stability bracket of the sweep and its provenance, running the sweep if needed."""
    plan = plan_sweep(spec, sets, name, logs, out)
    if not _fresh(plan.table_path, plan):
        cmd = [sys.executable, "-m", "pipeline", "sweep", spec, "--name", name,
               "--logs", str(logs), "--out", str(out), "--workers", str(workers)]
        for s in sets:
            cmd += ["--set", s]
        print(f"running sweep {name} ({len(plan.points)} points)", file=sys.stderr)
        r = subprocess.run(cmd, cwd=PROJECT_ROOT, stdout=sys.stderr, stderr=subprocess.PIPE,
                           text=True)
        if r.returncode != 0:
            last = (r.stderr.strip().splitlines() or ["no message"])[-1]
            raise RunFailed(f"sweep {name} failed (exit {r.returncode}): {last}")
    bracket = stability_bracket(plan.table_path, key, lag, predicted, unstable)
    prov = {"source": "sweep", "code_version": code_version(),
            "file": display_path(plan.table_path)}
    return bracket, prov
