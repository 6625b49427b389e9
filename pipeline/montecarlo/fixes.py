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

``fixes.json`` beside the Monte Carlo's verdict lists the fixes flown (the Monte Carlo's key
then, each fix's file and its digest); the reports judge each from its own current verdict
(:func:`judged`) and recommend the cheapest shown (:func:`recommend`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from pipeline.atomic_files import atomic_write_text
from pipeline.montecarlo.plan import MonteCarlo, nominal_spec
from pipeline.montecarlo.sealed import sealed_json, unseal

FIXES_NAME = "fixes.json"


@dataclass(frozen=True)
class FixChange:
    slug: str  # the fix's name within its Monte Carlo's: imex, dt, bus_D …
    changes: dict  # the overrides it adds to the Monte Carlo's ``set``
    words: str
    steps_per_s: float  # its cost: control steps per second of mission
    # A search's least change: chosen from these very samples, so their pass count at it is
    # no independent test (eq. 38 does not apply): the search's certificate (eq. 43) is.
    search_certified: bool | None = None  # None: chosen beforehand (imex)
    search_statement: str = ""


@dataclass(frozen=True)
class FixRecord:
    """What ``fixes.json`` keeps of a fix flown: the change, its Monte Carlo and file (with
    the file's digest, to tell a file written again since), and how it was chosen."""

    change: FixChange
    montecarlo: str  # the fix's own Monte Carlo (its page and verdict)
    file: str
    file_digest: str


@dataclass(frozen=True)
class FixesResult:
    montecarlo: str
    key: str  # the Monte Carlo's result key when its fixes were flown
    fixes: list[FixRecord]


@dataclass(frozen=True)
class FlownFix:
    """A fix as its own current verdict judges it (eq. 38; eq. 43 for a search's change)."""

    record: FixRecord
    samples: int
    passes: int
    lower_bound: float | None
    shown: bool | None
    statement: str
    worst_gain_margin_db: float | None
    worst_mode: str
    delay_held: str

    @property
    def words(self) -> str:
        return self.record.change.words

    @property
    def steps_per_s(self) -> float:
        return self.record.change.steps_per_s


def judged(record: FixRecord, v) -> FlownFix:
    """The fix ``record`` as its verdict ``v`` (a ``MonteCarloVerdict``) shows it. A change
    chosen beforehand (imex) is shown by its verdict (eq. 38). A search's least change was
    chosen from these samples: it is shown only by the search's certificate (eq. 43), and only
    if every sample meets it as flown."""
    c = record.change
    worst = v.worst[0] if v.worst else None
    if c.search_certified is None:
        shown, statement = v.shown, v.statement
    else:
        shown = (None if v.shown is None else
                 bool(c.search_certified) and v.passes == v.samples)
        statement = (f"{v.passes} of {v.samples} samples meet it as flown; chosen from these "
                     f"samples, it rests on the search: {c.search_statement}")
    return FlownFix(record, v.samples, v.passes, v.lower_bound, shown, statement,
                    None if worst is None else worst.gain_margin_db,
                    "" if worst is None else worst.worst_mode, v.requirement.loop)


def recommend(flown: list[FlownFix]) -> FlownFix | None:
    """The cheapest fix shown (fewest control steps per second, then the larger margin of its
    worst sample), or None."""
    shown = [f for f in flown if f.shown]
    return min(shown, key=lambda f: (f.steps_per_s, -(f.worst_gain_margin_db or -math.inf)),
               default=None)


def fix_changes(mc: MonteCarlo, searches: list[dict]) -> list[FixChange]:
    """The fixes to fly: imex where the loop integrates explicitly, and each search's least
    change, where it found one monotone on the samples or verified afresh (``searches``: their
    results as read, current ones only)."""
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
                             1.0 / (value if knob == "mission.dt" else dt),
                             bool(s["certified"]), "; ".join(
                                 x for x in (s["statement"], s["verification"]) if x)))
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


def write_fixes(path: Path, result: FixesResult) -> None:
    atomic_write_text(path, sealed_json(asdict(result), indent=1))


def read_fixes(path: Path) -> FixesResult:
    """``fixes.json`` (ValueError, KeyError or TypeError if it is damaged or altered)."""
    d = unseal(Path(path).read_text())
    return FixesResult(d["montecarlo"], d["key"], [
        FixRecord(FixChange(**f["change"]), f["montecarlo"], f["file"], f["file_digest"])
        for f in d["fixes"]])
