"""Checks of the model equations (eqs. 1–11, 19, 20): kinematics against finite differences
of the placements, inverses against NumPy, the transformed dynamics against their identities.
"""

from __future__ import annotations

import inspect

import numpy as np
import pinocchio as pin

from pipeline.verify.checks_base import (
    Outcome,
    check,
    code,
    fmt,
    maxdiff,
    near_singular_q,
    random_state,
    rng,
    robot,
    spec,
)

H = 1e-6  # central-difference step: truncation O(h²) ~ 1e-12, rounding ~ 1e-16·10 m / h ~ 1e-9
FD_TOL = 1e-6


def _pose(q: np.ndarray) -> dict[str, np.ndarray]:
    """Placements at q, copied (Terms may share Pinocchio's buffers)."""
    r = robot()
    T = r.terms(q, np.zeros(r.model.nv), dynamics=False)
    return {k: np.array(getattr(T, k), copy=True) for k in ("R_tb", "p_b", "p_c", "R_te", "p_e")}


def _fd_velocities(q: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    """Time derivatives along q(t) = q ⊕ t v by central differences, independent of Γ."""
    model = robot().model
    P, M = _pose(pin.integrate(model, q, H * v)), _pose(pin.integrate(model, q, -H * v))
    C = _pose(q)
    pd = {k: (P[k] - M[k]) / (2 * H) for k in ("p_c", "p_e", "p_b")}
    w_b = pin.log3(M["R_tb"].T @ P["R_tb"]) / (2 * H)  # body-frame rates
    w_e = pin.log3(M["R_te"].T @ P["R_te"]) / (2 * H)
    R_et = C["R_te"].T
    return {"v_c": pd["p_c"], "w_b": w_b, "nu_e": np.r_[R_et @ (pd["p_e"] - pd["p_c"]), w_e],
            "v_e": R_et @ pd["p_e"], "w_e": w_e}


def _state_text(salt: int) -> str:
    return f"random (q, v), seed {salt}, σ_min(J⊕) ≥ 2·floor; central differences h = {H:g}"


@check("1", "camera twist [v_e; ω_e] = J_e v (LOCAL) vs finite differences of the placement",
       "pipeline.sim.robot.GiordanoRobot.terms")
def _camera_twist() -> Outcome:
    from pipeline.sim.robot import LOCAL  # the frame convention the robot code uses

    q, v = random_state(1)
    r = robot()
    J_e = np.array(pin.computeFrameJacobian(r.model, r.data, q, r.frame_id, LOCAL), copy=True)
    fd = _fd_velocities(q, v)
    return Outcome(_state_text(1) + "; J_e in the robot code's frame convention",
                   maxdiff(J_e @ v, np.r_[fd["v_e"], fd["w_e"]]), FD_TOL)


@check("2", "CoM velocity from joints alone, R_tb J̄_v q̇, vs finite differences of p_c",
       "pipeline.sim.robot.Terms.J_bar_v",
       "pipeline.sim.task_transform.kinematic_terms")
def _j_bar_v() -> Outcome:
    q, v = random_state(2)
    v[:6] = 0.0  # bus still: only the joints move
    T = robot().terms(q, np.zeros(12), dynamics=False)
    pred = np.array(T.R_tb) @ np.array(T.J_bar_v) @ v[6:]
    return Outcome(_state_text(2) + ", bus velocity 0", maxdiff(pred, _fd_velocities(q, v)["v_c"]),
                   FD_TOL)


@check("3", "camera twist about the CoM from joints alone, J⊕ q̇, vs finite differences",
       "pipeline.sim.robot.Terms.J_oplus",
       "pipeline.sim.task_transform.kinematic_terms")
def _j_oplus() -> Outcome:
    q, v = random_state(3)
    v[:6] = 0.0
    T = robot().terms(q, np.zeros(12), dynamics=False)
    pred = np.array(T.J_oplus) @ v[6:]
    return Outcome(_state_text(3) + ", bus velocity 0", maxdiff(pred, _fd_velocities(q, v)["nu_e"]),
                   FD_TOL)


@check("4", "camera twist about the CoM from the bus rate alone, G_ωb ω_b, vs finite differences",
       "pipeline.sim.robot.Terms.G_wb",
       "pipeline.sim.task_transform.kinematic_terms")
def _g_wb() -> Outcome:
    q, v = random_state(4)
    v[6:] = 0.0  # joints still
    T = robot().terms(q, np.zeros(12), dynamics=False)
    pred = np.array(T.G_wb) @ v[3:6]
    return Outcome(_state_text(4) + ", joint rates 0", maxdiff(pred, _fd_velocities(q, v)["nu_e"]),
                   FD_TOL)


@check("5", "Γ rows: ν = Γ v = [v_c; ω_b; ν_e⊕] vs finite differences of p_c, R_tb, p_e, R_te",
       "pipeline.sim.robot.gamma_matrix")
def _gamma_rows() -> Outcome:
    q, v = random_state(5)
    nu = robot().terms(q, np.zeros(12), dynamics=False).gamma @ v
    fd = _fd_velocities(q, v)
    d = [maxdiff(nu[0:3], fd["v_c"]), maxdiff(nu[3:6], fd["w_b"]), maxdiff(nu[6:], fd["nu_e"])]
    return Outcome(_state_text(5), max(d), FD_TOL,
                   f"per row block (v_c, ω_b, ν_e⊕): {', '.join(fmt(x) for x in d)}")


@check("6", "closed-form Γ⁻¹ vs numpy.linalg.inv(Γ), away from the singularity",
       "pipeline.sim.robot.gamma_inverse")
def _gamma_inverse() -> Outcome:
    q, _ = random_state(6)
    T = robot().terms(q, np.zeros(12), dynamics=False)
    return Outcome(_state_text(6) + f" (σ_min(J⊕) = {fmt(T.s_min_J)})",
                   maxdiff(T.gamma_inv, np.linalg.inv(np.array(T.gamma))), 1e-9)


def _tikhonov(J: np.ndarray, floor: float, damping: float) -> np.ndarray:
    """J⁺ = (JᵀJ + λ²I)⁻¹ Jᵀ with λ² of eq. 6, σ_min from numpy.linalg.norm(J, -2)."""
    smin = np.linalg.norm(J, -2)
    lam2 = damping**2 * (1 - (smin / floor) ** 2) if smin < floor else 0.0
    return np.linalg.solve(J.T @ J + lam2 * np.eye(J.shape[1]), J.T)


@check("6", "damped J⊕ pseudo-inverse vs the Tikhonov form (JᵀJ + λ²I)⁻¹Jᵀ, above and below "
       "the floor", "pipeline.sim.robot.damped_pinv")
def _damped_pinv() -> Outcome:
    damped_pinv = code("pipeline.sim.robot.damped_pinv", "pipeline.sim.task_transform.damped_pinv")
    r, g = robot(), rng(60)
    diffs, smins = [], []
    for smin in (0.5, r.floor * 0.25):  # exact inverse, then damped
        U, _ = np.linalg.qr(g.standard_normal((6, 6)))
        V, _ = np.linalg.qr(g.standard_normal((6, 6)))
        J = U @ np.diag([1.5, 1.2, 1.0, 0.8, 0.6, smin]) @ V.T
        J_inv, s, _ = damped_pinv(J, r.floor, r.damping)
        diffs.append(maxdiff(J_inv, _tikhonov(J, r.floor, r.damping)))
        smins.append(s)
    return Outcome(f"random 6×6 J with σ_min = {fmt(smins[0])} and {fmt(smins[1])} (floor "
                   f"{r.floor:g}, damping {r.damping:g})", max(diffs), 1e-9)


@check("6", "damped reconstruction v = Γ⁻¹ν near the singularity vs a block solve with the "
       "Tikhonov J⊕⁺", "pipeline.sim.robot.gamma_inverse")
def _damped_reconstruction() -> Outcome:
    r = robot()
    q = near_singular_q()
    T = r.terms(q, np.zeros(12), dynamics=False)
    nu = rng(61).standard_normal(12)
    R_tb, p_bc = np.array(T.R_tb), np.array(T.p_bc)
    J_bar_v, G_wb, J = np.array(T.J_bar_v), np.array(T.G_wb), np.array(T.J_oplus)
    w_b = nu[3:6]
    qd = _tikhonov(J, r.floor, r.damping) @ (nu[6:] - G_wb @ w_b)
    v_b = R_tb.T @ nu[0:3] + np.cross(p_bc, w_b) - J_bar_v @ qd
    return Outcome(f"arm at q̄ with a straight elbow, σ_min(J⊕) = {fmt(T.s_min_J)} < floor; "
                   "random ν", maxdiff(T.gamma_inv @ nu, np.r_[v_b, w_b, qd]), 1e-9)


@check("7", "Γ̇ vs the central difference (Γ(q ⊕ hv) − Γ(q ⊖ hv))/2h",
       "pipeline.sim.robot.gamma_time_derivative",
       "pipeline.sim.task_transform.gamma_time_derivative",
       "pipeline.sim.robot.Terms.gamma_dot")
def _gamma_dot() -> Outcome:
    q, v = random_state(7)
    r = robot()
    G = [np.array(r.terms(pin.integrate(r.model, q, s * H * v), np.zeros(12),
                          dynamics=False).gamma) for s in (1, -1)]
    return Outcome(_state_text(7), maxdiff(r.terms(q, v).gamma_dot, (G[0] - G[1]) / (2 * H)),
                   FD_TOL)


@check("8", "M̂ = Γ⁻ᵀMΓ⁻¹: CoM block − m I₃, cross blocks, and ½vᵀMv − ½νᵀM̂ν",
       "pipeline.sim.robot.Terms.M_hat", "pipeline.sim.task_transform.transformed_dynamics")
def _m_hat_structure() -> Outcome:
    q, v = random_state(8)
    r = robot()
    T = r.terms(q, v)
    Mh = np.array(T.M_hat)
    nu = np.array(T.gamma) @ v
    d = [maxdiff(Mh[:3, :3], r.mass * np.eye(3)), float(np.abs(Mh[:3, 3:]).max()),
         float(np.abs(Mh[3:, :3]).max()), abs(0.5 * v @ T.M @ v - 0.5 * nu @ Mh @ nu)]
    return Outcome(_state_text(8) + f", m = {r.mass:g} kg", max(d), 1e-9,
                   "CoM block, upper and lower cross blocks, energy: "
                   + ", ".join(fmt(x) for x in d))


def _c_hat_independent(q, v):
    """Ĉ from Pinocchio's C, numpy's inverse of Γ and a central-difference Γ̇."""
    r = robot()
    G = [np.array(r.terms(pin.integrate(r.model, q, s * H * v), np.zeros(12),
                          dynamics=False).gamma) for s in (1, -1)]
    Gd = (G[0] - G[1]) / (2 * H)
    T = r.terms(q, v)
    Gi = np.linalg.inv(np.array(T.gamma))
    M = np.array(T.M)
    C = np.array(pin.computeCoriolisMatrix(r.model, r.data, q, v))
    return Gi.T @ (C - M @ Gi @ Gd) @ Gi, r.terms(q, v)


def _m_hat_dot(q, v):
    r = robot()
    Mh = [np.array(r.terms(pin.integrate(r.model, q, s * H * v), np.zeros(12)).M_hat)
          for s in (1, -1)]
    return (Mh[0] - Mh[1]) / (2 * H)


@check("9", "Ĉ vs Γ⁻ᵀ(C − MΓ⁻¹Γ̇)Γ⁻¹ with numpy's Γ⁻¹ and a finite-difference Γ̇; "
       "M̂̇ − 2Ĉ skew", "pipeline.sim.robot.Terms.C_hat",
       "pipeline.sim.task_transform.transformed_dynamics")
def _c_hat() -> Outcome:
    q, v = random_state(9)
    Ch_ind, T = _c_hat_independent(q, v)
    S = _m_hat_dot(q, v) - 2 * np.array(T.C_hat)
    d = [maxdiff(T.C_hat, Ch_ind), float(np.abs(S + S.T).max())]
    return Outcome(_state_text(9), max(d), 1e-5,
                   f"Ĉ vs independent: {fmt(d[0])}; (M̂̇ − 2Ĉ) + (M̂̇ − 2Ĉ)ᵀ: {fmt(d[1])}")


@check("10", "M̆ = M̂[3:, 3:] vs the block of Γ⁻ᵀMΓ⁻¹ with numpy's inverse",
       "pipeline.sim.robot.Terms.reduced_inertia")
def _m_breve() -> Outcome:
    q, v = random_state(10)
    T = robot().terms(q, v)
    Gi = np.linalg.inv(np.array(T.gamma))
    ref = (Gi.T @ np.array(T.M) @ Gi)[3:, 3:]
    return Outcome(_state_text(10), maxdiff(T.reduced_inertia, ref), 1e-9)


@check("11", "C̆, C_c vs blocks of the independent Ĉ; M̆̇ − 2C̆ skew-symmetric",
       "pipeline.sim.robot.Terms.reduced_coriolis")
def _c_breve() -> Outcome:
    q, v = random_state(11)
    Ch_ind, T = _c_hat_independent(q, v)
    S = _m_hat_dot(q, v)[3:, 3:] - 2 * np.array(T.reduced_coriolis)
    d = [maxdiff(T.reduced_coriolis, Ch_ind[3:, 3:]), maxdiff(T.com_coupling, Ch_ind[3:, :3]),
         float(np.abs(S + S.T).max())]
    return Outcome(_state_text(11), max(d), 1e-5,
                   "C̆, C_c, skew residual: " + ", ".join(fmt(x) for x in d))


@check("19", "one-pass (σ_min, κ) vs numpy.linalg.norm(A, −2) and numpy.linalg.cond(A), from "
       "the identity and (the simulator's) from a nearby matrix's right vectors; one SVD call; "
       "NaN → None", "pipeline.sim.sampling.sigma_min_and_cond",
       "pipeline.sim.sampling.conditioning_from")
def _sigma_min_and_cond() -> Outcome:
    from pipeline.sim import sampling

    # One pass: the compiled function's source makes exactly one decomposition call.
    src = inspect.getsource(getattr(sampling.sigma_min_and_cond, "py_func",
                                    sampling.sigma_min_and_cond))
    calls = src.count("singular_values(") + src.count("svd(")
    if calls != 1:
        raise AssertionError(f"{calls} SVD calls, expected one pass")
    g = rng(19)
    diffs = []
    for shape in ((12, 12), (6, 6), (9, 4)):
        A = g.standard_normal(shape)
        smin, kappa = sampling.sigma_min_and_cond(A)
        ref_s = np.linalg.norm(A, -2)
        diffs += [abs(smin - ref_s) / ref_s, abs(kappa - np.linalg.cond(A, 2)) / kappa]
        if shape[0] == shape[1]:  # the step's chain: the next matrix from this one's vectors
            _, _, Vt = sampling.conditioning_from(A, np.empty((0, 0)))
            B = A + 1e-3 * g.standard_normal(shape)
            smin, kappa, _ = sampling.conditioning_from(B, Vt)
            ref_s = np.linalg.norm(B, -2)
            diffs += [abs(smin - ref_s) / ref_s, abs(kappa - np.linalg.cond(B, 2)) / kappa]
    bad = A.copy()
    bad[0, 0] = np.nan
    if sampling.sigma_min(bad) is not None:
        raise AssertionError("sigma_min of a NaN matrix is not None")
    return Outcome("random 12×12, 6×6, 9×4 matrices (relative difference)", max(diffs), 1e-12)


def _ramp(sigma, low, high, floor):
    """The γ ramp as a clamped linear interpolation (numpy.interp)."""
    return float(np.interp(sigma, [low, high], [floor, 1.0]))


@check("20", "γ ramp scale_by_svd vs numpy.interp over [low, high] → [floor, 1], inside, at the "
       "knees and outside", "pipeline.sim.sampling.scale_by_svd")
def _gamma_ramp() -> Outcome:
    from pipeline.sim.sampling import scale_by_svd

    g = rng(20)
    low, high, floor = 0.01, 0.05, 0.3
    sig = np.r_[g.uniform(-0.02, 0.08, 200), low, high, 0.0, 1.0]
    d = max(abs(scale_by_svd(s, low, high, floor) - _ramp(s, low, high, floor)) for s in sig)
    return Outcome(f"{sig.size} σ in [−0.02, 0.08] incl. low, high (low {low}, high {high}, "
                   f"floor {floor})", d, 1e-15)


@check("20", "conditioning_scale(s_min_G) vs the ramp with controller.base.conditioning knobs",
       "pipeline.sim.base_controller.conditioning_scale")
def _conditioning_scale() -> Outcome:
    from pipeline.sim.base_controller import conditioning_scale

    c = spec().controller
    k = c.base.conditioning
    sig = np.linspace(0, 2 * k.high, 101)
    d = max(abs(conditioning_scale(s, c) - _ramp(s, k.low, k.high, k.floor)) for s in sig)
    return Outcome(f"101 s_min_G in [0, {2 * k.high:g}], spec {spec().name} (low {k.low}, "
                   f"high {k.high}, floor {k.floor})", d, 1e-15)


# This module's checks, in the order the cross-check shows them: an explicit list, read by
# :func:`pipeline.verify.suite.all_checks` (no registration by import).
CHECKS = (
    _camera_twist,
    _j_bar_v,
    _j_oplus,
    _g_wb,
    _gamma_rows,
    _gamma_inverse,
    _damped_pinv,
    _damped_reconstruction,
    _gamma_dot,
    _m_hat_structure,
    _c_hat,
    _m_breve,
    _c_breve,
    _sigma_min_and_cond,
    _gamma_ramp,
    _conditioning_scale,
)
