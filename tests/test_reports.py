"""Reports: equation parsing, the code index, the cross-check, rendering, escaping, baselines."""

from __future__ import annotations

import inspect
import json
import re
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import footer_metadata
from report_fixtures import analyse_pair, built, write_spec

from pipeline.claims import baselines
from pipeline.reports.render import render_all
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec
from pipeline.verify import sources
from pipeline.verify.checks_base import Check, CheckResult, Outcome, run_check
from pipeline.verify.cross_check import _pair, build_cross_check

# -- equations and code sites -------------------------------------------------------------

DOC = """# Title
## Index
| 1 | not a heading |
### (1) First: Γ
text
```
Γ = [ … ]
### (99) inside a fence is not a heading
```
### (13a) A sub-label
## (eq. 7) Another form
#### Eq. 8: and another
### (1) a repeated number keeps its first heading
### Mechanism (no number)
"""


def test_equation_headings_are_parsed_in_their_forms(tmp_path):
    p = tmp_path / "equations.md"
    p.write_text(DOC)
    eqs = sources.parse_equations(p)
    assert [e.number for e in eqs] == ["1", "13a", "7", "8"]
    assert eqs[0].title == "First: Γ"
    assert eqs[0].body.startswith("Γ = [ … ]")
    assert sources.parse_equations(tmp_path / "missing.md") == []


@pytest.mark.parametrize("text,labels", [
    ("(eq. 6)", ("6",)),
    ("eqs. 13–16", ("13", "14", "15", "16")),
    ("(eqs. 13, 20)", ("13", "20")),
    ("eq. 13e, 22 and eq. 15b", ("13e", "22", "15b")),
    ("no citation, equation 5", ()),
])
def test_citations(text, labels):
    assert sources.parse_citations(text) == labels


def test_sub_labels_belong_to_their_parent_heading_unless_they_have_their_own():
    assert sources.label_matches("13", ("13c",), {"13"})
    assert not sources.label_matches("13", ("13c",), {"13", "13c"})
    assert not sources.label_matches("1", ("13",), {"1", "13"})


def test_code_sites_carry_the_line_that_inspect_reports():
    """The index's file:line for a function equals the line of its ``def`` by inspect."""
    from pipeline.sim import sampling

    index = sources.scan_package()
    site = index.by_qualname("pipeline.sim.sampling.scale_by_svd")[0]
    lines, start = inspect.getsourcelines(sampling.scale_by_svd)
    offset = next(i for i, line in enumerate(lines) if line.lstrip().startswith("def "))
    assert site.where == f"pipeline/sim/sampling.py:{start + offset}"
    assert "20" in site.cites
    assert not any(s.path.startswith("pipeline/reports/") for s in index.sites)


# -- the cross-check ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def cross_check():
    return build_cross_check()


def test_cross_check_has_one_row_per_equation_each_with_code_and_a_check(cross_check):
    numbers = [e.number for e in sources.parse_equations()]
    assert [r.equation.number for r in cross_check.rows] == numbers
    for row in cross_check.rows:
        assert row.sites, f"eq. {row.equation.number}: no code found"
        assert row.checks, f"eq. {row.equation.number}: no numerical check"


def test_cross_check_rows_pass(cross_check):
    bad = {r.equation.number: [c.result.note for c in r.checks if c.status != "PASS"]
           for r in cross_check.rows if r.status != "PASS"}
    assert not bad
    assert not cross_check.orphans


def test_a_check_outside_its_tolerance_fails():
    c = Check("20", "deliberately wrong", ("pipeline.sim.sampling.scale_by_svd",),
              lambda: Outcome("x", 1e-3, 1e-12))
    assert run_check(c).status == "FAIL"
    boom = Check("20", "raises", ("pipeline.sim.sampling.scale_by_svd",),
                 lambda: 1 / 0)
    r = run_check(boom)
    assert r.status == "FAIL" and "ZeroDivisionError" in r.note


def test_a_check_whose_code_does_not_cite_its_equation_fails():
    index = sources.scan_package()
    ok = CheckResult(Check("20", "t", ("pipeline.sim.sampling.scale_by_svd",), lambda: None),
                     "", 0.0, 1.0, "PASS", "")
    assert _pair(ok, index, {"20", "21"}).status == "PASS"
    wrong_eq = CheckResult(Check("21", "t", ("pipeline.sim.sampling.scale_by_svd",),
                                 lambda: None), "", 0.0, 1.0, "PASS", "")
    assert _pair(wrong_eq, index, {"20", "21"}).status == "FAIL"
    gone = CheckResult(Check("20", "t", ("pipeline.sim.sampling.no_such_function",),
                             lambda: None), "", 0.0, 1.0, "PASS", "")
    paired = _pair(gone, index, {"20"})
    assert paired.status == "FAIL" and "not found" in paired.result.note


