"""Sweeps on Dask (architecture §5): one spec over a grid of overrides, one task per point.

``python -m pipeline sweep SPEC --set KEY=V1,V2,… [--set …]`` runs every point of the product
of the ``--set`` lists as a Dask task that simulates (unless cached), analyses, and writes
``<logs>/<sweep>/<point>/run.parquet`` and ``analysis.json``; the driver writes
``<out>/<sweep>/sweep.parquet`` (one row per point). See docs/sweeps.md.

- ``grid``: ``--set`` parsing, validation of every point, point names;
- ``point``: the task (cache, per-point lock, run, analyse, record);
- ``cluster``: LocalCluster, existing scheduler, SLURM (adapt, worker lifetimes, sbatch
  refusals), waiting for workers;
- ``progress``: points done, failed, running and retried, as they change;
- ``results``: the table, the summary, ``stability_bracket`` (claim C12);
- ``driver``: planning, submission, results as they complete, signals, exit codes;
- ``throughput``: points per second and Dask's per-point overhead (``make bench``).
"""

from pipeline.sweep.driver import Sweep, execute, plan_sweep, run_sweep, sweep_command
from pipeline.sweep.grid import Point, build_grid, parse_sets, point_name
from pipeline.sweep.results import read_sweep_table, stability_bracket

__all__ = [
    "Point", "Sweep", "build_grid", "execute", "parse_sets", "plan_sweep", "point_name",
    "read_sweep_table", "run_sweep", "stability_bracket", "sweep_command",
]
