"""Bus block of the controller and the conditioning derate (eqs. 13, 20)."""

from __future__ import annotations

import numpy as np

from pipeline.sim.sampling import scale_by_svd
from pipeline.spec import Controller


def conditioning_scale(s_min_G: float, ctrl: Controller) -> float:
    """γ = scale_by_svd(s_min_G, controller.base.conditioning) (eq. 20)."""
    c = ctrl.base.conditioning
    return scale_by_svd(s_min_G, c.low, c.high, c.floor)


def block_gains(ctrl: Controller, gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """K̆, D̆ = blockdiag(k_b I₃, k_p I₃, k_o I₃), likewise D (eq. 13).

    The bus block is multiplied by γ only when ``controller.base.derate.gain`` is true.
    """
    g = ctrl.gains
    scale = gamma if ctrl.base.derate.gain else 1.0
    k = np.repeat([g.bus.K * scale, g.cam_pos.K, g.cam_ori.K], 3)
    d = np.repeat([g.bus.D * scale, g.cam_pos.D, g.cam_ori.D], 3)
    return np.diag(k), np.diag(d)
