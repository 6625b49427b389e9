"""Did the run leave the arm's joint ranges (eq. 42)? Over every logged step, from the logged
q and the robot file, checked against the log's own ``joint_excess`` and
``outside_joint_range`` columns: a log whose columns say otherwise than its q is refused."""

from __future__ import annotations

import numpy as np

from pipeline.analysis import schema as rs
from pipeline.errors import CheckFailed, LogError
from pipeline.joint_ranges import JointRanges, outside
from pipeline.log_layout import JOINT_EXCESS, OUTSIDE_JOINT_RANGE
from pipeline.logs import VerifiedLog

COLUMNS = ("step", "q", JOINT_EXCESS, OUTSIDE_JOINT_RANGE)


def joint_range_record(log: VerifiedLog, ranges: JointRanges, dt: float) -> rs.JointRangeRecord:
    """Each joint's excursions beyond each side of its range, over the whole log (eq. 42)."""
    n = len(ranges.names)
    worst = np.zeros((2, n))  # rows: above, below
    steps = np.zeros((2, n), dtype=np.int64)
    first = np.full((2, n), -1, dtype=np.int64)
    outside_steps = 0
    for chunk in log.iter_columns(list(COLUMNS)):
        e = ranges.excess(chunk["q"])
        if np.isnan(e).any():  # a complete log's q is finite (verify_log): this is not one
            raise LogError(f"{log.path}: q is not finite at step "
                           f"{int(chunk['step'][np.argmax(np.isnan(e).any(axis=1))])}")
        flag = outside(e)
        logged, logged_flag = chunk[JOINT_EXCESS], chunk[OUTSIDE_JOINT_RANGE]
        if logged.shape != e.shape:
            raise CheckFailed(f"{log.path}: {JOINT_EXCESS} has {logged.shape[-1]} columns for "
                              f"the robot file's {e.shape[1]} arm joints (eq. 42)")
        differs = np.any(e != logged, axis=1) | (flag != logged_flag)
        if differs.any():
            at = int(chunk["step"][np.argmax(differs)])
            raise CheckFailed(f"{log.path}: {JOINT_EXCESS}/{OUTSIDE_JOINT_RANGE} at step {at} "
                              f"are not those of the logged q and the robot file's ranges "
                              f"(eq. 42)")
        outside_steps += int(flag.sum())
        for side, mask in enumerate((e > 0.0, e < 0.0)):
            size = np.where(mask, np.abs(e), 0.0)
            worst[side] = np.maximum(worst[side], size.max(axis=0, initial=0.0))
            steps[side] += mask.sum(axis=0)
            hit = mask.any(axis=0) & (first[side] < 0)
            first[side, hit] = chunk["step"][np.argmax(mask[:, hit], axis=0)]
    joints = [rs.JointExcursion(joint=ranges.names[j], side=("above", "below")[side],
                                limit=float((ranges.upper, ranges.lower)[side][j]),
                                max_excess=float(worst[side, j]), steps=int(steps[side, j]),
                                seconds=float(steps[side, j] * dt),
                                first_step=int(first[side, j]))
              for side in range(2) for j in range(n) if steps[side, j]]
    joints.sort(key=lambda x: -x.max_excess)
    return rs.JointRangeRecord(left=bool(outside_steps), steps_outside=outside_steps,
                               seconds_outside=outside_steps * dt,
                               max_excess=float(worst.max(initial=0.0)), joints=joints)


def excursion_words(r: rs.JointRangeRecord) -> str:
    """One line for the CLI and the reports: inside every range, or which joint left which
    side, by how much, on how many steps in all and first when."""
    if not r.left:
        return "inside every joint range"
    parts = [f"{x.joint} {x.side} {x.limit:.3g} rad by up to {x.max_excess:.3g} rad, "
             f"{x.steps} steps ({x.seconds:.3g} s) in all, first at step {x.first_step}"
             for x in r.joints]
    return (f"LEFT ITS JOINT RANGES on {r.steps_outside} steps ({r.seconds_outside:.3g} s): "
            + "; ".join(parts) + " — a verdict on this run is one on a trajectory the arm "
            "cannot fly")


def range_words(r: rs.JointRangeRecord) -> str:
    """"" inside every range, else the worst excursion in a few words (eq. 42)."""
    if not r.left:
        return ""
    x = r.joints[0]
    more = f" and {len(r.joints) - 1} more" if len(r.joints) > 1 else ""
    return (f"left its joint ranges ({x.joint} up to {x.max_excess:.3g} rad {x.side} its "
            f"{x.limit:.3g} rad limit, {x.seconds:.3g} s{more}; {r.seconds_outside:.3g} s "
            f"in all)")


def range_mark(run: str, r: rs.JointRangeRecord) -> str:
    """The mark a verdict on a run carries when the run left a joint range (eq. 42), "" when
    it did not: the worst joint, by how much and for how long."""
    words = range_words(r)
    return f" Marked: {run} {words}: a trajectory the arm cannot fly." if words else ""
