"""The equation cross-check: each numbered equation, the code that cites it, and its checks.

Rows come from the headings of docs/equations.md (or, if that file is missing, from the
equation numbers the code cites). The code column lists every site whose docstring or comment
cites the equation (file:line from the syntax tree). A check belongs to the row of the
equation it names, and its code under test must be a site that cites that equation: if the
site is gone or no longer cites it, the check fails, so the pairing cannot rot silently.
The result is data (``GNC/cross_check.json``); :mod:`pipeline.reports.render` renders it.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.atomic_files import atomic_write_text
from pipeline.paths import PROJECT_ROOT
from pipeline.provenance.keys import source_version
from pipeline.verify.checks_base import CheckResult, defining_qualname
from pipeline.verify.sources import (
    EQUATIONS_MD,
    CodeIndex,
    Equation,
    Site,
    label_matches,
    parse_equations,
    scan_package,
)
from pipeline.verify.suite import run_checks


@dataclass
class PairedCheck:
    result: CheckResult
    site: Site | None  # the code under test, found in the index

    @property
    def status(self) -> str:
        return self.result.status


@dataclass
class Row:
    equation: Equation
    sites: list[Site]
    checks: list[PairedCheck] = field(default_factory=list)

    @property
    def status(self) -> str:
        if not self.sites:
            return "NO CODE"
        if any(c.status != "PASS" for c in self.checks):
            return "FAIL"
        return "PASS" if self.checks else "NO CHECK"

    @property
    def worst(self) -> PairedCheck | None:
        """The check with the largest difference relative to its tolerance (failures first)."""
        if not self.checks:
            return None

        def key(c: PairedCheck):
            r = c.result
            ratio = r.max_abs_diff / r.tol if r.tol and r.tol > 0 else r.max_abs_diff
            return (c.status == "PASS", -(ratio if ratio == ratio else float("inf")))

        return sorted(self.checks, key=key)[0]


@dataclass
class CrossCheck:
    rows: list[Row]
    orphans: list[PairedCheck]  # checks of an equation the document does not have
    source: str  # where the rows came from
    n_sites: int
    source_version: str  # every source of the package (the checks inspect them all)

    def summary(self) -> dict[str, int]:
        st = [r.status for r in self.rows]
        n_checks = sum(len(r.checks) for r in self.rows) + len(self.orphans)
        failed = sum(c.status != "PASS" for r in self.rows for c in r.checks)
        return {
            "rows": len(self.rows), "pass": st.count("PASS"), "fail": st.count("FAIL"),
            "unchecked": st.count("NO CHECK"), "uncited": st.count("NO CODE"),
            "checks": n_checks, "checks_failed": failed + len(self.orphans),
            "orphans": len(self.orphans),
            "failures": st.count("FAIL") + len(self.orphans),
        }


def _rows_from_code(index: CodeIndex) -> list[Equation]:
    labels = {c for s in index.sites for c in s.cites}

    def order(label: str):
        m = re.fullmatch(r"(\d+)([a-z]?)", label)
        return (int(m.group(1)), m.group(2)) if m else (10**6, label)

    return [Equation(label, "(no docs/equations.md: numbered from the code's citations)", "", 0)
            for label in sorted(labels, key=order)]


def _row_for(eq_label: str, numbers: set[str]) -> str | None:
    if eq_label in numbers:
        return eq_label
    parent = re.match(r"\d+", eq_label)
    return parent.group(0) if parent and parent.group(0) in numbers else None


def _pair(result: CheckResult, index: CodeIndex, headings: set[str]) -> PairedCheck:
    """Find the check's code under test; a missing or non-citing site makes it fail."""
    eq, found = result.check.eq, []
    for path in result.check.targets:
        qual = defining_qualname(path)
        sites = index.by_qualname(qual) if qual else []
        citing = [s for s in sites if label_matches(eq, s.cites, headings | {eq})]
        if citing:
            return PairedCheck(result, citing[0])
        found += sites
    names = " or ".join(result.check.targets)
    why = (f"code under test {names} cites {', '.join(found[0].cites)}, not eq. {eq}" if found
           else f"code under test {names} not found among the sites that cite an equation")
    failed = CheckResult(result.check, result.inputs, result.max_abs_diff, result.tol, "FAIL",
                         "; ".join(x for x in (why, result.note) if x))
    return PairedCheck(failed, found[0] if found else None)


def build_cross_check(equations_md: Path = EQUATIONS_MD) -> CrossCheck:
    """Scan the docs and the code, run every check, and pair them into rows."""
    index = scan_package()
    equations = parse_equations(equations_md)
    source = str(Path(equations_md).relative_to(PROJECT_ROOT)) if Path(equations_md).is_relative_to(
        PROJECT_ROOT) else str(equations_md)
    if not equations:
        equations, source = _rows_from_code(index), "the code's citations (docs missing)"
    numbers = {e.number for e in equations}
    rows = {e.number: Row(e, index.citing(e.number, numbers)) for e in equations}
    orphans = []
    for result in run_checks():
        paired = _pair(result, index, numbers)
        label = _row_for(result.check.eq, numbers)
        if label is None:
            orphans.append(paired)
        else:
            rows[label].checks.append(paired)
    return CrossCheck(list(rows.values()), orphans, source, len(index.sites),
                      source_version())


def write_cross_check_json(out_dir: Path, cc: CrossCheck) -> Path:
    """``out_dir/GNC/cross_check.json``: the summary and each row's status."""
    path = Path(out_dir) / "GNC" / "cross_check.json"
    data = {"source_version": cc.source_version, "source": cc.source, **cc.summary(),
            "rows_status": {r.equation.number: r.status for r in cc.rows}}
    atomic_write_text(path, json.dumps(data, indent=1) + "\n")
    return path
