"""Each recommended fix of a Monte Carlo's loop flown through the same Monte Carlo (issue 52).

A fix is a change of the loop: the implicit damping (``controller.integrator: imex``) at the
same step, or the least change of a knob that every sample meets, certified by a search
(:mod:`pipeline.montecarlo.search`, ``search-<knob>.json``). Each is written as a Monte Carlo
file of its own (``<out>/<montecarlo>/fixes/<montecarlo>+<fix>.yaml``): the same mission, seed,
target and dispersions, its ``set`` the Monte Carlo's and the change. So sample i of the fix
draws what sample i of the Monte Carlo drew (common random numbers: its inertias, the
dispersed gains' ε, its delay and arrival, its noise and jitter streams, bitwise), and the fix
is flown, judged and kept like any Monte Carlo: its verdict under ``<out>/<montecarlo>+<fix>/``,
each of its samples re-runnable alone (``--sample I``). A change of step holds the delay as the
file says (``latency_step``: the arrival and jitter in seconds, the whole steps in steps).

``fixes.json`` beside the Monte Carlo's verdict lists each fix with its verdict, its worst
sample's margin and its cost, and the one recommended: the cheapest whose verdict shows the
target.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from pipeline.atomic_files import atomic_write_text
from pipeline.montecarlo.plan import MonteCarlo
from pipeline.montecarlo.sealed import sealed_json, unseal

FIXES_NAME = "fixes.json"


@dataclass(frozen=True)
class FixChange:
    slug: str  # the fix's name within its Monte Carlo's: imex, dt, bus_D …
    changes: dict  # the overrides it adds to the Monte Carlo's ``set``
    words: str
    steps_per_s: float  # its cost: control steps per second of mission


@dataclass(frozen=True)
class FlownFix:
    """A fix flown through the Monte Carlo's samples, as its verdict judged it (eq. 38)."""

    slug: str
    words: str
    montecarlo: str  # the fix's own Monte Carlo (its page and verdict)
    file: str
    samples: int
    passes: int
    lower_bound: float | None
    shown: bool | None
    statement: str
    worst_gain_margin_db: float | None
    worst_mode: str
    steps_per_s: float
    delay_held: str


@dataclass(frozen=True)
class FixesResult:
    montecarlo: str
    fixes: list[FlownFix]
    recommended: str  # the slug of the cheapest fix shown, "" when none is
    statement: str


def fix_changes(mc: MonteCarlo, searches: list[dict]) -> list[FixChange]:
    """The fixes to fly: imex where the loop integrates explicitly, and each search's least
    change, where it found one monotone on the samples or verified afresh (``searches``: their
    results as read, current ones only)."""
    from pipeline.montecarlo.plan import nominal_spec

    nominal = nominal_spec(mc.base, mc.config)
    dt = nominal.mission.dt
    out = []
    if nominal.controller.integrator == "explicit":
        out.append(FixChange("imex", {"controller.integrator": "imex"},
                             "the implicit damping (imex) at the same step", 1.0 / dt))
    for s in searches:
        r = s["search"]
        # A least change found, and either monotone on the samples or verified afresh.
        if r["chosen"] is None or r["chosen"] == r["nominal"] or (
                r["violations"] and not s["certified"]):
            continue
        knob, value = s["knob"], float(r["chosen"])
        slug = "dt" if knob == "mission.dt" else knob.removeprefix("controller.gains.").replace(
            ".", "_")
        out.append(FixChange(slug, {knob: value}, f"{knob} {r['nominal']:g} → {value:.6g}",
                             1.0 / (value if knob == "mission.dt" else dt)))
    return out


def write_fix_file(mc: MonteCarlo, fix: FixChange, folder: Path) -> Path:
    """The fix's Monte Carlo file: the Monte Carlo's own, its ``set`` with the change, its
    mission named by absolute path (the file lives among the reports)."""
    from pipeline.spec import resolve_spec_path

    data = mc.config.model_dump(mode="json", exclude_none=True)
    data["description"] = f"{mc.config.description}; fix: {fix.words}"
    data["mission"] = str(resolve_spec_path(mc.config.mission, mc.path.resolve().parent)
                          .resolve())
    data["set"] = {**mc.config.set, **fix.changes}
    path = folder / f"{mc.name}+{fix.slug}.yaml"
    atomic_write_text(path, f"# The fix {fix.words} of {mc.path.name} (pipeline fixes): the "
                      "same draws, written by the pipeline.\n"
                      + yaml.safe_dump(data, sort_keys=False, allow_unicode=True))
    return path


def summarise(mc_name: str, flown: list[FlownFix]) -> FixesResult:
    shown = sorted((f for f in flown if f.shown), key=lambda f: f.steps_per_s)
    best = shown[0] if shown else None
    statement = (f"recommended: {best.words} ({best.montecarlo}): {best.statement}; cost "
                 f"{best.steps_per_s:.4g} control steps per second" if best else
                 "no fix flown shows the target across the dispersions")
    return FixesResult(mc_name, flown, best.slug if best else "", statement)


def write_fixes(path: Path, result: FixesResult) -> None:
    atomic_write_text(path, sealed_json(asdict(result), indent=1))


def read_fixes(path: Path) -> FixesResult:
    d = unseal(Path(path).read_text())
    return FixesResult(d["montecarlo"], [FlownFix(**f) for f in d["fixes"]], d["recommended"],
                       d["statement"])
