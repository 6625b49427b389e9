"""A mission too short to judge says so (issue 51, eq. 36): its record's agreement is null,
never false, and the terminal, the mechanism page and the fix table name the least mission
that would determine it; a still robot says that instead and names no duration."""

from __future__ import annotations

import json

import numpy as np
from conftest import run_cli_in_process

from pipeline.analysis.ringing import MIN_STEPS, SHORT, STILL, ring
from pipeline.analysis.verdict import judge, mode_loops
from pipeline.sim import margins as mg
from pipeline.spec import load_spec


def test_a_hundred_step_mission_is_undetermined_and_names_the_mission_that_would_do(
        tmp_path):
    spec = tmp_path / "hundred.yaml"
    spec.write_text("extends: short_nominal\nmission: {duration: 3.0}\n")  # 100 steps
    r = run_cli_in_process("run", spec, "--out", tmp_path / "logs")
    assert r.returncode == 0, r.stderr
    log = tmp_path / "logs" / "hundred" / "run.parquet"
    r = run_cli_in_process("analyze", log, "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    record = json.loads((tmp_path / "out" / "hundred" / "analysis.json").read_text())
    p = record["prediction"]
    assert p["agrees"] is None  # null, never false
    # The second half of a mission of n steps holds ⌈n/2⌉: 399 steps hold 200.
    assert p["least_mission_steps"] == 2 * MIN_STEPS - 1 == 399
    assert all(j["measured"]["undetermined"] == SHORT for j in p["modes"])
    assert "a mission of at least 399 steps (11.97 s at dt 0.03 s) would determine it" in (
        r.stdout)
    assert "DISAGREE" not in r.stdout


def test_a_still_robot_is_undetermined_without_a_duration():
    """Synthetic ν̆ with known answers: no motion at all over 1000 steps (a still robot); one
    mode's coordinate moving slowly and the rest still; a window too short."""
    spec = load_spec("nominal")
    M = np.diag([0.015625, 0.1, 0.1, 2.0, 2.0, 2.0, 0.01, 0.01, 0.01])
    D = np.eye(9)
    modes = mode_loops(M, D, 0.01, "explicit", 0, mg.Requirement(6.0, 30.0, 1.0))
    still = np.full((1000, 9), 0.25)
    p = judge(modes, M, still, 0.01, 0, spec.controller.limits, 0.5, least_steps=399)
    assert p.agrees is None and p.least_mission_steps is None
    assert "no motion above the numbers' resolution (a still robot)" in p.undetermined_why
    assert "steps" not in p.undetermined_why.split("(a still robot)")[1]
    assert ring(still[:, 0], "x", "rad/s").undetermined == STILL
    # One mode's coordinate moving slowly (quiet, as predicted), the others still: still
    # undetermined, by those eight, and not "a still robot".
    moving = still.copy()
    moving[:, 2] += 0.1 * np.sin(2 * np.pi * np.arange(1000) / 500)
    part = judge(modes, M, moving, 0.01, 0, spec.controller.limits, 0.5, least_steps=399)
    assert part.agrees is None and part.undetermined == 8
    assert part.undetermined_why.startswith("8 of 9 modes' coordinates show no motion")
    assert "still robot" not in part.undetermined_why
    short = judge(modes, M, still[:MIN_STEPS - 1], 0.01, 0, spec.controller.limits, 0.5,
                  least_steps=399)
    assert short.agrees is None and short.least_mission_steps == 399
    # A disagreement is never hidden by an undetermined mode: the modes say stable, the map
    # says unstable, and the verdict is false.
    assert judge(modes, M, still, 0.01, 0, spec.controller.limits, 1.5).agrees is False
