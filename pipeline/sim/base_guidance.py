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

# The references as one flat vector, the step kernel's input: (field, size), 3×3 row-major.
REFERENCE_FIELDS = (("p_c", 3), ("v_c", 3), ("a_c", 3), ("R_b", 9), ("w_b", 3), ("p_e", 3),
                    ("v_e", 3), ("R_e", 9), ("w_e", 3), ("aim", 3))
REFERENCE_SIZE = sum(n for _, n in REFERENCE_FIELDS)


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

    def as_vector(self) -> np.ndarray:
        """The fields flattened in the order of ``REFERENCE_FIELDS``."""
        return np.concatenate([np.ravel(getattr(self, f)) for f, _ in REFERENCE_FIELDS])


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


@jit
def reference_vector(out, tau, p_b, use_p_b, params):
    """:func:`references` written into ``out`` in the order of ``REFERENCE_FIELDS``;
    ``params`` = [phase, radius, ω, aim amplitude, aim period, h, o_ce_b (3), x_e_b (3)]."""
    p_c, v_c, a_c, R_b, w_b, p_e, v_e, R_e, w_e, aim = references(
        tau, p_b, use_p_b, params[0], params[1], params[2], params[3], params[4],
        params[6:9].copy(), params[9:12].copy(), params[5])
    out[:] = np.concatenate((p_c, v_c, a_c, R_b.ravel(), w_b, p_e, v_e, R_e.ravel(), w_e, aim))


@jit
def unpack_reference(r):
    """The fields of a reference vector (``REFERENCE_FIELDS``), as contiguous arrays."""
    return (r[0:3].copy(), r[3:6].copy(), r[6:9].copy(), r[9:18].copy().reshape((3, 3)),
            r[18:21].copy(), r[21:24].copy(), r[24:27].copy(), r[27:36].copy().reshape((3, 3)),
            r[36:39].copy(), r[39:42].copy())


class BaseGuidance:
    """References for an inspection orbit about a target at the t-frame origin."""

    def __init__(self, cfg: Guidance, o_ce_b: np.ndarray, x_e_b: np.ndarray):
        self.cfg = cfg
        self.o_ce_b = np.ascontiguousarray(o_ce_b, dtype=float)  # camera from CoM, bus frame
        self.x_e_b = np.ascontiguousarray(x_e_b, dtype=float)  # camera x-axis at start, bus frame
        self.omega = 2 * np.pi / cfg.orbit_period
        self.phase = float(np.deg2rad(cfg.orbit_phase_deg))
        self._zero3 = np.zeros(3)
        self._params = np.array([self.phase, cfg.orbit_radius, self.omega, cfg.aim_amplitude,
                                 cfg.aim_period, _H, *self.o_ce_b, *self.x_e_b])

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

    def reference_into(self, out: np.ndarray, tau: float, p_b: np.ndarray) -> None:
        """:meth:`reference` at (τ, p_b) as one vector (``REFERENCE_FIELDS``), into ``out``:
        the simulator's per-step form, one compiled call and no objects."""
        reference_vector(out, tau, p_b, True, self._params)
