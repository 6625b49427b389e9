"""The arm's posture once the camera is on its first aim: the rule that chose the seed missions'
robot.q_bar (issue 50).

    .venv/bin/python scripts/settled_posture.py SPEC [--q-bar ANGLES] [--within DEG]

Flies SPEC (optionally from another q̄) and prints the arm's joint angles at the first step
whose camera boresight error is below DEG (default 1°), rounded to 3 decimals, with how far
each joint then sits from its range and the largest excursion beyond a range on the way there.
A mission started from that posture begins with its camera already on its aim: it has no
opening slew to drive a joint past its range (the old nominal's wrist_1 went 0.55 rad past its
upper limit turning the camera 90° onto its aim in its first 4 s).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from pipeline.joint_ranges import JointRanges
from pipeline.shapes import Q
from pipeline.sim.mission import Mission
from pipeline.spec import load_spec, with_overrides


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("spec")
    p.add_argument("--q-bar", help="JSON list of joint angles to fly from instead")
    p.add_argument("--within", type=float, default=1.0, help="boresight error (deg)")
    a = p.parse_args()
    spec = load_spec(a.spec)
    if a.q_bar:
        spec = with_overrides(spec, {"robot.q_bar": json.loads(a.q_bar)})
    mission = Mission(spec)
    cols = mission.run().columns
    on_aim = np.flatnonzero(cols["boresight_err_deg"] < a.within)
    if not on_aim.size:
        print(f"{spec.name}: the camera never comes within {a.within:g}° of its aim",
              file=sys.stderr)
        return 1
    k = int(on_aim[0])
    q = np.round(cols["q"][k, Q.joints], 3)
    ranges = JointRanges.of(mission.robot.model)
    margin = np.minimum(q - ranges.lower, ranges.upper - q)
    worst = float(np.abs(cols["joint_excess"][: k + 1]).max(initial=0.0))
    print(f"{spec.name}: camera within {a.within:g}° of its aim at step {k} "
          f"(t {k * spec.mission.dt:.2f} s); largest excursion beyond a range before it "
          f"{worst:.3f} rad")
    for name, x, m in zip(ranges.names, q, margin, strict=True):
        print(f"  {name}: {x:.3f} rad, {m:.3f} rad inside its range")
    print(f"robot: {{q_bar: {json.dumps(q.tolist())}}}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