# -- rendered reports ---------------------------------------------------------------------

class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("href", "src"):
            if a.get(key):
                self.links.append(a[key])


def local_links(page: Path) -> list[Path]:
    parser = _Links()
    parser.feed(page.read_text())
    out = []
    for link in parser.links:
        u = urlparse(link)
        assert not u.scheme and not u.netloc, f"{page.name}: external link {link}"
        out.append((page.parent / unquote(u.path)).resolve())
    return out


def test_every_link_of_the_index_and_mechanism_pages_resolves():
    b = built()
    pages = [b.reports / "index.html", *b.reports.glob("*/mechanism.html"),
             b.reports / "GNC" / "cross_check.html"]
    assert len(pages) == 4  # two mechanism reports: nominal and imex, each against dt010
    for page in pages:
        for target in local_links(page):
            assert target.is_file(), f"{page.name} links to missing {target}"
    for figure in ("rates", "lag1", "gamma_ramp", "conditioning", "dt_mu", "eig_t_nominal"):
        assert (b.reports / "figures" / f"{figure}.png").stat().st_size > 1000


def test_mechanism_report_numbers_come_from_analysis_json():
    b = built()
    rec = json.loads((b.reports / "t_nominal" / "analysis.json").read_text())
    md = (b.reports / "t_nominal" / "mechanism.md").read_text()
    assert "Unstable as flown" in md and "The modes of the loop as flown" in md
    th = rec["theory"]
    assert f"{th['spectral_radius']:.4g}" in md
    for m in th["modes"]:  # the table of modes, one row each, with its margins
        assert m["name"] in md and f"{m['margins']['gain_margin_db']:.3g}" in md
    for value in (rec["dominant"]["lag1"], th["dt_mu_max"], th["dt_star_damping"],
                  th["dt_star_map"], rec["alignment"]["abs_cos"],
                  rec["comparison"]["amplitude_ratio"]):
        assert f"{value:.4g}" in md
    for row in rec["comparison"]["table"]:
        assert row["quantity"].replace("|", "\\|") in md
    imex = (b.reports / "t_imex" / "mechanism.md").read_text()
    assert "imex" in imex and "keeps every mode stable" in imex


