"""The compile stage compiles every kernel a run, an analysis and the equation checks use, each
for the one signature they call it with: afterwards nothing compiles again (pipeline/compile.py)."""

from __future__ import annotations

import sys

from numba.core.registry import CPUDispatcher

from pipeline import compile as kc
from pipeline.analysis.stages import analyze_log
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
    analyze_log(run_spec(spec, tmp_path).path)
    build_cross_check()
    new = {n: c - before.get(n, 0) for n, c in compiled().items() if c > before.get(n, 0)}
    assert not new, f"compiled after the compile stage: {new}"
    assert not {name: list(k.signatures) for name, k in kernels().items()
                if len(k.signatures) > 1}


def test_a_slice_assigned_from_the_wrong_shape_still_raises_value_error():
    """pipeline.sim.jit swaps the message of Numba's shape check for its plain one (a cheaper
    compile); the check itself stays: a wrong shape is a ValueError, a right one assigns."""
    import numpy as np
    import pytest
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
