"""What jittered time stamps do to the period-2 detection: analysed at their own instants
(``import --max-jitter``) against resampled onto the nominal step (``import --resample``).

Run from the repository: ``.venv/bin/python scripts/jitter_study.py``. A synthetic bus rate
of the seed's kind: a period-2 ripple of amplitude A = 0.15 rad/s (the nominal run's ω_b,z)
on a slow sinusoid of 0.05 rad/s (period 20 s), one sample per control step of dt = 0.03 s,
2000 steps. Its stamps are jittered uniformly by ±J·dt (seeded), as a telemetry stamps rows
when it publishes them.

- at its own instants: the samples are the loop's, one per step; the lag-1 and the
  alternating amplitude are computed on them as they are;
- resampled: linearly interpolated onto t_0 + k·dt, as the importer resamples v. A grid
  point a fraction λ past a sample takes (1 − λ)x_k + λx_{k+1}: an alternating signal keeps
  |1 − 2λ| of its amplitude there.

Printed per J: the lag-1 (period-2 reads −1) and the amplitude of (x_k − x_{k+1})/2's RMS
against A, both ways. The numbers are in docs/importing.md.
"""

from __future__ import annotations

import numpy as np

from pipeline.analysis.signals import lag1_autocorrelation

DT, N, A, SEED = 0.03, 2000, 0.15, 33


def alternating_amplitude(x: np.ndarray) -> float:
    """RMS of half the step-to-step change: A for A·(−1)^k, near 0 for a slow signal."""
    return float(np.sqrt(np.mean((np.diff(x) / 2) ** 2)))


def study(jitter: float) -> tuple[float, float, float, float]:
    k = np.arange(N)
    x = A * (-1.0) ** k + 0.05 * np.sin(2 * np.pi * k * DT / 20.0)
    rng = np.random.default_rng(SEED)
    t = k * DT + rng.uniform(-jitter, jitter, N) * DT
    grid = t[0] + np.arange(int((t[-1] - t[0]) // DT) + 1) * DT
    resampled = np.interp(grid, t, x)
    return (float(lag1_autocorrelation(x[:, None])[0]), alternating_amplitude(x) / A,
            float(lag1_autocorrelation(resampled[:, None])[0]),
            alternating_amplitude(resampled) / A)


def main() -> None:
    print("jitter (×dt) | own instants: lag-1, amplitude/A | resampled: lag-1, amplitude/A")
    for j in (0.0, 0.02, 0.05, 0.1, 0.2):
        own_lag, own_amp, res_lag, res_amp = study(j)
        print(f"{j:12.2f} | {own_lag:+.4f}, {own_amp:.4f} | {res_lag:+.4f}, {res_amp:.4f}")


if __name__ == "__main__":
    main()
