"""Joint ranges (issue 50, eq. 42): each arm joint's excess beyond the robot file's range, per
step in every log, and what ``analyze`` and the reports say of a run that left a range."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pinocchio as pin
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import footer_metadata, run_cli, run_cli_in_process, sealed

from pipeline.joint_ranges import JointRanges, outside
from pipeline.sim.robot import GiordanoRobot
from pipeline.spec import load_spec

# The seed missions' posture before issue 50 (the nominal family's until then): the arm
# turns the camera onto its first aim and drives wrist_1 past its upper limit of 0.524 rad.
PAST_A_LIMIT = "[0.0, -0.367, -1.763, -0.993, -5.95, 0.0]"


def test_excess_on_either_side_of_each_limit_and_none_for_an_unbounded_joint():
    """(42a) on hand-made angles: above the upper limit, below the lower, on each limit
    exactly (inside), and a joint the file leaves unbounded (Pinocchio's ±1.8e308 default
    read as none)."""
    model = pin.Model(GiordanoRobot(load_spec("nominal")).model)
    lo = np.array(model.lowerPositionLimit[7:])
    hi = np.array(model.upperPositionLimit[7:])
    model.lowerPositionLimit[12] = -np.finfo(float).max  # the last joint: unbounded
    model.upperPositionLimit[12] = np.finfo(float).max
    ranges = JointRanges.of(model)
    q = np.tile(pin.neutral(model), (5, 1))
    q[0, 7:12] = hi[:5] + np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    q[1, 7:12] = lo[:5] - np.array([0.5, 0.4, 0.3, 0.2, 0.1])
    q[2, 7:12] = hi[:5]
    q[3, 7:12] = lo[:5]
    q[:, 12] = [1e6, -1e6, 0.0, 0.0, 0.0]
    e = ranges.excess(q)
    np.testing.assert_allclose(e[0], [0.1, 0.2, 0.3, 0.4, 0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(e[1], [-0.5, -0.4, -0.3, -0.2, -0.1, 0.0], atol=1e-12)
    assert np.all(e[2:] == 0.0)
    assert outside(e).tolist() == [True, True, False, False, False]
    assert ranges.names[3] == "wrist_1_joint" and hi[3] == pytest.approx(0.5235987755982988)


@pytest.fixture(scope="module")
def past_a_limit(tmp_path_factory):
    """A 12 s seed mission from the posture that drives wrist_1 past its range, its log."""
    root = tmp_path_factory.mktemp("ranges")
    spec = root / "past_a_limit.yaml"
    spec.write_text(f"extends: nominal\nmission: {{duration: 12.0}}\n"
                    f"robot: {{q_bar: {PAST_A_LIMIT}}}\n")
    r = run_cli_in_process("run", spec, "--out", root / "logs")
    assert r.returncode == 0, r.stderr
    return root, root / "logs" / "past_a_limit" / "run.parquet"


def test_a_mission_driven_past_a_limit_is_flagged_in_its_log(past_a_limit):
    """The log's excess and flag (42a–b) against the ranges MuJoCo reads from the same robot
    file (a second parser), computed here from the logged q."""
    _, log = past_a_limit
    t = pq.read_table(log)
    q = np.asarray(t.column("q").combine_chunks().flatten()).reshape(t.num_rows, -1)
    e = np.asarray(t.column("joint_excess").combine_chunks().flatten()).reshape(t.num_rows, -1)
    flag = t.column("outside_joint_range").to_numpy()
    spec = load_spec("nominal")
    mj = mujoco.MjModel.from_xml_path(str(spec.robot_path))
    names = [mj.joint(j).name for j in range(mj.njnt)
             if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    rng = np.array([mj.joint(n).range for n in names])
    arm = q[:, 7:]
    expect = np.where(arm > rng[:, 1], arm - rng[:, 1],
                      np.where(arm < rng[:, 0], arm - rng[:, 0], 0.0))
    np.testing.assert_allclose(e, expect, rtol=0, atol=1e-12)
    wrist_1 = names.index("wrist_1_joint")
    assert e[:, wrist_1].max() > 0.1 and flag.any()
    assert np.array_equal(flag, np.any(expect != 0.0, axis=1))


def test_analyze_and_the_report_say_which_joint_left_by_how_much_and_for_how_long(past_a_limit):
    root, log = past_a_limit
    r = run_cli("analyze", log, "--out", root / "reports")
    assert r.returncode == 0, r.stderr
    t = pq.read_table(log)
    e = np.asarray(t.column("joint_excess").combine_chunks().flatten()).reshape(t.num_rows, -1)
    above = e[:, 3] > 0
    line = next(x for x in r.stdout.splitlines() if "joint ranges" in x)
    assert "LEFT ITS JOINT RANGES" in line and "wrist_1_joint above 0.524 rad" in line, line
    assert (f"by up to {e[:, 3].max():.3g} rad, {int(above.sum())} steps "
            f"({above.sum() * 0.03:.3g} s) in all, first at step {int(np.argmax(above))}"
            in line), line
    rec = json.loads((root / "reports" / "past_a_limit" / "analysis.json").read_text())
    jr = rec["joint_ranges"]
    assert jr["left"] and jr["joints"][0]["joint"] == "wrist_1_joint"
    assert jr["joints"][0]["first_step"] == int(np.argmax(above))


def test_a_log_whose_range_columns_are_not_its_q_is_refused(past_a_limit, tmp_path):
    """A log resealed with its excess zeroed (the run made to look inside its ranges) fails
    analyze's check of the columns against q, exit 1, naming the columns and the step."""
    _, log = past_a_limit
    t = pq.read_table(log)
    width = t.schema.field("joint_excess").type.list_size
    zeros = pa.FixedSizeListArray.from_arrays(pa.array(np.zeros(t.num_rows * width)), width)
    t = t.set_column(t.schema.get_field_index("joint_excess"), "joint_excess", zeros)
    t = t.set_column(t.schema.get_field_index("outside_joint_range"), "outside_joint_range",
                     pa.array(np.zeros(t.num_rows, dtype=bool)))
    bad = tmp_path / "past_a_limit" / "run.parquet"
    bad.parent.mkdir()
    pq.write_table(sealed(t, footer_metadata(log)), bad)
    r = run_cli_in_process("analyze", bad, "--out", tmp_path / "reports")
    assert r.returncode == 1, r.stderr
    e = np.asarray(pq.read_table(log).column("joint_excess").combine_chunks().flatten())
    first = int(np.argmax(np.any(e.reshape(-1, width) != 0.0, axis=1)))
    assert (f"joint_excess/outside_joint_range at step {first} are not those of the logged q"
            in r.stderr and "eq. 42" in r.stderr), r.stderr


