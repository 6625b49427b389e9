"""The least change of one knob that every sample of a Monte Carlo meets, certified at the cost
of about one Monte Carlo (issue 52; the scenario approach, eq. 43; docs/montecarlo.md).

A knob k is a number of the mission spec that the loop's margins fall with: the step
``mission.dt`` or a damping gain (``controller.gains.<block>.D``): the loop gain of the fastest
damping mode, g = dt·μ, grows with both (eq. 35). Sample i of the Monte Carlo, on common random
numbers (the same inertias, gains' dispersions, delays and noise streams whatever k,
:func:`pipeline.montecarlo.plan.derive`), meets the requirement for k at or below its critical
value k_i. The value every sample meets is k* = min_i k_i: a scenario solution with one decision
variable (Campi and Garatti 2008), so, if pass/fail is monotone in k for every case,

    P(the probability that a case fails at k* exceeds ε) ≤ (1 − ε)^N         (eq. 43)

0.0999 for ε = 1 − 0.9973 and N = 852: the same statement as 852 samples none failing (eq. 38b),
for the least change rather than a change chosen beforehand.

Not K flights per sample: the samples are flown at the nominal value (the Monte Carlo's own
records), the failing ones taken in the order of their critical value predicted from their
gain margin (k̂ = k·10^((GM − GM_req)/20), exact when the loop gain is proportional to k and
the delay is in steps), the first bisected to its k_i, every sample not yet met at that value
flown there once, and only those failing there bisected in turn. Monotonicity is checked, not
assumed: no sample may pass at a value above one it fails at, and a random tenth of the samples
met at a larger value are flown again at k*; where it fails the result says so and is not
certified (``python -m pipeline search`` then verifies k* with a fresh Monte Carlo).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# The knobs a search moves, each with the words for it; the requirement's margins fall as each
# grows (eq. 35), so the search looks below the nominal value.
KNOBS = {"mission.dt": "the control step (s)",
         "controller.gains.bus.D": "the bus attitude's damping gain",
         "controller.gains.cam_pos.D": "the camera position's damping gain",
         "controller.gains.cam_ori.D": "the camera orientation's damping gain"}
# The knobs `make studies` searches for a Monte Carlo that does not show its target.
FIX_KNOBS = ("mission.dt", "controller.gains.bus.D", "controller.gains.cam_ori.D")
CHECK_FRACTION = 0.1  # of the samples, flown again at the chosen value
RTOL = 1e-3  # the bisection's relative width
FLOOR = 1e-3  # the search gives up below this fraction of the nominal value


@dataclass(frozen=True)
class Outcome:
    """A sample flown at one value of the knob: whether it meets the requirement, and its
    least gain margin (dB; NaN where its run did not complete)."""

    passes: bool
    gain_margin_db: float


Fly = Callable[[float, list[int]], dict[int, Outcome]]


@dataclass(frozen=True)
class SampleBracket:
    """What the search learned of sample i's critical value k_i: it meets the requirement at
    ``passes_at`` (the largest value flown where it did) and not at ``fails_at`` (the smallest
    where it did not; None: met wherever flown)."""

    index: int
    passes_at: float | None
    fails_at: float | None
    margin_at_pass: float | None  # its least gain margin at passes_at, dB


@dataclass(frozen=True)
class LeastChange:
    knob: str
    nominal: float
    chosen: float | None  # k*: None when some sample meets the requirement at no value tried
    samples: int
    flights: int
    set_by: int | None  # the sample whose critical value k* is
    bisected: list[int]  # the samples bisected, in turn
    checked: list[int]  # flown again at k* for the monotonicity check
    violations: list[str]  # where pass/fail was not monotone in the knob
    brackets: list[SampleBracket] = field(default_factory=list)

    @property
    def monotone(self) -> bool:
        return not self.violations

    def risk(self, p: float) -> float:
        """β = (1 − ε)^N, ε = 1 − p: the bound of eq. 43 on the probability that k* fails more
        than ε of the cases (valid where pass/fail is monotone in the knob)."""
        return float(math.exp(self.samples * math.log(p)))


def predicted(value: float, gain_margin_db: float, required_db: float) -> float:
    """k̂ = k·10^((GM − GM_req)/20): the knob's value at which the loop gain, proportional to
    it, leaves exactly the required gain margin (eq. 35). NaN margins (a run that did not
    complete) predict half the value."""
    if not math.isfinite(gain_margin_db):
        return 0.5 * value
    return value * 10.0 ** ((gain_margin_db - required_db) / 20.0)


def least_change(nominal: float, indices: list[int], required_db: float, fly: Fly,
                 seed: int = 0, rtol: float = RTOL,
                 check_fraction: float = CHECK_FRACTION,
                 floor: Callable[[int], float] | None = None) -> LeastChange:
    """k* = min_i k_i over the samples ``indices`` (see the module docstring): ``fly(value,
    samples)`` flies those samples at that value of the knob and says how each did; the
    samples the monotonicity check flies again are drawn from a generator seeded ``seed``.
    ``floor(i)``: the least value sample i can be flown at (a step its latency fits in); the
    search goes no lower than the largest of them, which every sample can fly, nor below a
    thousandth of the nominal."""
    lowest = max([FLOOR * nominal, *(floor(i) for i in indices)] if floor is not None
                 else [FLOOR * nominal])

    passes_at: dict[int, float] = {}
    fails_at: dict[int, float] = {}
    margin: dict[int, float] = {}
    last_margin: dict[int, float] = {}
    flights = 0

    def flown(value: float, which: list[int]) -> dict[int, Outcome]:
        nonlocal flights
        got = fly(value, which)
        flights += len(which)
        for i in which:
            o = got[i]
            last_margin[i] = o.gain_margin_db
            if o.passes and (i not in passes_at or value > passes_at[i]):
                passes_at[i], margin[i] = value, o.gain_margin_db
            if not o.passes and (i not in fails_at or value < fails_at[i]):
                fails_at[i] = value
        return got

    def result(chosen: float | None, set_by: int | None, bisected: list[int],
               checked: list[int], violations: list[str]) -> LeastChange:
        brackets = [SampleBracket(i, passes_at.get(i), fails_at.get(i), margin.get(i))
                    for i in indices]
        return LeastChange("", nominal, chosen, len(indices), flights, set_by, bisected,
                           checked, violations, brackets)

    got = flown(nominal, list(indices))
    pending = [i for i in indices if not got[i].passes]
    best, set_by, bisected = nominal, None, []
    while pending:
        i = min(pending, key=lambda j: predicted(fails_at[j], last_margin[j], required_db))
        hi = fails_at[i]

        def below(v: float, i: int = i) -> float:
            # Just below the prediction from the margin at v, at most a fifth below v; a
            # fifth below where the margin predicts nothing lower (the sample fails on
            # another part of the requirement); never below what every sample can fly.
            guess = predicted(v, last_margin[i], required_db) * (1.0 - 2.0 * rtol)
            return max(guess if guess < v * (1.0 - 2.0 * rtol) else 0.8 * v, 0.8 * v, lowest)

        value = below(hi)
        while True:  # a value that sample i meets, stepping down from the prediction
            if flown(value, [i])[i].passes:
                break
            if value <= lowest:
                return result(None, i, [*bisected, i], [], [
                    f"sample {i} meets the requirement at no value down to {value:.6g}, the "
                    "least every sample can be flown at"])
            hi, value = value, below(value)
        lo = value
        probe = lo * (1.0 + 4.0 * rtol)  # the prediction is often that close: bracket it
        if probe < hi and hi - lo > rtol * hi:
            lo, hi = (probe, hi) if flown(probe, [i])[i].passes else (lo, probe)
        while hi - lo > rtol * hi:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if flown(mid, [i])[i].passes else (lo, mid)
        best, set_by = lo, i
        bisected.append(i)
        # Every sample not yet met at a value at or above k* is flown there once.
        others = [j for j in indices if j != i and passes_at.get(j, -math.inf) < best]
        got = flown(best, others) if others else {}
        pending = [j for j in others if not got[j].passes]
    # Monotonicity: no sample fails at a value at or below one it passes at, and a random
    # tenth of those met only above k* meet it at k* too.
    pool = [i for i in indices if passes_at.get(i, best) > best]
    size = min(len(pool), math.ceil(check_fraction * len(indices)))
    checked = sorted(int(x) for x in np.random.default_rng(seed).choice(
        pool, size=size, replace=False)) if size else []
    if checked:
        flown(best, checked)
    violations = [f"sample {i} fails at {fails_at[i]:.6g} but meets the requirement at "
                  f"{passes_at[i]:.6g}, above it" for i in indices
                  if i in fails_at and i in passes_at and fails_at[i] <= passes_at[i]]
    return result(best, set_by, bisected, checked, violations)


@dataclass(frozen=True)
class SearchResult:
    """A search's result as written (``<out>/<montecarlo>/search-<knob>.json``, sealed)."""

    montecarlo: str
    knob: str
    knob_words: str
    loop: str  # the plant, the delay and how it is held when the knob is the step
    required_gain_margin_db: float
    target_p: float
    confidence: float
    risk: float  # β of eq. 43b at the target's ε, over the samples
    certified: bool  # k* found, pass/fail monotone on the samples, β ≤ 1 − C
    statement: str
    cost: str
    verification: str  # a fresh Monte Carlo at k* when not monotone ("": none flown)
    search: LeastChange
    wall_s: float
    key: str = ""  # the Monte Carlo's result key and the knob: current while it is this code's
    file: str = ""


