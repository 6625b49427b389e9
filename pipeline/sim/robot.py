"""The free-floating robot: Pinocchio model, task transform Γ and transformed dynamics.

Conventions (eq. 1): q = [p_b (t frame); quat_tb (x, y, z, w); q_arm (6)],
v = [v_b (b frame); ω_b (b frame); q̇ (6)], Pinocchio's free-flyer convention. Frames: t
inertial (target-centred), b bus, c the whole robot's CoM, e the camera. R_xy rotates
y-coordinates into x. The camera Jacobian is taken in the camera's LOCAL frame.

Pinocchio loads the model; the per-state terms (CRBA, the Coriolis matrix, the camera
Jacobian and its time variation, the centroidal map with its time variation) come from the
compiled :mod:`pipeline.sim.rigid_body_terms`, which the mission loop calls without Python and
which Pinocchio checks in the tests. The dense algebra on them lives in
:mod:`pipeline.sim.task_transform`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.shapes import Q
from pipeline.sim import task_transform as tt
from pipeline.sim.jit import jit
from pipeline.sim.rigid_body_terms import dynamics_terms, placement_terms, robot_terms
from pipeline.sim.robot_file import (
    RobotCard,
    camera_frame_id,
    load_spec_robot,
    robot_card,
    robot_shape,
)
from pipeline.sim.sampling import Sampling, sigma_min_and_cond
from pipeline.spec import Spec

LOCAL = pin.ReferenceFrame.LOCAL
damped_pinv = tt.damped_pinv
gamma_matrix = tt.gamma_matrix
gamma_inverse = tt.gamma_inverse


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
    gamma_dot: np.ndarray  # Γ̇ (eq. 7); zeros when only kinematics were asked for
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
    """Model, data, sampler and per-state terms of a free-floating robot (eqs. 1–11)."""

    def __init__(self, spec: Spec):
        self.spec = spec
        self.model = load_spec_robot(spec)
        self.data = self.model.createData()
        self.frame_id = camera_frame_id(self.model, spec.robot.camera_frame)
        self.mass = float(pin.computeTotalMass(self.model))
        self.shape = robot_shape(self.model)
        self.n = self.shape.n
        self.sampling = Sampling(spec.config_sampling)
        self.q_bar = np.asarray(spec.robot.q_bar, dtype=float)
        self.floor = spec.robot.damped_inverse.floor
        self.damping = spec.robot.damped_inverse.damping
        self._zero_12 = np.zeros((self.model.nv, self.model.nv))
        self._zero_12.flags.writeable = False
        self.bundle = robot_terms(self.model, self.frame_id)  # the compiled terms' model

    def card(self, q: np.ndarray) -> RobotCard:
        """The robot card at configuration q, with the spec's bus and camera orientation
        damping gains (eq. 21)."""
        gains = self.spec.controller.gains
        return robot_card(self.model, q, gains.bus.D, gains.cam_ori.D, self.frame_id,
                          self.bus_yaw_mode_rate(q))

    def bus_yaw_mode_rate(self, q: np.ndarray) -> float:
        """μ of the bus-yaw damping mode of (D̆, M̆) at q (eq. 21): of the modes of M̆⁻¹D̆ with
        the spec's gains, the one with the largest share d_i e_i²/μ on ω_b,z."""
        from pipeline.sim.base_controller import block_gains
        from pipeline.sim.stability import BUS_YAW_AXIS, damping_modes

        M = np.asarray(self.terms(q, np.zeros(self.model.nv)).reduced_inertia)
        _, D = block_gains(self.spec.controller, 1.0, self.shape.null_space_dim)
        d = np.diag(D)

        def yaw_share(m) -> float:  # d_z e_z²/Σ d_i e_i² (= /μ); an undamped mode by e_z²
            w = d * m.vector ** 2 if m.mu > 0 else m.vector ** 2
            return float(w[BUS_YAW_AXIS] / w.sum())

        return float(max(damping_modes(M, D), key=yaw_share).mu)

    # -- configurations -------------------------------------------------------------------
    def full_configuration(self, q_joint: np.ndarray) -> np.ndarray:
        """Bus at the origin with identity attitude, arm at ``q_joint``."""
        q = pin.neutral(self.model)
        q[Q.joints] = q_joint
        return q

    def gamma_of_joints(self, q_joint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scoring function for the sampler: (q_full, Γ(q_full))."""
        q = self.full_configuration(q_joint)
        # Γ alone: the kinematic terms (Γ is the same bits as with the dynamics, eqs. 2–6).
        return q, self.terms(q, np.zeros(self.model.nv), dynamics=False).gamma

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
    def kinematic_inputs(self, q: np.ndarray) -> tuple[np.ndarray, ...]:
        """(R_tb, p_b, R_te, p_e, J_e, M) at q: what eqs. 2–6 take, the camera Jacobian in the
        LOCAL frame (:func:`~pipeline.sim.rigid_body_terms.placement_terms`)."""
        return placement_terms(self.bundle, np.array(q, dtype=float))

    def gamma_matrices(self, q: np.ndarray) -> np.ndarray:
        """Γ(q_k) for every row of q (N×13 → N×12×12, eq. 5): the analysis' rebuild, by the
        simulator's kernels, so a Γ rebuilt from a logged q is the simulator's to the bit."""
        q = np.array(q, dtype=float)  # a writable C copy: one compiled specialisation
        out = np.empty((len(q), self.model.nv, self.model.nv))
        gamma_stack(self.bundle, q, self.mass, out)
        return out

    def j_oplus_conditioning(self, q: np.ndarray) -> np.ndarray:
        """(σ_min, κ) of the damped J⊕ for every row of q (N×nq → N×2, eqs. 6, 19): what a
        run logs as ``s_min_J`` and ``kappa_J``, by the step's own kernels, in one compiled
        loop (:meth:`terms` per row would also take Γ's SVD and a Python call a row)."""
        q = np.array(q, dtype=float)  # a writable C copy: one compiled specialisation
        out = np.empty((len(q), 2))
        j_oplus_conditioning_stack(self.bundle, q, self.mass, self.floor, self.damping, out)
        return out

    def dynamics_inputs(self, q: np.ndarray, v: np.ndarray) -> tt.DynamicsInputs:
        """The terms at (q, v) that eqs. 2–11 take, by name (R_tb, p_b, R_te, p_e, J_e, J̇_e,
        M, C, A_g, Ȧ_g), camera Jacobians in the LOCAL frame
        (:func:`~pipeline.sim.rigid_body_terms.dynamics_terms`)."""
        return dynamics_terms(self.bundle, np.array(q, dtype=float), np.array(v, dtype=float))

    def terms(self, q: np.ndarray, v: np.ndarray, dynamics: bool = True) -> Terms:
        """All terms of eqs. 1–11 at (q, v), from one call of the compiled rigid-body terms.

        With ``dynamics=False`` only the kinematic terms (Γ, Γ⁻¹, conditioning) are computed
        and v is not used; the dynamic fields are zeros.
        """
        m = self.mass
        # Writable C copies (a log's columns are read-only): one compiled specialisation.
        q, v = np.array(q, dtype=float), np.array(v, dtype=float)
        if dynamics:
            d = self.dynamics_inputs(q, v)
            t = tt.full_transform(d, m, self.floor, self.damping, v, np.empty((0, 0)))
            return Terms(d.R_tb, d.p_b, t.p_c, d.p_e, d.R_te, t.p_bc, t.J_bar_v, t.J_oplus,
                         t.J_oplus_inv, t.G_wb, t.gamma, t.gamma_inv, t.gamma_dot, d.M, d.C,
                         t.M_hat, t.C_hat, float(t.s_min_J), float(t.kappa_J),
                         float(t.s_min_G), float(t.kappa_G))
        R_tb, p_b, R_te, p_e, J_e, M = self.kinematic_inputs(q)
        (p_bc, p_c, _, _, J_bar_v, J_oplus, G_wb, J_inv, s_min_J, kappa_J, gamma,
         gamma_inv) = tt.task_transform(R_tb, p_b, R_te, p_e, J_e, M, m, self.floor,
                                        self.damping)
        z = self._zero_12
        s_min_G, kappa_G = sigma_min_and_cond(gamma)
        return Terms(R_tb, p_b, p_c, p_e, R_te, p_bc, J_bar_v, J_oplus, J_inv, G_wb, gamma,
                     gamma_inv, z, M, z, z, z, float(s_min_J), float(kappa_J),
                     float(s_min_G), float(kappa_G))


@jit
def gamma_stack(bundle, q, mass, out):
    """out[k] = Γ(q[k]) for every row (eq. 5): the terms and Γ of each step in one compiled
    loop (:func:`~pipeline.sim.task_transform.gamma_of_placements`)."""
    for k in range(q.shape[0]):
        R_tb, p_b, R_te, p_e, J_e, M = placement_terms(bundle, q[k])
        out[k] = tt.gamma_of_placements(R_tb, p_b, R_te, p_e, J_e, M, mass)


@jit
def j_oplus_conditioning_stack(bundle, q, mass, floor, damping, out):
    """out[k] = (σ_min, κ) of the damped J⊕ at q[k] (eqs. 6, 19), as
    :func:`~pipeline.sim.task_transform.task_transform` gives them to a step."""
    for k in range(q.shape[0]):
        R_tb, p_b, R_te, p_e, J_e, M = placement_terms(bundle, q[k])
        t = tt.task_transform(R_tb, p_b, R_te, p_e, J_e, M, mass, floor, damping)
        out[k, 0] = t[8]
        out[k, 1] = t[9]
