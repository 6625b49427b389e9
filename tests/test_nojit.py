"""``NUMBA_DISABLE_JIT=1`` runs the compiled kernels as plain Python (pipeline/sim/jit.py): a
mission run that way must log what the compiled run logs, and its log must pass the analysis.

Under the interpreter a Numba ``ExternalFunction`` (the LAPACK routines bound by name in
pipeline/sim/svd.py) was only a type: calling it built a signature and returned it, LAPACK
never ran, and ``singular_values`` returned its ``np.empty`` buffer, so s_min_G, κ_G, γ and
everything after them were garbage. The kernels now call the same routines through ctypes
there (pipeline/sim/lapack.py).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.claims.baselines import compare_logs
from pipeline.paths import PROJECT_ROOT
from pipeline.sim.lapack import cholesky_lower, inverse

# A 1 s cut of the nominal mission: 33 steps, every term of the step (Γ's conditioning, the
# γ ramp, both loops, the limits, the coverage).
SPEC = "extends: nominal\nmission: {duration: 1.0}\n"


def _cli(*args: str, jit: bool) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONWARNINGS="error")
    env.pop("NUMBA_DISABLE_JIT", None)
    if not jit:
        env["NUMBA_DISABLE_JIT"] = "1"
    return subprocess.run([sys.executable, "-m", "pipeline", *args], cwd=PROJECT_ROOT,
                          capture_output=True, text=True, timeout=600, env=env)


def test_python_mode_logs_the_compiled_run_bitwise_and_passes_analysis(tmp_path: Path):
    """Every logged column of the Python-mode run equals the compiled run's to the bit
    (max |diff| = 0, NaN counting as a difference), and the Python-mode log passes
    ``pipeline analyze`` (its provenance rebuild, run in Python mode too, included).

    Tolerance 0, not a small one: both modes make the same LAPACK calls (SciPy's, the ones
    Numba's ``np.linalg`` makes; pipeline/sim/lapack.py) on the same inputs, and this
    explicit dt = 0.03 s loop is unstable by design (dominant eigenvalue ≈ −2.9), so a
    last-bit difference in the state would grow about 3^33 ≈ 10^15-fold over the 33 steps:
    a tolerance of 1e-12 on it would be no looser than 0.
    """
    spec = tmp_path / "nojit.yaml"
    spec.write_text(SPEC)
    logs = {}
    for jit in (True, False):
        out = tmp_path / ("jit" if jit else "python")
        r = _cli("run", str(spec), "--out", str(out), "--force", jit=jit)
        assert r.returncode == 0, r.stderr
        logs[jit] = out / "nojit" / "run.parquet"
    diff = compare_logs(logs[True], logs[False])
    assert diff["notes"] == [] and diff["max_abs_diff"] == 0.0, diff
    r = _cli("analyze", str(logs[False]), "--out", str(tmp_path / "report"), jit=False)
    assert r.returncode == 0, r.stderr


def test_lapack_cholesky_and_inverse_match_numpy_and_refuse_bad_input(rng):
    """The kernels' Cholesky factor and inverse (Numba's LAPACK calls, pipeline/sim/lapack.py)
    agree with NumPy's to rounding and raise LinAlgError where ``np.linalg`` does."""
    A = rng.standard_normal((9, 9))
    M = A @ A.T + 9 * np.eye(9)
    L = cholesky_lower(M)
    assert np.array_equal(L, np.tril(L))
    assert np.allclose(L, np.linalg.cholesky(M), rtol=0, atol=1e-13)
    assert np.allclose(inverse(L), np.linalg.inv(L), rtol=0, atol=1e-13)
    for bad, call in ((-np.eye(3), cholesky_lower), (np.zeros((3, 3)), inverse),
                      (np.full((3, 3), np.nan), inverse)):
        with pytest.raises(np.linalg.LinAlgError):
            call(bad)
