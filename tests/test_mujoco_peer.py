"""A MuJoCo peer of the pipeline's task transform and reduced dynamics (issue 22 item 4).

For both robots a short mission runs (``short_nominal``, ``short_servicer_nominal``) and, at
several logged steps, Γ (eq. 5), M̆ (eq. 10) and μ = eig(M̆⁻¹D̆) (eq. 21) are rebuilt here from
the logged q with MuJoCo's own dynamics and NumPy/SciPy, and compared with the pipeline's:
Γ rebuilt by the analysis (``rebuild_gamma``), the logged σ_min(Γ) and σ_min(J⊕), M̆ from the
robot's terms, the logged dt·μ_max, and M̆ and μ_max of the analysis at the representative step.

The peer takes nothing from Pinocchio. MuJoCo gives, per unit of its own qvel, the CoM velocity
in t (``mj_jacSubtreeCom``), the camera's linear and angular velocity in t (``mj_jacSite`` on
the seed's site, ``mj_jacBody`` on the servicer's camera link) and the joint-space inertia
(``mj_fullM``). Its free joint's qvel is [ṗ_b in t; ω_b in b], Pinocchio's v = [v_b; ω_b]
both in b (eq. 1), so qvel = T v with T = blkdiag(R_tb, I₃, I₆), and

    M = Tᵀ M_mj T,
    Γ = [ J_c T ;  [0 I₃ 0] ;  blkdiag(R_te, R_te)ᵀ [J_p − J_c ; J_r] T ]

straight from the definition ν = [v_c; ω_b; R_et (ṗ_e − ṗ_c); ω_e] (eq. 1), not through
the closed forms of eqs. 2–5 that the pipeline implements. Then Γ⁻¹ is the exact inverse (a
linear solve), M̂ = Γ⁻ᵀ M Γ⁻¹, M̆ = M̂[3:, 3:] and μ the generalised eigenvalues of (D̆, M̆), D̆
from the spec's gains (no derating in these specs).

Tolerances: round-off. Γ is compared to ULPS·ε·max|Γ|·(1 + |p|), |p| the largest position
in the scene (MuJoCo's Jacobians subtract world positions of that size); σ_min by Weyl's
inequality to 12× that (‖ΔΓ‖₂ ≤ ‖ΔΓ‖_F ≤ 12 max|ΔΓ|). M̆ and μ_max go through Γ⁻¹, whose
relative error is κ(Γ) times Γ's, so they are held to ULPS·ε·κ(Γ)·(1 + |p|) relative. The
comparison holds where the pipeline inverts J⊕ exactly: at steps with s_min_J at or above the
damped inverse's floor (eq. 6); a step below it is flagged and left out.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import scipy.linalg as sla

from pipeline.analysis.directions import rebuild_gamma
from pipeline.analysis.schema import CompleteRecord
from pipeline.analysis.stages import analyze_log
from pipeline.logs import read_columns, verify_log
from pipeline.paths import PROJECT_ROOT
from pipeline.sim import robot_file
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.robot_crosscheck import mujoco_model
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides

MISSIONS = ("short_nominal", "short_servicer_nominal")
N_STEPS = 8  # logged steps compared per mission, evenly spaced, plus the representative one
ULPS = 256
EPS = np.finfo(float).eps


@dataclass
class PeerRun:
    spec: object
    robot: GiordanoRobot
    mj: object
    cols: dict
    steps: list[int]
    below_floor: list[int]
    record: CompleteRecord


# The tests on a mission's log are slow: the fixture runs a mission of its own per robot.
@pytest.fixture(scope="module", params=MISSIONS)
def peer_run(request, tmp_path_factory) -> PeerRun:
    spec = load_spec(request.param)
    path = run_spec(spec, tmp_path_factory.mktemp(request.param)).path
    robot = GiordanoRobot(spec)
    cols = read_columns(path, ["q", "v", "s_min_J", "s_min_G", "kappa_G", "dt_mu_max"])
    n = len(cols["q"])
    record = analyze_log(verify_log(path))
    steps = sorted({*np.linspace(0, n - 1, N_STEPS).astype(int).tolist(),
                    record.theory.step})
    below = [k for k in steps if cols["s_min_J"][k] < robot.floor]
    return PeerRun(spec, robot, mujoco_model(spec.robot_path), cols,
                   [k for k in steps if k not in below], below, record)


@dataclass
class Peer:
    gamma: np.ndarray  # Γ, 12×12 (eq. 5); (6 + n) square for a redundant arm (eq. 37c)
    M: np.ndarray  # joint-space inertia in Pinocchio's velocity convention (eq. 1)
    M_hat: np.ndarray  # Γ⁻ᵀ M Γ⁻¹ (eq. 8)
    M_breve: np.ndarray  # M̂[3:, 3:] (eq. 10)
    mu: np.ndarray  # eig(M̆⁻¹ D̆), ascending (eq. 21)
    s_min_J: float  # σ_min(J⊕) (eq. 19)
    s_min_G: float  # σ_min(Γ)
    kappa_G: float
    lever: float  # 1 + the largest |position| in the scene, m


def mujoco_peer(mj, camera: str, q: np.ndarray, D_breve: np.ndarray,
                joints: tuple[str, ...] | None = None, locked: dict[str, float] | None = None,
                z_ref: np.ndarray | None = None) -> Peer:
    """Γ, M, M̂, M̆ and μ at the logged q from MuJoCo alone (see the module docstring).

    ``joints``: the arm joints of the pipeline's model by name, when MuJoCo's file has more
    (joints the spec locks, at their ``locked`` values: their dofs held still are left out of
    M and the Jacobians). A redundant arm's null-space rows follow from their definition
    (eq. 37): H the inertia of w = [ω_b; q̇] at a still CoM (from MuJoCo's CoM Jacobian), z
    SciPy's null space of J⊕, its sign that of ``z_ref``, ν_n = (zᵀH_qq z)⁻¹ zᵀ H_q· w."""
    d = mujoco.MjData(mj)
    free = int(np.flatnonzero(mj.jnt_type == mujoco.mjtJoint.mjJNT_FREE)[0])
    assert mj.jnt_qposadr[free] == 0 and mj.jnt_dofadr[free] == 0
    qpos = np.zeros(mj.nq)
    qpos[:7] = np.concatenate([q[:3], q[[6, 3, 4, 5]]])  # quat (x,y,z,w) → (w,x,y,z)
    if joints is None:
        assert mj.nq == 13
        qpos[7:] = q[7:]
        dofs = np.arange(mj.nv)
    else:
        ids = [mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, name) for name in joints]
        qpos[mj.jnt_qposadr[ids]] = q[7:]
        for name, value in (locked or {}).items():
            qpos[mj.jnt_qposadr[mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, name)]] = value
        dofs = np.r_[np.arange(6), mj.jnt_dofadr[ids]]
    d.qpos[:] = qpos
    mujoco.mj_forward(mj, d)
    bus = mj.jnt_bodyid[free]
    R_tb = d.xmat[bus].reshape(3, 3)
    nv = len(dofs)
    T = np.eye(nv)
    T[:3, :3] = R_tb  # qvel = T v
    M_mj = np.zeros((mj.nv, mj.nv))
    mujoco.mj_fullM(mj, d, M_mj)
    M = T.T @ M_mj[np.ix_(dofs, dofs)] @ T
    J_c, J_p, J_r = np.zeros((3, mj.nv)), np.zeros((3, mj.nv)), np.zeros((3, mj.nv))
    mujoco.mj_jacSubtreeCom(mj, d, J_c, bus)
    site = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_SITE, camera)
    if site >= 0:
        mujoco.mj_jacSite(mj, d, J_p, J_r, site)
        R_te = d.site_xmat[site].reshape(3, 3)
    else:
        body = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_BODY, camera)
        mujoco.mj_jacBody(mj, d, J_p, J_r, body)
        R_te = d.xmat[body].reshape(3, 3)
    J_c, J_p, J_r = J_c[:, dofs] @ T, J_p[:, dofs] @ T, J_r[:, dofs] @ T
    rows_b = np.hstack([np.zeros((3, 3)), np.eye(3), np.zeros((3, nv - 6))])
    gamma = np.vstack([J_c, rows_b, np.vstack([R_te.T @ (J_p - J_c), R_te.T @ J_r])])
    J_oplus = gamma[6:12, 6:]
    s_min_J = float(np.linalg.svd(J_oplus, compute_uv=False)[-1])
    if nv > 12:
        W = np.vstack([-np.linalg.solve(J_c[:, 0:3], J_c[:, 3:]), np.eye(nv - 3)])
        H = W.T @ M @ W
        Z = sla.null_space(J_oplus)
        Z *= np.sign(Z.T @ z_ref)[:, 0] if z_ref is not None else 1.0
        Lam = Z.T @ H[3:, 3:] @ Z
        gamma = np.vstack([gamma, np.hstack([np.zeros((Z.shape[1], 3)),
                                             np.linalg.solve(Lam, Z.T @ H[3:, :])])])
        # The pipeline's σ_min(J⊕) of a redundant arm is its H_qq-weighted one (eq. 37d).
        L = np.linalg.cholesky(H[3:, 3:])
        s_min_J = float(np.linalg.svd(J_oplus @ np.linalg.inv(L).T, compute_uv=False)[-1])
    gamma_inv = np.linalg.solve(gamma, np.eye(nv))
    M_hat = gamma_inv.T @ M @ gamma_inv
    M_breve = 0.5 * (M_hat[3:, 3:] + M_hat[3:, 3:].T)
    s = np.linalg.svd(gamma, compute_uv=False)
    return Peer(gamma=gamma, M=M, M_hat=M_hat, M_breve=M_breve,
                mu=sla.eigh(D_breve, M_breve, eigvals_only=True), s_min_J=s_min_J,
                s_min_G=float(s[-1]), kappa_G=float(s[0] / s[-1]),
                lever=1.0 + float(np.max(np.abs(d.xpos))))


