"""The same logs on another processor: the pinned baselines re-run under another Numba CPU
target and another OpenBLAS kernel, bitwise.

The simulator's linear algebra is the project's own (pipeline/sim/linalg.py) and its
transcendental functions the C library's, so neither the CPU target the kernels are compiled
for nor the BLAS kernel the processor selects may move a bit. Before that change, forcing
OpenBLAS's Sandybridge or Prescott kernels on this machine moved baseline_nominal's ``v`` by
1.5e-6 and the other baselines by 2e-11 to 1e-9, as a processor with AVX-512 did (issue 21).
This test compiles every kernel again for the generic x86-64 target into a cache of its own,
so it is marked slow.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.claims.baselines import PINNED, baseline_names, compare_logs
from pipeline.paths import PROJECT_ROOT

# x86-64 only: another machine's generic target and BLAS kernels have other names.
X86 = platform.machine() in ("x86_64", "AMD64")

# Each stands for another processor: LLVM's baseline x86-64 target (SSE2, no AVX, no FMA),
# and the oldest OpenBLAS kernel set a current build still dispatches to.
OTHER_PLATFORM = {"NUMBA_CPU_NAME": "generic", "OPENBLAS_CORETYPE": "Prescott"}


@pytest.mark.slow
@pytest.mark.skipif(not X86, reason="the generic target and Prescott kernels are x86-64's")
def test_pinned_baselines_rerun_bitwise_under_another_cpu_target_and_blas_kernel(
        tmp_path: Path):
    env = dict(os.environ, **OTHER_PLATFORM, NUMBA_CACHE_DIR=str(tmp_path / "kernels"))
    env.pop("NUMBA_DISABLE_JIT", None)
    names = baseline_names()
    r = subprocess.run([sys.executable, "-m", "pipeline", "run", *names, "--out",
                        str(tmp_path / "logs"), "--force"], cwd=PROJECT_ROOT, env=env,
                       capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stderr[-2000:]
    diffs = {}
    for name in names:
        cmp = compare_logs(PROJECT_ROOT / PINNED / name / "run.parquet",
                           tmp_path / "logs" / name / "run.parquet")
        diffs[name] = (cmp["max_abs_diff"], cmp["worst_column"], cmp["notes"])
    assert all(d == (0.0, "", []) for d in diffs.values()), diffs
