"""What the robot file allows a log to hold: each arm joint's coordinate within the file's
limits, give or take :data:`LIMIT_MARGIN_RAD`.

The consistency check (eq. 33) cannot see a joint logged in degrees in both q and v: the two
still describe one motion. The robot file can: the seed's elbow logged in degrees reads −98.8
"rad" where the file bounds it to [−2.44, 2.09]. A coordinate beyond a limit by more than the
margin is refused, naming the joint, the row and, where dividing by 180/π would bring the
joint inside its limits, the likely unit.

The margin is 1 rad because the file's limits are not what the simulator enforces (it applies
none): the seed robot's own missions hold its wrist_1 up to 0.56 rad past the file's upper
limit of 0.524 rad (``nominal``, measured 2026-12-04), and a log of them must import. A joint
in degrees is still caught unless its angle is within about 1.5° (for the wrist_1's limits)
to 7° (a ±2π joint) of zero, where the consistency and the limits cannot tell it anyway.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.errors import SpecError
from pipeline.joint_ranges import UNLIMITED

LIMIT_MARGIN_RAD = 1.0


def check_joint_limits(model: pin.Model, q: np.ndarray, angle_unit: str, source: Path) -> None:
    """SpecError naming the first arm joint whose coordinate (q in radians, the project's
    conventions) leaves the robot file's limits by more than :data:`LIMIT_MARGIN_RAD`."""
    for j in range(2, model.njoints):  # 0: the universe, 1: the bus's free flyer
        i, n = model.joints[j].idx_q, model.joints[j].nq
        lo, hi = model.lowerPositionLimit[i:i + n], model.upperPositionLimit[i:i + n]
        for k in range(n):
            if abs(lo[k]) > UNLIMITED and abs(hi[k]) > UNLIMITED:
                continue
            x = q[:, i + k]
            out = (x < lo[k] - LIMIT_MARGIN_RAD) | (x > hi[k] + LIMIT_MARGIN_RAD)
            if not out.any():
                continue
            row = int(np.argmax(out))
            in_degrees = np.deg2rad(x)
            hint = (" (degrees declared as radians? --angle-unit deg)"
                    if angle_unit == "rad" and np.all((in_degrees >= lo[k]) & (in_degrees <= hi[k]))
                    else "")
            raise SpecError(f"{source}: q: joint {model.names[j]} is {x[row]:.4g} rad on row "
                            f"{row}, outside the robot file's limits [{lo[k]:.3g}, {hi[k]:.3g}] "
                            f"rad by more than {LIMIT_MARGIN_RAD:g} rad{hint}")
