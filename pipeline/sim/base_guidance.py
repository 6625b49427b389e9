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


@jit
def references(tau, p_b, use_p_b, phase, radius, omega, aim_amplitude, aim_period, o_ce_b,
               x_e_b, h):
    """All references at τ (eq. 17): the poses at τ and, by central differences of the
    orbit-based poses at τ ± h, the camera velocity and the attitude rates ω = vee(Ṙ Rᵀ)."""
    p_c, v_c, a_c = orbit(tau, phase, radius, omega)
    R_b, p_e, R_e, aim = poses(tau, p_b, use_p_b, phase, radius, omega, aim_amplitude,
                               aim_period, o_ce_b, x_e_b)
    R_bp, p_ep, R_ep, _ = poses(tau + h, p_b, False, phase, radius, omega, aim_amplitude,
                                aim_period, o_ce_b, x_e_b)
    R_bm, p_em, R_em, _ = poses(tau - h, p_b, False, phase, radius, omega, aim_amplitude,
                                aim_period, o_ce_b, x_e_b)
    w_b = vee((R_bp - R_bm) / (2 * h) @ np.ascontiguousarray(R_b.T))
    w_e = vee((R_ep - R_em) / (2 * h) @ np.ascontiguousarray(R_e.T))
    return p_c, v_c, a_c, R_b, w_b, p_e, (p_ep - p_em) / (2 * h), R_e, w_e, aim


class BaseGuidance:
    """References for an inspection orbit about a target at the t-frame origin."""

    def __init__(self, cfg: Guidance, o_ce_b: np.ndarray, x_e_b: np.ndarray):
        self.cfg = cfg
        self.o_ce_b = np.ascontiguousarray(o_ce_b, dtype=float)  # camera from CoM, bus frame
        self.x_e_b = np.ascontiguousarray(x_e_b, dtype=float)  # camera x-axis at start, bus frame
        self.omega = 2 * np.pi / cfg.orbit_period
        self.phase = float(np.deg2rad(cfg.orbit_phase_deg))
        self._zero3 = np.zeros(3)

    def reference(self, tau: float, p_b: np.ndarray | None = None) -> Reference:
        """References at τ. With the bus position ``p_b`` the desired bus z-axis points from
        the actual bus at the target (so orbit-tracking error does not become pointing error);
        without it, from the desired CoM. Rates are those of the orbit-based references.
        """
        c = self.cfg
        return Reference(*references(
            tau, self._zero3 if p_b is None else p_b, p_b is not None, self.phase,
            c.orbit_radius, self.omega, c.aim_amplitude, c.aim_period, self.o_ce_b, self.x_e_b,
            _H))