def d_breve(spec, null_space_dim: int = 0) -> np.ndarray:
    """D̆ = blockdiag(d_b I₃, d_p I₃, d_o I₃, d_n I_k) from the spec's gains (eqs. 13, 37f),
    not derated."""
    g = spec.controller.gains
    assert not spec.controller.base.derate.gain
    d = np.repeat([g.bus.D, g.cam_pos.D, g.cam_ori.D], 3)
    if null_space_dim:
        d = np.r_[d, [spec.controller.null_space.D] * null_space_dim]
    return np.diag(d)


def _peers(run: PeerRun, steps) -> dict[int, Peer]:
    D = d_breve(run.spec)
    return {k: mujoco_peer(run.mj, run.spec.robot.camera_frame, run.cols["q"][k], D)
            for k in steps}


@pytest.mark.slow
def test_the_compared_steps_are_above_the_floor(peer_run):
    """Every compared step inverts J⊕ exactly; any below the floor is flagged, not compared."""
    assert len(peer_run.steps) >= N_STEPS - 1, peer_run.below_floor
    assert peer_run.record.theory.at_or_above_floor
    for k, p in _peers(peer_run, peer_run.steps).items():
        assert p.s_min_J >= peer_run.robot.floor, k


@pytest.mark.slow
def test_gamma_and_its_conditioning_match_mujoco(peer_run):
    """Γ rebuilt by the analysis (eq. 5) against the peer's; logged σ_min(Γ), κ(Γ), σ_min(J⊕)."""
    r = peer_run
    gammas = rebuild_gamma(r.robot, r.cols["q"][r.steps])
    for k, G in zip(r.steps, gammas, strict=True):
        p = _peers(r, [k])[k]
        tol = ULPS * EPS * np.max(np.abs(p.gamma)) * p.lever
        np.testing.assert_allclose(G, p.gamma, rtol=0, atol=tol, err_msg=f"step {k}")
        assert abs(r.cols["s_min_G"][k] - p.s_min_G) <= 12 * tol, k
        assert abs(r.cols["s_min_J"][k] - p.s_min_J) <= 12 * tol, k
        # δκ/κ ≤ δσ_max/σ_max + δσ_min/σ_min ≤ 24 tol / σ_min
        assert abs(r.cols["kappa_G"][k] / p.kappa_G - 1) <= 24 * tol / p.s_min_G, k


