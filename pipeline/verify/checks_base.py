"""The numerical checks of the cross-check: code against an independent implementation.

A check names the equation it tests and the code it tests (a qualified name, looked up in the
code index so its file:line is found by inspection), and returns the inputs it used, the
largest absolute difference and the tolerance. The ``checks_*`` modules mark their checks with
:func:`check` and list them in ``CHECKS``; :mod:`pipeline.verify.suite` collects them
explicitly, and :func:`run_check` runs one, turning an exception into a FAIL.
"""

from __future__ import annotations

import importlib
import inspect
import math
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import numpy as np

from pipeline.spec import Spec, load_spec


@dataclass(frozen=True)
class Outcome:
    """What a check measured."""

    inputs: str
    max_abs_diff: float
    tol: float
    note: str = ""


@dataclass(frozen=True)
class Check:
    eq: str  # equation label it tests, e.g. "13a" or "22"
    title: str
    targets: tuple[str, ...]  # import paths of the code under test, first that resolves wins
    fn: Callable[[], Outcome]

    @property
    def target(self) -> str:
        return self.targets[0]


@dataclass(frozen=True)
class CheckResult:
    check: Check
    inputs: str
    max_abs_diff: float
    tol: float
    status: str  # PASS or FAIL
    note: str

    @property
    def passed(self) -> bool:
        return self.status == "PASS"


def check(eq: str, title: str, *targets: str) -> Callable:
    """Mark ``fn`` as the check of equation ``eq`` against the code at ``targets`` (import
    paths, e.g. ``pipeline.sim.robot.gamma_matrix`` or a dataclass field ``…Terms.M_hat``):
    the ``Check`` is attached as ``fn.check``; nothing is registered."""

    def deco(fn: Callable[[], Outcome]) -> Callable[[], Outcome]:
        fn.check = Check(eq, title, tuple(targets), fn)
        return fn

    return deco


def _unwrap(obj):
    if isinstance(obj, property):
        obj = obj.fget
    obj = getattr(obj, "py_func", obj)  # a Numba dispatcher wraps the Python function
    return inspect.unwrap(obj)


def resolve(path: str):
    """The object at an import path (``package.module.name.attr``), or None."""
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for attr in parts[i:]:
                obj = inspect.getattr_static(obj, attr) if inspect.isclass(obj) else getattr(
                    obj, attr)
        except AttributeError:
            return None
        return obj
    return None


def defining_qualname(path: str) -> str | None:
    """Where the code at an import path is defined: ``module.Class.name`` after following
    re-exports and wrappers; a dataclass field keeps its class's defining module."""
    obj = resolve(path)
    if obj is None or not (callable(obj) or inspect.ismodule(obj) or isinstance(obj, property)):
        head, _, attr = path.rpartition(".")
        cls = resolve(head)
        if inspect.isclass(cls) and attr in getattr(cls, "__annotations__", {}):
            return f"{cls.__module__}.{cls.__qualname__}.{attr}"
        return None
    if inspect.ismodule(obj):
        return obj.__name__
    obj = _unwrap(obj)
    mod, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{mod}.{qual}" if mod and qual else None


def code(*paths: str):
    """The first callable found at ``paths`` (the code under test, wherever it now lives)."""
    for p in paths:
        obj = resolve(p)
        if obj is not None:
            return obj
    raise ImportError(f"none of {', '.join(paths)} exists")


def run_check(c: Check) -> CheckResult:
    try:
        out = c.fn()
    except Exception as exc:  # a check that cannot run is a failing row, never a crash
        where = traceback.extract_tb(exc.__traceback__)[-1]
        msg = f"{type(exc).__name__}: {exc} (at {where.filename.split('/')[-1]}:{where.lineno})"
        return CheckResult(c, "", math.nan, math.nan, "FAIL", msg.splitlines()[0])
    ok = math.isfinite(out.max_abs_diff) and out.max_abs_diff <= out.tol
    return CheckResult(c, out.inputs, out.max_abs_diff, out.tol, "PASS" if ok else "FAIL",
                       out.note)


# -- shared inputs ------------------------------------------------------------------------

SEED = 20240601
CHECK_SPEC = "nominal"


@cache
def spec() -> Spec:
    return load_spec(CHECK_SPEC)


@cache
def robot():
    from pipeline.sim.robot import GiordanoRobot

    return GiordanoRobot(spec())


def rng(salt: int = 0) -> np.random.Generator:
    return np.random.default_rng(SEED + salt)


def random_state(salt: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A random (q, v) of the checks' robot (:func:`draw_state` with its defaults)."""
    return draw_state(robot(), rng(salt))


# The speeds of a random state's velocity: bus linear (m/s), bus angular, arm joints (rad/s).
STATE_SPEEDS = np.r_[0.1 * np.ones(3), 0.2 * np.ones(3), 0.5 * np.ones(6)]


def draw_state(robot, g: np.random.Generator, position: float = 2.0, spread: float = 0.3,
               margin: float = 2.0, speeds: np.ndarray | float = STATE_SPEEDS
               ) -> tuple[np.ndarray, np.ndarray]:
    """A random (q, v): bus position within ±``position`` m, uniform attitude (a normalised
    4-D Gaussian), arm joints within ±``spread`` rad of q̄, redrawn until σ_min(J⊕) is at
    least ``margin`` × the damped floor (so Γ⁻¹ is exact); v ~ ``speeds``·N(0, I). The one
    random-state draw of the equation checks and the tests."""
    import pinocchio as pin

    for _ in range(100):
        quat = g.standard_normal(4)
        quat /= np.linalg.norm(quat)
        q = np.concatenate([g.uniform(-position, position, 3), quat,
                            robot.q_bar + g.uniform(-spread, spread, robot.n)])
        T = robot.terms(q, np.zeros(robot.model.nv), dynamics=False)
        if T.s_min_J > margin * robot.floor:
            v = g.standard_normal(robot.model.nv) * speeds
            return pin.normalize(robot.model, q), v
    raise RuntimeError("no well-conditioned random state found in 100 draws")


def near_singular_q() -> np.ndarray:
    """The arm at q̄ with the elbow nearly straight, so σ_min(J⊕) is below the damped floor."""
    r = robot()
    for elbow in (0.1, 0.05, 0.02):
        q_joint = np.array(r.q_bar, dtype=float)
        q_joint[2] = elbow
        q = r.full_configuration(q_joint)
        if r.terms(q, np.zeros(r.model.nv), dynamics=False).s_min_J < r.floor:
            return q
    raise RuntimeError("no configuration below the damped floor found")


def maxdiff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


def fmt(x: float) -> str:
    return f"{x:.3g}"
