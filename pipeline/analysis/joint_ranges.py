"""Did the run leave the arm's joint ranges (eq. 42)? Over every logged step, from the logged
q and the robot file, checked against the log's own ``joint_excess`` and
``outside_joint_range`` columns: a log whose columns say otherwise than its q is refused."""

from __future__ import annotations

import numpy as np

from pipeline.analysis import schema as rs
from pipeline.errors import LogError
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
        flag = outside(e)
        if not (np.array_equal(e, chunk[JOINT_EXCESS], equal_nan=True)
                and np.array_equal(flag, chunk[OUTSIDE_JOINT_RANGE])):
            bad = np.flatnonzero(np.any(e != chunk[JOINT_EXCESS], axis=1)
                                 | (flag != chunk[OUTSIDE_JOINT_RANGE]))
            at = int(chunk["step"][bad[0]]) if bad.size else int(chunk["step"][0])
            raise LogError(f"{log.path}: {JOINT_EXCESS}/{OUTSIDE_JOINT_RANGE} at step {at} are "
                           f"not those of the logged q and the robot file's ranges (eq. 42)")
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
    side, by how much, for how long and from when."""
    if not r.left:
        return "inside every joint range (eq. 42)"
    parts = [f"{x.joint} {x.side} {x.limit:.3f} rad by up to {x.max_excess:.3f} rad for "
             f"{x.steps} steps ({x.seconds:.2f} s) from step {x.first_step}"
             for x in r.joints]
    return (f"LEFT ITS JOINT RANGES on {r.steps_outside} steps ({r.seconds_outside:.2f} s): "
            + "; ".join(parts) + " — a verdict on this run is one on a trajectory the arm "
            "cannot fly")


def range_mark(run: str, r: rs.JointRangeRecord) -> str:
    """The mark a verdict on a run carries when the run left a joint range (eq. 42), "" when
    it did not: the worst joint, by how much and for how long."""
    if not r.left:
        return ""
    x = r.joints[0]
    more = f" and {len(r.joints) - 1} more" if len(r.joints) > 1 else ""
    return (f" Marked: {run} left its joint ranges ({x.joint} up to {x.max_excess:.3g} rad "
            f"{x.side} its {x.limit:.3g} rad limit, {x.seconds:.3g} s{more}; "
            f"{r.seconds_outside:.3g} s in all): a trajectory the arm cannot fly.")
