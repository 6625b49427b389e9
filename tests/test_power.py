"""The detectors' power study (eq. 40f): the crossing's interpolation by hand, a bad file
refused in one line, and a small study end to end on Dask, its rates counted again from its
own table."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from pipeline.montecarlo.power import crossing, read_power
from tests.conftest import run_cli

SMALL = """\
ripple: omega_ripple_sampled
quiet: omega_ripple_sampled_dt010
set: {mission.duration: 12.0}
seed: 1
samples: 2
noise: gyro_arw
levels: [0.0, 0.3]
"""


def test_crossing_interpolates_in_log_level():
    # missed 0.2 at 1e-3, 0.8 at 1e-1: half-way in log, 1e-2
    assert crossing([1e-3, 1e-1], [0.2, 0.8]) == pytest.approx(1e-2, rel=1e-12)
    assert crossing([0.0, 1e-2], [0.0, 1.0]) == pytest.approx(5e-3, rel=1e-12)
    assert crossing([1e-3, 1e-2], [0.6, 1.0]) == 1e-3
    assert crossing([1e-3, 1e-2], [0.0, 0.4]) is None


@pytest.mark.parametrize("text, field", [
    (SMALL.replace("noise: gyro_arw", "noise: wind"), "field noise"),
    (SMALL.replace("levels: [0.0, 0.3]", "levels: [0.3, 0.0]"), "field levels"),
    (SMALL.replace("samples: 2", "samples: 0"), "field samples"),
    (SMALL + "fixed: {gyro_lsb: 1.0e-3, wind: 2.0}\n", "field fixed.wind")])
def test_bad_power_files_are_refused(tmp_path, text, field):
    (tmp_path / "p.yaml").write_text(text)
    r = run_cli("power", tmp_path / "p.yaml", "--logs", tmp_path / "l", "--out", tmp_path / "o")
    assert r.returncode == 2 and field in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


@pytest.mark.slow
def test_power_study_end_to_end(tmp_path):
    """No noise: the ringing mission is seen by both detectors and the quiet one by neither.
    At 0.3 rad/√s (σ = 1.7 rad/s a sample at dt 0.03 s, ten times the ripple) both miss it.
    The result's rates are the table's counts."""
    (tmp_path / "p.yaml").write_text(SMALL)
    r = run_cli("power", tmp_path / "p.yaml", "--logs", tmp_path / "l", "--out", tmp_path / "o",
                timeout=300)
    assert r.returncode == 0, r.stderr
    res = read_power(tmp_path / "o" / "p" / "power.json")
    table = pd.read_parquet(tmp_path / "o" / "p" / "power.parquet")
    assert len(table) == 8 and (table["status"] == "complete").all()
    quiet0, ripple0 = res.levels[0].false_alarm, res.levels[0].missed
    assert quiet0 == {"lag1": 0.0, "spectral": 0.0} and ripple0 == {"lag1": 0.0, "spectral": 0.0}
    assert res.levels[1].missed["spectral"] == 1.0
    for j, level in enumerate(res.levels):
        at = table[table["level_index"] == j]
        for d in ("lag1", "spectral"):
            q, rr = at[at["case"] == "quiet"], at[at["case"] == "ripple"]
            assert level.false_alarm[d] == q[f"{d}_detects"].mean()
            assert level.missed[d] == 1 - rr[f"{d}_detects"].mean()
    assert res.crossing["spectral"] is not None and 0.0 < res.crossing["spectral"] <= 0.3
    assert not math.isnan(res.levels[0].ripple_amplitude)
    again = run_cli("power", tmp_path / "p.yaml", "--logs", tmp_path / "l", "--out",
                    tmp_path / "o", timeout=300)
    assert again.returncode == 0
    assert not pd.read_parquet(tmp_path / "o" / "p" / "power.parquet")["ran"].any()
