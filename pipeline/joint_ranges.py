"""The arm joints' position ranges from the robot file, and how far a configuration lies
beyond them (issue 50; architecture §8, "joint limits are part of the robot").

The simulator enforces no joint limits: a joint driven past its range keeps going. So every
log carries, per step, each arm joint's excess beyond its range (``joint_excess``: q_j − upper
above the range, q_j − lower below it, 0 inside or for a joint the file leaves unbounded) and
one flag, ``outside_joint_range``, set when any joint is outside (eq. 42). The simulator writes
them from the q it logs, the importer from the q it imports, and the analysis recomputes them
from the logged q and refuses a log whose columns disagree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.shapes import Q

UNLIMITED = 1e10  # a limit beyond this is none (Pinocchio's default for an unbounded joint)


@dataclass(frozen=True)
class JointRanges:
    """Each arm joint's name and range [lower, upper] (rad), in q's order; an unbounded
    joint's range is (−inf, inf)."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, model: pin.Model) -> JointRanges:
        lo = np.array(model.lowerPositionLimit[Q.joints], dtype=float)
        hi = np.array(model.upperPositionLimit[Q.joints], dtype=float)
        unbounded = (np.abs(lo) > UNLIMITED) & (np.abs(hi) > UNLIMITED)
        lo[unbounded], hi[unbounded] = -np.inf, np.inf
        return cls(tuple(model.names)[2:], lo, hi)

    def excess(self, q: np.ndarray) -> np.ndarray:
        """e_j = q_j − upper_j above the range, q_j − lower_j below it, 0 inside (eq. 42), for
        each row of q (N×nq → N×n; a NaN angle gives NaN)."""
        a = np.asarray(q, dtype=float)[:, Q.joints]
        out = np.where(a > self.upper, a - self.upper, np.where(a < self.lower, a - self.lower,
                                                               0.0))
        out[np.isnan(a)] = np.nan
        return out


def outside(excess: np.ndarray) -> np.ndarray:
    """The per-step flag: any joint outside its range (a NaN excess counts as outside)."""
    e = np.asarray(excess)
    return ~np.all(e == 0.0, axis=1)
