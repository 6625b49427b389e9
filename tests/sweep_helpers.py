"""Helpers of the sweep tests: a sweep as a ``python -m pipeline sweep`` subprocess (warnings as
errors, stderr not a terminal) and its table."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd

from pipeline.paths import PROJECT_ROOT
from pipeline.sweep.results import read_sweep_table


def sweep_env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("DASK_SCHEDULER_ADDRESS", None)  # only the sweeps that ask for one use a scheduler
    return {**env, "PYTHONWARNINGS": "error", **extra}


def sweep_argv(tmp: Path, *args: str, name: str = "s", out: str = "out") -> list[str]:
    return [sys.executable, "-m", "pipeline", "sweep", *args, "--name", name,
            "--logs", str(tmp / "logs"), "--out", str(tmp / out)]


def sweep(tmp: Path, *args: str, name: str = "s", out: str = "out", timeout: float = 180,
          **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(sweep_argv(tmp, *args, name=name, out=out), cwd=PROJECT_ROOT,
                          capture_output=True, text=True, timeout=timeout, env=sweep_env(**env))


def table(tmp: Path, name: str = "s", out: str = "out") -> pd.DataFrame:
    return read_sweep_table(tmp / out / name / "sweep.parquet")
