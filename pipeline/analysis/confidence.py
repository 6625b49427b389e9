"""A verdict at a stated confidence (eq. 38): the pass fraction of N dispersed runs, its
one-sided Clopper–Pearson lower bound, and the runs a zero-failure demonstration needs.

A dispersion analysis asks whether a requirement holds for at least a fraction p of the cases
at confidence C. With k of N independent samples passing, the exact (Clopper–Pearson) lower
bound p_L on the pass probability is the p at which k or more passes would occur with
probability 1 − C:

    P(X ≥ k | N, p_L) = 1 − C   ⇔   p_L = B⁻¹(1 − C; k, N − k + 1)    (k > 0; p_L = 0 if k = 0)

B⁻¹ the beta distribution's quantile. With no failure allowed (k = N) it is p_L = (1 − C)^(1/N),
so N ≥ ln(1 − C)/ln p samples, all passing, show p at confidence C: 852 for p = 0.9973 (3σ) at
C = 90 % (the success-run theorem; Hanson and Beard, NASA/TP-2010-216447), 1109 at 95 %
(ln 0.05/ln 0.9973 = 1108.03: 1108 is one short).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


def _check(name: str, value: float, lo: float, hi: float) -> None:
    if not (lo < value < hi):
        raise ValueError(f"{name} = {value!r}: must lie strictly between {lo:g} and {hi:g}")


def samples_needed(p: float, confidence: float) -> int:
    """The fewest samples N, all passing, that show a pass probability of at least ``p`` at
    ``confidence``: the least N with p^N ≤ 1 − C (eq. 38)."""
    _check("p", p, 0.0, 1.0)
    _check("confidence", confidence, 0.0, 1.0)
    n = math.ceil(math.log1p(-confidence) / math.log(p))
    # The logarithms' rounding may put an exact integer one above: take the least that holds.
    while n > 1 and p ** (n - 1) <= 1.0 - confidence:
        n -= 1
    while p**n > 1.0 - confidence:
        n += 1
    return n


def confidence_reachable(p: float, n: int) -> float:
    """The most confidence that ``n`` samples can show for a pass probability ``p``: with none
    failing, p_L = (1 − C)^(1/N) reaches p at C = 1 − p^N (eq. 38d); 0 for no samples."""
    _check("p", p, 0.0, 1.0)
    if n < 0:
        raise ValueError(f"n = {n!r}: a count of samples is 0 or more")
    return float(-math.expm1(n * math.log(p)))


def lower_bound(passes: int, n: int, confidence: float) -> float:
    """The one-sided Clopper–Pearson lower bound on the pass probability from ``passes`` of
    ``n`` samples at ``confidence`` (eq. 38); 0 when none passed."""
    import scipy.stats

    if n < 1 or not 0 <= passes <= n:
        raise ValueError(f"passes = {passes!r} of n = {n!r}: need 0 ≤ passes ≤ n and n ≥ 1")
    _check("confidence", confidence, 0.0, 1.0)
    if passes == 0:
        return 0.0
    return float(scipy.stats.beta.ppf(1.0 - confidence, passes, n - passes + 1))


def samples_to_show(failures: int, p: float, confidence: float) -> int:
    """The fewest samples N that, with ``failures`` of them failing, show a pass probability
    of at least ``p`` at ``confidence``: the least N with p_L(N − k passes of N) ≥ p (eq. 38a);
    :func:`samples_needed` when none fail. p_L grows with N at a fixed count of failures, so
    the least N is bracketed by doubling and then bisected."""
    if failures < 0:
        raise ValueError(f"failures = {failures!r}: a count of samples is 0 or more")
    if failures == 0:
        return samples_needed(p, confidence)

    def shows(n: int) -> bool:
        return lower_bound(n - failures, n, confidence) >= p

    lo = samples_needed(p, confidence) + failures  # fewer cannot: even none failing needs that
    if shows(lo):
        return lo
    hi = 2 * lo
    while not shows(hi):
        lo, hi = hi, 2 * hi
    while hi - lo > 1:  # not shows(lo), shows(hi)
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if shows(mid) else (mid, hi)
    return hi


@dataclass(frozen=True)
class ConfidenceVerdict:
    """Whether N samples show a pass probability of at least ``target`` at ``confidence``."""

    n: int
    passes: int
    confidence: float
    target: float  # the pass probability the requirement asks for, p
    fraction: float  # passes / n
    lower_bound: float  # one-sided Clopper–Pearson at ``confidence``
    needed: int  # the samples, all passing, that would show ``target``

    @property
    def meets(self) -> bool:
        return self.lower_bound >= self.target


def confidence_verdict(passes: int, n: int, target: float, confidence: float
                       ) -> ConfidenceVerdict:
    """The verdict of eq. 38 for ``passes`` of ``n`` samples against ``target`` at
    ``confidence``."""
    return ConfidenceVerdict(n=n, passes=passes, confidence=confidence, target=target,
                             fraction=passes / n if n else math.nan,
                             lower_bound=lower_bound(passes, n, confidence),
                             needed=samples_needed(target, confidence))
