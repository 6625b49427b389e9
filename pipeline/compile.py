"""``python -m pipeline compile``: compile every Numba kernel once, before the work fans out.

The kernels are compiled on first use and cached on disk (:mod:`pipeline.sim.jit`), so without
this stage the first mission compiles the simulator's kernels, the first analysis the
analysis' ones, and any process that starts meanwhile (a sweep's workers, a second ``make``)
would compile them again. Here they are compiled once per version of the simulator's sources,
in units of disjoint kernels that two processes take in turn, each the first unit of
:data:`UNITS` whose prerequisites are done (:func:`next_unit`):

==========  =============================================================  =================
unit        kernels it compiles (and nothing another unit compiles)        waits for
==========  =============================================================  =================
linalg      ``linalg.py``'s products and decompositions, every unit's leaf    —
rotations   ``skew``, the leaf most kernels call                           linalg
updates     eqs. 15a, 15b, 21, 35: both integrators, μ = eig(M̆⁻¹D̆),     linalg
            the margins' stability test (Schur–Cohn)
rhs         eq. 13's right-hand side and its named terms                   linalg
kinematics  eqs. 2–6's pieces: kinematic terms, damped inverse, Γ, Γ⁻¹     rotations
redundancy  eq. 37's null-space basis, H, Γ, Γ⁻¹ and Γ̇ of a redundant arm  kinematics
rates       Γ̇ (eq. 7), M̂ and Ĉ (eqs. 8, 9) and σ_min, κ (eq. 19)          rotations
errors      the task errors of eq. 14 and the CoM loop of eq. 12           rotations
guidance    the references of eq. 17 and the coverage test of eq. 18       linalg
terms       the rigid-body terms (CRBA, Coriolis, Jacobians, centroidal    linalg
            map) and q ⊕ δ (eqs. 1–11, 22)
transform   ``task_transform`` and ``full_transform`` (eqs. 2–9, 19, 37)  kinematics, rates,
                                                                           redundancy, terms
loop        ``loop_update``, both loops of one step (eqs. 12–16, 21)       rhs, updates, errors
row         the step kernel's readers and writers, γ (eq. 20), coverage   linalg
step        ``controller_step`` and the compiled mission loop (eq. 22), as  all of the above
            a mission's first step calls them
analysis    Γ's rebuild from a logged q and the batched SVDs, an import's  kinematics,
            J⊕ conditioning                                                redundancy, terms,
                                                                           transform
plant       the sampled-data plant: RK4 on the articulated-body algorithm  linalg
            (eq. 29)
==========  =============================================================  =================

The order is the priority: the unit with the longest chain of compile time still behind it
first, so the step kernel, which only one process can compile, starts as early as it can (a
cold compile took 58.8 s on two processes in fixed shares of six units, 49.0 s with these
twelve taken in turn; the thirteenth, the linear algebra, came later). A unit either makes
exactly the calls a run makes (a mission's first step, the start pose's terms, the
analysis' rebuild of Γ) or compiles its kernels for the types their callers pass
(``Dispatcher.compile``; the bundles are built from the same field tables). A callee
another unit compiled is loaded from the cache, never compiled again, and
each kernel ends with one specialisation (``tests/test_compile.py`` checks both, from an
empty cache). A stamp in the cache folder makes the next call a no-op (``compile: up to
date``).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import queue
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import RunFailed
from pipeline.orphans import exit_with_parent
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


def _compile(kernel, *args) -> None:
    """Compile ``kernel`` for the Numba types of ``args`` (their values are never used)."""
    from numba import typeof

    kernel.compile(tuple(typeof(a) for a in args))


def _c(*shape: int):
    """A C-ordered float64 array: the layout of the kernels' own copies and products."""
    import numpy as np

    return np.zeros(shape)


def _reference():
    from pipeline.sim.base_guidance import REFERENCE_FIELDS, Reference

    return Reference(**{f: _c(3, 3) if size == 9 else _c(size) for f, size in REFERENCE_FIELDS})


def _layout():
    """The step's layouts of the seed spec's six-joint robot (the places' types are the same
    for every arm)."""
    from pipeline.sim.control_step import step_layout

    return step_layout(seed().robot.shape)


def _task_errors():
    from pipeline.sim.control_step import TaskErrors

    return TaskErrors(x_tilde=_c(9), J_x=_c(9, 9), v_breve_des=_c(9), G_vc=_c(9, 3),
                      com_vel_err=_c(3), com_pos_err=_c(3))


