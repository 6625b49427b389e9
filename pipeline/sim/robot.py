"""The free-floating servicer: Pinocchio model, task transform Γ and transformed dynamics.

Conventions (docs/equations.md §1): q = [p_b (t frame); quat_tb (x, y, z, w); q_arm (6)],
v = [v_b (b frame); ω_b (b frame); q̇ (6)], Pinocchio's free-flyer convention. Frames: t
inertial (target-centred), b bus, c the whole robot's CoM, e the camera. R_xy rotates
y-coordinates into x. The camera Jacobian is taken in the camera's LOCAL frame.

One call of :meth:`GiordanoRobot.terms` runs each Pinocchio routine once per state: CRBA,
Coriolis matrix, the joint Jacobians and their time variation (for the camera frame), and
the centroidal map with its time variation. Everything else is small dense algebra.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.sim.rotations import skew
from pipeline.sim.sampling import Sampling, sigma_min_and_cond
from pipeline.spec import Spec

LOCAL = pin.ReferenceFrame.LOCAL


def damped_pinv(J: np.ndarray, floor: float, damping: float) -> tuple[np.ndarray, float, float]:
    """Damped SVD pseudo-inverse of J and its (σ_min, κ) from the same SVD (eq. 6).

    J⁺ = V diag(σ_i / (σ_i² + λ²)) Uᵀ,  λ² = damping² (1 − (σ_min/floor)²) if σ_min < floor,
    else 0: the exact inverse away from the singularity, a bounded one near it.
    """
    U, s, Vt = np.linalg.svd(J)
    smin = s[-1]
    lam2 = damping**2 * (1.0 - (smin / floor) ** 2) if smin < floor else 0.0
    J_inv = (Vt.T * (s / (s * s + lam2))) @ U.T
    kappa = s[0] / smin if smin > 0 else np.inf
    return J_inv, float(smin), float(kappa)


@dataclass
class Terms:
    """Kinematic and dynamic terms of one state (q, v), eqs. 1–11."""

    R_tb: np.ndarray  # bus attitude, 3×3
    p_b: np.ndarray  # bus origin in t
    p_c: np.ndarray  # CoM in t
    p_e: np.ndarray  # camera origin in t
    R_te: np.ndarray  # camera attitude
    p_bc: np.ndarray  # CoM from bus origin, b frame
    J_bar_v: np.ndarray  # 3×6 CoM Jacobian of the joints, b frame (eq. 2)
    J_oplus: np.ndarray  # 6×6 generalized Jacobian (eq. 3)
    J_oplus_inv: np.ndarray  # its damped inverse (eq. 6)
    G_wb: np.ndarray  # 6×3 (eq. 4)
    gamma: np.ndarray  # Γ, 12×12 (eq. 5)
    gamma_inv: np.ndarray  # closed-form Γ⁻¹ (eq. 6)
    gamma_dot: np.ndarray  # Γ̇ (eq. 7)
    M: np.ndarray
    C: np.ndarray
    M_hat: np.ndarray  # Γ⁻ᵀ M Γ⁻¹ (eq. 8)
    C_hat: np.ndarray  # Γ⁻ᵀ (C − M Γ⁻¹ Γ̇) Γ⁻¹ (eq. 9)
    s_min_J: float
    kappa_J: float
    s_min_G: float
    kappa_G: float

    @property
    def reduced_inertia(self) -> np.ndarray:
        """M̆ = M̂[3:, 3:], the 9×9 [ω_b; ν_e⊕] block (eq. 10)."""
        return self.M_hat[3:, 3:]

    @property
    def reduced_coriolis(self) -> np.ndarray:
        """C̆ = Ĉ[3:, 3:] (eq. 11)."""
        return self.C_hat[3:, 3:]

    @property
    def com_coupling(self) -> np.ndarray:
        """C_c = Ĉ[3:, :3] (eq. 11)."""
        return self.C_hat[3:, :3]


class GiordanoRobot:
    """Model, data, sampler and per-state terms of the servicer (DESIGN §2)."""

    def __init__(self, spec: Spec):
        self.spec = spec
        self.model = pin.buildModelFromUrdf(str(spec.robot_path), pin.JointModelFreeFlyer())
        self.model.gravity.setZero()
        self.data = self.model.createData()
        if not self.model.existFrame(spec.robot.camera_frame):
            raise ValueError(f"robot has no frame {spec.robot.camera_frame!r}")
        self.frame_id = self.model.getFrameId(spec.robot.camera_frame)
        self.mass = float(pin.computeTotalMass(self.model))
        self.n = self.model.nv - 6
        self.sampling = Sampling(spec.config_sampling)
        self.q_bar = np.asarray(spec.robot.q_bar, dtype=float)
        self.floor = spec.robot.damped_inverse.floor
        self.damping = spec.robot.damped_inverse.damping

    # -- configurations -------------------------------------------------------------------
    def full_configuration(self, q_joint: np.ndarray) -> np.ndarray:
        """Bus at the origin with identity attitude, arm at ``q_joint``."""
        q = pin.neutral(self.model)
        q[7:] = q_joint
        return q

    def gamma_of_joints(self, q_joint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scoring function for the sampler: (q_full, Γ(q_full))."""
        q = self.full_configuration(q_joint)
        return q, self.terms(q, np.zeros(self.model.nv)).gamma

    def start_configuration(self) -> np.ndarray:
        """The best-conditioned sample on Γ near q̄, else the analytic fallback."""
        best = self.sampling.best_sample(self.q_bar, self.gamma_of_joints)
        if best is None:
            return self.deterministic_q_init()
        return best.q_full

    def deterministic_q_init(self) -> np.ndarray:
        """Analytic fallback: the arm exactly at q̄, bus at the origin."""
        return self.full_configuration(self.q_bar)

    # -- per-state terms ------------------------------------------------------------------
    def terms(self, q: np.ndarray, v: np.ndarray, dynamics: bool = True) -> Terms:
        """All terms of eqs. 1–11 at (q, v); each Pinocchio routine runs once."""
        model, data, fid, m = self.model, self.data, self.frame_id, self.mass
        pin.computeJointJacobiansTimeVariation(model, data, q, v)
        pin.updateFramePlacement(model, data, fid)
        J_e = pin.getFrameJacobian(model, data, fid, LOCAL)
        pin.computeCentroidalMapTimeVariation(model, data, q, v)
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T

        R_tb = data.oMi[1].rotation.copy()
        p_b = data.oMi[1].translation.copy()
        p_c = data.com[0].copy()
        oMe = data.oMf[fid]
        R_te, p_e = oMe.rotation.copy(), oMe.translation.copy()
        R_eb = R_te.T @ R_tb
        p_bc = R_tb.T @ (p_c - p_b)
        p_ec = R_te.T @ (p_c - p_e)  # e frame

        J_bar_v = M[0:3, 6:] / m
        R_eb0 = np.vstack([R_eb, np.zeros((3, 3))])
        J_oplus = J_e[:, 6:] - R_eb0 @ J_bar_v
        G_wb = np.vstack([skew(p_ec) @ R_eb, R_eb])
        J_inv, s_min_J, kappa_J = damped_pinv(J_oplus, self.floor, self.damping)

        gamma = gamma_matrix(R_tb, p_bc, J_bar_v, G_wb, J_oplus)
        gamma_inv = gamma_inverse(R_tb, p_bc, J_bar_v, G_wb, J_inv)
        s_min_G, kappa_G = sigma_min_and_cond(gamma)

        if not dynamics:
            z = np.zeros((12, 12))
            return Terms(R_tb, p_b, p_c, p_e, R_te, p_bc, J_bar_v, J_oplus, J_inv, G_wb, gamma,
                         gamma_inv, z, M, z, z, z, s_min_J, kappa_J, s_min_G, kappa_G)

        # Γ̇ (eq. 7) from the Jacobian and centroidal-map time variations.
        w_b, qd = v[3:6], v[6:]
        dJ_e = pin.getFrameJacobianTimeVariation(model, data, fid, LOCAL)
        twist_e = J_e @ v
        v_e, w_e = twist_e[:3], twist_e[3:]
        J_bar_v_dot = -skew(w_b) @ J_bar_v + R_tb.T @ data.dAg[0:3, 6:] / m
        p_bc_dot = J_bar_v @ qd
        R_eb_dot = -skew(w_e) @ R_eb + R_eb @ skew(w_b)
        p_ec_dot = -skew(w_e) @ p_ec + R_te.T @ (data.Ag[0:3, :] @ v) / m - v_e
        G_wb_dot = np.vstack([skew(p_ec_dot) @ R_eb + skew(p_ec) @ R_eb_dot, R_eb_dot])
        J_oplus_dot = dJ_e[:, 6:] - np.vstack([R_eb_dot @ J_bar_v + R_eb @ J_bar_v_dot,
                                               np.zeros((3, self.n))])
        R_tb_dot = R_tb @ skew(w_b)
        gamma_dot = np.zeros((12, 12))
        gamma_dot[0:3, 0:3] = R_tb_dot
        gamma_dot[0:3, 3:6] = -R_tb_dot @ skew(p_bc) - R_tb @ skew(p_bc_dot)
        gamma_dot[0:3, 6:] = R_tb_dot @ J_bar_v + R_tb @ J_bar_v_dot
        gamma_dot[6:, 3:6] = G_wb_dot
        gamma_dot[6:, 6:] = J_oplus_dot

        C = pin.computeCoriolisMatrix(model, data, q, v).copy()
        Gi = gamma_inv
        M_hat = Gi.T @ M @ Gi
        C_hat = Gi.T @ (C - M @ Gi @ gamma_dot) @ Gi
        return Terms(R_tb, p_b, p_c, p_e, R_te, p_bc, J_bar_v, J_oplus, J_inv, G_wb, gamma,
                     gamma_inv, gamma_dot, M, C, M_hat, C_hat, s_min_J, kappa_J, s_min_G,
                     kappa_G)


