"""The shipped redundant posture is the one its stated rule gives (issue 50, docs/equations.md
"How the shipped missions stay inside"): panda_nominal's q̄ is, to its 3 rounded decimals, what
the rule gives when followed from the ready pose, and no posture near it on its self-motion is
wider (Gauss-Newton steps, independent of the optimiser), so an edited q̄ fails here, not only
in a claim."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.joint_ranges import JointRanges
from pipeline.sim.mission import Mission
from pipeline.spec import load_spec

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "settled_posture.py"


def _rule():
    spec = importlib.util.spec_from_file_location("settled_posture", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.widest_on_self_motion


def _least_margin(q, ranges):
    half = (ranges.upper - ranges.lower) / 2.0
    return float(np.min(np.minimum(q - ranges.lower, ranges.upper - q) / half))


READY = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]  # the Panda's usual ready pose


def test_the_panda_posture_is_the_widest_on_its_self_motion():
    """The rule followed whole: fly panda_nominal from the ready pose, take the posture where
    the camera first comes within 1° of its aim, move along its self-motion to the widest
    posture: the shipped q̄, to its 3 rounded decimals."""
    from pipeline.shapes import Q
    from pipeline.spec import with_overrides

    shipped = load_spec("panda_nominal")
    ready = Mission(with_overrides(shipped, {"robot.q_bar": READY}))
    cols = ready.run().columns
    settled = cols["q"][int(np.flatnonzero(cols["boresight_err_deg"] < 1.0)[0]), Q.joints]
    mission = Mission(shipped)
    robot, ranges = mission.robot, JointRanges.of(mission.robot.model)
    q_bar = np.asarray(robot.q_bar, dtype=float)
    widest = _rule()(mission, settled, ranges)
    # Rounding q̄ to 3 decimals moves it at most 5e-4 per joint off the optimum.
    assert np.max(np.abs(widest - q_bar)) < 2e-3
    # Independently of the optimiser: no posture on the self-motion near q̄ is wider. Steps
    # along the null space of the camera's bus-frame Jacobian, projected back onto the
    # self-motion by Gauss-Newton on the camera pose, never raise the least margin.
    model, data, fid = robot.model, robot.model.createData(), robot.frame_id

    def pose(q):
        pin.framesForwardKinematics(model, data, robot.full_configuration(q))
        return data.oMf[fid].copy()

    def jacobian(q):
        full = robot.full_configuration(q)
        J = pin.computeFrameJacobian(model, data, full, fid, pin.LOCAL)
        return J[:, 6:]

    held = pose(q_bar)
    z = np.linalg.svd(jacobian(q_bar))[2][-1]
    best = _least_margin(q_bar, ranges)
    for step in (-0.05, -0.01, 0.01, 0.05):
        q = q_bar + step * z
        for _ in range(20):
            e = pin.log6(held.actInv(pose(q))).vector
            q = q - np.linalg.pinv(jacobian(q)) @ e
        assert np.abs(pin.log6(held.actInv(pose(q))).vector).max() < 1e-10
        assert _least_margin(q, ranges) <= best + 1e-3