def _transform_bundle():
    from pipeline.sim.task_transform import Transform

    return Transform(p_bc=_c(3), p_c=_c(3), J_bar_v=_c(3, 6), J_oplus=_c(6, 6), G_wb=_c(6, 3),
                     J_oplus_inv=_c(6, 6), s_min_J=1.0, kappa_J=1.0, gamma=_c(12, 12),
                     gamma_inv=_c(12, 12), gamma_dot=_c(12, 12), M_hat=_c(12, 12),
                     C_hat=_c(12, 12), s_min_G=1.0, kappa_G=1.0, gamma_vt=_c(12, 12))


def _step_state():
    from pipeline.sim import control_step as cs

    flags = ("has_prev", "measure", "warm")
    return cs.StepState(**{f: (False if f in flags else 0.0 if size == 1 else
                               _c(12, 12) if f == "gamma_vt" else _c(size))
                           for f, size in _layout().state_fields if f != "dq"})


def _linalg() -> None:
    """The leaves of :mod:`pipeline.sim.linalg`, for the C-ordered float64 arrays every caller
    passes (the callers make contiguous copies first)."""
    from pipeline.sim import linalg as la

    for kernel, args in ((la.dot, (_c(3), _c(3))), (la.matvec, (_c(3, 3), _c(3))),
                         (la.matmul, (_c(3, 3), _c(3, 3))), (la.solve, (_c(9, 9), _c(9))),
                         (la.inverse, (_c(9, 9),)), (la.cholesky_lower, (_c(9, 9),)),
                         (la.eigvalsh, (_c(9, 9),)), (la.svd, (_c(6, 6),)),
                         (la.singular_values, (_c(12, 12),)), (la.determinant, (_c(6, 6),)),
                         (la.svd_right_from, (_c(12, 12), _c(12, 12)))):
        _compile(kernel, *args)


def _rotations() -> None:
    from pipeline.sim.rotations import skew

    _compile(skew, _c(3))


def _rhs() -> None:
    from pipeline.sim.breve_controller import breve_rhs

    # C̆_c is a view of Ĉ (tr.C_hat[3:, :3]): not contiguous, Numba's layout "A".
    _compile(breve_rhs, _c(9, 9), _c(9, 9), _c(12, 12)[3:, :3], _c(12, 12), _c(9), _c(9),
             _task_errors(), _c(9, 9), _c(9, 9), 1.0, _c(6), _c(6), 1.0)


def _updates() -> None:
    from pipeline.sim import breve_controller as bc

    _compile(bc.explicit_update, _c(9, 9), _c(9), _c(9), 1.0, _c(3), _c(3))
    _compile(bc.imex_update, _c(9, 9), _c(9, 9), _c(9), _c(9), 1.0, _c(3), _c(3))
    _compile(bc.damping_rates, _c(9, 9), _c(9, 9))
    from pipeline.sim import margins

    _compile(margins.schur_stable, _c(5))  # the margins' stability test (eq. 35)


def _errors() -> None:
    from pipeline.sim.com_controller import com_update
    from pipeline.sim.control_step import task_error_terms

    _compile(task_error_terms, _c(3, 3), _c(3, 3), _c(3), _c(3), _reference(), 1.0, _c(3), 9)
    _compile(com_update, *(_c(3) for _ in range(5)), *(1.0 for _ in range(7)))


def _loop() -> None:
    """``loop_update`` for the types :func:`controller_step` passes it: C-ordered float64
    arrays (copies, products, ``np.diag``), float64 scalars, booleans for the flags."""
    from pipeline.sim import control_step as cs
    from pipeline.sim.task_transform import DynamicsInputs

    # The rigid-body terms' arrays, all C-ordered.
    pose = DynamicsInputs(R_tb=_c(3, 3), p_b=_c(3), R_te=_c(3, 3), p_e=_c(3), J_e=_c(6, 12),
                          dJ_e=_c(6, 12), M=_c(12, 12), C=_c(12, 12), Ag=_c(6, 12),
                          dAg=_c(6, 12))
    p = cs.ControlParams(**{f: (False if f in ("derate_gain", "imex") else
                                1.0 if size == 1 else _c(size))
                            for f, size in _layout().controller_fields})
    _compile(cs.loop_update, pose, _transform_bundle(), _reference(), p,
             _step_state(), 1.0, _c(9, 9), _c(9, 9))


