"""The figures can be read: every axis labelled with its unit, legends of 8 pt or more, and
each run drawn in one colour in every figure (the report's palette)."""

from __future__ import annotations

import re

import pytest
from matplotlib.colors import to_hex
from matplotlib.container import BarContainer
from report_fixtures import built

from pipeline.reports import figures as fg
from pipeline.reports.render import figure_jobs, load_runs

DEFAULT_RUNS = ["nominal", "omega_ripple_dt010", "omega_ripple_imex", "omega_ripple_reach",
                "omega_ripple_unbounded", "servicer_nominal", "servicer_dt010", "servicer_imex"]
UNIT = re.compile(r"\([^()]+\)\s*$")  # "t (s)", "γ (dimensionless)"


def test_the_default_runs_have_distinct_styles_whatever_the_company():
    full = fg.palette(DEFAULT_RUNS)
    assert len({s.color for s in full.values()}) == len(DEFAULT_RUNS)
    for name in DEFAULT_RUNS:
        assert fg.palette([name, "servicer_dt010"])[name] == full[name] == fg.run_style(name)


def test_runs_whose_names_say_nothing_still_get_distinct_colours():
    styles = fg.palette(["alpha", "beta", "nominal", "gamma"])
    assert len({s.color for s in styles.values()}) == 4
    assert styles["nominal"] == fg.run_style("nominal")  # sorted first of its style


@pytest.fixture(scope="module")
def drawn() -> list:
    """Every figure of the shared report, as matplotlib drew it (not saved)."""
    out = built().reports
    figs: list = []
    mp = pytest.MonkeyPatch()
    mp.setattr(fg, "_save", lambda fig, path: figs.append((path.name, fig)))
    try:
        jobs, skipped = figure_jobs(out, load_runs(out))
        whys = [fg.draw_or_why(draw, out / fig.file) for fig, draw in jobs]  # in this process
    finally:
        mp.undo()
    assert not skipped and not any(whys), (skipped, whys)
    assert len(figs) == len(jobs) >= 8
    return figs


def _label(ax, axis: str) -> str:
    """The axis label, or that of an axes sharing this axis (small multiples label once)."""
    own = (ax.get_xlabel() if axis == "x" else ax.get_ylabel()).strip()
    if own:
        return own
    shared = ax.get_shared_x_axes() if axis == "x" else ax.get_shared_y_axes()
    return next((_label(s, axis) for s in shared.get_siblings(ax)
                 if s is not ax and (s.get_xlabel() if axis == "x" else s.get_ylabel())), "")


def test_every_axis_is_labelled_with_its_unit(drawn):
    bad = []
    for name, fig in drawn:
        for ax in fig.axes:
            for axis in "xy":
                # An axis that shows no scale (a panel turned off for a key, the short side
                # of a colour bar) has nothing to label.
                if not ax.axison or not len(ax.get_xticks() if axis == "x" else ax.get_yticks()):
                    continue
                text = _label(ax, axis)
                if not (UNIT.search(text) or text == "run"):
                    bad.append(f"{name}: {axis} label {text!r} of {ax.get_title()!r}")
    assert not bad, bad


def test_every_legend_is_8_pt_or_more(drawn):
    small = []
    for name, fig in drawn:
        legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes)]
        for lg in filter(None, legends):
            small += [f"{name}: {t.get_text()!r} at {t.get_fontsize()} pt"
                      for t in lg.get_texts() if t.get_fontsize() < fg.LEGEND_MIN_PT]
    assert not small, small


def test_each_run_has_one_colour_in_every_figure(drawn):
    runs = load_runs(built().reports)
    styles = fg.palette([r.name for r in runs])
    seen: dict[str, set[str]] = {r.name: set() for r in runs}
    for _name, fig in drawn:
        for ax in fig.axes:
            for handle, text in zip(*ax.get_legend_handles_labels(), strict=True):
                run = text.split(" (")[0]
                if run not in seen:
                    continue
                face = (handle.patches[0].get_facecolor() if isinstance(handle, BarContainer)
                        else handle.get_color())
                seen[run].add(to_hex(face))
    for run, colours in seen.items():
        assert colours == {styles[run].color}, f"{run}: drawn in {colours}"