@pytest.mark.slow
def test_mass_matrix_and_reduced_inertia_match_mujoco(peer_run):
    """M (eq. 1), M̂'s CoM block m I₃ (eq. 8) and M̆ (eq. 10) from the robot's terms."""
    r = peer_run
    m = float(r.mj.body_mass.sum())
    for k, p in _peers(r, r.steps).items():
        T = r.robot.terms(r.cols["q"][k], r.cols["v"][k])
        M = np.triu(T.M) + np.triu(T.M, 1).T
        np.testing.assert_allclose(M, p.M, rtol=0, atol=ULPS * EPS * np.max(np.abs(M)) * p.lever,
                                   err_msg=f"step {k}")
        rel = ULPS * EPS * p.kappa_G * p.lever
        np.testing.assert_allclose(p.M_hat[:3, :3], m * np.eye(3), rtol=0, atol=rel * m)
        np.testing.assert_allclose(T.reduced_inertia, p.M_breve, rtol=0,
                                   atol=rel * np.max(np.abs(p.M_breve)), err_msg=f"step {k}")


@pytest.mark.slow
def test_mu_max_matches_mujoco(peer_run):
    """The logged dt·μ_max (eq. 21) against the peer's generalised eigenvalues."""
    r = peer_run
    dt = r.spec.mission.dt
    for k, p in _peers(r, r.steps).items():
        rel = ULPS * EPS * p.kappa_G * p.lever
        assert abs(r.cols["dt_mu_max"][k] / (dt * p.mu[-1]) - 1) <= rel, k