def _kinematics() -> None:
    from pipeline.sim import task_transform as tt

    _compile(tt.kinematic_terms, _c(3, 3), _c(3), _c(3, 3), _c(3), _c(6, 12), _c(12, 12), 1.0)
    _compile(tt.damped_pinv, _c(6, 6), 1.0, 1.0)
    _compile(tt.gamma_matrix, _c(3, 3), _c(3), _c(3, 6), _c(6, 3), _c(6, 6))
    _compile(tt.gamma_inverse, _c(3, 3), _c(3), _c(3, 6), _c(6, 3), _c(6, 6))


def _rates() -> None:
    from pipeline.sim import task_transform as tt
    from pipeline.sim.sampling import conditioning_from, sigma_min_and_cond

    _compile(tt.gamma_time_derivative, _c(3, 3), _c(3, 3), _c(3, 3), _c(3), _c(3), _c(3, 6),
             _c(6, 12), _c(12), _c(6, 12), _c(6, 12), _c(6, 12), 1.0)
    _compile(tt.transformed_dynamics, *(_c(12, 12) for _ in range(4)))
    _compile(sigma_min_and_cond, _c(12, 12))
    _compile(conditioning_from, _c(12, 12), _c(12, 12))


def _terms() -> None:
    """The rigid-body terms (eqs. 1–11) and q ⊕ δ (eq. 22), as the mission loop, the
    robot's terms and the analysis' rebuild call them."""
    from pipeline.sim.configuration import integrate_configuration
    from pipeline.sim.rigid_body_terms import dynamics_terms, placement_terms

    s = seed()
    dynamics_terms(s.robot.bundle, s.q.copy(), s.v.copy())
    placement_terms(s.robot.bundle, s.q.copy())
    integrate_configuration(s.q.copy(), s.v.copy())


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
    p_b = np.zeros(3)  # the rigid-body terms' own array, as the mission passes it
    g.reference(0.0)
    g.reference(0.0, p_b.copy())
    g.reference_into(np.zeros(REFERENCE_SIZE), 0.0, p_b)
    # The coverage test (eq. 18): the step kernel's own, with the types it passes.
    visible(build_target(s.spec.target), np.zeros(3), pin.exp3(np.zeros(3)), s.spec.camera)


def _row() -> None:
    import numpy as np

    from pipeline.sim import control_step as cs
    from pipeline.sim.base_guidance import read_reference
    from pipeline.sim.plant import commanded_force
    from pipeline.sim.sampling import scale_by_svd
    from pipeline.sim.target import mark_visible

    flags = np.zeros(3, dtype=np.bool_)
    out = cs.LoopResult(v=_c(12), v_c=_c(3), v_breve=_c(9), integral=_c(3), x_tilde=_c(9),
                        v_breve_des=_c(9), mu_max=1.0, hit_acc=flags, hit_rate=flags,
                        sat_v_c_acc=False, sat_v_c_rate=False, sat_v_max=False,
                        com_pos_err=_c(3))
    layout = _layout()
    _compile(cs.read_params, _c(1), layout.places.controller)
    _compile(cs.read_state, _c(1), layout.places.state)
    _compile(read_reference, _c(1))
    _compile(cs.write_row, _c(layout.row_size), layout.places.row, _step_state(),
             _transform_bundle(), 1.0, 1.0, out, _c(12), 1.0, 1.0, 1.0)
    _compile(commanded_force, *(_c(12, 12) for _ in range(4)), _c(12), _c(12), _c(12), 1.0)
    _compile(cs.pointing_errors, _c(3, 3), _c(3), _c(3, 3), _c(3), _c(3))
    _compile(cs.state_is_finite, _c(13), _c(12), _c(9), _c(3))
    _compile(scale_by_svd, 1.0, 1.0, 1.0, 1.0)
    _compile(mark_visible, _c(1, 3), _c(1, 3), _c(3), _c(3, 3), 1.0, 1.0, 1.0, 1.0,
             np.zeros(1, dtype=np.bool_))


def _step() -> None:
    from pipeline.sim.mission import Mission

    s = seed()
    m = Mission(s.spec, s.robot)
    s0 = m.initial_state()
    m.critical_steps(s0)
    m.step(s0)  # the step kernel, exactly as a run calls it


def _analysis() -> None:
    import numpy as np

    from pipeline.sim.linalg import batched_singular_values, svd_right, svd_right_sequence

    s = seed()
    gamma = s.robot.gamma_matrices(np.stack([s.q, s.q]))  # Γ rebuilt from logged q (eq. 5)
    s.robot.j_oplus_conditioning(np.stack([s.q]))  # an import's J⊕ conditioning (eq. 19)
    batched_singular_values(gamma[np.array([True, False])])
    svd_right(gamma)
    _, Vt = svd_right_sequence(gamma[np.array([True, False])], np.empty((0, 0)))
    svd_right_sequence(gamma[np.array([False, True])], np.ascontiguousarray(Vt[-1]))


