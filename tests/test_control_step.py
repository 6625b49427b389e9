"""The compiled step's flat layouts, read by name and sensitive to every swap of two fields,
the analysis' Jacobi SVDs against NumPy's, and the kernel cache's source key."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from pipeline.log_layout import limit_flags
from pipeline.sim import jit as jit_mod
from pipeline.sim.base_guidance import REFERENCE_FIELDS, read_reference
from pipeline.sim.control_step import controller_step, read_params
from pipeline.sim.layout import offsets, pack, unpack
from pipeline.sim.linalg import batched_singular_values, svd_right
from pipeline.sim.mission import Mission
from pipeline.sim.target import CoverageCounter
from pipeline.spec import load_spec, with_overrides


@pytest.fixture(scope="module")
def mission() -> Mission:
    return Mission(with_overrides(load_spec("short_nominal"), {"mission.duration": 1.0}))


@pytest.fixture(scope="module")
def layout(mission):
    return mission.layout


def test_layouts_have_unique_names_and_cover_the_log(layout):
    from pipeline.log_layout import SCALAR_COLUMNS, vector_columns

    for fields in (layout.state_fields, layout.row_fields, layout.controller_fields,
                   REFERENCE_FIELDS):
        names = [n for n, _ in fields]
        assert len(names) == len(set(names))
    row = dict(layout.row_fields)
    widths = vector_columns(layout.shape)
    assert {c: row[c] for c in widths} == widths
    assert widths["q"] == 13 and widths["v"] == widths["u_cmd"] == 12
    assert widths["v_breve"] == widths["x_tilde"] == 9
    assert set(SCALAR_COLUMNS) - set(row) == {"t"}
    assert row["limit_flags"] == len(limit_flags(layout.shape)) == 9


def test_pack_rejects_unknown_fields_and_wrong_sizes(layout):
    with pytest.raises(ValueError, match="nope"):
        pack(layout.state_fields, {"nope": 1.0})
    with pytest.raises(ValueError, match="q: 3 values for 13"):
        pack(layout.state_fields, {"q": np.zeros(3)})


def test_read_params_reads_each_named_field(layout):
    """Distinct values everywhere (one flag set, one clear): the kernel's reader gives each
    field back under its own name."""
    fields = layout.controller_fields
    values = {name: np.arange(n) + 0.25 + 100 * i for i, (name, n) in enumerate(fields)}
    values |= {"derate_gain": 1.0, "imex": 0.0}
    got = read_params(pack(fields, values), layout.places.controller)
    assert got._fields == tuple(name for name, _ in fields)
    for name, want in values.items():
        if name in ("derate_gain", "imex"):
            assert getattr(got, name) is (want > 0.5), name
        else:
            np.testing.assert_array_equal(np.ravel(getattr(got, name)), want, err_msg=name)


def test_reference_vector_round_trip(mission):
    ref = mission.guidance.reference(3.7, np.array([1.0, -2.0, 0.5]))
    vec = np.zeros(sum(n for _, n in REFERENCE_FIELDS))
    mission.guidance.reference_into(vec, 3.7, np.array([1.0, -2.0, 0.5]))
    np.testing.assert_array_equal(vec, ref.as_vector())
    back = read_reference(vec)
    for name, _ in REFERENCE_FIELDS:
        np.testing.assert_array_equal(getattr(back, name), getattr(ref, name), err_msg=name)


# -- a swapped field changes the step --------------------------------------------------------
#
# The kernel reads and writes its flat vectors through places frozen from the layouts. Below,
# one step is taken with every input field set to a distinct value, then again with the inputs
# packed (or the row read) under a layout in which two fields trade places: what a kernel that
# confused the two would see. For every pair of every layout the step's result must change, so
# the field-by-field checks of test_log_row.py would catch such a confusion.

FLAG_BOUNDS = {  # the controller field bounding each limit flag, and the block it bounds
    "sat_omega_b_acc": ("acc_bounds", 0), "sat_omega_b_rate": ("rate_bounds", 0),
    "sat_nu_e_lin_acc": ("acc_bounds", 1), "sat_nu_e_lin_rate": ("rate_bounds", 1),
    "sat_nu_e_ang_acc": ("acc_bounds", 2), "sat_nu_e_ang_rate": ("rate_bounds", 2),
    "sat_v_c_acc": ("v_c_acc", 0), "sat_v_c_rate": ("v_c_rate", 0), "sat_v_max": ("v_max", 0)}


def _swapped(fields, i, j):
    f = list(fields)
    f[i], f[j] = f[j], f[i]
    return tuple(f)


@pytest.fixture(scope="module")
def distinct_step(mission):
    """(mission, q, v, named controller, state and reference values), all distinct: a real
    mid-mission state of the seed robot, limits that bind, γ on its ramp, the damped inverse
    damping, a CoM integral to bound; the ``dq`` slot holds values the kernel overwrites."""
    s = mission.initial_state()
    for _ in range(20):
        s, _ = mission.step(s)
    T = mission.robot.terms(s.q, s.v)
    ctrl = unpack(mission.layout.controller_fields, mission.controller_vector())
    ctrl |= {"k": ctrl["k"] * (1 + 0.01 * np.arange(9)),
             "d": ctrl["d"] * (1 + 0.013 * np.arange(9)),
             "derate_gain": 1.0, "imex": 0.0, "k_posture": 0.37, "k_null": 0.27,
             "acc_bounds": [0.031, 0.052, 0.073], "rate_bounds": [0.0041, 0.0062, 0.0083],
             "com_K": 0.21, "com_D": 0.43, "com_Ki": 0.057, "com_i_max": 1.1e-5,
             "v_c_acc": 7.1e-4, "v_c_rate": 0.0123, "v_max": 0.0021,
             "ramp_low": 0.5 * T.s_min_G, "ramp_high": 2.1 * T.s_min_G, "ramp_floor": 0.29,
             "inverse_floor": 1.7 * T.s_min_J, "inverse_damping": 0.047}
    state = {"q": s.q, "v": s.v, "v_c": s.v_c, "v_breve": s.v_breve, "tau": s.tau,
             "integral": [2.3e-4, -3.1e-4, 1.7e-4], "v_breve_des_prev": s.v_breve_des_prev,
             "has_prev": 1.0, "dq": 1000.0 + np.arange(12)}
    ref = mission.guidance.reference(s.tau, T.p_b)
    ref = {name: getattr(ref, name) for name, _ in REFERENCE_FIELDS}
    for named in (ctrl, state, ref):  # swaps are within one layout
        scalars = [float(np.ravel(x)[0]) for x in named.values() if np.size(x) == 1]
        assert len(set(scalars)) == len(scalars)
    return mission, s.q, s.v, ctrl, state, ref


def _kernel_step(mission, q, v, ctrl, state, ref, layouts=None):
    """One call of the step kernel with the named inputs packed under ``layouts`` (default: the
    kernel's own); the row read under the kernel's layout and the state under ``layouts``."""
    own = mission.layout
    lay = {"ctrl": own.controller_fields, "state": own.state_fields, "ref": REFERENCE_FIELDS,
           **(layouts or {})}
    vec = pack(lay["state"], state)
    rows = np.zeros((1, own.row_size))
    cov = CoverageCounter.start(mission.target, mission.spec.camera)
    try:
        with np.errstate(all="ignore"):
            controller_step(mission.robot.dynamics_inputs(q, v), pack(lay["ref"], ref),
                            pack(lay["ctrl"], ctrl), vec, rows, 0, cov, own.index)
    except (np.linalg.LinAlgError, ZeroDivisionError, ValueError) as exc:
        return type(exc).__name__
    return rows[0], unpack(lay["state"], vec)


def _same(a, b, row_places, tol: float = 1e-8) -> bool:
    """Two results alike: the same exception, or every field of the row and of the state
    within ``tol`` of the largest entry (a change smaller than the tolerances of
    test_log_row.py would go unnoticed there, so it counts as no change)."""
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    fields = [(a[0][sl], b[0][sl]) for sl in row_places.values()]
    fields += [(a[1][k], b[1][k]) for k in a[1]]
    return all(np.all(np.isfinite(y)) and np.max(np.abs(x - y)) <= tol * np.max(np.abs(x))
               for x, y in fields)


@pytest.mark.parametrize("layout", ["ctrl", "state", "ref"])
def test_swapping_two_input_fields_changes_the_step(distinct_step, layout):
    mission, q, v, ctrl, state, ref = distinct_step
    own = mission.layout
    fields = {"ctrl": own.controller_fields, "state": own.state_fields,
              "ref": REFERENCE_FIELDS}[layout]
    base = _kernel_step(mission, q, v, ctrl, state, ref)
    assert not isinstance(base, str), base
    assert np.all(np.isfinite(base[0])) and all(np.all(np.isfinite(x)) for x in base[1].values())
    unchanged = [(fields[i][0], fields[j][0])
                 for i in range(len(fields)) for j in range(i + 1, len(fields))
                 if _same(base, _kernel_step(mission, q, v, ctrl, state, ref,
                                             {layout: _swapped(fields, i, j)}), own.row)]
    # The null-space stiffness is a redundant arm's: a six-joint step never reads it, so its
    # swap with a flag (derate_gain 1, imex 0: no value differs from both) cannot show here.
    assert set(unchanged) <= {("k_null", "imex"), ("derate_gain", "k_null")}, unchanged


def test_swapping_two_row_fields_changes_the_log(distinct_step):
    """The row's fields read under a layout with two fields swapped differ from those read
    under the kernel's, in at least one of five steps: the distinct-valued step and four in
    which the bounds are 0 or 10⁹ by the bits of each flag's number, so the nine flags' values
    across the steps differ pairwise (and are checked: a bound of 0 binds, 10⁹ does not)."""
    mission, q, v, ctrl, state, ref = distinct_step
    own = mission.layout
    ROW, ROW_FIELDS = own.row, own.row_fields
    flags = limit_flags(own.shape)
    rows = [_kernel_step(mission, q, v, ctrl, state, ref)[0]]
    for bit in range(4):
        c = {k: np.array(x, dtype=float) for k, x in ctrl.items()}
        want = {}
        for n, (flag, (field, block)) in enumerate(FLAG_BOUNDS.items(), start=1):
            want[flag] = bool((n >> bit) & 1)
            c[field].reshape(-1)[block] = 0.0 if want[flag] else 1e9
        row = _kernel_step(mission, q, v, c, state, ref)[0]
        got = {flag: bool(row[ROW["limit_flags"].start + flags.index(flag)])
               for flag in FLAG_BOUNDS}
        assert got == want
        rows.append(row)
    assert set(FLAG_BOUNDS) == set(flags)
    # The kernel writes u_applied as a copy of u_cmd and attitude_excursion_deg as 0 (the
    # sampled-data plant overwrites both, by name): no swap involving them shows here (0 also
    # being this step's coverage). test_actuation reads them where they differ.
    blind = {("u_cmd", "u_applied"), ("coverage", "attitude_excursion_deg")}
    unchanged = []
    for i in range(len(ROW_FIELDS)):
        for j in range(i + 1, len(ROW_FIELDS)):
            swapped = offsets(_swapped(ROW_FIELDS, i, j))
            if all(np.max(np.abs(r[swapped[name]] - r[ROW[name]]))
                   <= 1e-8 * np.max(np.abs(r[ROW[name]]))
                   for r in rows for name, _ in ROW_FIELDS):
                unchanged.append((ROW_FIELDS[i][0], ROW_FIELDS[j][0]))
    assert set(unchanged) <= blind, unchanged


def test_svd_right_against_numpy():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((40, 12, 12))
    A[5] = A[5] @ np.diag([1.0] * 11 + [1e-9])  # nearly singular
    S, Vt = svd_right(A)
    s_ref = np.linalg.svd(A, compute_uv=False)
    np.testing.assert_allclose(S, s_ref, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(batched_singular_values(A), s_ref, rtol=1e-12, atol=1e-14)
    # Vᵀ's rows are orthonormal and A v_i has norm σ_i.
    np.testing.assert_allclose(Vt @ np.swapaxes(Vt, 1, 2), np.broadcast_to(np.eye(12), A.shape),
                               atol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(A @ np.swapaxes(Vt, 1, 2), axis=1), S, rtol=1e-10,
                               atol=1e-13)


def test_svd_right_marks_non_finite_input():
    A = np.eye(12)[None].repeat(2, axis=0)
    A[1, 3, 3] = np.nan
    S, _ = svd_right(A)
    np.testing.assert_array_equal(S[0], np.ones(12))
    assert np.isnan(S[1]).all()
    assert np.isnan(batched_singular_values(A)[1]).all()


def test_kernel_cache_is_keyed_on_every_sim_source(tmp_path):
    """Numba alone would keep a caller's cached kernel after its callee's file changed."""
    src = tmp_path / "sim"
    shutil.copytree(jit_mod.SIM_DIR, src, ignore=shutil.ignore_patterns("__pycache__"))
    before = jit_mod.source_stamp(src)
    assert jit_mod.source_stamp(src) == before
    target = src / "breve_controller.py"
    target.write_text(target.read_text() + "\n# edited\n")
    assert jit_mod.source_stamp(src) != before
    if os.environ.get("NUMBA_CACHE_DIR"):
        pytest.skip("NUMBA_CACHE_DIR set by the user: used as it is")
    from numba.core import config

    assert jit_mod.source_stamp() in config.CACHE_DIR


def test_every_module_whose_names_the_kernels_freeze_is_in_their_cache_key():
    """A compiled kernel freezes the globals it reads (the shapes' blocks, TASK_DOF, the
    layouts' places): a module outside pipeline/sim that supplies one must be hashed into the
    kernels' cache folder (jit.KERNEL_CONSTANTS), or an edit of it would leave stale kernels."""
    import ast
    import importlib
    import types

    from numba.core.registry import CPUDispatcher

    def names(code: types.CodeType) -> set[str]:
        out = set(code.co_names)
        for const in code.co_consts:
            if isinstance(const, types.CodeType):
                out |= names(const)
        return out

    supplying = set()
    for path in sorted(jit_mod.SIM_DIR.glob("*.py")):
        module = importlib.import_module(f"pipeline.sim.{path.stem}")
        origin = {alias.asname or alias.name: node.module
                  for node in ast.walk(ast.parse(path.read_text()))
                  if isinstance(node, ast.ImportFrom) and node.module
                  and node.module.startswith("pipeline.")
                  and not node.module.startswith("pipeline.sim")
                  for alias in node.names}
        for obj in vars(module).values():
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == module.__name__:
                supplying |= {origin[n] for n in names(obj.py_func.__code__) if n in origin}
    hashed = {f"pipeline.{p.stem}" for p in jit_mod.KERNEL_CONSTANTS}
    assert "pipeline.shapes" in supplying  # the scan sees them
    assert supplying <= hashed, supplying - hashed
