"""Base guidance: the CoM inspection orbit, the bus pointing and the camera's aim (eq. 17).

All references are pure functions of the guidance time τ. The mission advances τ by γ·dt per
step, γ the conditioning ramp (eq. 20), so near a singularity every commanded rate slows by γ:
velocities below are d/dτ and the mission multiplies them by γ.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.layout import field_places, pack
from pipeline.sim.linalg import matmul, matvec
from pipeline.sim.rotations import look_at, vee
from pipeline.spec import Guidance

_H = 1e-4  # s, central-difference step for the attitude references' rates

# The references as one flat vector, the step kernel's input: (field, size), 3×3 row-major.
REFERENCE_FIELDS = (("p_c", 3), ("v_c", 3), ("a_c", 3), ("R_b", 9), ("w_b", 3), ("p_e", 3),
                    ("v_e", 3), ("R_e", 9), ("w_e", 3), ("aim", 3))
REFERENCE_SIZE = sum(n for _, n in REFERENCE_FIELDS)
REFERENCE_AT = field_places("ReferencePlaces", REFERENCE_FIELDS)

# The guidance's constants as one flat vector (see ``BaseGuidance``): the orbit's phase (rad),
# radius (m) and rate ω (rad/s), the aim point's amplitude (m) and period (s), the
# central-difference step h (s), the camera's CoM offset o_ce_b and its x-axis x_e_b (bus frame).
GUIDANCE_FIELDS = (("phase", 1), ("radius", 1), ("omega", 1), ("aim_amplitude", 1),
                   ("aim_period", 1), ("h", 1), ("o_ce_b", 3), ("x_e_b", 3))
GUIDANCE_AT = field_places("GuidancePlaces", GUIDANCE_FIELDS)


class Reference(NamedTuple):
    """Desired CoM, bus and camera motion at one guidance time (t frame, d/dτ rates); the
    fields of ``REFERENCE_FIELDS``, passed by name into and built inside compiled code."""

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
    # math's: the C library's cos and sin compiled and in Python mode alike (NumPy's may run
    # SIMD code chosen for the processor).
    c, s = math.cos(phi), math.sin(phi)
    return (radius * np.array([c, s, 0.0]), radius * omega * np.array([-s, c, 0.0]),
            -radius * omega * omega * np.array([c, s, 0.0]))


@jit
def poses(tau, p_b, use_p_b, g):
    """Desired bus attitude, camera position and attitude, and the aim point at τ (eq. 17),
    with the guidance's constants ``g`` (``GUIDANCE_FIELDS``).

    The bus z-axis points at the target (from ``p_b`` if ``use_p_b``, else from the desired
    CoM) with x along the orbit; the camera keeps the CoM offset ``o_ce_b`` (bus frame) and
    aims at a point sweeping the target's z-axis, its x-axis near the bus-frame ``x_e_b``.
    """
    p_c, v_c, _ = orbit(tau, g[GUIDANCE_AT.phase], g[GUIDANCE_AT.radius], g[GUIDANCE_AT.omega])
    R_b = look_at(-p_b if use_p_b else -p_c, v_c)
    p_e = p_c + matvec(R_b, g[GUIDANCE_AT.o_ce_b].copy())
    aim = np.array([0.0, 0.0, g[GUIDANCE_AT.aim_amplitude]
                    * math.sin(2 * math.pi * tau / g[GUIDANCE_AT.aim_period])])
    R_e = look_at(aim - p_e, matvec(R_b, g[GUIDANCE_AT.x_e_b].copy()))
    return R_b, p_e, R_e, aim


@jit
def references(tau, p_b, use_p_b, g):
    """All references at τ (eq. 17) as a ``Reference``, with the guidance's constants ``g``
    (``GUIDANCE_FIELDS``): the poses at τ and, by central differences of the orbit-based poses
    at τ ± h, the camera velocity and the attitude rates ω = vee(Ṙ Rᵀ)."""
    h = g[GUIDANCE_AT.h]
    p_c, v_c, a_c = orbit(tau, g[GUIDANCE_AT.phase], g[GUIDANCE_AT.radius],
                          g[GUIDANCE_AT.omega])
    R_b, p_e, R_e, aim = poses(tau, p_b, use_p_b, g)
    # False as a boolean, not the literal False: one compiled specialisation of poses.
    orbit_based = use_p_b and not use_p_b
    R_bp, p_ep, R_ep, _ = poses(tau + h, p_b, orbit_based, g)
    R_bm, p_em, R_em, _ = poses(tau - h, p_b, orbit_based, g)
    w_b = vee(matmul((R_bp - R_bm) / (2 * h), np.ascontiguousarray(R_b.T)))
    w_e = vee(matmul((R_ep - R_em) / (2 * h), np.ascontiguousarray(R_e.T)))
    return Reference(p_c=p_c, v_c=v_c, a_c=a_c, R_b=R_b, w_b=w_b, p_e=p_e,
                     v_e=(p_ep - p_em) / (2 * h), R_e=R_e, w_e=w_e, aim=aim)


@jit
def reference_vector(out, tau, p_b, use_p_b, g):
    """:func:`references` written into ``out`` by name (``REFERENCE_FIELDS``)."""
    r = references(tau, p_b, use_p_b, g)
    out[REFERENCE_AT.p_c] = r.p_c
    out[REFERENCE_AT.v_c] = r.v_c
    out[REFERENCE_AT.a_c] = r.a_c
    out[REFERENCE_AT.R_b] = r.R_b.ravel()
    out[REFERENCE_AT.w_b] = r.w_b
    out[REFERENCE_AT.p_e] = r.p_e
    out[REFERENCE_AT.v_e] = r.v_e
    out[REFERENCE_AT.R_e] = r.R_e.ravel()
    out[REFERENCE_AT.w_e] = r.w_e
    out[REFERENCE_AT.aim] = r.aim


@jit
def read_reference(r):
    """A reference vector (``REFERENCE_FIELDS``) as a ``Reference`` of contiguous copies."""
    return Reference(p_c=r[REFERENCE_AT.p_c].copy(), v_c=r[REFERENCE_AT.v_c].copy(),
                     a_c=r[REFERENCE_AT.a_c].copy(),
                     R_b=r[REFERENCE_AT.R_b].copy().reshape((3, 3)),
                     w_b=r[REFERENCE_AT.w_b].copy(), p_e=r[REFERENCE_AT.p_e].copy(),
                     v_e=r[REFERENCE_AT.v_e].copy(),
                     R_e=r[REFERENCE_AT.R_e].copy().reshape((3, 3)),
                     w_e=r[REFERENCE_AT.w_e].copy(), aim=r[REFERENCE_AT.aim].copy())


class BaseGuidance:
    """References for an inspection orbit about a target at the t-frame origin."""

    def __init__(self, cfg: Guidance, o_ce_b: np.ndarray, x_e_b: np.ndarray):
        self.cfg = cfg
        self.o_ce_b = np.ascontiguousarray(o_ce_b, dtype=float)  # camera from CoM, bus frame
        self.x_e_b = np.ascontiguousarray(x_e_b, dtype=float)  # camera x-axis at start, bus frame
        self.omega = 2 * np.pi / cfg.orbit_period
        self.phase = float(np.deg2rad(cfg.orbit_phase_deg))
        self._zero3 = np.zeros(3)
        self.params = pack(GUIDANCE_FIELDS, {
            "phase": self.phase, "radius": cfg.orbit_radius, "omega": self.omega,
            "aim_amplitude": cfg.aim_amplitude, "aim_period": cfg.aim_period, "h": _H,
            "o_ce_b": self.o_ce_b, "x_e_b": self.x_e_b})

    def reference(self, tau: float, p_b: np.ndarray | None = None) -> Reference:
        """References at τ. With the bus position ``p_b`` the desired bus z-axis points from
        the actual bus at the target (so orbit-tracking error does not become pointing error);
        without it, from the desired CoM. Rates are those of the orbit-based references.
        """
        return references(tau, self._zero3 if p_b is None else p_b, p_b is not None,
                          self.params)

    def reference_into(self, out: np.ndarray, tau: float, p_b: np.ndarray) -> None:
        """:meth:`reference` at (τ, p_b) as one vector (``REFERENCE_FIELDS``), into ``out``:
        the simulator's per-step form, one compiled call and no objects."""
        reference_vector(out, tau, p_b, True, self.params)
