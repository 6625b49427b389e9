"""The log row's layout, defined once (architecture §6): the fields the compiled step writes,
in order, with their widths, sized by the robot's shape (:class:`pipeline.shapes.RobotShape`).
The kernel's row (:mod:`pipeline.sim.control_step`), the log's columns (:mod:`pipeline.logs`)
and the row's size in the budget (:mod:`pipeline.budget`) are all read from here; the kernels
freeze each field's place for every joint count (``control_step.STEP_PLACES``), so this file is
part of their cache key (:data:`pipeline.sim.jit.KERNEL_CONSTANTS`).
"""

from __future__ import annotations

import functools

from pipeline.shapes import BREVE_BLOCK_NAMES, NULL_SPACE_BLOCK, TASK_ERROR_SIZE, RobotShape

# The limit flags every log has: each task block's acceleration and rate bound (eq. 16), the
# CoM loop's two and the v_max clip. A redundant arm's null-space block adds its two
# (:func:`limit_flags`).
LIMIT_FLAGS = tuple(
    [f"sat_{name}_{kind}" for name in BREVE_BLOCK_NAMES for kind in ("acc", "rate")]
    + ["sat_v_c_acc", "sat_v_c_rate", "sat_v_max"]
)
NULL_SPACE_FLAGS = tuple(f"sat_{NULL_SPACE_BLOCK}_{kind}" for kind in ("acc", "rate"))

# The row's scalar fields after its vectors, in order.
ROW_SCALARS = ("s_min_G", "kappa_G", "s_min_J", "kappa_J", "gamma", "dt_mu_max",
               "pointing_err_deg", "boresight_err_deg", "com_err", "coverage",
               "attitude_excursion_deg")
SCALAR_COLUMNS = ("t", "tau", *ROW_SCALARS)


# Each arm joint's excess beyond its range and the flag of a step with any (eq. 42): written
# beside the kernel's row from the logged q (pipeline.joint_ranges), not by the kernel.
JOINT_EXCESS = "joint_excess"
OUTSIDE_JOINT_RANGE = "outside_joint_range"


def limit_flags(shape: RobotShape) -> tuple[str, ...]:
    """The limit flags of a log of ``shape``, in the row's order (eq. 16)."""
    return LIMIT_FLAGS + (NULL_SPACE_FLAGS if shape.null_space_dim else ())


@functools.lru_cache(maxsize=16)
def row_fields(shape: RobotShape) -> tuple[tuple[str, int], ...]:
    """One log row of ``shape`` as the kernel writes it; the mission adds ``t`` and ``step``.
    A field of width one is a scalar column; the vectors are fixed-size lists of float64
    (q nq, v nv, v̆ 9 + k, x̃ 9, u nv); ``limit_flags`` holds the flags of
    :func:`limit_flags`, each written as a boolean column."""
    return (("tau", 1), ("q", shape.nq), ("v", shape.nv), ("v_c", 3),
            ("v_breve", shape.n_breve), ("v_breve_des", shape.n_breve),
            ("x_tilde", TASK_ERROR_SIZE), ("u_cmd", shape.nv), ("u_applied", shape.nv),
            *((name, 1) for name in ROW_SCALARS), ("limit_flags", len(limit_flags(shape))))


def row_size(shape: RobotShape) -> int:
    """The row's width in floats."""
    return sum(n for _, n in row_fields(shape))


def vector_columns(shape: RobotShape) -> dict[str, int]:
    """The log's vector columns of ``shape`` and their widths."""
    return {name: n for name, n in row_fields(shape) if n > 1 and name != "limit_flags"}