@pytest.mark.slow
def test_the_representative_step_matches_mujoco(peer_run):
    """The analysis' theory at its representative step: M̆ and μ_max (eqs. 10, 21)."""
    r = peer_run
    th = r.record.theory
    p = _peers(r, [th.step])[th.step]
    rel = ULPS * EPS * p.kappa_G * p.lever
    np.testing.assert_allclose(np.array(th.M_breve), p.M_breve, rtol=0,
                               atol=rel * np.max(np.abs(p.M_breve)))
    assert abs(th.mu_max / p.mu[-1] - 1) <= rel


def test_the_peer_sees_the_old_seed_camera(monkeypatch):
    """The peer can fail: on the seed file before issue 22 (the camera site inside the
    jointless payload), Pinocchio's Γ and M̆, the loader's cross-parse bypassed, are those of
    another camera than MuJoCo's: at the nominal q̄ of that time, σ_min(Γ) 0.1 % and M̆ 79 %
    away (round-off is 1e-14)."""
    old = PROJECT_ROOT / "tests" / "fixtures" / "seed_ur3_box_issue2534.xml"
    monkeypatch.setattr(robot_file, "crosscheck_robot_file",
                        lambda *a: SimpleNamespace(notes=[]))  # bypassed: nothing to say
    spec = with_overrides(load_spec("nominal"), {
        "robot.file": str(old), "robot.q_bar": [0.0, -0.367, -1.763, -0.993, -5.95, 0.0]})
    robot = GiordanoRobot(spec)
    q = robot.deterministic_q_init()
    T = robot.terms(q, np.zeros(12))
    p = mujoco_peer(mujoco_model(old), "camera", q, d_breve(spec))
    assert T.s_min_J >= robot.floor
    assert abs(T.s_min_G / p.s_min_G - 1) > 1e-4
    assert np.max(np.abs(T.reduced_inertia - p.M_breve)) > 0.5 * np.max(np.abs(p.M_breve))
    M = np.triu(T.M) + np.triu(T.M, 1).T
    np.testing.assert_allclose(M, p.M, rtol=0, atol=1e-12)  # the bodies agree: M does


def test_the_redundant_servicer_matches_mujoco(tmp_path):
    """The 7-DoF servicer (issue 34): at logged steps of a short mission, Γ rebuilt by the
    analysis' kernel (eq. 37c, its null-space row included), M̆ from the robot's terms, the
    logged σ_min of the weighted J⊕ and dt·μ_max (the null-space mode among them) against the
    peer, which also finds M̂ block diagonal (the null-space velocity dynamically consistent,
    eq. 37d) from MuJoCo's own inertia."""
    spec = load_spec("short_panda_nominal")
    path = run_spec(spec, tmp_path).path
    robot = GiordanoRobot(spec)
    cols = read_columns(path, ["q", "v", "s_min_J", "dt_mu_max"])
    steps = np.linspace(0, len(cols["q"]) - 1, 5).astype(int)
    mj = mujoco_model(spec.robot_path)
    D = d_breve(spec, robot.shape.null_space_dim)
    gammas = rebuild_gamma(robot, cols["q"][steps])
    for k, G in zip(steps, gammas, strict=True):
        T = robot.terms(cols["q"][k], cols["v"][k])
        assert cols["s_min_J"][k] >= robot.floor, k  # the inverse is exact: comparable
        p = mujoco_peer(mj, spec.robot.camera_frame, cols["q"][k], D, robot.shape.joints,
                        spec.robot.locked_joints, z_ref=T.gamma_inv[6:, 12:])
        assert p.gamma.shape == (13, 13)
        tol = ULPS * EPS * np.max(np.abs(p.gamma)) * p.lever
        np.testing.assert_allclose(G, p.gamma, rtol=0, atol=tol, err_msg=f"step {k}")
        rel = ULPS * EPS * p.kappa_G * p.lever
        scale = np.max(np.abs(p.M_breve))
        np.testing.assert_allclose(p.M_breve[:9, 9:], 0.0, rtol=0, atol=rel * scale)
        np.testing.assert_allclose(T.reduced_inertia, p.M_breve, rtol=0, atol=rel * scale,
                                   err_msg=f"step {k}")
        assert abs(cols["s_min_J"][k] - p.s_min_J) <= 12 * tol, k
        assert abs(cols["dt_mu_max"][k] / (spec.mission.dt * p.mu[-1]) - 1) <= rel, k
        # The block check can fail: the plain null-space speed ν_n = z̃ᵀq̇ (not weighted by
        # the inertia) couples the null space to the task in M̂.
        plain = p.gamma.copy()
        plain[12] = np.r_[np.zeros(6), T.gamma_inv[6:, 12]]
        plain_inv = np.linalg.inv(plain)
        cross = (plain_inv.T @ p.M @ plain_inv)[3:12, 12]
        assert np.max(np.abs(cross)) > 1e3 * rel * scale, k
