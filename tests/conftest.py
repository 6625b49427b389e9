"""Shared fixtures: a seeded ``rng``, the nominal robot, and random states away from singularity.

Every randomised test either takes ``rng`` (one fixed seed) or loops over ``SEEDS`` so that a
failure is reproducible from the seed printed in its message.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pipeline.paths import PROJECT_ROOT
from pipeline.sim.robot import GiordanoRobot
from pipeline.spec import Spec, load_spec

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


def random_quaternion(rng: np.random.Generator) -> np.ndarray:
    """Uniform random unit quaternion (x, y, z, w): a normalised 4-D Gaussian."""
    q = rng.standard_normal(4)
    return q / np.linalg.norm(q)


def random_state(robot: GiordanoRobot, rng: np.random.Generator, spread: float = 0.5,
                 margin: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """A random (q, v): random bus pose (position within ±6 m, uniform attitude), arm joints
    uniform within ±``spread`` rad of q̄, redrawn until σ_min(J⊕) > ``margin`` × the damped
    floor (so J⊕ is inverted exactly), and a velocity v ~ 0.3·N(0, I) (m/s, rad/s: the
    mission's speeds).
    """
    for _ in range(200):
        q = pin.neutral(robot.model)
        q[0:3] = rng.uniform(-6.0, 6.0, 3)
        q[3:7] = random_quaternion(rng)
        q[7:] = robot.q_bar + rng.uniform(-spread, spread, robot.n)
        T = robot.terms(q, np.zeros(robot.model.nv), dynamics=False)
        if T.s_min_J > margin * robot.floor:
            v = 0.3 * rng.standard_normal(robot.model.nv)
            return q, v
    raise AssertionError("no configuration away from singularity found in 200 draws")


def run_cli(*args: str, cwd: Path | None = None, timeout: float = 120
            ) -> subprocess.CompletedProcess:
    """``python -m pipeline ARGS`` in a fresh interpreter (stderr not a TTY: no progress bar)."""
    env = dict(os.environ, PYTHONWARNINGS="error")
    return subprocess.run([sys.executable, "-m", "pipeline", *args], cwd=cwd or PROJECT_ROOT,
                          capture_output=True, text=True, timeout=timeout, env=env)


def footer_metadata(path: Path) -> dict[bytes, bytes]:
    """A log's metadata as its writer left it (the Parquet footer: the keys known at the start
    and those written at the end), to carry over when a test rewrites the log."""
    from pipeline.logs import file_metadata

    return {k.encode(): v.encode() for k, v in file_metadata(path).items()}


# -- The kernels: compiled once per session, before the first test ---------------------------

_COMPILE_FAILED: list[str] = []  # the compile stage's error, raised again by every test


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
    r = subprocess.run([sys.executable, "-m", "pipeline", "compile"], cwd=PROJECT_ROOT,
                       capture_output=True, text=True, timeout=900)
    lines = r.stderr.strip().splitlines() or ["compile: (no output)"]
    if r.returncode != 0:
        _COMPILE_FAILED.append(f"the compile stage failed (exit {r.returncode}): "
                               + "\n".join(lines[-20:]))
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
