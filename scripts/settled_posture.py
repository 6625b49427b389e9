"""The arm's posture once the camera is on its first aim: the rule that chose the shipped
missions' robot.q_bar (issue 50).

    .venv/bin/python scripts/settled_posture.py SPEC [--q-bar ANGLES] [--within DEG] [--widest]

Flies SPEC (optionally from another q̄) and prints the arm's joint angles at the first step
whose camera boresight error is below DEG (default 1°), rounded to 3 decimals, with how far
each joint then sits from its range and the largest excursion beyond a range on the way there.
A mission started from that posture begins with its camera already on its aim: it has no
opening slew to drive a joint past its range (the old nominal's wrist_1 went 0.55 rad past its
upper limit turning the camera 90° onto its aim in its first 4 s).

``--widest`` (a redundant arm, n > 6): then moves along that posture's self-motion, the
postures with the same camera pose in the bus frame, to the one whose least joint-range margin,
each joint's over its half-range, is largest (eq. 42's ranges; SLSQP on
max t s.t. (q_i − lo_i)/h_i ≥ t, (hi_i − q_i)/h_i ≥ t, log₆(T_e(q̄)⁻¹ T_e(q)) = 0, started
at the settled posture, so it stays on that posture's branch). The null-space spring of eq. 37f
pulls the arm towards q̄ in flight, so the self-motion's widest posture is where it holds the
arm. A six-joint arm has no self-motion: its settled posture is the answer.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize

from pipeline.joint_ranges import JointRanges
from pipeline.shapes import Q
from pipeline.sim.mission import Mission
from pipeline.spec import load_spec, with_overrides


def widest_on_self_motion(mission: Mission, q_joint: np.ndarray,
                          ranges: JointRanges) -> np.ndarray:
    """The posture with q_joint's camera pose in the bus frame whose least normalised
    joint-range margin is largest (the rule of ``--widest``)."""
    robot = mission.robot
    model, data, fid = robot.model, robot.model.createData(), robot.frame_id
    lo, hi = ranges.lower, ranges.upper
    half = (hi - lo) / 2.0

    def camera(qj: np.ndarray) -> pin.SE3:
        pin.framesForwardKinematics(model, data, robot.full_configuration(qj))
        return data.oMf[fid].copy()

    held = camera(q_joint)
    constraints = [
        {"type": "eq", "fun": lambda x: pin.log6(held.actInv(camera(x[:-1]))).vector},
        {"type": "ineq", "fun": lambda x: np.concatenate([(x[:-1] - lo) / half - x[-1],
                                                           (hi - x[:-1]) / half - x[-1]])}]
    start = np.concatenate([q_joint, [0.0]])
    res = minimize(lambda x: -x[-1], start, constraints=constraints, method="SLSQP",
                   options={"maxiter": 500, "ftol": 1e-12})
    pose_error = float(np.abs(constraints[0]["fun"](res.x)).max())
    if not res.success or pose_error > 1e-9:
        raise SystemExit(f"{mission.spec.name}: the self-motion search did not converge "
                         f"({res.message}; pose error {pose_error:.2g})")
    return res.x[:-1]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("spec")
    p.add_argument("--q-bar", help="JSON list of joint angles to fly from instead")
    p.add_argument("--within", type=float, default=1.0, help="boresight error (deg)")
    p.add_argument("--widest", action="store_true",
                   help="a redundant arm: the widest-margin posture on the settled one's "
                        "self-motion")
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
    q = cols["q"][k, Q.joints]
    ranges = JointRanges.of(mission.robot.model)
    worst = float(np.abs(cols["joint_excess"][: k + 1]).max(initial=0.0))
    print(f"{spec.name}: camera within {a.within:g}° of its aim at step {k} "
          f"(t {k * spec.mission.dt:.2f} s); largest excursion beyond a range before it "
          f"{worst:.3f} rad")
    if a.widest and q.size > 6:
        q = widest_on_self_motion(mission, q, ranges)
        print("the widest posture on its self-motion (the camera's pose in the bus frame "
              "held):")
    q = np.round(q, 3)
    margin = np.minimum(q - ranges.lower, ranges.upper - q)
    for name, x, m in zip(ranges.names, q, margin, strict=True):
        print(f"  {name}: {x:.3f} rad, {m:.3f} rad inside its range")
    print(f"robot: {{q_bar: {json.dumps(q.tolist())}}}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
