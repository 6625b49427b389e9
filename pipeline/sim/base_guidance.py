"""Base guidance: the CoM inspection orbit, the bus pointing and the camera's aim (eq. 17).

All references are pure functions of the guidance time τ. The mission advances τ by γ·dt per
step, γ the conditioning ramp (eq. 20), so near a singularity every commanded rate slows by γ:
velocities below are d/dτ and the mission multiplies them by γ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.rotations import look_at, vee
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


@jit
def orbit(tau, phase, radius, omega):
    """Circular CoM orbit in the t-frame x–y plane: position, velocity, acceleration at τ."""
    phi = phase + omega * tau
    c, s = np.cos(phi), np.sin(phi)
    return (radius * np.array([c, s, 0.0]), radius * omega * np.array([-s, c, 0.0]),
            -radius * omega * omega * np.array([c, s, 0.0]))


@jit
def poses(tau, p_b, use_p_b, phase, radius, omega, aim_amplitude, aim_period, o_ce_b, x_e_b):
    """Desired bus attitude, camera position and attitude, and the aim point at τ (eq. 17).

    The bus z-axis points at the target (from ``p_b`` if ``use_p_b``, else from the desired
    CoM) with x along the orbit; the camera keeps the CoM offset ``o_ce_b`` (bus frame) and
    aims at a point sweeping the target's z-axis, its x-axis near the bus-frame ``x_e_b``.
    """
    p_c, v_c, _ = orbit(tau, phase, radius, omega)
    R_b = look_at(-p_b if use_p_b else -p_c, v_c)
    p_e = p_c + R_b @ o_ce_b
    aim = np.array([0.0, 0.0, aim_amplitude * np.sin(2 * np.pi * tau / aim_period)])
    R_e = look_at(aim - p_e, R_b @ x_e_b)
    return R_b, p_e, R_e, aim


class BaseGuidance:
    """References for an inspection orbit about a target at the t-frame origin."""

    def __init__(self, cfg: Guidance, o_ce_b: np.ndarray, x_e_b: np.ndarray):
        self.cfg = cfg
        self.o_ce_b = np.ascontiguousarray(o_ce_b, dtype=float)  # camera from CoM, bus frame
        self.x_e_b = np.ascontiguousarray(x_e_b, dtype=float)  # camera x-axis at start, bus frame
        self.omega = 2 * np.pi / cfg.orbit_period
        self.phase = float(np.deg2rad(cfg.orbit_phase_deg))

    def _poses(self, tau: float, p_b: np.ndarray | None = None):
        c = self.cfg
        return poses(tau, np.zeros(3) if p_b is None else np.ascontiguousarray(p_b),
                     p_b is not None, self.phase, c.orbit_radius, self.omega, c.aim_amplitude,
                     c.aim_period, self.o_ce_b, self.x_e_b)

    def reference(self, tau: float, p_b: np.ndarray | None = None) -> Reference:
        """References at τ. With the bus position ``p_b`` the desired bus z-axis points from
        the actual bus at the target (so orbit-tracking error does not become pointing error);
        without it, from the desired CoM. Rates are those of the orbit-based references,
        the attitude rates by central differences: ω = vee(Ṙ Rᵀ).
        """
        p_c, v_c, a_c = orbit(tau, self.phase, self.cfg.orbit_radius, self.omega)
        R_b, p_e, R_e, aim = self._poses(tau, p_b)
        R_bp, p_ep, R_ep, _ = self._poses(tau + _H)
        R_bm, p_em, R_em, _ = self._poses(tau - _H)
        return Reference(
            p_c=p_c, v_c=v_c, a_c=a_c,
            R_b=R_b, w_b=vee((R_bp - R_bm) / (2 * _H) @ R_b.T),
            p_e=p_e, v_e=(p_ep - p_em) / (2 * _H),
            R_e=R_e, w_e=vee((R_ep - R_em) / (2 * _H) @ R_e.T),
            aim=aim,
        )
