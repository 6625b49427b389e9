"""The compiled step's flat layouts, checked field by field against independent computations,
the analysis' LAPACK SVDs against NumPy's, and the kernel cache's source key."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest
import scipy.linalg

from pipeline.sim import jit as jit_mod
from pipeline.sim.base_controller import block_gains, conditioning_scale
from pipeline.sim.base_guidance import REFERENCE_FIELDS, unpack_reference
from pipeline.sim.control_step import (
    CONTROLLER_FIELDS,
    ROW_FIELDS,
    STATE_FIELDS,
    pack,
    unpack_controller,
)
from pipeline.sim.mission import Mission, task_errors
from pipeline.sim.svd import batched_singular_values, svd_right
from pipeline.spec import load_spec, with_overrides


@pytest.fixture(scope="module")
def mission() -> Mission:
    return Mission(with_overrides(load_spec("short_nominal"), {"mission.duration": 1.0}))


def test_layouts_have_unique_names_and_cover_the_log():
    from pipeline.logs import SCALAR_COLUMNS, VECTOR_COLUMNS
    from pipeline.sim.limits import LIMIT_FLAGS

    for fields in (STATE_FIELDS, ROW_FIELDS, CONTROLLER_FIELDS, REFERENCE_FIELDS):
        names = [n for n, _ in fields]
        assert len(names) == len(set(names))
    row = dict(ROW_FIELDS)
    assert {c: row[c] for c in VECTOR_COLUMNS} == VECTOR_COLUMNS
    assert set(SCALAR_COLUMNS) - set(row) == {"t"}
    assert all(row[f] == 1 for f in LIMIT_FLAGS)


def test_pack_rejects_unknown_fields_and_wrong_sizes():
    with pytest.raises(ValueError, match="nope"):
        pack(STATE_FIELDS, {"nope": 1.0})
    with pytest.raises(ValueError, match="q: 3 values for 13"):
        pack(STATE_FIELDS, {"q": np.zeros(3)})


def test_unpack_controller_reads_each_named_field():
    """Distinct values everywhere (flags true): the kernel's reader, flattened in order, gives
    back the vector, so a shifted or overlapping offset shows."""
    flags = ("derate_gain", "imex")
    values = {name: 1.0 if name in flags else np.arange(n) + 0.25 + 100 * i
              for i, (name, n) in enumerate(CONTROLLER_FIELDS)}
    vec = pack(CONTROLLER_FIELDS, values)
    got = np.concatenate([np.ravel(np.asarray(g, dtype=float))
                          for g in unpack_controller(vec)])
    np.testing.assert_array_equal(got, vec)


def test_reference_vector_round_trip(mission):
    ref = mission.guidance.reference(3.7, np.array([1.0, -2.0, 0.5]))
    vec = np.zeros(sum(n for _, n in REFERENCE_FIELDS))
    mission.guidance.reference_into(vec, 3.7, np.array([1.0, -2.0, 0.5]))
    np.testing.assert_array_equal(vec, ref.as_vector())
    for (name, _), part in zip(REFERENCE_FIELDS, unpack_reference(vec), strict=True):
        np.testing.assert_array_equal(part, getattr(ref, name), err_msg=name)


def test_step_row_fields_against_independent_computations(mission):
    """Row k written by the kernel, field by field, against NumPy/SciPy from the same state."""
    s = mission.initial_state()
    for _ in range(25):  # past the start, with a v̆_des history
        s, _ = mission.step(s)
    nxt, row = mission.step(s)
    spec, dt = mission.spec, mission.dt
    for name in ("q", "v", "v_c", "v_breve"):
        np.testing.assert_array_equal(row[name], getattr(s, name), err_msg=name)
    assert row["tau"] == s.tau
    T = mission.robot.terms(s.q, s.v)
    sg = np.linalg.svd(T.gamma, compute_uv=False)
    sj = np.linalg.svd(T.J_oplus, compute_uv=False)
    assert row["s_min_G"] == pytest.approx(sg[-1], rel=1e-12)
    assert row["kappa_G"] == pytest.approx(sg[0] / sg[-1], rel=1e-12)
    assert row["s_min_J"] == pytest.approx(sj[-1], rel=1e-12)
    assert row["kappa_J"] == pytest.approx(sj[0] / sj[-1], rel=1e-12)
    gamma = conditioning_scale(T.s_min_G, spec.controller)
    assert row["gamma"] == gamma
    _, D = block_gains(spec.controller, gamma)
    mu = scipy.linalg.eigvals(D, T.reduced_inertia).real  # D̆ x = μ M̆ x: μ = eig(M̆⁻¹D̆)
    assert row["dt_mu_max"] == pytest.approx(dt * mu.max(), rel=1e-9)
    ref = mission.guidance.reference(s.tau, T.p_b)
    err = task_errors(T, ref, gamma, s.v_c)
    np.testing.assert_allclose(row["x_tilde"], err.x_tilde, rtol=0, atol=1e-14)
    np.testing.assert_allclose(row["v_breve_des"], err.v_breve_des, rtol=0, atol=1e-14)
    assert row["com_err"] == pytest.approx(np.linalg.norm(err.com_pos_err), rel=1e-12)

    def angle(a, b):
        return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))

    assert row["pointing_err_deg"] == pytest.approx(angle(T.R_tb[:, 2], -T.p_b), abs=1e-9)
    assert row["boresight_err_deg"] == pytest.approx(angle(T.R_te[:, 2], ref.aim - T.p_e),
                                                     abs=1e-9)
    assert 0.0 <= row["coverage"] <= 1.0
    # The carried state: τ advances by γ dt and v̆_des becomes the previous one.
    assert nxt.tau == s.tau + gamma * dt
    np.testing.assert_array_equal(nxt.v_breve_des_prev, row["v_breve_des"])


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


def test_cached_pinocchio_views_follow_every_call(mission):
    """The step reads placements and the centroidal map through views taken once; after
    Pinocchio runs at new states they must equal what Pinocchio's accessors return."""
    import pinocchio as pin

    robot = mission.robot
    assert robot._views is not None  # this Pinocchio hands out views
    rng = np.random.default_rng(11)
    for _ in range(3):
        q = pin.randomConfiguration(robot.model, -np.ones(robot.model.nq),
                                    np.ones(robot.model.nq))
        got = [np.array(a) for a in robot.dynamics_inputs(q, rng.standard_normal(robot.model.nv))]
        fresh = robot.model.createData()  # independent of the robot's data and its views
        pin.forwardKinematics(robot.model, fresh, q)
        pin.updateFramePlacement(robot.model, fresh, robot.frame_id)
        oMb, oMe = fresh.oMi[1], fresh.oMf[robot.frame_id]
        for a, b in zip(got[:4], (oMb.rotation, oMb.translation, oMe.rotation, oMe.translation),
                        strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
        np.testing.assert_allclose(got[8], pin.computeCentroidalMap(robot.model, fresh, q),
                                   rtol=0, atol=1e-12)
