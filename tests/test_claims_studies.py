"""A claim that needs a study (docs/montecarlo.md, "the decision and the studies"): deferred
while no current result of the study file's full N exists, naming the N that ran and the most
confidence that N can show (eq. 38d, against its closed form here); judged once `studies` has
flown the full N, and the claims evaluated again when a result appears. The decision
(`claims`, reading) flies nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.conftest import run_cli

# Six samples of 0.5 s of the seed robot's sampled flight loop at dt 3.5 ms (143 steps each).
STUDY = """\
description: test study
mission: omega_ripple_sampled_delay_dt0035
set: {mission.duration: 0.5}
seed: 11
samples: 6
target: {p: 0.9, confidence: 0.5}
ripple_max: 1.0e-4
dispersions:
  controller.gains.bus.D: {dist: uniform, rel: 0.1}
"""

CLAIMS = """\
logs: {logs}
montecarlo:
  small: {{file: study.yaml{samples}}}
claims:
  - id: S1
    kind: physics
    statement: 'Every one of the study''s samples is judged.'
    expect: hold
    checks:
      - {{metric: "montecarlo:small.errored", op: eq, threshold: 0}}
      - {{metric: "montecarlo:small.samples", op: eq, threshold: 6}}
"""


def _claims(tmp_path: Path, samples: int | None) -> Path:
    path = tmp_path / ("claims.yaml" if samples is None else f"claims_{samples}.yaml")
    path.write_text(CLAIMS.format(logs=tmp_path / "logs",
                                  samples="" if samples is None else f", samples: {samples}"))
    return path


def _claim(out: Path) -> dict:
    return json.loads((out / "claims.json").read_text())["claims"][0]


@pytest.mark.slow
def test_a_claim_on_a_study_is_deferred_until_the_full_n_has_flown(tmp_path):
    (tmp_path / "study.yaml").write_text(STUDY)
    full, small = _claims(tmp_path, None), _claims(tmp_path, 3)

    # The decision reads: no result, nothing flown, deferred with N 0 (exit 0).
    r = run_cli("claims", "--claims", full, "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    c = _claim(tmp_path / "out")
    assert c["status"] == "DEFERRED" and "make studies" in c["deferred"]
    assert "no current result" in c["deferred"] and "0 samples can show p 0.9 at no more " \
        "than 0 % confidence" in c["deferred"], c["deferred"]
    assert not (tmp_path / "logs" / "montecarlo").exists()
    assert "S1 DEFERRED" in r.stdout

    # Flown at a declared N below the file's: judged on what ran, still deferred, with what
    # three samples can show: 1 − 0.9³ = 27.1 %, six 46.9 %.
    r = run_cli("claims", "--claims", small, "--out", tmp_path / "ci", "--studies", "run",
                timeout=300)
    assert r.returncode == 0, r.stderr
    c = _claim(tmp_path / "ci")
    assert c["status"] == "DEFERRED", c
    assert "3 of the 6 samples ran" in c["deferred"], c["deferred"]
    assert f"at no more than {100 * (1 - 0.9**3):.3g} % confidence" in c["deferred"]
    assert f"6 at {100 * (1 - 0.9**6):.3g} %" in c["deferred"]
    assert c["checks"][1]["value"] == 3 and c["checks"][0]["value"] == 0

    # `studies` flies the full N (the three kept records reused), then the claims read it.
    r = run_cli("studies", "--claims", full, "--out", tmp_path / "out", timeout=600)
    assert r.returncode == 0, r.stderr
    c = _claim(tmp_path / "out")
    assert c["status"] == "PASS" and not c["deferred"], c
    table = tmp_path / "out" / "montecarlo" / "study" / "montecarlo.parquet"
    import pandas as pd

    assert int(pd.read_parquet(table)["ran"].sum()) == 3
    # The index reads it under the decision: current (its own file, not a shipped one).
    index = (tmp_path / "out" / "index.html").read_text()
    assert "Across the dispersions</strong> (the current Monte Carlos" in index
    assert "not decided here" not in index and ">no</span>: made by other code" not in index

    # Up to date now; a study's result altered: not read, deferred again.
    r = run_cli("claims", "--claims", full, "--out", tmp_path / "out")
    assert r.returncode == 0 and "claims: up to date" in r.stderr, r.stderr
    verdict = tmp_path / "out" / "montecarlo" / "study" / "verdict.json"
    data = json.loads(verdict.read_text())
    data["samples"] = 852
    verdict.write_text(json.dumps(data))
    r = run_cli("claims", "--claims", full, "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    assert _claim(tmp_path / "out")["status"] == "DEFERRED"
    assert "altered or damaged" in r.stderr
