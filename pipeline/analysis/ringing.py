"""What rings in the data, measured as it is (eq. 36): one scalar series over the analysis
window, its short-period part's peak-to-peak size and dominant period, and whether that part
is a sustained oscillation.

A damping mode of the loop as flown that is unstable oscillates over 2 to 6 steps (eq. 35: period
2 without delay; 2π/arccos(1/(2√g)) ∈ (4, 6] with one step of it); the guidance moves the
coordinates over hundreds of steps. The short-period band is the periods of at most
``BAND_STEPS`` = 20 steps, between the two with a factor of three either way. The series,
less its least-squares line, is split by its discrete Fourier transform:

    band share  = Σ_band P_f / Σ_{f ≥ 1/60} P_f       (P: periodogram under a Hann window)
    line share  = Σ_{|f − f_peak| ≤ 3 bins} P_f / Σ_band P_f
    growth      = rms(last third) / rms(first third)   of the band's part
    rings       ⇔  band share > ½  and  line share > ½
    trend       growing (growth > 2), decaying (growth < ½), steady

"most of the fast motion about its trend is at short periods, and most of that is one spectral
line" (white noise fills the band but no line; a smooth reference leaves the band empty, its
power falling with frequency); the trend says whether it lasts (a stable lightly damped mode's
ring fades over the window: :func:`pipeline.analysis.verdict.judge` counts a decaying ring of
a mode called stable as its transient). The share is of the motion at periods of at most
``REFERENCE_STEPS`` = 60 (three times the band's longest), not of all of it: a slow manoeuvre
of any size leaves it unchanged (a Hann window's leakage from hundreds of steps to 60 is
below 1e−9 of its power), so a ring under a large slew is still seen. "Decaying" is the last
third of the window's band part less than half the size of its first third: a root of modulus
r fades by r^(N/3), so on a window of N steps a mode decaying faster than 2^(−3/N) per step
reads as decaying. The peak's
period is 1/f_peak, f_peak refined by a parabola through the log periodogram at the peak and
its neighbours (period 2 exactly at the Nyquist bin); the size is the peak-to-peak of the band's
part of the series (:func:`short_period_part`). A series shorter than
``MIN_STEPS`` (ten periods of the band's longest), or without motion about its line, is
undetermined: no verdict.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BAND_STEPS = 20  # the longest period of the short-period band, in steps
LINE_BINS = 3  # the spectral line's half-width, in bins (a Hann window spreads a tone over 3)
MOST = 0.5
TRIM = 4 * BAND_STEPS  # the high pass's start-up transient, trimmed at either end
REFERENCE_STEPS = 3 * BAND_STEPS  # the fast motion the band's share is of
MIN_STEPS = 10 * BAND_STEPS
RESOLUTION_ULPS = 64
DECAYING = 0.5  # the last third's size against the first's: below, decaying
GROWING = 2.0  # above: the data grow over the window


@dataclass(frozen=True)
class Ring:
    """One series' short-period motion over the window (eq. 36). ``rings`` None: undetermined
    (too short, or no motion about its line)."""

    coordinate: str
    unit: str
    peak_to_peak: float | None
    period_steps: float | None
    band_share: float | None
    line_share: float | None
    growth: float | None  # rms of the band's part, last third over first third
    rings: bool | None
    # Why ``rings`` is None: SHORT (the window holds fewer than MIN_STEPS), STILL (no motion
    # about its line beyond the numbers' resolution) or NON_FINITE; None when determined.
    undetermined: str | None = None

    @property
    def trend(self) -> str | None:
        """'growing', 'steady' or 'decaying' over the window, from ``growth``."""
        if self.growth is None:
            return None
        return ("growing" if self.growth > GROWING else
                "decaying" if self.growth < DECAYING else "steady")


SHORT, STILL, NON_FINITE = "short", "still", "non-finite"


def _undetermined(coordinate: str, unit: str, why: str) -> Ring:
    return Ring(coordinate, unit, None, None, None, None, None, None, why)


def ring(x: np.ndarray, coordinate: str, unit: str, scale: float = 1.0) -> Ring:
    """The short-period motion of series ``x`` (eq. 36); sizes are multiplied by ``scale``
    (a modal coordinate's share of the reduced coordinate it is named by)."""
    x = np.asarray(x, dtype=float)
    n = x.size
    if n < MIN_STEPS:
        return _undetermined(coordinate, unit, SHORT)
    if not np.all(np.isfinite(x)):
        return _undetermined(coordinate, unit, NON_FINITE)
    k = np.arange(n, dtype=float)
    detrended = x - np.polyval(np.polyfit(k, x, 1), k)
    # No motion about the line beyond the numbers' resolution (a constant series leaves the
    # fit's rounding, a few ulps of its size): nothing to judge.
    if not np.std(detrended) > RESOLUTION_ULPS * np.finfo(float).eps * np.max(np.abs(x)):
        return _undetermined(coordinate, unit, STILL)
    f = np.fft.rfftfreq(n)
    P = np.abs(np.fft.rfft(detrended * np.hanning(n))) ** 2
    total = float(P[f >= 1.0 / REFERENCE_STEPS].sum())
    band = f >= 1.0 / BAND_STEPS
    band_power = float(P[band].sum())
    peak = int(np.flatnonzero(band)[np.argmax(P[band])])
    # The line's bins within the band only, so that its share never exceeds one.
    near = np.zeros_like(band)
    near[max(0, peak - LINE_BINS):peak + LINE_BINS + 1] = True
    line = float(P[near & band].sum())
    part = short_period_part(x)
    band_share = band_power / total if total > 0 else 0.0
    line_share = line / band_power if band_power > 0 else 0.0
    third = part.size // 3
    early, late = (float(np.sqrt(np.mean(p ** 2))) for p in (part[:third], part[-third:]))
    # A band part that starts from nothing grows without bound: the largest finite float
    # stands for it (the record is JSON, which has no infinity).
    growth = late / early if early > 0 else (np.finfo(float).max if late > 0 else 1.0)
    return Ring(coordinate=coordinate, unit=unit,
                peak_to_peak=float((part.max() - part.min()) * abs(scale)),
                period_steps=_peak_period(P, f, peak), band_share=band_share,
                line_share=line_share, growth=float(growth),
                rings=bool(band_share > MOST and line_share > MOST))


def short_period_part(x: np.ndarray) -> np.ndarray:
    """The band's part of a series: a zero-phase 4th-order Butterworth high-pass at period
    ``BAND_STEPS`` (SciPy's sosfiltfilt; it removes a trend up to a cubic), less ``TRIM``
    steps at either end where the filter's start-up transients lie (measured: a period-2
    series' size within 2e-5 after 80 steps, 4e-3 after 40; a transform's part would wrap the
    series' ends onto each other and put their jump in every bin)."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, 2.0 / BAND_STEPS, btype="highpass", output="sos")
    return sosfiltfilt(sos, x)[TRIM:-TRIM]


def _peak_period(P: np.ndarray, f: np.ndarray, peak: int) -> float:
    """1/f at the periodogram's peak, refined by a parabola through log P at the peak and its
    two neighbours; 2 at the Nyquist bin (the spectrum is symmetric about it)."""
    if peak == len(f) - 1 and f[peak] == 0.5:
        return 2.0
    if peak == 0 or peak == len(f) - 1:
        return float(1.0 / f[peak])
    a, b, c = np.log(np.maximum(P[peak - 1:peak + 2], np.finfo(float).tiny))
    denom = a - 2.0 * b + c
    shift = 0.5 * (a - c) / denom if denom < 0 else 0.0
    return float(1.0 / (f[peak] + shift * (f[1] - f[0])))
