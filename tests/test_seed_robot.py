"""The seed robot (issue 11): its file, its reduced inertia and damping rates against
independent computations, divergence, and the note's update order of the discrete map.

Independent references:
- M̆ from the kinetic energy of every body, with body velocities by central differences of
  their placements (``framesForwardKinematics`` alone: no CRBA, Jacobian or Γ code), and ν → v
  through a Γ built column by column from finite differences of the CoM and camera pose. T is
  exactly quadratic, so M̆ is read by polarisation, T(a + b) − T(a − b) = 2 aᵀ M̆ b.
- μ_bus = D_b / I_zz,bus with I_zz,bus summed by hand from the MJCF's numbers
  (box 0.01 + base_link 0.005625 kg·m², both centres of mass on the shoulder-pan axis).
- The discrete map's eigenvalues from the scalar characteristic polynomial, written out here.

Finite-difference error: central differences with h = 1e-6 of placements of size ≲ 1 m have
roundoff ~ε/h ≈ 2e-10 and truncation ~h² ≈ 1e-12; M̆'s entries are O(1e-2..1), so the
tolerance 1e-6 relative to max |M̆| leaves a 1000× margin while a frame or block error is O(1).
"""

from __future__ import annotations

import re
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg as sla
from conftest import SEEDS, random_state, run_cli

from pipeline.analysis import theory
from pipeline.analysis.stages import analyze_log
from pipeline.errors import SpecError
from pipeline.logs import num_rows, read_columns, read_meta, verify_log
from pipeline.paths import SHIPPED_SPECS
from pipeline.sim.base_controller import block_gains
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.robot_file import load_robot_model
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides

I_ZZ_BUS = 0.01 + 0.005625  # kg·m², the MJCF's box_base izz + base_link izz, by hand
SEED_FILE = SHIPPED_SPECS / "robots" / "seed_ur3_box.xml"
H = 1e-6


# -- the robot file ------------------------------------------------------------------------------

def test_the_seed_robot_is_the_notes_system(robot):
    """The default missions run the MJCF seed robot: 17.18 kg, I_zz,bus = 0.015625 kg·m²."""
    assert robot.spec.robot_path == SEED_FILE
    assert robot.model.nq == 13 and robot.model.nv == 12
    card = robot.card(robot.start_configuration())
    assert card.total_mass == pytest.approx(17.18, rel=1e-12)
    assert card.bus_mass == pytest.approx(7.0, rel=1e-12)  # box 5 kg + UR3 base_link 2 kg
    assert card.bus_links == ["box_base", "base_link"]  # the card says so (issue 33, item 4)
    assert card.I_zz_bus == pytest.approx(I_ZZ_BUS, rel=1e-12)
    assert card.pan_axis_offset == pytest.approx(0.0, abs=1e-15)
    assert card.mu_bus == pytest.approx(2.0 / I_ZZ_BUS, rel=1e-12)  # 128 1/s
    assert card.dt_star_bus == pytest.approx(2.0 / 128.0, rel=1e-12)


def test_the_servicer_card_predicts_a_slow_bus():
    r = GiordanoRobot(load_spec("servicer_nominal"))
    card = r.card(r.start_configuration())
    assert card.I_zz_bus == pytest.approx(10.625, rel=1e-12)  # the URDF's bus izz
    assert card.bus_links == ["bus"]
    assert card.mu_bus == pytest.approx(2.0 / 10.625, rel=1e-12)  # ≈ 0.19 1/s


MJCF_HEAD = '<mujoco model="t"><compiler angle="radian"/><worldbody>'


def _chain(n_joints: int, free: bool = True, site: str = "camera") -> str:
    body = "".join(f'<body name="l{i}" pos="0 0 0.1"><joint name="j{i}" type="hinge" '
                   f'axis="0 0 1"/><inertial pos="0 0 0.05" mass="1" diaginertia="0.01 0.01 '
                   f'0.01"/>' for i in range(n_joints))
    close = "</body>" * n_joints
    return (MJCF_HEAD + '<body name="bus">' + ("<freejoint/>" if free else "")
            + '<inertial pos="0 0 0" mass="5" diaginertia="0.1 0.1 0.1"/>' + body
            + f'<site name="{site}"/>' + close + "</body></worldbody></mujoco>")


