"""What `make all` shows: each stage's start and end lines on stderr, plain off a terminal
(pipeline/progress.py), for the stages the claims run on demand (pipeline/store/door.py), and
the compile stage's plan (pipeline/compile.py)."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from pipeline import compile as kc
from pipeline.progress import stage
from pipeline.sim import run as sim_run
from pipeline.sim.run import RunOutcome
from pipeline.spec import load_spec, with_overrides
from pipeline.store.door import ArtefactStore

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

    monkeypatch.setattr(sim_run, "run_spec", fake_run)
    log = SimpleNamespace(spec=spec, path=tmp_path / "tiny" / "run.parquet",
                          meta=SimpleNamespace(status="complete"))
    monkeypatch.setattr(ArtefactStore, "open_log", lambda self, path: log)
    ArtefactStore(tmp_path).run(spec)
    err = capsys.readouterr().err
    assert seen["progress"] is False and "\r" not in err
    lines = err.splitlines()
    assert lines[0] == (f"mission tiny: started ({spec.n_steps} steps) -> "
                        f"{tmp_path / 'tiny' / 'run.parquet'}")
    assert DONE.match(lines[1]).groups() == ("mission tiny", "complete")


def test_compile_stage_each_unit_once_and_its_waits_cannot_deadlock():
    """Two processes taking units as the stage hands them out (each the first ready one)
    finish every unit once, whichever of the two running units ends first."""
    assert all(set(u.deps) <= set(kc.UNITS) for u in kc.UNITS.values())
    for first_ends_first in (True, False):
        done: set[str] = set()
        running: list[str] = []
        order = []
        while len(done) < len(kc.UNITS):
            while len(running) < 2 and (name := kc.next_unit(done, done | set(running))):
                running.append(name)
            assert running, f"deadlock after {sorted(done)}"
            ended = running.pop(0 if first_ends_first else -1)
            done.add(ended)
            order.append(ended)
        assert sorted(order) == sorted(kc.UNITS)
        for i, name in enumerate(order):  # a unit never ends before what it waits for
            assert set(kc.UNITS[name].deps) <= set(order[:i])


def test_next_unit_takes_the_first_ready_unit_in_order():
    names = list(kc.UNITS)
    free = [n for n in names if not kc.UNITS[n].deps]
    assert kc.next_unit(set(), set()) == free[0]
    assert kc.next_unit(set(), set(free)) is None  # the rest wait for something
    everything_but_step = set(names) - {"step"}
    assert kc.next_unit(everything_but_step, everything_but_step) == "step"


def test_compile_is_skipped_without_the_jit(monkeypatch, capsys):
    from numba.core import config

    monkeypatch.setattr(config, "DISABLE_JIT", True)
    assert kc.compile_kernels() is None
    assert capsys.readouterr().err.startswith("compile: skipped")