def test_a_pair_of_another_mission_is_not_called_the_same_mission(tmp_path):
    """The fixture's pair differs in the step alone: the same mission, coverage compared. The
    same pair as if the other run had flown half as long, or from another posture: the keys
    named (and both durations where they differ), the orbit's rows marked, coverage not
    compared (it grows along the orbit and depends on the posture); with no r₁ flip the
    report does not call the flip the dt-independent evidence."""
    from dataclasses import replace

    from pipeline.reports.mechanism import mechanism_context
    from pipeline.reports.render import load_runs
    from pipeline.reports.templating import render

    b = built()
    assert "runs the same mission at dt" in (b.reports / "t_nominal" / "mechanism.md").read_text()
    runs = load_runs(b.reports)
    run = next(r for r in runs if r.name == "t_nominal")
    comp = run.record.comparison
    assert comp.coverage_diff_pp is not None and comp.mission_differs == []
    seconds = run.record.n_steps * run.record.dt
    for other, differs, flew in (
            (replace(comp.other, n_steps=comp.other.n_steps // 2), ["mission.duration"],
             f"; it flew {seconds / 2:.4g} s, this run {seconds:.4g} s"),
            (comp.other, ["robot.q_bar"], "")):
        changed = replace(run, record=replace(run.record, comparison=replace(
            comp, other=other, mission_differs=differs, coverage_diff_pp=None,
            lag1_flip=False)))
        ctx = mechanism_context(changed, runs)
        md = render("mechanism.md.j2", tmp_path / "m.md", **ctx).read_text()
        html = render("mechanism.html.j2", tmp_path / "m.html", **ctx).read_text()
        assert "runs the same mission" not in md
        assert f"another mission: the specs also differ in {differs[0]}{flew}; their orbit" in md
        assert ("it flew" in md) == bool(flew)
        assert "Coverage differs" not in md + html
        assert md.count("Coverage is not compared: another mission") == 1
        assert md.count("final coverage (another mission: not compared)") == 2  # §4 and §7
        assert "the r₁ flip is the dt-independent evidence" not in md


def test_cross_check_markdown_has_a_row_per_equation_with_file_and_line():
    b = built()
    md = (b.reports / "GNC" / "cross_check.md").read_text()
    for e in sources.parse_equations():
        assert re.search(rf"^\| \({re.escape(e.number)}\) \|.*pipeline/[\w/]+\.py:\d+", md,
                         re.MULTILINE), f"eq. {e.number}"


def test_html_escapes_spec_names_and_descriptions(tmp_path):
    """A spec whose name and description carry HTML is shown as text, never as markup."""
    b = built()
    evil = "<i>evil"
    desc = "<b>x</b><script>alert(1)</script>"
    spec_path = write_spec(tmp_path, evil, "short_nominal", description=f"'{desc}'")
    spec = load_spec(spec_path)
    assert spec.name == evil and spec.description == desc
    log = run_spec(spec, tmp_path / "logs").path
    out = tmp_path / "reports"
    analyse_pair(log, b.logs / "t_dt010" / "run.parquet", out)
    render_all(out)
    pages = [out / "index.html", out / evil / "mechanism.html"]
    for page in pages:
        html = page.read_text()
        assert "<b>x</b>" not in html and "<script>alert" not in html and "<i>evil" not in html
        assert "&lt;b&gt;x&lt;/b&gt;&lt;script&gt;alert(1)&lt;/script&gt;" in html
        assert "&lt;i&gt;evil" in html
        for target in local_links(page):
            assert target.is_file(), f"{page.name} links to missing {target}"
    md = (out / evil / "mechanism.md").read_text()
    assert "<script>" not in md


# -- baselines ------------------------------------------------------------------------------

def _perturb(path: Path, column: str, row: int, delta: float) -> None:
    t = pq.read_table(path)
    md = footer_metadata(path)
    x = t.column(column).to_numpy().copy()
    x[row] += delta
    t = t.set_column(t.schema.get_field_index(column), column, pa.array(x))
    pq.write_table(t.replace_schema_metadata(md), path)


def test_baseline_check_is_zero_on_a_rerun_and_names_a_changed_column(tmp_path, monkeypatch):
    monkeypatch.setattr(baselines, "baseline_names", lambda: ["baseline_nominal"])
    pinned = tmp_path / "pinned"
    assert baselines.repin(pinned) == ["baseline_nominal: newly pinned"]
    report = baselines.check(tmp_path / "out", pinned)
    assert report["all_zero"] and report["max_abs_diff"] == 0.0
    assert "0.000e+00" in (tmp_path / "out" / "baselines.md").read_text()

    _perturb(pinned / "baseline_nominal" / "run.parquet", "s_min_G", 7, 1e-9)
    report = baselines.check(tmp_path / "out", pinned)
    entry = report["baselines"]["baseline_nominal"]
    assert entry["max_abs_diff"] == pytest.approx(1e-9, rel=1e-6)
    assert entry["worst_column"] == "s_min_G" and not report["all_zero"]
    changes = baselines.repin(pinned)
    assert "max_abs_diff 1.000e-09" in changes[0] and "s_min_G" in changes[0]


def test_pinned_baselines_exist_for_every_baseline_spec():
    names = baselines.baseline_names()
    assert len(names) >= 5
    for name in names:
        path = baselines.PINNED / name / "run.parquet"
        assert path.is_file(), f"{name} is not pinned (make repin)"
        assert path.stat().st_size < 500_000
    assert not np.isnan(baselines.compare_logs(path, path)["max_abs_diff"])


def test_baselines_cli_exit_codes(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(baselines, "baseline_names", lambda: ["baseline_imex"])
    monkeypatch.setattr(baselines, "PINNED", tmp_path / "pinned")
    assert baselines.main(["repin"]) == 0
    assert "baseline_imex: newly pinned" in capsys.readouterr().out
    assert baselines.main(["check", "--out", str(tmp_path / "out")]) == 0
    assert "baseline_imex        max_abs_diff 0.000e+00" in capsys.readouterr().out
    _perturb(tmp_path / "pinned" / "baseline_imex" / "run.parquet", "t", 3, 0.5)
    assert baselines.main(["check", "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert "baseline_imex" in err and len(err.strip().splitlines()) == 1
