"""The ripple's detectors on the bus rate as measured (eqs. 25, 36, 40): what a ground
segment would run on telemetry to say "ω_b rings period-2".

- **lag-1**: the lag-1 autocorrelation of ω_b's dominant step component (eq. 25,
  :func:`pipeline.analysis.stages.bus_rate_data`) below ``LAG1_THRESHOLD`` = −0.5, the claims'
  threshold for a period-2 ring (C1, C15, C30): a period-2 series reads −1, a smooth one +1,
  white noise 0.
- **spectral**: one of ω_b's components rings (eq. 36: most of its short-period motion about
  its trend in the band of periods up to 20 steps, most of that one spectral line) at a period
  of at most ``PERIOD2_MAX`` = 2.5 steps (the period-2 line at the Nyquist frequency; an
  unstable mode with one step of delay rings over 4 to 6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.analysis.harm import period2_amplitude
from pipeline.analysis.ringing import ring
from pipeline.analysis.stages import bus_rate_data

LAG1_THRESHOLD = -0.5
PERIOD2_MAX = 2.5


@dataclass(frozen=True)
class RippleDetection:
    lag1: float | None  # of ω_b's dominant step component; None: undetermined
    lag1_detects: bool
    spectral_detects: bool
    period_steps: float | None  # of the component that rings (None: none rings)
    amplitude: float  # rad/s: ω_b's largest period-2 amplitude (eq. 30)


def detect_ripple(w_b: np.ndarray) -> RippleDetection:
    """Both detectors on ω_b (N×3, bus frame) over a window (module docstring)."""
    lag1 = bus_rate_data(w_b).lag1
    rings = [ring(w_b[:, i], f"omega_b[{i}]", "rad/s") for i in range(3)]
    hits = [r for r in rings if r.rings and r.period_steps is not None
            and r.period_steps <= PERIOD2_MAX]
    return RippleDetection(
        lag1=lag1, lag1_detects=bool(lag1 is not None and lag1 < LAG1_THRESHOLD),
        spectral_detects=bool(hits), period_steps=hits[0].period_steps if hits else None,
        amplitude=float(np.max(period2_amplitude(w_b))))
