"""Every count, seed and size a user gives a study is checked before any work (issue 49 item
3): a one-line error naming it, exit 2, in seconds and without growing memory, nothing
written."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from conftest import run_cli_in_process

BASE = """\
description: counts
mission: omega_ripple_sampled_delay_dt0035
set: {{mission.duration: {duration}}}
seed: {seed}
{samples}target: {{p: {p}, confidence: 0.9}}
ripple_max: 1.0e-4
dispersions:
  controller.gains.bus.D: {{dist: normal, sd: 0.1{truncate}}}
"""


def _file(tmp_path: Path, duration=0.1, seed=7, samples="samples: 2\n", p=0.9, truncate=""):
    path = tmp_path / "counts.yaml"
    path.write_text(BASE.format(duration=duration, seed=seed, samples=samples, p=p,
                                truncate=truncate))
    return path


@pytest.mark.parametrize("fields,extra,needle", [
    ({"samples": "samples: 1000000000\n"}, [], "field samples: 1,000,000,000 samples, over"),
    ({}, ["--samples", "1000000000"], "--samples 1000000000: 1,000,000,000 samples, over"),
    ({"samples": "", "p": 0.9999999999}, [], "field target: 23,025,8"),
    ({}, ["--samples", "0"], "--samples"),
    ({}, ["--samples", "-1"], "--samples"),
    ({"truncate": ", truncate: 1.0e-300"}, [], "truncate"),
    ({"seed": -1}, [], "seed"),
    ({"duration": 1.0e6}, [], "field mission.duration"),
    ({}, ["--workers", "1000"], "--workers 1000: more than this machine's"),
    ({}, ["--workers", "0"], "--workers 0"),
    ({}, ["--scheduler", "not an address"], "not a scheduler address"),
])
def test_a_bad_count_is_one_line_before_any_work(tmp_path, fields, extra, needle):
    path = _file(tmp_path, **fields)
    t0 = time.perf_counter()
    r = run_cli_in_process("montecarlo", path, "--logs", tmp_path / "logs", "--out",
                           tmp_path / "out", *extra)
    assert time.perf_counter() - t0 < 30
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    # argparse's own refusals print its usage before their one line
    assert needle in lines[-1] and (len(lines) == 1 or lines[0].startswith("usage:")), lines
    assert not (tmp_path / "logs").exists() and not (tmp_path / "out").exists()


def test_the_study_time_is_judged_on_its_workers(tmp_path, monkeypatch):
    """Each sample within the budget, the samples together past it on one worker."""
    monkeypatch.setenv("BREVE_TIME_BUDGET_H", "0.001")  # 3.6 s
    path = _file(tmp_path, duration=1.0, samples="samples: 100\n")
    r = run_cli_in_process("montecarlo", path, "--workers", "1", "--logs", tmp_path / "logs",
                           "--out", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    assert "100 samples on 1 workers would take about" in r.stderr, r.stderr


@pytest.mark.parametrize("field", ["config_sampling.seed", "target.seed",
                                   "mission.plant.timing.seed", "mission.plant.sensors.seed"])
def test_a_negative_seed_in_a_spec_is_refused_by_validate(tmp_path, field):
    *blocks, key = field.split(".")
    text = "extends: omega_ripple_sampled_delay_dt0035\n"
    indent = ""
    for b in blocks:
        text += f"{indent}{b}:\n"
        indent += "  "
    text += f"{indent}{key}: -5\n"
    spec = tmp_path / "neg.yaml"
    spec.write_text(text)
    r = run_cli_in_process("validate", spec)
    assert r.returncode == 2, r.stderr
    assert field in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_workers_up_to_the_cores_are_taken(tmp_path):
    """The bound is the machine's: as many workers as cores pass the check."""
    from pipeline.sweep.cluster import ClusterOptions, check_workers

    check_workers(ClusterOptions(workers=os.cpu_count() or 1))
