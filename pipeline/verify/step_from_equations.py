"""One controller step computed from docs/equations.md alone, with NumPy, SciPy and Pinocchio:
the independent side of the checks of the simulator's step (eq. 16's check in checks_step.py,
tests/test_log_row.py).

It shares none of the package's numerical helpers: Γ is assembled from Pinocchio's CoM and
camera Jacobians (eq. 1's definition of ν), Γ⁻¹ from Γ's blocks (eq. 6), Γ̇ by central
differences of Γ along v, attitude errors from SciPy's quaternions, μ from SciPy's generalized
symmetric eigensolver, coverage from a per-point test of eq. 18. Only the inputs come from the
package: the spec, the target's sampled points and the references at τ_k (the guidance, eq. 17,
has its own check).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import scipy.linalg
from scipy.spatial.transform import Rotation

from pipeline.sim.robot_file import camera_frame_id, load_spec_robot
from pipeline.spec import Spec


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


class Robot:
    """A fresh Pinocchio model of the spec's robot, and Γ of eq. 1 from its definition."""

    def __init__(self, spec: Spec):
        self.model = load_spec_robot(spec)
        self.data = self.model.createData()
        self.fid = camera_frame_id(self.model, spec.robot.camera_frame)
        self.mass = sum(inertia.mass for inertia in self.model.inertias)

    def placements(self, q):
        pin.framesForwardKinematics(self.model, self.data, q)
        oMb, oMe = self.data.oMi[1], self.data.oMf[self.fid]
        return (oMb.rotation.copy(), oMb.translation.copy(), oMe.rotation.copy(),
                oMe.translation.copy(), pin.centerOfMass(self.model, self.data, q).copy())

    def gamma(self, q) -> np.ndarray:
        """ν = Γ v with ν = [ṗ_c; ω_b; R_et (ṗ_e − ṗ_c); ω_e] (eq. 1): ṗ_c from the CoM
        Jacobian (t frame), the camera twist from its LOCAL Jacobian, R_et ṗ_e = v_e."""
        R_te = self.placements(q)[2]
        J_c = pin.jacobianCenterOfMass(self.model, self.data, q)
        J_e = pin.computeFrameJacobian(self.model, self.data, q, self.fid, pin.LOCAL)
        G = np.zeros((12, 12))
        G[0:3] = J_c
        G[3:6, 3:6] = np.eye(3)
        G[6:9] = J_e[:3] - R_te.T @ J_c
        G[9:12] = J_e[3:]
        return G

    def dynamics(self, q, v):
        M = pin.crba(self.model, self.data, q)
        M = np.triu(M) + np.triu(M, 1).T  # Pinocchio may fill the upper triangle only
        C = pin.computeCoriolisMatrix(self.model, self.data, q, v).copy()
        return M, C


def _gamma_inverse(G: np.ndarray, floor: float, damping: float):
    """Γ⁻¹ of eq. 6 from Γ's blocks, with the damped J⊕⁺; J⊕ = Γ[6:, 6:] and its σ."""
    R_tb, J_oplus, G_wb = G[0:3, 0:3], G[6:, 6:], G[6:, 3:6]
    S_pbc = -R_tb.T @ G[0:3, 3:6]  # [p_bc]×
    J_bar_v = R_tb.T @ G[0:3, 6:]
    U, s, Vt = np.linalg.svd(J_oplus)
    lam2 = damping**2 * (1 - (s[-1] / floor) ** 2) if s[-1] < floor else 0.0
    Jp = Vt.T @ np.diag(s / (s**2 + lam2)) @ U.T
    Gi = np.zeros((12, 12))
    Gi[0:3, 0:3] = R_tb.T
    Gi[0:3, 3:6] = S_pbc + J_bar_v @ Jp @ G_wb
    Gi[0:3, 6:] = -J_bar_v @ Jp
    Gi[3:6, 3:6] = np.eye(3)
    Gi[6:, 3:6] = -Jp @ G_wb
    Gi[6:, 6:] = Jp
    return Gi, s


