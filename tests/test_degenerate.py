"""Degenerate inputs get a one-line refusal or "undetermined", never a verdict (issue 36,
item 4): a mission shorter than one step, a log too short for its analysis window's
statistics, and series too short or too still for eq. 36's ringing test."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_cli_in_process

from pipeline.analysis.ringing import MIN_STEPS, ring
from pipeline.errors import SpecError
from pipeline.spec import load_spec, with_overrides


def test_a_mission_shorter_than_one_step_is_refused():
    with pytest.raises(SpecError, match="shorter than one step"):
        with_overrides(load_spec("short_nominal"), {"mission.duration": 0.01})


def test_a_log_too_short_for_its_window_is_refused_in_one_line_naming_it(tmp_path):
    spec = tmp_path / "two.yaml"
    spec.write_text("extends: short_nominal\nmission: {duration: 0.06}\n")
    run = run_cli_in_process("run", spec, "--out", tmp_path / "logs")
    assert run.returncode == 0, run.stderr
    log = tmp_path / "logs" / "two" / "run.parquet"
    out = run_cli_in_process("analyze", log, "--out", tmp_path / "rep")
    assert out.returncode == 2
    last = out.stderr.strip().splitlines()
    assert len(last) == 1 and str(log) in last[0] and "fewer than the 3" in last[0]
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("series", [np.zeros(1000), np.full(1000, 3.0),
                                    np.resize([1.0, -1.0], MIN_STEPS - 1),
                                    np.r_[np.nan, np.ones(999)]])
def test_a_series_too_short_still_or_not_finite_rings_undetermined(series):
    r = ring(series, "x", "1")
    assert r.rings is None and r.peak_to_peak is None and r.period_steps is None


def test_the_line_share_never_exceeds_one_at_the_bands_edge():
    """A tone just past the band's edge (period 21 steps): the line's bins outside the band
    were counted against the band's power (a share of 1856 was read)."""
    k = np.arange(1000, dtype=float)
    r = ring(np.sin(2 * np.pi * k / 21), "x", "1")
    assert 0.0 <= r.line_share <= 1.0 and not r.rings
