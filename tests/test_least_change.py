"""The least change of a knob that every sample meets (eq. 43, pipeline/montecarlo/search.py),
on synthetic samples whose critical values are known: the search must find their minimum, in
about N flights, and say when pass/fail is not monotone in the knob."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.montecarlo.search import RTOL, Outcome, least_change, predicted

REQUIRED_DB = 6.0


def oracle(critical: np.ndarray, flights: list[tuple[float, int]], exact_margin: bool = True):
    """Sample i meets the requirement at k iff k ≤ critical[i], with the gain margin a loop
    gain proportional to k leaves (eq. 35: 6 dB at its critical value); ``exact_margin``
    False: a margin that predicts a critical value 30 % off, which only orders the search."""
    def fly(value: float, which: list[int]) -> dict[int, Outcome]:
        out = {}
        for i in which:
            flights.append((value, i))
            guess = critical[i] if exact_margin else critical[i] * (1.3 if i % 2 else 0.7)
            out[i] = Outcome(bool(value <= critical[i]),
                             REQUIRED_DB + 20.0 * math.log10(guess / value))
        return out
    return fly


@pytest.mark.parametrize("exact_margin", [True, False])
def test_the_least_change_is_the_least_critical_value_in_about_n_flights(exact_margin):
    """852 samples, 2 % of them failing at the nominal value: k* within the bisection's width
    below min_i k_i, every sample met there, in fewer than 1.2 N flights; the sample that sets
    it is the one of least critical value."""
    rng = np.random.default_rng(5)
    n, nominal = 852, 2.5e-3
    critical = nominal * np.where(rng.random(n) < 0.02, rng.uniform(0.8, 1.0, n),
                                  rng.uniform(1.0, 3.0, n))
    flights: list[tuple[float, int]] = []
    r = least_change(nominal, list(range(n)), REQUIRED_DB, oracle(critical, flights,
                                                                  exact_margin))
    assert r.chosen is not None and r.monotone
    assert critical.min() * (1 - RTOL) <= r.chosen <= critical.min()
    assert r.set_by == int(np.argmin(critical))
    assert r.flights == len(flights) < 1.2 * n
    assert len({i for _, i in flights}) == n  # every sample flown
    assert len(r.checked) == math.ceil(0.1 * n)  # a tenth flown again at k*
    assert all((r.chosen, i) in flights for i in r.checked)
    # what each sample's bracket says holds of its own critical value
    for b in r.brackets:
        assert b.passes_at is None or b.passes_at <= critical[b.index]
        assert b.fails_at is None or b.fails_at > critical[b.index]


def test_nothing_to_change_when_every_sample_meets_the_nominal():
    critical = np.full(50, 3.0)
    flights: list[tuple[float, int]] = []
    r = least_change(2.0, list(range(50)), REQUIRED_DB, oracle(critical, flights))
    assert r.chosen == 2.0 and r.set_by is None and r.bisected == []
    assert r.monotone and r.flights == 50 and r.checked == []  # none met only above k*


def test_a_sample_that_is_not_monotone_in_the_knob_is_named():
    """Sample 7 meets the requirement below its critical value except in a band below k*:
    the check flies it again at k* (seeded so), it fails there, and the result says so."""
    n, nominal = 40, 1.0
    critical = np.linspace(1.2, 2.0, n)
    critical[3] = 0.9  # the one failing at the nominal value

    def fly(value, which):
        out = {}
        for i in which:
            ok = value <= critical[i] and not (i != 3 and 0.85 < value < 0.95)
            out[i] = Outcome(bool(ok), REQUIRED_DB + 20 * math.log10(critical[i] / value))
        return out

    r = least_change(nominal, list(range(n)), REQUIRED_DB, fly, check_fraction=1.0)
    assert not r.monotone
    assert any("meets the requirement at 1, above it" in v for v in r.violations)


def test_a_sample_met_at_no_value_stops_the_search():
    critical = np.array([5.0, 1e-9, 5.0])
    r = least_change(1.0, [0, 1, 2], REQUIRED_DB, oracle(critical, []))
    assert r.chosen is None and r.set_by == 1
    assert "meets the requirement at no value" in r.violations[0]


def test_the_prediction_is_the_critical_value_of_a_proportional_loop_gain():
    """eq. 43c against eq. 35's gain margin of g·k: GM = 20 log10(g_c/(g k))."""
    g_c, g = 0.5, 40.0
    for k in (1e-3, 2.5e-3, 4e-3):
        gm = 20 * math.log10(g_c / (g * k))
        k_req = g_c / g / 10 ** (REQUIRED_DB / 20)
        assert predicted(k, gm, REQUIRED_DB) == pytest.approx(k_req, rel=1e-12)


def test_a_failure_the_margin_does_not_see_steps_down_by_a_fifth():
    """A sample failing on another part of the requirement (its gain margin 20 dB, above the
    required 6) until the knob is below 0.3 of its nominal: stepped down a fifth at a time,
    not a bisection's width (a few flights, not thousands)."""
    def fly(value, which):
        return {i: Outcome(bool(i != 0 or value <= 0.3), 20.0) for i in which}

    r = least_change(1.0, list(range(10)), REQUIRED_DB, fly)
    assert r.chosen is not None and 0.3 * (1 - RTOL) <= r.chosen <= 0.3
    assert r.flights < 10 + 25


def test_the_search_goes_no_lower_than_every_sample_can_fly():
    """Each sample's least value (a step its latency fits in): the search stops at the
    largest, which every sample can fly, and says so when a sample needs less."""
    critical = np.array([2.0, 0.5, 2.0, 2.0])
    floors = {0: 0.1, 1: 0.1, 2: 0.7, 3: 0.2}
    asked: list[tuple[float, int]] = []
    r = least_change(1.0, [0, 1, 2, 3], REQUIRED_DB, oracle(critical, asked),
                     floor=floors.__getitem__)
    assert r.chosen is None and min(v for v, _ in asked) >= 0.7
    assert "the least every sample can be flown at" in r.violations[0]
