"""The compile stage compiles every kernel a run, an analysis and the equation checks use, each
for the one signature they call it with: afterwards nothing compiles again (pipeline/compile.py)."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys

import pytest
from numba.core.registry import CPUDispatcher

from pipeline import compile as kc
from pipeline.analysis.stages import analyze_log
from pipeline.logs import verify_log
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides


def kernels() -> dict[str, CPUDispatcher]:
    return {f"{name}.{k}": v for name, mod in list(sys.modules.items())
            if name.startswith("pipeline.") for k, v in vars(mod).items()
            if isinstance(v, CPUDispatcher) and v.py_func.__module__ == name}


def compiled() -> dict[str, int]:
    """Each kernel's compilations in this process (cache misses; a load from the cache is a
    hit, and a callee inside a loaded caller is not even looked up)."""
    return {name: sum(k.stats.cache_misses.values()) for name, k in kernels().items()}


def test_after_the_compile_units_a_run_its_analysis_and_the_checks_compile_nothing(tmp_path):
    from pipeline.verify.cross_check import build_cross_check

    for unit in kc.UNITS.values():  # in this process, from the cache if it holds them
        unit.run()
    one = {name: list(k.signatures) for name, k in kernels().items() if len(k.signatures) > 1}
    assert not one, f"more than one specialisation: {one}"
    before = compiled()
    spec = with_overrides(load_spec("short_nominal"), {"mission.duration": 3.0}, name="warm")
    analyze_log(verify_log(run_spec(spec, tmp_path).path))
    build_cross_check()
    new = {n: c - before.get(n, 0) for n, c in compiled().items() if c > before.get(n, 0)}
    assert not new, f"compiled after the compile stage: {new}"
    assert not {name: list(k.signatures) for name, k in kernels().items()
                if len(k.signatures) > 1}


# A new process with the cache the compile stage filled: a short mission, its analysis and the
# equation checks, then the number of kernels each dispatcher compiled (cache misses).
_AFTER_COMPILE = """
from pipeline.analysis.stages import analyze_log
from pipeline.logs import verify_log
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides
from pipeline.verify.cross_check import build_cross_check
import sys
spec = with_overrides(load_spec("short_nominal"), {"mission.duration": 3.0}, name="cold")
analyze_log(verify_log(run_spec(spec, sys.argv[1]).path))
build_cross_check()
from numba.core.registry import CPUDispatcher
print(sorted(f"{m}.{k}" for m, mod in list(sys.modules.items()) if m.startswith("pipeline.")
             for k, v in vars(mod).items() if isinstance(v, CPUDispatcher)
             and v.py_func.__module__ == m and sum(v.stats.cache_misses.values())))
"""


@pytest.mark.compile  # into an empty cache (a minute on two cores), or the session's
def test_from_an_empty_cache_the_stage_compiles_each_kernel_once_and_then_nothing_compiles(
        tmp_path, cold_compile, record_property):
    """The stage as `make all` runs it (two processes taking the units in turn) into an empty
    cache: every kernel's index holds one specialisation (a unit that compiled a callee for
    other types than its caller passes would leave two), and a new process then runs a
    mission, its analysis and the checks without compiling anything. When this session's own
    compile started from an empty cache (a fresh clone, as in CI), that compile is the one
    checked, in the copy tests/conftest.py took before the first test could add to it;
    otherwise the stage runs again into an empty folder."""
    cache = cold_compile or tmp_path / "kernels"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    if cold_compile is None:
        subprocess.run([sys.executable, "-m", "pipeline", "compile"], env=env, check=True,
                       capture_output=True, text=True)
    record_property("compile", "the session's, from an empty cache" if cold_compile
                    else "its own, into an empty folder")
    specialisations = {}
    for index in cache.rglob("*.nbi"):
        with open(index, "rb") as f:  # Numba's index: its version, then (stamp, overloads)
            pickle.load(f)
            _, overloads = pickle.loads(f.read())
        specialisations[index.name] = len(overloads)
    assert len(specialisations) >= 40
    assert {k: n for k, n in specialisations.items() if n != 1} == {}
    after = subprocess.run([sys.executable, "-c", _AFTER_COMPILE, str(tmp_path / "logs")],
                           env=env, check=True, capture_output=True, text=True)
    assert after.stdout.strip().splitlines()[-1] == "[]", after.stdout


def test_a_slice_assigned_from_the_wrong_shape_still_raises_value_error():
    """pipeline.sim.jit swaps the message of Numba's shape check for its plain one (a cheaper
    compile); the check itself stays: a wrong shape is a ValueError, a right one assigns."""
    import numpy as np
    from numba import njit

    import pipeline.sim.jit  # noqa: F401  (the swap happens on import)

    @njit
    def assign(a, b):
        a[1:4] = b

    a = np.zeros(5)
    assign(a, np.arange(3.0))
    assert a.tolist() == [0.0, 0.0, 1.0, 2.0, 0.0]
    with pytest.raises(ValueError):
        assign(a, np.arange(2.0))


def test_what_all_imports_while_the_last_kernel_compiles_compiles_nothing():
    """`pipeline all` imports the later stages' modules in a thread beside the compile stage's
    last unit (pipeline.cli._import_later_stages): importing must not compile or even load a
    kernel, or it would race the stage for the same cache entries."""
    code = ("from pipeline.cli import _import_later_stages; _import_later_stages()\n"
            "import sys\nfrom numba.core.registry import CPUDispatcher\n"
            "ks = [v for m, mod in list(sys.modules.items()) if m.startswith('pipeline.')\n"
            "      for v in vars(mod).values() if isinstance(v, CPUDispatcher)]\n"
            "print(len(ks), sum(len(k.overloads) for k in ks))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    n_kernels, n_loaded = map(int, r.stdout.split())
    assert n_kernels >= 40 and n_loaded == 0