def _plant() -> None:
    """The sampled-data plant's step (eqs. 29, 41): RK4 on the compiled articulated-body
    algorithm, whole or split by the command's arrival, as ``Mission._hold`` calls
    it, and the dynamics alone, as the equation check does."""
    import numpy as np

    from pipeline.sim.forward_dynamics import forward_dynamics, rigid_tree
    from pipeline.sim.plant import integrate_held, integrate_split

    s = seed()
    tree = rigid_tree(s.robot.model)
    tau = np.zeros(s.robot.model.nv)
    forward_dynamics(tree, s.q.copy(), s.v.copy(), tau)
    integrate_held(tree, s.q.copy(), s.v.copy(), tau, 0.03, s.spec.mission.plant.substeps)
    # A command arriving within the step (eq. 41): the split hold.
    integrate_split(tree, s.q.copy(), s.v.copy(), tau, tau, 0.03, 0.25,
                    s.spec.mission.plant.substeps)


def _redundancy() -> None:
    """Eq. 37's kernels for a 7-joint arm (the shapes are not part of a kernel's type: any n
    uses the same specialisation)."""
    from pipeline.sim import redundancy as rd

    _compile(rd.null_space_map, _c(6, 7), _c(13, 13), 1.0)
    _compile(rd.null_space_terms, _c(6, 7), _c(6, 3), _c(13, 13), 1.0, 1.0, 1.0)
    _compile(rd.extended_gamma, _c(13, 13), _c(1, 10))
    ns = rd.NullSpace(Z=_c(7, 1), H=_c(10, 10), Lambda_n=_c(1, 1), Y=_c(1, 10), X_w=_c(7, 3),
                      X_e=_c(7, 6), s_min_J=1.0, kappa_J=1.0)
    _compile(rd.extended_gamma_inverse, _c(3, 3), _c(3), _c(3, 7), ns)
    _compile(rd.extended_gamma_dot, _c(12, 13), _c(6, 7), _c(13, 13), _c(13, 13), 1.0, ns)


# In priority order (the module docstring's table): a free process takes the first unit whose
# prerequisites are done. The order is by the longest chain of compile time from each unit to
# the end (the classic list-scheduling rule), with the times a cold compile measured here.
UNITS = {u.name: u for u in (
    Unit("linalg", "the products, LU, Cholesky and Jacobi leaves", (), _linalg),
    Unit("rotations", "the shared rotation leaf", ("linalg",), _rotations),
    Unit("updates", "the integrators and damping rates (eqs. 15, 21)", ("linalg",), _updates),
    Unit("rhs", "eq. 13's right-hand side", ("linalg",), _rhs),
    Unit("kinematics", "the pieces of eqs. 2-6", ("rotations",), _kinematics),
    Unit("redundancy", "a redundant arm's null-space terms (eq. 37)", ("kinematics",),
         _redundancy),
    Unit("rates", "Γ̇, M̂, Ĉ and Γ's conditioning (eqs. 7-9, 19)", ("rotations",), _rates),
    Unit("errors", "the task errors and CoM loop (eqs. 12, 14)", ("rotations",), _errors),
    Unit("guidance", "the references and coverage (eqs. 17, 18)", ("linalg",), _guidance),
    Unit("terms", "the rigid-body terms and q ⊕ δ (eqs. 1-11, 22)", ("linalg",), _terms),
    Unit("transform", "the task transform (eqs. 2-9, 19, 37)",
         ("kinematics", "rates", "redundancy", "terms"), _transform),
    Unit("loop", "the loops of one step (eqs. 12-16, 21)", ("rhs", "updates", "errors"),
         _loop),
    Unit("row", "the step's readers, writers and γ ramp (eq. 20)", ("linalg",), _row),
    Unit("step", "the step kernel and the mission loop (eq. 22)",
         ("transform", "loop", "guidance", "row"), _step),
    Unit("analysis", "the analysis' rebuild of Γ and its SVDs",
         ("kinematics", "redundancy", "terms", "transform"), _analysis),
    Unit("plant", "the sampled-data plant's RK4 and dynamics (eq. 29)", ("linalg",), _plant),
)}