@pytest.mark.parametrize("name,text,needle", [
    ("garbage.xml", "this is not XML <<<", "not a loadable robot file"),
    ("five.xml", _chain(5), "5 arm joints (j0, j1, j2, j3, j4) to the camera frame"),
    ("nocam.xml", _chain(6, site="lens"), "no frame 'camera'"),
    ("nofree.xml", _chain(6, free=False), "root joint must be a free joint"),
    ("garbage.urdf", "<robot name='x'><link name='a'/><joint", "not a loadable robot file"),
])
def test_bad_robot_files_are_one_line_spec_errors(tmp_path, name, text, needle):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(SpecError) as exc:
        load_robot_model(path, "camera")
    msg = str(exc.value)
    assert str(path) in msg and needle in msg and "\n" not in msg


def test_a_six_joint_mjcf_with_a_camera_loads(tmp_path):
    path = tmp_path / "ok.xml"
    path.write_text(_chain(6))
    model = load_robot_model(path, "camera")
    assert (model.nq, model.nv) == (13, 12)
    assert np.all(model.gravity.linear == 0)


def test_bus_inertia_scale_scales_the_bus_body_alone():
    base = load_robot_model(SEED_FILE, "camera")
    scaled = load_robot_model(SEED_FILE, "camera", bus_inertia_scale=3.0)
    np.testing.assert_allclose(scaled.inertias[1].inertia, 3.0 * base.inertias[1].inertia,
                               rtol=1e-15)
    assert scaled.inertias[1].mass == base.inertias[1].mass
    np.testing.assert_array_equal(scaled.inertias[1].lever, base.inertias[1].lever)
    for i in range(2, base.njoints):
        np.testing.assert_array_equal(scaled.inertias[i].inertia, base.inertias[i].inertia)


# -- M̆ and μ against independent computations ---------------------------------------------------

def _poses(model, data, q):
    """(CoM of each body in t, rotation of each body) and the CoM and camera pose, from
    placements alone."""
    pin.framesForwardKinematics(model, data, q)
    coms = [data.oMi[i].act(model.inertias[i].lever) for i in range(1, model.njoints)]
    rots = [data.oMi[i].rotation.copy() for i in range(1, model.njoints)]
    return coms, rots


def _vee(W):
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


def _kinetic_energy(model, q, v):
    """T(q, v) = Σ ½ m_i |ċ_i|² + ½ ω_iᵀ R_i I_i R_iᵀ ω_i, velocities by central differences."""
    data = model.createData()
    (cp, Rp) = _poses(model, data, pin.integrate(model, q, H * v))
    (cm, Rm) = _poses(model, data, pin.integrate(model, q, -H * v))
    (_, R0) = _poses(model, data, q)
    T = 0.0
    for i in range(1, model.njoints):
        c_dot = (cp[i - 1] - cm[i - 1]) / (2 * H)
        w = _vee((Rp[i - 1] - Rm[i - 1]) / (2 * H) @ R0[i - 1].T)  # t frame
        I_t = R0[i - 1] @ model.inertias[i].inertia @ R0[i - 1].T
        T += 0.5 * model.inertias[i].mass * c_dot @ c_dot + 0.5 * w @ I_t @ w
    return T


def _gamma_fd(robot, q):
    """Γ column by column: the task velocity [ṗ_c; ω_b; R_et(ṗ_e − ṗ_c); ω_e] of each unit v."""
    model, data = robot.model, robot.model.createData()

    def pose(qq):
        p_c = pin.centerOfMass(model, data, qq).copy()
        pin.framesForwardKinematics(model, data, qq)
        oMe = data.oMf[robot.frame_id]
        return p_c, oMe.translation.copy(), oMe.rotation.copy()

    _, _, R_te = pose(q)
    G = np.zeros((12, 12))
    for i in range(12):
        e = np.zeros(12)
        e[i] = 1.0
        (cp, ep, Rp), (cm, em, Rm) = pose(pin.integrate(model, q, H * e)), pose(
            pin.integrate(model, q, -H * e))
        pc_dot = (cp - cm) / (2 * H)
        G[:, i] = np.concatenate([pc_dot, e[3:6], R_te.T @ ((ep - em) / (2 * H) - pc_dot),
                                  _vee(R_te.T @ (Rp - Rm) / (2 * H))])
    return G


