"""The one suite of equation ↔ code checks, collected by an explicit generator.

:func:`all_checks` yields every check of the ``checks_*`` modules in a fixed order. The suite
is used twice: ``tests/test_equations.py`` parametrises pytest with one test id per check, and
the cross-check report (:mod:`pipeline.verify.cross_check`) renders the same results.
"""

from __future__ import annotations

from collections.abc import Iterator

from pipeline.verify import (
    checks_analysis,
    checks_loop,
    checks_model,
    checks_redundancy,
    checks_step,
)
from pipeline.verify.checks_base import Check, CheckResult, run_check

MODULES = (checks_model, checks_redundancy, checks_loop, checks_step, checks_analysis)


def all_checks() -> Iterator[Check]:
    """Every check, module by module in ``MODULES`` order, each in its ``CHECKS`` order."""
    for module in MODULES:
        for fn in module.CHECKS:
            yield fn.check


def check_id(c: Check) -> str:
    """A stable pytest id: the equation and the check function's name."""
    return f"eq{c.eq}-{c.fn.__name__.lstrip('_')}"


def run_checks() -> list[CheckResult]:
    return [run_check(c) for c in all_checks()]
