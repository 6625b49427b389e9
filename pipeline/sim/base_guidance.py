"""Base guidance: the CoM inspection orbit, the bus pointing and the camera's aim (eqs. 17–18).

All references are pure functions of the guidance time τ. The mission advances τ by γ·dt per
step, γ the conditioning ramp (eq. 20), so near a singularity every commanded rate slows by γ:
velocities below are d/dτ and the mission multiplies them by γ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.sim.rotations import look_at
from pipeline.spec import Guidance

_H = 1e-4  # s, central-difference step for the attitude references' rates


@dataclass(frozen=True)
class Reference:
    """Desired CoM, bus and camera motion at one guidance time (t frame, d/dτ rates)."""

    p_c: np.ndarray
    v_c: np.ndarray
    a_c: np.ndarray
    R_b: np.ndarray
    w_b: np.ndarray
    p_e: np.ndarray
    v_e: np.ndarray
    R_e: np.ndarray
    w_e: np.ndarray
    aim: np.ndarray


def _vee_rate(R_plus: np.ndarray, R_minus: np.ndarray, R: np.ndarray) -> np.ndarray:
    """ω (t frame) from Ṙ Rᵀ = [ω]×, by a central difference."""
    W = (R_plus - R_minus) / (2 * _H) @ R.T
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


class BaseGuidance:
    """References for an inspection orbit about a target at the t-frame origin.

    The CoM circles the target in the t-frame x–y plane; the bus z-axis points at the target
    with its x-axis along the orbit; the camera keeps its start offset from the CoM (in the
    bus frame) and aims at a point sweeping the target's z-axis.
    """

    def __init__(self, cfg: Guidance, o_ce_b: np.ndarray, x_e_b: np.ndarray):
        self.cfg = cfg
        self.o_ce_b = np.asarray(o_ce_b, dtype=float)  # camera offset from CoM, bus frame
        self.x_e_b = np.asarray(x_e_b, dtype=float)  # camera x-axis at start, bus frame
        self.omega = 2 * np.pi / cfg.orbit_period

    def _orbit(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        phi = np.deg2rad(self.cfg.orbit_phase_deg) + self.omega * tau
        r, w = self.cfg.orbit_radius, self.omega
        c, s = np.cos(phi), np.sin(phi)
        return (r * np.array([c, s, 0.0]), r * w * np.array([-s, c, 0.0]),
                -r * w * w * np.array([c, s, 0.0]))

    def _poses(self, tau: float, p_b: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        p_c, v_c, _ = self._orbit(tau)
        R_b = look_at(-(p_c if p_b is None else p_b), v_c)
        p_e = p_c + R_b @ self.o_ce_b
        aim = np.array([0.0, 0.0, self.cfg.aim_amplitude
                        * np.sin(2 * np.pi * tau / self.cfg.aim_period)])
        R_e = look_at(aim - p_e, R_b @ self.x_e_b)
        return R_b, p_e, R_e, aim

    def reference(self, tau: float, p_b: np.ndarray | None = None) -> Reference:
        """References at τ. With the bus position ``p_b`` the desired bus z-axis points from
        the actual bus at the target (so orbit-tracking error does not become pointing error);
        without it, from the desired CoM. Rates are those of the orbit-based references.
        """
        p_c, v_c, a_c = self._orbit(tau)
        R_b, p_e, R_e, aim = self._poses(tau, p_b)
        R_bp, p_ep, R_ep, _ = self._poses(tau + _H)
        R_bm, p_em, R_em, _ = self._poses(tau - _H)
        return Reference(
            p_c=p_c, v_c=v_c, a_c=a_c,
            R_b=R_b, w_b=_vee_rate(R_bp, R_bm, R_b),
            p_e=p_e, v_e=(p_ep - p_em) / (2 * _H),
            R_e=R_e, w_e=_vee_rate(R_ep, R_em, R_e),
            aim=aim,
        )
