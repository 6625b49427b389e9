"""What `make all` shows: each stage's start and end lines on stderr, plain off a terminal
(pipeline/progress.py), for the stages the claims run on demand (pipeline/orchestrate.py), and
the compile stage's plan (pipeline/compile.py)."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from pipeline import compile as kc
from pipeline import orchestrate
from pipeline.progress import stage
from pipeline.sim.run import RunOutcome
from pipeline.spec import load_spec, with_overrides

DONE = re.compile(r"^(.+): done in \d+\.\d s(?: \((.*)\))?$")


def test_a_stage_says_when_it_starts_and_ends_with_its_time(capsys):
    with stage("mission x", "(3 steps) -> logs/x/run.parquet") as st:
        st.done("complete")
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "mission x: started (3 steps) -> logs/x/run.parquet"
    assert DONE.match(err[1]).groups() == ("mission x", "complete")


def test_a_failing_stage_says_so_and_raises(capsys):
    with pytest.raises(ValueError), stage("sweep s"):
        raise ValueError("boom")
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "sweep s: started"
    assert re.fullmatch(r"sweep s: failed after \d+\.\d s", err[1])


def test_a_mission_the_claims_run_is_a_stage_with_plain_lines_off_a_terminal(
        tmp_path, capsys, monkeypatch):
    """stderr is not a terminal under pytest: no bar, no carriage return, only the lines."""
    spec = with_overrides(load_spec("short_nominal"), {"mission.duration": 0.09}, name="tiny")
    seen = {}

    def fake_run(spec_, logs_dir, progress, raise_on_failure):
        seen["progress"] = progress
        return RunOutcome(Path(logs_dir) / spec_.name / "run.parquet", "complete", 3, [])

    monkeypatch.setattr(orchestrate, "run_spec", fake_run)
    log = SimpleNamespace(spec=spec, path=tmp_path / "tiny" / "run.parquet", meta=None)
    monkeypatch.setattr(orchestrate, "verify_log", lambda path: log)
    orchestrate.ensure_run(spec, tmp_path)
    err = capsys.readouterr().err
    assert seen["progress"] is False and "\r" not in err
    lines = err.splitlines()
    assert lines[0] == (f"mission tiny: started ({spec.n_steps} steps) -> "
                        f"{tmp_path / 'tiny' / 'run.parquet'}")
    assert DONE.match(lines[1]).groups() == ("mission tiny", "complete")


def test_compile_stage_each_unit_once_and_its_waits_cannot_deadlock():
    shares = kc.SHARES
    assert sorted(u for share in shares for u in share) == sorted(kc.UNITS)
    done: set[str] = set()
    cursors = [0] * len(shares)
    while len(done) < len(kc.UNITS):  # run the shares in lock step, as the processes do
        progressed = False
        for i, share in enumerate(shares):
            if cursors[i] < len(share) and set(kc.UNITS[share[cursors[i]]].deps) <= done:
                done.add(share[cursors[i]])
                cursors[i] += 1
                progressed = True
        assert progressed, f"deadlock after {sorted(done)}"


def test_compile_is_skipped_without_the_jit(monkeypatch, capsys):
    from numba.core import config

    monkeypatch.setattr(config, "DISABLE_JIT", True)
    assert kc.compile_kernels() is None
    assert capsys.readouterr().err.startswith("compile: skipped")
