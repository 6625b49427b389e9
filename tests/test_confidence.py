"""The verdict at a stated confidence (eq. 38, issue 35 item 2) against what others computed:
the sample sizes Hanson and Beard publish, the binomial tail that defines the Clopper–Pearson
bound (SciPy's binomial distribution, not the beta quantile the code takes), its closed form
with no failure, and SciPy's own exact interval."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.stats

from pipeline.analysis.confidence import (
    confidence_reachable,
    confidence_verdict,
    lower_bound,
    samples_needed,
    samples_to_show,
)


@pytest.mark.parametrize(("p", "c", "n"), [(0.9973, 0.90, 852), (0.9973, 0.95, 1109),
                                           (0.5, 0.75, 2), (0.9, 0.9, 22)])
def test_samples_needed_are_the_published_ones_and_the_least(p, c, n):
    """852 at 90 %: NASA/TP-2010-216447 (and issue 35). At 95 % issue 35 says 1108, but
    ln(0.05)/ln(0.9973) = 1108.03: 1108 passes give p_L = 0.05^(1/1108) = 0.997296 < 0.9973,
    so 1109 is the least. 0.5² = 0.25 exactly at C = 0.75."""
    assert samples_needed(p, c) == n
    assert p**n <= 1 - c < p ** (n - 1)


@pytest.mark.parametrize(("k", "n", "c"), [(852, 852, 0.9), (851, 852, 0.9), (40, 50, 0.95),
                                           (1, 10, 0.9), (1109, 1109, 0.95), (3, 7, 0.99)])
def test_the_bound_is_where_the_binomial_tail_is_one_minus_c(k, n, c):
    p_low = lower_bound(k, n, c)
    # P(X ≥ k) at the bound is 1 − C; just below it, less likely still.
    assert scipy.stats.binom.sf(k - 1, n, p_low) == pytest.approx(1 - c, rel=1e-9)
    assert scipy.stats.binom.sf(k - 1, n, p_low * (1 - 1e-6)) < 1 - c
    # SciPy's exact two-sided interval at level 1 − 2α has the one-sided bound at 1 − α.
    ci = scipy.stats.binomtest(k, n).proportion_ci(confidence_level=1 - 2 * (1 - c),
                                                   method="exact")
    assert p_low == pytest.approx(ci.low, rel=1e-12)


def test_no_failure_is_the_closed_form_and_the_verdict_follows_the_bound():
    for n in (1, 22, 852):
        assert lower_bound(n, n, 0.9) == pytest.approx(0.1 ** (1 / n), rel=1e-12)
    v = confidence_verdict(852, 852, 0.9973, 0.9)
    assert v.meets and v.needed == 852 and v.fraction == 1.0
    one_failure = confidence_verdict(851, 852, 0.9973, 0.9)
    assert not one_failure.meets and one_failure.lower_bound < 0.9973
    assert lower_bound(0, 10, 0.9) == 0.0


@pytest.mark.parametrize(("call", "words"), [
    (lambda: samples_needed(1.0, 0.9), "p = 1.0"),
    (lambda: samples_needed(0.9, 0.0), "confidence = 0.0"),
    (lambda: lower_bound(11, 10, 0.9), "passes = 11 of n = 10"),
    (lambda: lower_bound(1, 10, math.nan), "confidence = nan"),
])
def test_bad_arguments_are_refused_naming_them(call, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(")):
        call()


def test_the_bound_is_a_lower_bound_in_coverage():
    """Coverage, by simulation: at a true p, the bound lies below p in at least C of the
    experiments (Clopper–Pearson is conservative)."""
    rng = np.random.default_rng(35)
    p, n, c = 0.97, 200, 0.9
    passes = rng.binomial(n, p, size=4000)
    covered = np.mean([lower_bound(int(k), n, c) <= p for k in passes])
    assert covered >= c


@pytest.mark.parametrize("p,n", [(0.9973, 0), (0.9973, 32), (0.9973, 852), (0.9, 3), (0.5, 7)])
def test_the_confidence_n_samples_can_reach_is_where_their_clean_bound_meets_p(p, n):
    """Eq. 38d: C = 1 − p^N is the confidence at which N samples, none failing, bring SciPy's
    Clopper–Pearson bound up to p exactly; at any higher confidence it stays below p."""
    c = confidence_reachable(p, n)
    assert c == pytest.approx(1 - p**n, rel=1e-12, abs=1e-15)
    if n:
        assert scipy.stats.beta.ppf(1 - c, n, 1) == pytest.approx(p, rel=1e-9)
        assert scipy.stats.beta.ppf(1 - min(c + 1e-3, 0.999999), n, 1) < p
        assert samples_needed(p, c - 1e-9) <= n
        assert samples_needed(p, min(c + 1e-6, 0.999999)) > n


@pytest.mark.parametrize(("k", "p", "c"), [(0, 0.9973, 0.9), (1, 0.9973, 0.9),
                                           (16, 0.9973, 0.9), (3, 0.9, 0.95), (92, 0.99, 0.9)])
def test_samples_to_show_are_the_least_that_show_the_target_with_k_failing(k, p, c):
    """The least N whose exact one-sided bound from N − k passes reaches p, by SciPy's own
    exact interval (its two-sided Clopper–Pearson at 1 − 2α has the one-sided bound at 1 − α),
    not by this module's bound."""
    n = samples_to_show(k, p, c)

    def scipy_bound(passes: int, total: int) -> float:
        return scipy.stats.binomtest(passes, total).proportion_ci(
            confidence_level=1 - 2 * (1 - c), method="exact").low

    assert scipy_bound(n - k, n) >= p * (1 - 1e-12)
    assert scipy_bound(n - 1 - k, n - 1) < p
