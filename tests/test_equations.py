"""The equation ↔ code checks, one pytest id per check: the same suite the cross-check report
renders (``pipeline.verify.suite``), so a broken equation fails its own test id."""

from __future__ import annotations

import pytest

from pipeline.verify.checks_base import run_check
from pipeline.verify.suite import all_checks, check_id

CHECKS = list(all_checks())


@pytest.mark.parametrize("check", CHECKS, ids=[check_id(c) for c in CHECKS])
def test_equation(check):
    r = run_check(check)
    assert r.passed, (f"eq. {check.eq} ({check.title}) against {check.target}: "
                      f"max |diff| {r.max_abs_diff:.3g} > tol {r.tol:.3g}; {r.note}")


def test_the_suite_is_collected_explicitly_and_once():
    ids = [check_id(c) for c in CHECKS]
    assert len(ids) == len(set(ids)) == 64
    assert list(all_checks()) == CHECKS  # a second collection gives the same list, in order