def _attitude_error(R: np.ndarray, R_des: np.ndarray):
    """2ε and E = ηI + [ε]× of q_err = quat(R_desᵀ R) = (ε, η), η ≥ 0 (eq. 14)."""
    x, y, z, w = Rotation.from_matrix(R_des.T @ R).as_quat()  # SciPy: scalar last
    eps, eta = np.array([x, y, z]), w
    if eta < 0:
        eps, eta = -eps, -eta
    return 2 * eps, eta * np.eye(3) + _skew(eps)


def _sat(x: np.ndarray, bound: float):
    n = np.linalg.norm(x)
    return (x * bound / n, True) if n > bound else (x, False)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)))


def expected_step(mission, s, h: float = 1e-6) -> tuple[dict, dict]:
    """The log row of step k and the state of step k + 1 (as ``LoopState`` fields) of
    ``mission`` (a ``Mission``) from the state ``s`` (a ``LoopState``), from eqs. 1–22."""
    spec, dt = mission.spec, mission.spec.mission.dt
    c, lim = spec.controller, spec.controller.limits
    rob = Robot(spec)
    q, v = s.q, s.v
    R_tb, p_b, R_te, p_e, p_c = rob.placements(q)
    G = rob.gamma(q)
    # Γ̇ along v (eq. 7), by central differences of Γ(q ⊕ ±h v).
    G_dot = (rob.gamma(pin.integrate(rob.model, q, h * v))
             - rob.gamma(pin.integrate(rob.model, q, -h * v))) / (2 * h)
    M, C = rob.dynamics(q, v)
    Gi, s_J = _gamma_inverse(G, spec.robot.damped_inverse.floor,
                             spec.robot.damped_inverse.damping)
    s_G = np.linalg.svd(G, compute_uv=False)
    M_hat = Gi.T @ M @ Gi  # eq. 8
    C_hat = Gi.T @ (C - M @ Gi @ G_dot) @ Gi  # eq. 9
    M_b, C_b, C_c = M_hat[3:, 3:], C_hat[3:, 3:], C_hat[3:, :3]  # eqs. 10–11

    ramp = c.base.conditioning
    gamma = float(np.interp(s_G[-1], [ramp.low, ramp.high], [ramp.floor, 1.0]))  # eq. 20
    g, derate = c.gains, (gamma if c.base.derate.gain else 1.0)
    K = np.diag(np.repeat([g.bus.K * derate, g.cam_pos.K, g.cam_ori.K], 3))  # eq. 13
    D = np.diag(np.repeat([g.bus.D * derate, g.cam_pos.D, g.cam_ori.D], 3))
    mu = scipy.linalg.eigh(D, M_b, eigvals_only=True)  # D̆ w = μ M̆ w (eq. 21)

    ref = mission.guidance.reference(s.tau, p_b)
    x_b, E_b = _attitude_error(R_tb, ref.R_b)  # eq. 14
    x_e, E_e = _attitude_error(R_te, ref.R_e)
    x_tilde = np.concatenate([x_b, p_e - ref.p_e, x_e])
    J_x = scipy.linalg.block_diag(E_b, R_te, E_e)
    v_des = np.concatenate([R_tb.T @ (gamma * ref.w_b), R_te.T @ (gamma * (ref.v_e - ref.v_c)),
                            R_te.T @ (gamma * ref.w_e)])
    G_vc = np.vstack([np.zeros((3, 3)), R_te.T, np.zeros((3, 3))])
    xc, xdc = p_c - ref.p_c, s.v_c - gamma * ref.v_c
    v_des_dot = (np.zeros(9) if s.v_breve_des_prev is None
                 else (v_des - s.v_breve_des_prev) / dt)

    vb = s.v_breve
    rhs = (-C_b @ vb - D @ (vb - v_des) - J_x.T @ K @ x_tilde - (C_c + D @ G_vc) @ xdc
           - Gi[6:, 3:].T @ (g.posture * (q[7:] - np.asarray(spec.robot.q_bar)))
           + M_b @ v_des_dot + C_b @ v_des)  # eq. 13
    if c.integrator == "imex":  # eq. 15b
        acc = (np.linalg.solve(M_b + dt * D, M_b @ vb + dt * (rhs + D @ vb)) - vb) / dt
    else:  # eq. 15a
        acc = np.linalg.solve(M_b, rhs)
    row, vb_new = {}, np.zeros(9)
    for j, name in enumerate(("omega_b", "nu_e_lin", "nu_e_ang")):  # eq. 16
        blk = slice(3 * j, 3 * j + 3)
        a, row[f"sat_{name}_acc"] = _sat(acc[blk], getattr(lim, f"{name}_acc"))
        vb_new[blk], row[f"sat_{name}_rate"] = _sat(vb[blk] + dt * a,
                                                     getattr(lim, f"{name}_rate"))
    integral = np.clip(s.integral + dt * xc, -c.com.i_max, c.com.i_max)  # eq. 12
    a_c, row["sat_v_c_acc"] = _sat(-c.com.K * xc - c.com.D * xdc - c.com.Ki * integral
                                   + gamma**2 * ref.a_c, lim.v_c_acc)
    v_c_new, row["sat_v_c_rate"] = _sat(s.v_c + dt * a_c, lim.v_c_rate)
    v_raw = Gi @ np.concatenate([v_c_new, vb_new])
    row["sat_v_max"] = bool(np.any(np.abs(v_raw) > lim.v_max))
    v_new = np.clip(v_raw, -lim.v_max, lim.v_max)
    # The commanded force (eq. 29): the RNEA of the generalized acceleration of the commanded
    # change of ν = [v_c; v̆]; the update of eq. 15 applies it as it is, at a constant rate.
    nu_dot = (np.concatenate([v_c_new, vb_new]) - np.concatenate([s.v_c, vb])) / dt
    u = pin.rnea(rob.model, rob.data, q, v, Gi @ (nu_dot - G_dot @ v)).copy()

    cam, tgt = spec.camera, mission.target  # eq. 18, from nothing seen
    r = tgt.points - p_e
    xyz = r @ R_te
    seen = ((xyz[:, 2] >= cam.d_min) & (xyz[:, 2] <= cam.d_max)
            & (np.hypot(xyz[:, 0], xyz[:, 1]) <= xyz[:, 2] * np.tan(np.radians(cam.fov_deg) / 2))
            & (-np.sum(tgt.normals * r, axis=1)
               >= np.linalg.norm(r, axis=1) * np.cos(np.radians(cam.max_angle_deg))))

    row |= {"tau": s.tau, "q": q, "v": v, "v_c": s.v_c, "v_breve": vb, "v_breve_des": v_des,
            "x_tilde": x_tilde, "s_min_G": s_G[-1], "kappa_G": s_G[0] / s_G[-1],
            "s_min_J": s_J[-1], "kappa_J": s_J[0] / s_J[-1], "gamma": gamma,
            "dt_mu_max": dt * mu.max(), "pointing_err_deg": _angle_deg(R_tb[:, 2], -p_b),
            "boresight_err_deg": _angle_deg(R_te[:, 2], ref.aim - p_e),
            "com_err": np.linalg.norm(xc), "coverage": seen.mean(), "u_cmd": u,
            "u_applied": u, "attitude_excursion_deg": 0.0}
    # Eq. 42 element by element, from the model's limits (a joint without one: none).
    lo, hi = rob.model.lowerPositionLimit[7:], rob.model.upperPositionLimit[7:]
    excess = np.array([0.0 if abs(a) > 1e10 and abs(b) > 1e10 else x - b if x > b
                       else x - a if x < a else 0.0
                       for x, a, b in zip(q[7:], lo, hi, strict=True)])
    row |= {"joint_excess": excess, "outside_joint_range": bool(np.any(excess != 0.0))}
    nxt = {"q": pin.integrate(rob.model, q, v_new * dt), "v": v_new, "v_c": v_c_new,
           "v_breve": vb_new, "tau": s.tau + gamma * dt, "integral": integral,
           "v_breve_des_prev": v_des}
    return row, nxt
