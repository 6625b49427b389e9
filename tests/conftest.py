"""Shared fixtures: a seeded ``rng``, the nominal robot, and random states away from singularity.

Every randomised test either takes ``rng`` (one fixed seed) or loops over ``SEEDS`` so that a
failure is reproducible from the seed printed in its message.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline.paths import PROJECT_ROOT
from pipeline.sim.robot import GiordanoRobot
from pipeline.spec import Spec, load_spec
from pipeline.verify.checks_base import draw_state

SEEDS = (0, 1, 2, 3, 4)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240601)


@pytest.fixture(scope="session")
def nominal_spec() -> Spec:
    return load_spec("nominal")


@pytest.fixture(scope="session")
def robot(nominal_spec: Spec) -> GiordanoRobot:
    return GiordanoRobot(nominal_spec)


def random_state(robot: GiordanoRobot, rng: np.random.Generator, spread: float = 0.5,
                 margin: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """A random (q, v) for the tests: the equation checks' draw (draw_state), over a wider
    workspace (bus within ±6 m, arm within ±``spread`` rad of q̄) and at the mission's speeds
    (v ~ 0.3·N(0, I))."""
    return draw_state(robot, rng, position=6.0, spread=spread, margin=margin, speeds=0.3)


def run_cli(*args: str | Path, cwd: Path | None = None, timeout: float = 120
            ) -> subprocess.CompletedProcess:
    """``python -m pipeline ARGS`` in a fresh interpreter (stderr not a TTY: no progress bar),
    every warning an error."""
    env = dict(os.environ, PYTHONWARNINGS="error")
    return subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)],
                          cwd=cwd or PROJECT_ROOT, capture_output=True, text=True,
                          timeout=timeout, env=env)


def run_cli_in_process(*args: str | Path, cwd: Path | None = None,
                       timeout: float | None = None) -> subprocess.CompletedProcess:
    """``python -m pipeline ARGS`` as :func:`run_cli` returns it, run by ``pipeline.cli.main``
    in this process: for the many cases of one command's bad input, where a fresh
    interpreter (about a second each) would test only the start of Python again. Each
    command keeps a test through :func:`run_cli`. An exception that escapes ``main`` (what
    would be a traceback) fails the test that called it. ``timeout``: :func:`run_cli`'s,
    for the same call; a command in this process is not a child to time out."""
    from pipeline.cli import main

    out, err = io.StringIO(), io.StringIO()
    here = Path.cwd()
    try:
        os.chdir(cwd or PROJECT_ROOT)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in args])
            except SystemExit as exc:  # argparse's own refusals: usage, then its error
                code = exc.code if isinstance(exc.code, int) else 2
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["pipeline", *map(str, args)], code, out.getvalue(),
                                       err.getvalue())


SHORT = ("short_nominal", "short_omega_ripple_dt010", "short_omega_ripple_imex")


@pytest.fixture(scope="session")
def short_logs(tmp_path_factory) -> dict[str, Path]:
    """The three short missions (30 s) run once per session through run_spec into Parquet
    logs, by spec name. Shared: a test that alters a log copies it first."""
    from pipeline.sim.run import run_spec

    out = tmp_path_factory.mktemp("short_logs")
    logs = {}
    for name in SHORT:
        o = run_spec(load_spec(name), out)
        assert o.status == "complete"
        logs[name] = o.path
    return logs


def footer_metadata(path: Path) -> dict[bytes, bytes]:
    """A log's metadata as its writer left it (the Parquet footer: the keys known at the start
    and those written at the end), to carry over when a test rewrites the log."""
    from pipeline.logs import file_metadata

    return {k.encode(): v.encode() for k, v in file_metadata(path).items()}


def sealed(table, metadata: dict[bytes, bytes]):
    """``table`` with ``metadata`` and the seal of its own columns (``pipeline.logs.SEAL_KEY``),
    as the simulator's writer would seal it: for a test that rewrites a log to reach a check
    other than the seal (a log that is whole but wrong in another way)."""
    from pipeline.logs import SEAL_KEY, TableDigest

    digest = TableDigest(table.column_names)
    digest.update(table)
    return table.replace_schema_metadata({**metadata,
                                          SEAL_KEY.encode(): digest.hexdigest().encode()})


# -- The kernels: compiled once per session, before the first test ---------------------------

_COMPILE_FAILED: list[str] = []  # the compile stage's error, raised again by every test
# A copy of the kernel cache as the session's compile left it, when it started from an empty
# cache (a fresh clone, as in CI, or sources just edited), taken before the first test can add
# to it: tests/test_compile.py checks that compile instead of making a second one.
_COLD_COMPILE: list[Path] = []


def _kernel_cache() -> Path:
    """The kernel cache the session's compile writes (pipeline/sim/jit.py; a relative
    ``NUMBA_CACHE_DIR`` is the compile's, run from the project's root)."""
    from pipeline.sim.jit import kernel_cache_dir

    return PROJECT_ROOT / (os.environ.get("NUMBA_CACHE_DIR") or kernel_cache_dir())


def _copy_of_cold_cache(session, cache: Path) -> None:
    """Keep a copy of the cache the session's compile filled from nothing, when a
    ``compile`` test is selected to check it; a copy that fails leaves that test its own
    compile."""
    if not any(item.get_closest_marker("compile") for item in session.items):
        return
    folder = Path(tempfile.mkdtemp(prefix="breve-cold-compile-"))
    try:
        shutil.copytree(cache, folder / "kernels")
    except OSError:
        shutil.rmtree(folder, ignore_errors=True)
        return
    _COLD_COMPILE.append(folder / "kernels")


def pytest_collection_finish(session):
    """Run the compile stage (``python -m pipeline compile``, pipeline/compile.py) once, after
    collection and before the first test, so that no test pays for compiling a kernel (a
    cold cache took 50 s on two processes; then ``compile: up to date``, about a second).
    Its last line goes to the terminal. Not for ``--collect-only`` or an empty selection;
    under ``NUMBA_DISABLE_JIT=1`` the stage says it skips. A failure is raised by
    :func:`_kernels_compiled` in every test, with the stage's own message."""
    if session.config.option.collectonly or not session.items:
        return
    t0 = time.monotonic()
    from pipeline.compile import STAMP  # the compile stage's stamp file

    cache = _kernel_cache()
    # No kernel and no compile stamp (importing the package makes Numba's empty folders;
    # a stamp without kernels would make the compile a no-op and the copy empty).
    cold = (not os.environ.get("NUMBA_DISABLE_JIT") and not (cache / STAMP).exists()
            and not any(cache.rglob("*.nb[ic]")))
    r = subprocess.run([sys.executable, "-m", "pipeline", "compile"], cwd=PROJECT_ROOT,
                       capture_output=True, text=True, timeout=900)
    lines = r.stderr.strip().splitlines() or ["compile: (no output)"]
    if r.returncode != 0:
        _COMPILE_FAILED.append(f"the compile stage failed (exit {r.returncode}): "
                               + "\n".join(lines[-20:]))
    elif cold and cache.is_dir():
        _copy_of_cold_cache(session, cache)
    tr = session.config.pluginmanager.get_plugin("terminalreporter")
    line = f"tests: {lines[-1]} ({time.monotonic() - t0:.1f} s, before the first test)"
    if tr is not None:
        tr.write_line(line)
    else:
        print(line, file=sys.stderr)