def _reduced_inertia_fd(robot, q):
    """M̆ from the kinetic energy: M̂_ij = [T(e_i + e_j) − T(e_i − e_j)]/2 in ν, with
    v = Γ_fd⁻¹ ν and T computed body by body (polarisation of a quadratic form)."""
    Gi = np.linalg.inv(_gamma_fd(robot, q))
    n = 12
    M_hat = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            a, b = Gi[:, i], Gi[:, j]
            M_hat[i, j] = M_hat[j, i] = 0.5 * (_kinetic_energy(robot.model, q, a + b)
                                               - _kinetic_energy(robot.model, q, a - b))
    return M_hat[3:, 3:]


@pytest.fixture(scope="module")
def short_nominal_log(short_logs):
    return short_logs["short_nominal"]


def test_reduced_inertia_at_the_representative_step_matches_the_kinetic_energy(
        robot, short_nominal_log):
    """M̆ at the analysis' representative step against M̆ from finite differences of the
    kinetic energy; μ_max there against the closed form D_b / I_zz,bus."""
    rec = analyze_log(verify_log(short_nominal_log))
    k = rec.theory.step
    q = read_columns(short_nominal_log, ["q"], k, k + 1)["q"][0]
    T = robot.terms(q, np.zeros(12))
    assert T.s_min_J > robot.floor  # the exact inverse: M̆ is the kinetic energy's
    M_fd = _reduced_inertia_fd(robot, q)
    scale = np.abs(M_fd).max()
    np.testing.assert_allclose(T.reduced_inertia, M_fd, atol=1e-6 * scale, rtol=0)
    # The bus yaw e_z is an eigen-direction of M̆ with inertia I_zz,bus: M̆ e_z = I_zz,bus e_z.
    np.testing.assert_allclose(M_fd[:, 2], I_ZZ_BUS * np.eye(9)[2], atol=1e-6 * scale)
    _, D = block_gains(robot.spec.controller, 1.0)
    mu_fd = sla.eigh(D, M_fd, eigvals_only=True)
    assert mu_fd[-1] == pytest.approx(2.0 / I_ZZ_BUS, rel=1e-6)
    assert rec.theory.mu_max == pytest.approx(2.0 / I_ZZ_BUS, rel=1e-9)
    assert np.array(rec.theory.M_breve) == pytest.approx(T.reduced_inertia, abs=1e-15)


@pytest.mark.parametrize("seed", SEEDS)
def test_mu_max_is_the_bus_yaw_closed_form_at_random_configurations(robot, seed):
    """Away from the singularity (σ_min(J⊕) > 2 × floor), at any bus pose and arm posture
    within ±0.5 rad of q̄: μ_max = D_b / I_zz,bus, whatever the conditioning."""
    rng = np.random.default_rng(seed)
    q, _ = random_state(robot, rng)
    T = robot.terms(q, np.zeros(12))
    _, D = block_gains(robot.spec.controller, 1.0)
    mu = sla.eigh(D, T.reduced_inertia, eigvals_only=True)
    assert mu[-1] == pytest.approx(robot.spec.controller.gains.bus.D / I_ZZ_BUS, rel=1e-9)


def test_mu_max_scales_with_the_bus_inertia():
    spec = with_overrides(load_spec("nominal"), {"robot.bus_inertia_scale": 1.5})
    r = GiordanoRobot(spec)
    T = r.terms(r.start_configuration(), np.zeros(12))
    _, D = block_gains(spec.controller, 1.0)
    mu = sla.eigh(D, T.reduced_inertia, eigvals_only=True)
    assert mu[-1] == pytest.approx(2.0 / (1.5 * I_ZZ_BUS), rel=1e-9)
    assert r.card(r.start_configuration()).I_zz_bus == pytest.approx(1.5 * I_ZZ_BUS)


