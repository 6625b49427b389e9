"""CoM loop (thrusters) on the inertial CoM velocity v_c (eq. 12)."""

from __future__ import annotations

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.limits import saturate


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
