"""``python -m pipeline compile``: compile every Numba kernel once, before the work fans out.

The kernels are compiled on first use and cached on disk (:mod:`pipeline.sim.jit`), so without
this stage the first mission compiles the simulator's kernels, the first analysis the
analysis' ones, and any process that starts meanwhile (a sweep's workers, a second ``make``)
would compile them again. Here they are compiled once per version of the simulator's sources,
in units of disjoint kernels spread over two processes:

=========  ===============================================================  ============
unit       kernels it compiles (and nothing another unit compiles)          waits for
=========  ===============================================================  ============
rotations  ``skew``, the one leaf both the transform and the loop call      —
transform  eqs. 2–9 and 19: ``task_transform``, ``full_transform``, SVDs     rotations
guidance   the references of eq. 17 and the coverage test of eq. 18         —
loop       both loops of one step (``loop_update``: eqs. 12–16, 21)         rotations
step       ``controller_step`` and the rest of a mission's calls            all above
analysis   Γ's rebuild from a logged q and the batched SVDs                 transform
=========  ===============================================================  ============

A unit compiles by making exactly the calls a run makes (a mission's first step, the
analysis' rebuild of Γ), or, for ``loop_update``, which only the step kernel calls, by
compiling it for the types the step kernel passes; Numba loads a callee another unit compiled
from the cache instead of compiling it again. Afterwards no mission, analysis, sweep worker
or check compiles anything (``tests/test_compile.py``). A stamp in the cache folder makes the
next call a no-op (``compile: up to date``).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import queue
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import RunFailed
from pipeline.paths import display_path
from pipeline.progress import interactive, say, stage

STAMP = "compiled.json"
SPEC = "nominal"  # any shipped spec: the kernels' types do not depend on its values


@dataclass(frozen=True)
class Unit:
    name: str
    what: str
    deps: tuple[str, ...]
    run: Callable[[], None]


class _Seed:
    """A robot at its start pose and Pinocchio's outputs there: built without any kernel."""

    def __init__(self):
        import numpy as np

        from pipeline.sim.robot import GiordanoRobot
        from pipeline.spec import load_spec

        self.spec = load_spec(SPEC)
        self.robot = GiordanoRobot(self.spec)
        self.q = self.robot.deterministic_q_init()
        self.v = np.full(self.robot.model.nv, 0.01)


_seed: _Seed | None = None


def seed() -> _Seed:
    global _seed
    if _seed is None:
        _seed = _Seed()
    return _seed


def _rotations() -> None:
    import numpy as np

    from pipeline.sim.rotations import skew

    skew(np.zeros(3))


def _transform() -> None:
    s = seed()
    s.robot.terms(s.q, s.v, dynamics=False)  # the start pose's search: Γ and its σ_min
    s.robot.terms(s.q, s.v)  # the guard's terms at the start


def _guidance() -> None:
    import numpy as np
    import pinocchio as pin

    from pipeline.sim.base_guidance import REFERENCE_SIZE, BaseGuidance
    from pipeline.sim.target import build_target, visible

    s = seed()
    g = BaseGuidance(s.spec.guidance, np.array([0.1, 0.0, 0.5]), np.array([1.0, 0.0, 0.0]))
    p_b = s.robot.dynamics_inputs(s.q, s.v).p_b  # Pinocchio's view, as the mission passes it
    g.reference(0.0)
    g.reference(0.0, p_b.copy())
    g.reference_into(np.zeros(REFERENCE_SIZE), 0.0, p_b)
    # The coverage test (eq. 18): the step kernel's own, with the types it passes.
    visible(build_target(s.spec.target), np.zeros(3), pin.exp3(np.zeros(3)), s.spec.camera)


def _loop() -> None:
    """``loop_update`` for the types :func:`controller_step` passes it: C-ordered float64
    arrays (copies, products, ``np.diag``), float64 scalars, booleans for the flags."""
    import numpy as np
    from numba import typeof

    from pipeline.sim import control_step as cs
    from pipeline.sim.base_guidance import REFERENCE_FIELDS, Reference
    from pipeline.sim.task_transform import Transform

    s = seed()
    d = s.robot.dynamics_inputs(s.q, s.v)
    pose = d._replace(R_tb=np.ascontiguousarray(d.R_tb).copy(), p_b=d.p_b.copy(),
                      R_te=np.ascontiguousarray(d.R_te).copy(), p_e=d.p_e.copy())
    n = s.robot.model.nv
    tr = Transform(p_bc=np.zeros(3), p_c=np.zeros(3), J_bar_v=np.zeros((3, n - 6)),
                   J_oplus=np.zeros((6, n - 6)), G_wb=np.zeros((6, 3)),
                   J_oplus_inv=np.zeros((n - 6, 6)), s_min_J=1.0, kappa_J=1.0,
                   gamma=np.zeros((n, n)), gamma_inv=np.zeros((n, n)),
                   gamma_dot=np.zeros((n, n)), M_hat=np.zeros((n, n)), C_hat=np.zeros((n, n)),
                   s_min_G=1.0, kappa_G=1.0)
    ref = Reference(**{f: np.zeros((3, 3)) if size == 9 else np.zeros(size)
                       for f, size in REFERENCE_FIELDS})
    p = cs.ControlParams(**{f: (False if f in ("derate_gain", "imex") else
                                1.0 if size == 1 else np.zeros(size))
                            for f, size in cs.CONTROLLER_FIELDS})
    st = cs.StepState(**{f: (False if f == "has_prev" else 0.0 if size == 1 else np.zeros(size))
                         for f, size in cs.STATE_FIELDS if f != "dq"})
    args = (pose, tr, ref, p, st, 1.0, np.zeros((9, 9)), np.zeros((9, 9)))
    cs.loop_update.compile(tuple(typeof(a) for a in args))