def statement(r: LeastChange, p: float, confidence: float) -> tuple[bool, str, str]:
    """(certified, what the search shows, its cost) in words (eq. 43)."""
    n, knob = r.samples, r.knob
    flights = f"{r.flights} flights for {n} samples ({r.flights / n:.3g} N)"
    if r.chosen is None:
        return False, (f"no value of {knob} below its nominal {r.nominal:g} meets the "
                       f"requirement for every sample ({'; '.join(r.violations)}): no change "
                       f"of this knob alone is a fix; {flights}"), ""
    cost = (f"{1.0 / r.chosen:.4g} control steps per second against {1.0 / r.nominal:.4g}"
            if knob == "mission.dt" else
            f"the gain {r.chosen / r.nominal:.3g} of its nominal: a slower damping mode")
    if r.chosen == r.nominal:
        return r.risk(p) <= 1.0 - confidence, (
            f"every one of the {n} samples meets the requirement at the nominal {knob} "
            f"{r.nominal:g}: nothing to change; {flights}"), cost
    beta = r.risk(p)
    less = 100 * (1 - r.chosen / r.nominal)
    if not r.monotone:
        return False, (f"{knob} ≤ {r.chosen:.6g} (nominal {r.nominal:g}, {less:.3g} % less) is "
                       f"the least value the search found, set by sample {r.set_by}; {flights};"
                       f" pass/fail is NOT monotone in {knob} on the samples "
                       f"({'; '.join(r.violations)}): not every sample is shown to meet it, "
                       "and the scenario bound (eq. 43b) is not claimed"), cost
    found = (f"{knob} ≤ {r.chosen:.6g} (nominal {r.nominal:g}, {less:.3g} % less) is the "
             f"least change every one of the {n} samples meets, set by sample "
             f"{r.set_by}; {flights}")
    shown = beta <= 1.0 - confidence
    return shown, (f"{found}; no sample flown contradicts pass/fail monotone in {knob} "
                   f"({len(r.checked)} met above it flown again at it); by the scenario "
                   f"approach (eq. 43b) the probability that it fails more than "
                   f"{100 * (1 - p):.3g} % of the cases is at most {beta:.4f}: p ≥ {p:g} at "
                   f"{100 * confidence:g} % confidence "
                   + ("shown" if shown else "NOT shown")), cost


def search_key(montecarlo_key: str, knob: str) -> str:
    """A search result's key: its Monte Carlo's result key, the knob and the search's code."""
    from pipeline.provenance.keys import search_version

    return f"{montecarlo_key}, knob {knob}, search {search_version()}"


def current_searches(folder: Path, montecarlo_key: str) -> list[dict]:
    """The search results in ``folder`` (``search-<knob>.json``, as read) made for the Monte
    Carlo whose result key is ``montecarlo_key`` (its file as it is now, this code); a damaged
    or stale one is not read."""
    from pipeline.montecarlo.sealed import unseal

    out = []
    for path in sorted(Path(folder).glob("search-*.json")):
        try:
            data = unseal(path.read_text())
        except (OSError, ValueError):
            continue
        if data.get("key") == search_key(montecarlo_key, str(data.get("knob"))):
            out.append({**data, "path": str(path)})
    return out