def next_unit(done: set[str], taken: set[str]) -> str | None:
    """The first unit of :data:`UNITS` not yet taken whose prerequisites are all done, or
    None when none is ready."""
    for name, unit in UNITS.items():
        if name not in taken and set(unit.deps) <= done:
            return name
    return None


def _worker(tasks, report, parent: int) -> None:
    """Compile the units named on ``tasks`` until it says None; ``report`` gets (unit,
    seconds, "") or (unit, None, message). Ends with the process ``parent`` (kill -9 too)."""
    exit_with_parent(parent)
    while (name := tasks.get()) is not None:
        t0 = time.perf_counter()
        try:
            UNITS[name].run()
        except BaseException as exc:  # reported to the parent, then raised again
            report.put((name, None, f"{type(exc).__name__}: {exc}"))
            raise
        report.put((name, time.perf_counter() - t0, ""))


def _stamp_text() -> str:
    import numba

    return json.dumps({"numba": numba.__version__, "python": sys.version.split()[0],
                       "units": list(UNITS)})


def compile_kernels(processes: int = 2, when_idle: Callable[[], None] | None = None
                    ) -> Path | None:
    """Compile every unit (see the module docstring) into the kernel cache, unless its stamp
    says it is done; returns the cache folder (None when Numba's JIT is disabled).

    ``when_idle`` is started in a thread of this process the first time a compiling process
    has no unit left to take while the other still compiles (here: during the step kernel,
    the last unit, one core free), and joined before this returns: `pipeline all` imports the
    next stages' modules there. It must not compile anything, nor raise."""
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
    processes = max(1, min(processes, len(UNITS)))
    with stage("compile", f"({len(UNITS)} units of kernels, {processes} processes) -> "
                          f"{display_path(folder)}") as st:
        _schedule(processes, when_idle)
        folder.mkdir(parents=True, exist_ok=True)
        stamp.write_text(text)
        st.done(f"{len(list(folder.rglob('*.nbi')))} kernels cached")
    return folder


def _schedule(processes: int, when_idle: Callable[[], None] | None = None) -> None:
    """Hand each free process the next unit (:func:`next_unit`) until every unit is done;
    print each unit as it ends (a bar on a terminal). A failed unit or a process that ends
    unexpectedly stops them all (RunFailed). ``when_idle``: see :func:`compile_kernels`."""
    import threading

    from tqdm import tqdm

    ctx = mp.get_context("spawn")
    report = ctx.Queue()
    tasks = [ctx.Queue() for _ in range(processes)]
    procs = [ctx.Process(target=_worker, args=(q, report, os.getpid()), daemon=True)
             for q in tasks]
    for p in procs:
        p.start()
    done: set[str] = set()
    running: dict[str, int] = {}  # unit -> the process compiling it
    idle_work: threading.Thread | None = None
    error = ""
    with tqdm(total=len(UNITS), disable=not interactive(), unit="unit", desc="compile",
              file=sys.stderr, leave=False) as bar:
        while len(done) < len(UNITS) and not error:
            for i in set(range(processes)) - set(running.values()):
                name = next_unit(done, done | running.keys())
                if name is None:
                    if when_idle is not None and running and idle_work is None:
                        idle_work = threading.Thread(target=when_idle, daemon=True)
                        idle_work.start()
                    break
                running[name] = i
                tasks[i].put(name)
            if not running:
                error = f"units {sorted(set(UNITS) - done)} wait for each other"
                break
            try:
                name, seconds, message = report.get(timeout=0.5)
            except queue.Empty:
                # A process that ended while a unit was its own: it cannot report any more
                # (a failed unit reports before its process ends, so read that first).
                if any(not procs[i].is_alive() for i in running.values()):
                    try:
                        name, seconds, message = report.get(timeout=1.0)
                    except queue.Empty:
                        error = "a compiling process ended unexpectedly"
                        continue
                else:
                    continue
            del running[name]
            if seconds is None:
                error = f"unit {name}: {message}"
                continue
            done.add(name)
            bar.clear()
            say(f"compile: {name} ({UNITS[name].what}) in {seconds:.1f} s")
            bar.update(1)
    for q in tasks:
        q.put(None)
    if not error:
        # Every unit has reported, so every kernel is in the cache: the processes end on
        # their own (their exit, Numba's and LLVM's teardown, took 1-2 s to wait for).
        if idle_work is not None:
            idle_work.join()
        return
    for p in procs:
        p.join(timeout=10)
        if p.is_alive():
            p.terminate()
    raise RunFailed(f"compile: {error}")


def compile_command(args) -> int:
    compile_kernels(args.processes)
    return 0
