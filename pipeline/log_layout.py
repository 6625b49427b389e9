"""The log row's layout, defined once (architecture §6): the fields the compiled step writes,
in order, with their widths. The kernel's row (:mod:`pipeline.sim.control_step`), the log's
columns (:mod:`pipeline.logs`) and the row's size in the budget (:mod:`pipeline.budget`) are
all read from here; the kernels freeze it as constants, so it is part of their cache key
(:func:`pipeline.sim.jit.source_stamp`).
"""

from __future__ import annotations

# The blocks of the reduced velocity v̆ = [ω_b; ν_e,lin; ν_e,ang], three components each, and
# the limit flags: each block's acceleration and rate bound (eq. 16), the CoM loop's two and
# the v_max clip.
BREVE_BLOCK_NAMES = ("omega_b", "nu_e_lin", "nu_e_ang")
LIMIT_FLAGS = tuple(
    [f"sat_{name}_{kind}" for name in BREVE_BLOCK_NAMES for kind in ("acc", "rate")]
    + ["sat_v_c_acc", "sat_v_c_rate", "sat_v_max"]
)

# One log row as the kernel writes it; the mission adds ``t`` and ``step``. A field of width
# one is a scalar column (the limit flags are written as booleans), a wider one a fixed-size
# list of float64.
ROW_FIELDS = (("tau", 1), ("q", 13), ("v", 12), ("v_c", 3), ("v_breve", 9), ("v_breve_des", 9),
              ("x_tilde", 9), ("u_cmd", 12), ("u_applied", 12), ("s_min_G", 1), ("kappa_G", 1),
              ("s_min_J", 1), ("kappa_J", 1), ("gamma", 1), ("dt_mu_max", 1),
              ("pointing_err_deg", 1), ("boresight_err_deg", 1), ("com_err", 1), ("coverage", 1),
              ("attitude_excursion_deg", 1), *((f, 1) for f in LIMIT_FLAGS))
ROW_SIZE = sum(n for _, n in ROW_FIELDS)

VECTOR_COLUMNS = {name: n for name, n in ROW_FIELDS if n > 1}
SCALAR_COLUMNS = ("t", *(name for name, n in ROW_FIELDS if n == 1 and name not in LIMIT_FLAGS))
