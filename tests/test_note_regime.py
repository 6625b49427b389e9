"""The seed note's regime (issue 50): the theory taken at the window's step of σ_min(Γ) nearest
a target (``analyze --at-s-min-G``, a claims run's ``at_s_min_G``), and the register that reads
one run's chosen σ for another."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import run_cli, run_cli_in_process

from pipeline.analysis.stages import representative_nearest
from pipeline.claims.register import load_claims, needed_runs
from pipeline.errors import SpecError
from pipeline.paths import SHIPPED_SPECS


def test_the_nearest_step_to_the_target_among_those_above_the_floor():
    # Step 1 is the nearest of all (exactly the target) but below the floor 0.02; of the
    # others step 3 is nearest; steps 2 and 5 tie, and a tie goes to the earlier.
    s_min_G = np.array([0.05, 0.032, 0.0331, 0.0325, 0.2, 0.0331])
    s_min_J = np.array([0.1, 0.01, 0.1, 0.1, 0.1, 0.1])
    rep = representative_nearest(s_min_G, s_min_J, 0.02, 0.032)
    assert rep.index == 3 and rep.below_floor == 1 and rep.above_floor
    assert "nearest 0.032" in rep.rule and "1 steps below it left out" in rep.rule
    tie = representative_nearest(s_min_G, s_min_J, 0.02, 0.0331)
    assert tie.index == 2
    every_below = representative_nearest(s_min_G, np.zeros(6), 0.02, 0.2)
    assert every_below.index == 4 and not every_below.above_floor


def _register(tmp_path, runs: str):
    p = tmp_path / "claims.yaml"
    p.write_text("runs:\n" + runs + "claims:\n  - id: C1\n    kind: physics\n    expect: hold\n"
                 "    statement: x\n    checks:\n      - {metric: \"b:dominant.lag1\", op: lt, "
                 "threshold: 0}\n")
    return p


def test_the_register_reads_a_target_from_a_run_analysed_before_it(tmp_path):
    cf = load_claims(_register(tmp_path, "  a: {spec: nominal, at_s_min_G: \"note:s_min_G."
                                         "nominal\"}\n  b: {spec: nominal, at_s_min_G: "
                                         "\"a:theory.s_min_G\"}\n"))
    assert needed_runs(cf) == ["a", "b"]
    shipped = load_claims(SHIPPED_SPECS / "claims.yaml")
    order = needed_runs(shipped)
    assert order.index("reach_note") < order.index("reach_dt010")


@pytest.mark.parametrize("runs, words", [
    ("  b: {spec: nominal, at_s_min_G: \"zz:theory.s_min_G\"}\n", "its source is the note"),
    ("  b: {spec: nominal, at_s_min_G: \"b:theory.s_min_G\"}\n", "its source is the note"),
    ("  a: {spec: nominal, at_s_min_G: \"b:theory.s_min_G\"}\n"
     "  b: {spec: nominal, at_s_min_G: \"a:theory.s_min_G\"}\n", "a cycle"),
    ("  b: {spec: nominal, at_s_min_G: -0.5}\n", "a finite σ above 0"),
])
def test_a_target_the_register_cannot_read_is_refused_in_one_line(tmp_path, runs, words):
    with pytest.raises(SpecError) as err:
        load_claims(_register(tmp_path, runs))
    assert words in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_analyze_at_a_target_takes_the_windows_nearest_step(tmp_path):
    """On the short reach run (σ_min(Γ) inside the γ ramp): the record's step is the window's
    step of s_min_G nearest 0.032 among those at or above the damped inverse's floor, found
    here from the log's own columns."""
    spec = tmp_path / "reach.yaml"
    spec.write_text("extends: short_omega_ripple_reach\nmission: {duration: 12.0}\n")
    r = run_cli_in_process("run", spec, "--out", tmp_path / "logs")
    assert r.returncode == 0, r.stderr
    log = tmp_path / "logs" / "reach" / "run.parquet"
    r = run_cli("analyze", log, "--at-s-min-G", "0.032", "--out", tmp_path / "rep")
    assert r.returncode == 0, r.stderr
    rec = json.loads((tmp_path / "rep" / "reach" / "analysis.json").read_text())
    t = pq.read_table(log, columns=["s_min_G", "s_min_J"])
    s_G, s_J = (t.column(c).to_numpy() for c in ("s_min_G", "s_min_J"))
    n = len(s_G)
    window = np.arange(n // 2, n)
    ok = window[s_J[window] >= 0.02]
    want = int(ok[np.argmin(np.abs(s_G[ok] - 0.032))])
    # The theory's σ_min is its own SVD of that step's Γ, from the identity; the log's was
    # started from the step before's vectors: equal to a few ε ‖Γ‖ (eq. 19).
    assert rec["theory"]["step"] == want
    assert rec["theory"]["s_min_G"] == pytest.approx(s_G[want], rel=0, abs=1e-14)
    assert "nearest 0.032" in rec["theory"]["rule"]
    bad = run_cli_in_process("analyze", log, "--at-s-min-G", "-1", "--out", tmp_path / "rep")
    assert bad.returncode == 2 and "give a finite σ above 0" in bad.stderr, bad.stderr


def test_a_record_taken_at_a_target_is_not_reused_as_the_default_one(tmp_path):
    """The store reuses a record only for the rule that chose its step: the default request
    after a target analyses again (the median step), a target request after it again, and the
    same target twice is up to date."""
    spec = tmp_path / "reach.yaml"
    spec.write_text("extends: short_omega_ripple_reach\nmission: {duration: 12.0}\n")
    assert run_cli_in_process("run", spec, "--out", tmp_path / "logs").returncode == 0
    log = tmp_path / "logs" / "reach" / "run.parquet"
    out = tmp_path / "rep"
    record = out / "reach" / "analysis.json"

    def analyse(*extra):
        r = run_cli_in_process("analyze", log, "--out", out, *extra)
        assert r.returncode == 0, r.stderr
        return "up to date" in r.stdout, json.loads(record.read_text())["theory"]

    reused, th = analyse("--at-s-min-G", "0.032")
    assert not reused and th["s_min_G_target"] == 0.032
    reused, th = analyse()
    assert not reused and "s_min_G_target" not in th and "median" in th["rule"]
    assert analyse()[0]
    assert not analyse("--at-s-min-G", "0.032")[0]
    assert analyse("--at-s-min-G", "0.032")[0]
