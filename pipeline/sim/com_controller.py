"""CoM loop (thrusters) on the inertial CoM velocity v_c (eq. 12)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.sim.jit import jit
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
    """The CoM loop's step (eq. 12) with the spec's gains and limits."""
    return ComUpdate(*com_update(x_c, xd_c, v_c, a_ff, integral, gains.K, gains.D, gains.Ki,
                                 gains.i_max, lim.v_c_acc, lim.v_c_rate, dt))


@jit
def com_update(x_c, xd_c, v_c, a_ff, integral, K, D, Ki, i_max, acc_bound, rate_bound, dt):
    """f_c/m = −K x̃_c − D ẋ̃_c − K_i ∫x̃_c + a_ff;  v_c ← sat(v_c + dt sat(f_c/m)) (eq. 12).

    Gains are per unit mass; the integral is bounded componentwise by ``i_max``.
    """
    integral = np.minimum(np.maximum(integral + dt * x_c, -i_max), i_max)
    acc = -K * x_c - D * xd_c - Ki * integral + a_ff
    acc, sat_acc = saturate(acc, acc_bound)
    v_new, sat_rate = saturate(v_c + dt * acc, rate_bound)
    return v_new, integral, sat_acc, sat_rate