def gamma_matrix(R_tb, p_bc, J_bar_v, G_wb, J_oplus) -> np.ndarray:
    """Γ (eq. 5): ν = [v_c; ω_b; ν_e⊕] = Γ v.

    Γ = [[R_tb, −R_tb [p_bc]×, R_tb J̄_v], [0, I₃, 0], [0, G_ωb, J⊕]].
    """
    n = J_oplus.shape[1]
    g = np.zeros((6 + n, 6 + n))
    g[0:3, 0:3] = R_tb
    g[0:3, 3:6] = -R_tb @ skew(p_bc)
    g[0:3, 6:] = R_tb @ J_bar_v
    g[3:6, 3:6] = np.eye(3)
    g[6:, 3:6] = G_wb
    g[6:, 6:] = J_oplus
    return g


def gamma_inverse(R_tb, p_bc, J_bar_v, G_wb, J_oplus_inv) -> np.ndarray:
    """Closed-form Γ⁻¹ through J⊕⁻¹ (eq. 6).

    Γ⁻¹ = [[R_tbᵀ, [p_bc]× + J̄_v J⊕⁻¹ G_ωb, −J̄_v J⊕⁻¹], [0, I₃, 0], [0, −J⊕⁻¹ G_ωb, J⊕⁻¹]].
    """
    n = J_oplus_inv.shape[0]
    JiG = J_oplus_inv @ G_wb
    g = np.zeros((6 + n, 6 + n))
    g[0:3, 0:3] = R_tb.T
    g[0:3, 3:6] = skew(p_bc) + J_bar_v @ JiG
    g[0:3, 6:] = -J_bar_v @ J_oplus_inv
    g[3:6, 3:6] = np.eye(3)
    g[6:, 3:6] = -JiG
    g[6:, 6:] = J_oplus_inv
    return g