def test_a_loop_that_meets_the_requirement_off_the_arms_ranges_is_not_a_fix(tmp_path):
    """The fix table (eq. 35, 42): the sampled plant's implicit damping meets the requirement
    without delay (claim C35), but flown from the posture that drives wrist_1 past its range
    it is not a fix: the arm would fly it another way."""
    from pipeline.analysis.stages import analyze_log
    from pipeline.logs import verify_log
    from pipeline.reports.figures import RunData
    from pipeline.reports.fixes import FIX, fix_row
    from pipeline.sim.run import run_spec
    from pipeline.spec import with_overrides

    spec = with_overrides(load_spec("omega_ripple_sampled_imex"), {
        "mission.duration": 12.0, "robot.q_bar": json.loads(PAST_A_LIMIT)}, name="off_range")
    log = verify_log(run_spec(spec, tmp_path).path)
    rec = analyze_log(log)
    assert rec.joint_ranges.left and all(m.margins.meets for m in rec.theory.modes)
    row = fix_row(RunData("off_range", rec, log, log.meta.spec, "off_range"))
    assert row.verdict != FIX
    assert row.verdict.startswith("meets the requirement, but left its joint ranges "
                                  "(wrist_1_joint up to "), row.verdict


def test_a_claim_reading_a_run_that_left_a_range_is_marked(tmp_path):
    """The claims page marks a claim whose checks read a run that left a joint range, and no
    other (eq. 42): a finding on a trajectory the arm cannot fly says so."""
    from types import SimpleNamespace

    from pipeline.analysis import schema as rs
    from pipeline.claims.evaluate import range_marks
    from pipeline.claims.register import load_claims

    p = tmp_path / "claims.yaml"
    p.write_text("runs:\n  a: {spec: nominal}\n  b: {spec: nominal}\nclaims:\n"
                 + "".join(f"  - id: C{i}\n    kind: physics\n    expect: hold\n"
                           f"    statement: x\n    checks:\n      - {{metric: \"{run}:dominant."
                           f"lag1\", op: lt, threshold: 0}}\n" for i, run in ((1, "a"), (2, "b"))))
    left = rs.JointRangeRecord(left=True, steps_outside=3, seconds_outside=0.09, max_excess=0.2,
                               joints=[rs.JointExcursion("j2", "above", 0.5, 0.2, 3, 0.09, 7)])
    inside = rs.JointRangeRecord(left=False, steps_outside=0, seconds_outside=0.0,
                                 max_excess=0.0, joints=[])
    ctx = SimpleNamespace(analyses={"a": SimpleNamespace(joint_ranges=left),
                                    "b": SimpleNamespace(joint_ranges=inside)})
    marks = range_marks(load_claims(p), ctx)
    assert set(marks) == {"C1"}
    assert marks["C1"].startswith("Marked: a left its joint ranges (j2 up to 0.2 rad above its "
                                  "0.5 rad limit"), marks["C1"]
