"""``NUMBA_DISABLE_JIT=1`` runs the compiled kernels as plain Python (pipeline/sim/jit.py): a
mission run that way must log what the compiled run logs, and its log must pass the analysis.

Two earlier ways this broke: under the interpreter a Numba ``ExternalFunction`` (LAPACK bound
by name) was only a type, so LAPACK never ran and σ were garbage; and on a processor with
AVX-512 the modes differed by 1.7e-12 in ``pointing_err_deg``, NumPy's SIMD arccos and BLAS in
Python mode against the C library's acos and SciPy's BLAS compiled. The kernels now do their
own linear algebra (pipeline/sim/linalg.py) and call the C library's functions through
``math`` in both modes.
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
from pipeline.sim.linalg import cholesky_lower, inverse

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


@pytest.mark.slow
def test_python_mode_logs_the_compiled_run_bitwise_and_passes_analysis(tmp_path: Path):
    """Every logged column of the Python-mode run equals the compiled run's to the bit
    (max |diff| = 0, NaN counting as a difference), and the Python-mode log passes
    ``pipeline analyze`` (its provenance rebuild, run in Python mode too, included).

    Tolerance 0, derived: in both modes every float the step makes comes from the same
    sequence of IEEE-754 operations (+ − × ÷ √, each correctly rounded, in the same order:
    the products and decompositions are the project's own loops, pipeline/sim/linalg.py) and
    from the same C-library calls (``math.sin``, ``math.cos``, ``math.acos``), so the bits
    cannot differ on any processor; and this explicit dt = 0.03 s loop is unstable by design
    (dominant eigenvalue ≈ −2.9), so a last-bit difference in the state would grow about
    3^33 ≈ 10^15-fold over the 33 steps: a tolerance of 1e-12 on it would be no looser
    than 0.
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


def test_cholesky_and_inverse_match_numpy_and_refuse_bad_input(rng):
    """The kernels' Cholesky factor and inverse (pipeline/sim/linalg.py) agree with NumPy's to
    rounding and raise LinAlgError where ``np.linalg`` does."""
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