# -- the discrete map under the note's update order ----------------------------------------------

@pytest.mark.parametrize("m,d,k,dt", [(I_ZZ_BUS, 2.0, 2.0, 0.03), (I_ZZ_BUS, 2.0, 2.0, 0.01),
                                      (1.0, 3.0, 0.5, 0.1)])
def test_scalar_maps_match_their_characteristic_polynomials(m, d, k, dt):
    """One mode: b = dt·d/m, a = dt²k/m. Note's order (x⁺ = x + dt e): λ² − (2 − b)λ +
    (1 − b + a) = 0. Simulator's order (x⁺ = x + dt e⁺): λ² − (2 − a − b)λ + (1 − b) = 0."""
    b, a = dt * d / m, dt * dt * k / m
    M, D, K, J = (np.array([[x]]) for x in (m, d, k, 1.0))
    for order, poly in (("note", [1, -(2 - b), 1 - b + a]), ("simulator", [1, -(2 - a - b),
                                                                            1 - b])):
        got = np.sort_complex(np.linalg.eigvals(theory.discrete_map(M, D, K, J, dt,
                                                                    "explicit", order)))
        np.testing.assert_allclose(got, np.sort_complex(np.roots(poly).astype(complex)),
                                   atol=1e-12)
    with pytest.raises(ValueError, match="update order"):
        theory.discrete_map(M, D, K, J, dt, "explicit", "backwards")


def test_the_note_eigenvalue_is_the_note_order_of_the_bus_yaw():
    """−2.81 (the note) is the note's order at dt 0.03; the simulator's order gives −2.93."""
    b, a = 0.03 * 2.0 / I_ZZ_BUS, 0.03**2 * 2.0 / I_ZZ_BUS
    note = min(np.roots([1, -(2 - b), 1 - b + a]).real)
    sim = min(np.roots([1, -(2 - a - b), 1 - b]).real)
    assert note == pytest.approx(-2.81, abs=5e-3)
    assert sim == pytest.approx(-2.926, abs=5e-3)


# -- divergence -----------------------------------------------------------------------------------

@pytest.mark.slow
def test_unbounded_mission_ends_diverged_with_the_bound_and_the_fix(tmp_path):
    r = run_cli("run", "omega_ripple_unbounded", "--out", str(tmp_path))
    assert r.returncode == 1, r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert "diverged" in line and "imex" in line and "v_max clip" in line
    # The bound as printed (3 and 4 significant digits), against the closed form at dt = 0.03 s:
    # μ_bus = D_b/I_zz,bus = 128 s⁻¹, dt* = 2/128 = 0.015625 s. Compared as numbers within the
    # printed precision, not as text: 0.015625 sits on a rounding tie of 4 digits, so a μ_max of
    # 128 ± 1e-12 at the diverging state prints as 0.01562 or 0.01563.
    found = re.search(r"dt·μ_max = ([0-9.]+), dt\*_damping = 2/μ_max = ([0-9.]+) s", line)
    assert found, line
    assert abs(float(found[1]) - 0.03 * 128) <= 0.005, line
    assert abs(float(found[2]) - 2 / 128) <= 0.5e-5 + 1e-12, line
    log = tmp_path / "omega_ripple_unbounded" / "run.parquet"
    meta = read_meta(log)
    assert meta.status == "diverged"
    assert num_rows(log) == meta.failed_step + 1
    c = read_columns(log, ["sat_v_max"])
    assert c["sat_v_max"][-3:].all()  # the criterion: three consecutive steps on the clip

    rec = analyze_log(verify_log(log))
    g = rec.divergence
    assert rec.status == "diverged" and "divergence step" in rec.note
    assert g.alternating and g.fit_steps[1] - g.fit_steps[0] >= 4
    # The measured growth is the simulator's map's eigenvalue, not the note's order's.
    assert g.growth_factor == pytest.approx(g.predicted, rel=0.02)
    assert abs(g.growth_factor / g.predicted_note_order - 1) > 0.02
    out = run_cli("analyze", str(log), "--out", str(tmp_path / "rep"))
    assert out.returncode == 0, out.stderr
    assert "diverged log" in out.stdout and "Φ predicts" in out.stdout
    assert not (tmp_path / "rep" / "omega_ripple_unbounded" / "directions.parquet").exists()