@pytest.fixture(scope="session", autouse=True)
def _kernels_compiled():
    """Every test: the kernels were compiled before it (pytest_collection_finish)."""
    if _COMPILE_FAILED:
        pytest.fail(_COMPILE_FAILED[0], pytrace=False)


@pytest.fixture(scope="session")
def cold_compile() -> Path | None:
    """The session's compile into an empty cache, as it left the cache (a copy: a test may
    use it as its own cache), or None when the session's cache was not empty."""
    return _COLD_COMPILE[0] if _COLD_COMPILE else None


def pytest_sessionfinish(session, exitstatus):
    for copy in _COLD_COMPILE:
        shutil.rmtree(copy.parent, ignore_errors=True)


# -- SLURM tests: CI must run them -----------------------------------------------------------

@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under ``CI=true`` a skipped ``slurm`` test is a failure: CI installs and starts SLURM
    (.ci/run), so a skip there means the SLURM path went untested."""
    outcome = yield
    rep = outcome.get_result()
    if (rep.skipped and item.get_closest_marker("slurm") is not None
            and os.environ.get("CI", "").lower() == "true"):
        reason = rep.longrepr[2] if isinstance(rep.longrepr, tuple) else str(rep.longrepr)
        rep.outcome = "failed"
        rep.longrepr = f"CI=true: a SLURM test must run, not skip ({reason})"


def pytest_terminal_summary(terminalreporter):
    """The figures the SLURM tests record (jobs submitted and replaced, wall time), so that
    a CI log shows them."""
    lines = [f"{rep.nodeid}: " + ", ".join(f"{k}={v}" for k, v in rep.user_properties)
             for rep in terminalreporter.getreports("passed")
             if rep.when == "call" and rep.user_properties]
    if lines:
        terminalreporter.section("recorded figures")
        for line in lines:
            terminalreporter.write_line(line)
