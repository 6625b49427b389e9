"""``analyze --against`` says what it compares: robot, dt, integrator, duration and windows in
seconds; another robot is refused (exit 2); different durations and windows are named."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from report_fixtures import write_spec

from pipeline.cli import main
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    """4 s runs of the seed robot at dt 0.03 s and of the servicer, and a 6 s run of the seed
    robot at dt 0.01 s (a longer run: its window is another stretch of time)."""
    root = tmp_path_factory.mktemp("against")
    long = root / "a_dt010_long.yaml"
    long.write_text("extends: short_omega_ripple_dt010\nmission: {duration: 6.0}\n")
    specs = {"a_nominal": write_spec(root, "a_nominal", "short_nominal"),
             "a_servicer": write_spec(root, "a_servicer", "short_servicer_nominal"),
             "a_dt010_long": long}
    return {name: run_spec(load_spec(path), root / "logs").path for name, path in specs.items()}


def _record(out: Path, name: str) -> dict:
    return json.loads((out / name / "analysis.json").read_text())


def test_against_states_robot_dt_duration_and_windows(logs, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["analyze", str(logs["a_nominal"]), "--against", str(logs["a_dt010_long"]),
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    rec = _record(out, "a_nominal")
    other = rec["comparison"]["other"]
    line = next(ln for ln in text.splitlines() if "compares a_nominal with a_dt010_long" in ln)
    assert "same robot" in line and f"I_zz,bus {rec['robot']['I_zz_bus']:.4g} kg·m²" in line
    assert "dt 0.03 s vs 0.01 s" in line
    da, db = rec["n_steps"] * rec["dt"], other["n_steps"] * other["dt"]
    assert f"duration {da:.4g} s vs {db:.4g} s" in line
    sa = rec["window"]["start_step"] * rec["dt"]
    sb = other["window"]["start_step"] * other["dt"]
    assert re.search(rf"window {sa:.4g}–{da:.4g} s vs {sb:.4g}–{db:.4g} s", line)
    assert f"note: different durations ({da:.4g} s vs {db:.4g} s)" in text
    assert "note: different windows" in text
    # Coverage grows along the orbit: runs of different lengths have no coverage difference.
    assert rec["comparison"]["coverage_diff_pp"] is None
    assert rec["comparison"]["mission_differs"] == ["mission.duration"]
    assert "coverage difference not compared (another mission)" in text
    assert "note: the specs also differ in mission.duration" in text


def test_against_names_no_difference_when_durations_agree(logs, tmp_path, capsys):
    """Same run against itself: equal durations and windows, and the note that the
    comparison tests neither dt nor the integrator."""
    log = str(logs["a_nominal"])
    assert main(["analyze", log, "--against", log, "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "compares a_nominal with a_nominal" in text
    assert "different durations" not in text and "different windows" not in text
    assert "tests neither the step nor the integrator" in text
    rec = _record(tmp_path, "a_nominal")
    assert rec["comparison"]["coverage_diff_pp"] == 0.0 and "coverage difference 0.00 pp" in text
    assert rec["comparison"]["mission_differs"] == [] and "specs also differ" not in text


def test_against_another_robot_is_refused(logs, tmp_path, capsys):
    out = tmp_path / "rep"
    code = main(["analyze", str(logs["a_nominal"]), "--against", str(logs["a_servicer"]),
                 "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1
    assert "another robot" in err and "servicer_ur3.urdf" in err and "seed_ur3_box.xml" in err
    assert not out.exists(), "a refused comparison wrote something"