def _step() -> None:
    from pipeline.sim.mission import Mission

    s = seed()
    m = Mission(s.spec, s.robot)
    s0 = m.initial_state()
    m.critical_steps(s0)
    m.step(s0)  # the step kernel, exactly as a run calls it


def _analysis() -> None:
    import numpy as np

    from pipeline.sim.svd import batched_singular_values, svd_right

    s = seed()
    gamma = s.robot.gamma_matrices(np.stack([s.q, s.q]))  # Γ rebuilt from logged q (eq. 5)
    batched_singular_values(gamma[np.array([True, False])])
    svd_right(gamma)


UNITS = {u.name: u for u in (
    Unit("rotations", "the shared rotation leaf", (), _rotations),
    Unit("transform", "the task transform (eqs. 2-9, 19)", ("rotations",), _transform),
    Unit("guidance", "the references and coverage (eqs. 17, 18)", (), _guidance),
    Unit("loop", "the loops of one step (eqs. 12-16, 21)", ("rotations",), _loop),
    Unit("step", "the step kernel (eq. 22)", ("transform", "guidance", "loop"), _step),
    Unit("analysis", "the analysis' rebuild of Γ and its SVDs", ("transform",), _analysis),
)}
# The two processes' shares: the longest chain (rotations, transform, step) in one, the rest
# in the other, so the two cores stay busy until the step kernel.
SHARES = (("rotations", "transform", "step"), ("guidance", "loop", "analysis"))


def _worker(names: tuple[str, ...], done: dict, failed, report) -> None:
    """Compile ``names`` in order, each once the units it waits for are done (in any
    process); ``report`` gets (unit, seconds) or (unit, None, message)."""
    for name in names:
        for dep in UNITS[name].deps:
            while not done[dep].wait(0.2):
                if failed.is_set():
                    return
        t0 = time.perf_counter()
        try:
            UNITS[name].run()
        except BaseException as exc:  # reported to the parent, then raised again
            failed.set()
            report.put((name, None, f"{type(exc).__name__}: {exc}"))
            raise
        done[name].set()
        report.put((name, time.perf_counter() - t0, ""))


def _stamp_text() -> str:
    import numba

    return json.dumps({"numba": numba.__version__, "python": sys.version.split()[0],
                       "units": list(UNITS)})


def compile_kernels(processes: int = 2) -> Path | None:
    """Compile every unit (see the module docstring) into the kernel cache, unless its stamp
    says it is done; returns the cache folder (None when Numba's JIT is disabled)."""
    from numba.core import config

    import pipeline.sim.jit  # noqa: F401  (sets the cache folder: one per source version)

    if config.DISABLE_JIT:
        say("compile: skipped (NUMBA_DISABLE_JIT=1: the kernels run as Python)")
        return None
    folder = Path(config.CACHE_DIR)
    stamp = folder / STAMP
    text = _stamp_text()
    if stamp.is_file() and stamp.read_text() == text:
        say(f"compile: up to date -> {display_path(folder)}")
        return folder
    shares = SHARES if processes > 1 else (tuple(UNITS),)
    with stage("compile", f"({len(UNITS)} units of kernels, {len(shares)} processes) -> "
                          f"{display_path(folder)}") as st:
        ctx = mp.get_context("spawn")
        done = {name: ctx.Event() for name in UNITS}
        failed, report = ctx.Event(), ctx.Queue()
        procs = [ctx.Process(target=_worker, args=(share, done, failed, report), daemon=True)
                 for share in shares]
        for p in procs:
            p.start()
        _follow(procs, report, failed)
        folder.mkdir(parents=True, exist_ok=True)
        stamp.write_text(text)
        st.done(f"{len(list(folder.rglob('*.nbi')))} kernels cached")
    return folder


def _follow(procs, report, failed) -> None:
    """Print each unit as it ends (a bar on a terminal) until every process has ended."""
    from tqdm import tqdm

    finished, error = 0, ""
    with tqdm(total=len(UNITS), disable=not interactive(), unit="unit", desc="compile",
              file=sys.stderr, leave=False) as bar:
        while finished < len(UNITS) and not error:
            try:
                name, seconds, message = report.get(timeout=0.5)
            except queue.Empty:
                if any(p.exitcode not in (None, 0) for p in procs):
                    error = "a compiling process ended unexpectedly"
                continue
            if seconds is None:
                error = f"unit {name}: {message}"
                continue
            finished += 1
            bar.clear()
            say(f"compile: {name} ({UNITS[name].what}) in {seconds:.1f} s")
            bar.update(1)
    if error:
        failed.set()
    for p in procs:
        p.join(timeout=None if not error else 10)
        if p.is_alive():
            p.terminate()
    if error:
        raise RunFailed(f"compile: {error}")


def compile_command(args) -> int:
    compile_kernels(args.processes)
    return 0