def test_a_complete_run_never_reaches_the_divergence_criterion(short_nominal_log):
    assert read_meta(short_nominal_log).status == "complete"
    assert not read_columns(short_nominal_log, ["sat_v_max"])["sat_v_max"].any()


# -- the note's table and the reports ------------------------------------------------------------

def test_note_table_puts_the_note_beside_our_values():
    from pipeline.claims.seed_note import NOTE_FILE, load_note, note_table
    from pipeline.reports.mechanism import note_rows

    note = load_note(NOTE_FILE)
    rec = {"spec_name": "nominal", "dominant": {"lag1": -0.999, "sigma": 0.7641},
           "theory": {"dt_mu_max": 3.84, "note_order": {"eig_dominant": {"real": -2.8098}},
                      "eig_dominant": {"real": -2.926}},
           "velocity_jump": {"median": 0.4245}}
    other = {"spec_name": "omega_ripple_dt010", "dominant": {"lag1": 0.9996},
             "theory": {"dt_mu_max": 1.28}}
    rows = {r.key: r for r in note_table(note, {"nominal": rec, "dt010": other})}
    lag = rows["dominant_lag1"].cells
    assert (lag[0].note, lag[0].ours) == (-0.92, -0.999)
    assert lag[0].rel_diff == pytest.approx((-0.999 + 0.92) / 0.92)
    assert lag[1].ours == 0.9996
    eig = rows["eig_dominant"].cells[0]
    assert eig.ours == -2.8098 and dict(eig.also) == {
        "simulator's update order (q moves with the updated velocity)": -2.926}
    assert rows["abs_cos"].cells[0].note is None and rows["abs_cos"].cells[0].rel_diff is None
    assert rows["provenance"].cells[0].ours is None  # not in this record: shown as —
    # The note's regime (issue 50): a reach column is compared with the note's nominal one.
    reach = {"spec_name": "omega_ripple_reach_note", "theory": {"dt_mu_max": 3.9}}
    rows = {r.key: r for r in note_table(note, {"nominal": rec, "reach_note": reach})}
    cells = rows["dt_mu_max"].cells
    assert [c.column for c in cells] == ["nominal", "dt010", "reach_note"]  # no reach_dt010
    assert (cells[2].note, cells[2].ours) == (3.84, 3.9)
    # The mechanism report shows the table for the note's own pair only (it reads the names),
    # with the note's regime when its runs are among the others.
    from pipeline.reports.mechanism import note_records

    name = SimpleNamespace
    got = note_records(name(**rec), name(**other), [])
    assert set(got) == {"nominal", "dt010"} and note_rows(got)
    assert not note_records(name(**rec), name(**{**other, "spec_name": "other"}), [])


@pytest.mark.slow
def test_reports_render_a_diverged_run_beside_a_pair(tmp_path):
    """A diverged log's analysis is listed with its growth and drawn in its own figure; it is
    kept out of the figures its runaway would swamp."""
    from pipeline.analysis.record import write_analysis
    from pipeline.analysis.stages import compare
    from pipeline.reports.render import render_all

    logs, out = tmp_path / "logs", tmp_path / "rep"
    run_spec(load_spec("omega_ripple_unbounded"), logs, raise_on_failure=False)
    write_analysis(analyze_log(verify_log(logs / "omega_ripple_unbounded" / "run.parquet")), out)
    spec = with_overrides(load_spec("nominal"), {"mission.duration": 6.0}, name="n6")
    dt010 = with_overrides(load_spec("omega_ripple_dt010"), {"mission.duration": 6.0},
                           name="d6")
    a, b = run_spec(spec, logs).path, run_spec(dt010, logs).path
    la, lb = verify_log(a), verify_log(b)
    rec = analyze_log(la)
    rec = replace(rec, comparison=compare(rec, analyze_log(lb), la.meta.spec, lb.meta.spec))
    write_analysis(rec, out)
    render_all(out)
    index = (out / "index.html").read_text()
    assert "diverged at step" in index and "growth_omega_ripple_unbounded.png" in index
    assert (out / "figures" / "growth_omega_ripple_unbounded.png").is_file()
    assert (out / "figures" / "rates.png").is_file()
    md = (out / "n6" / "mechanism.md").read_text()
    assert "## Robot card" in md
    assert "predicted μ_bus (D_b = 2 N·m·s/rad): the closed form D_b/I_zz,bus" in md
    assert "note's update order" in md or "note's fully" in md


