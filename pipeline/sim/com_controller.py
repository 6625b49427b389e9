"""CoM loop (thrusters) on the inertial CoM velocity v_c (eq. 12)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.sim.limits import saturate
from pipeline.spec import ComGains, Limits


@dataclass(frozen=True)
class ComUpdate:
    v_c: np.ndarray
    integral: np.ndarray
    sat_acc: bool
    sat_rate: bool


def com_step(x_c: np.ndarray, xd_c: np.ndarray, v_c: np.ndarray, a_ff: np.ndarray,
             integral: np.ndarray, gains: ComGains, lim: Limits, dt: float) -> ComUpdate:
    """f_c/m = −K x̃_c − D ẋ̃_c − K_i ∫x̃_c + a_ff;  v_c ← sat(v_c + dt sat(f_c/m)) (eq. 12).

    Gains are per unit mass; the integral is bounded componentwise by ``i_max``.
    """
    integral = np.minimum(np.maximum(integral + dt * x_c, -gains.i_max), gains.i_max)
    acc = -gains.K * x_c - gains.D * xd_c - gains.Ki * integral + a_ff
    acc, f_acc = saturate(acc, lim.v_c_acc)
    v_new, f_rate = saturate(v_c + dt * acc, lim.v_c_rate)
    return ComUpdate(v_new, integral, f_acc, f_rate)