def test_the_note_tables_cells_are_judged_by_the_claim_that_reads_them():
    """A cell's judgement comes from the claim whose check reads our value against the note's
    (threshold metric note:KEY.COLUMN), else a note-row claim reading it, else any; all of that
    claim's checks of the value make the tolerance. Round-off rows give no difference, and
    the open claims' reasons say where the missions differ."""
    from pipeline.claims.seed_note import NOTE_FILE, differences, load_note, note_table

    note = load_note(NOTE_FILE)
    rec = {"dominant": {"lag1": -0.999}, "theory": {"dt_mu_max": 3.84, "s_min_G": 0.096},
           "provenance": {"max_abs_s_min_G": 2.2e-16}}
    other = {"dominant": {"lag1": 0.9994}, "theory": {"dt_mu_max": 1.28},
             "provenance": {"max_abs_s_min_G": 0.0}}

    def chk(metric, op, thr, ok, tm=None, rel_tol=None):
        return {"metric": metric, "op": op, "threshold": thr, "ok": ok,
                "threshold_metric": tm, "rel_tol": rel_tol}

    claims = [
        {"id": "C3", "kind": "identity", "status": "PASS", "expect": "hold",
         "checks": [chk("nominal:theory.dt_mu_max", "gt", 2, True)]},
        {"id": "C17", "kind": "identity", "status": "PASS", "expect": "hold",
         "checks": [chk("nominal:theory.dt_mu_max", "close", 3.84, True,
                        "note:dt_mu_max.nominal", 0.02)]},
        {"id": "C1", "kind": "physics", "status": "PASS", "expect": "hold",
         "checks": [chk("nominal:dominant.lag1", "lt", -0.5, True)]},
        {"id": "C24", "kind": "note", "status": "PASS", "expect": "hold",
         "checks": [chk("nominal:dominant.lag1", "lt", -0.9, True)]},
        {"id": "C7", "kind": "software", "status": "PASS", "expect": "hold",
         "checks": [chk("nominal:provenance.max_abs_s_min_G", "le", 1e-12, True)]},
        {"id": "C25", "kind": "note", "status": "OPEN", "expect": "open", "reason": "q̄ moved.",
         "checks": [chk("nominal:theory.s_min_G", "gt", 0.01, True),
                    chk("nominal:theory.s_min_G", "lt", 0.05, False)]},
    ]
    rows = {r.key: r for r in note_table(note, {"nominal": rec, "dt010": other}, claims)}
    dt_mu = rows["dt_mu_max"].cells[0]
    assert (dt_mu.judgement.claim, dt_mu.judgement.tolerance, dt_mu.verdict) == (
        "C17", "within 2 %", "agrees")  # against the note's value, not C3's > 2
    assert rows["dominant_lag1"].cells[0].judgement.claim == "C24"  # the note row, not C1
    s_min = rows["s_min_G"].cells[0]
    assert (s_min.judgement.tolerance, s_min.verdict) == ("> 0.01 and < 0.05", "differs")
    prov = rows["provenance"].cells[0]
    assert prov.rel_diff is None and prov.verdict == "round-off"
    assert rows["abs_cos"].cells[0].verdict == "no number"
    assert rows["dt_mu_max"].cells[1].verdict == "not judged"  # no claim reads dt010's here
    assert differences(list(rows.values())) == [("C25", rows["s_min_G"].row, "q̄ moved.")]
