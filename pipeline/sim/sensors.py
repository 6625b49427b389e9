"""What the controller measures of the sampled plant (eq. 40): a rate gyro on the bus and the
joint encoders, seeded.

    ω̃_k = Q_g(ω_k + b_k + n_k),   n_k ~ N(0, N²/dt) per axis (angle random walk N, rad/√s),
    b_0 ~ N(0, σ_b²),  b_{k+1} = b_k + N(0, K²·dt)   (bias σ_b in rad/s, its walk K rad/s/√s)
    q̃_a,k = Q_e(q_a,k)
    q̇̃_a,k = q̇_a,k + [(Q_e(q_a,k) − Q_e(q_a,k−1)) − (q_a,k − q_a,k−1)] / dt
    Q(x) = lsb·round(x/lsb)   (lsb 0: x)

ω_b is the free flyer's angular velocity in the bus frame (v[3:6]); the joint rates carry the
encoders' quantisation as a rate taken from successive readings does (its error, not the
difference's lag: with no quantisation the rate is the plant's). The bus pose and linear
velocity are measured exactly. Each step draws three normals for n and three for the bias's
walk, in that order, whatever their scales, from ``SeedSequence([seed])``: the same seed gives
the same noise. The first instant (the initial state) is measured exactly.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.spec import Sensors


def quantise(x: np.ndarray, lsb: float) -> np.ndarray:
    """Q(x) = lsb·round(x/lsb), ties to even (eq. 40); ``lsb`` 0: x."""
    return x if lsb <= 0.0 else lsb * np.round(x / lsb)


class Measurement:
    """The sensors of one run (eq. 40): their stream, the gyro's bias, the last reading."""

    def __init__(self, sensors: Sensors, dt: float) -> None:
        self.s, self.dt = sensors, dt
        self.rng = np.random.default_rng(np.random.SeedSequence([sensors.seed]))
        self.bias = self.rng.standard_normal(3) * sensors.gyro_bias
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # (true, read) joint angles

    def measure(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q̃, ṽ) of the plant's (q, v) at this instant (eq. 40)."""
        s, dt = self.s, self.dt
        white = self.rng.standard_normal(3) * (s.gyro_arw / math.sqrt(dt))
        walk = self.rng.standard_normal(3) * (s.gyro_bias_walk * math.sqrt(dt))
        q_m, v_m = q.copy(), v.copy()
        v_m[3:6] = quantise(v[3:6] + self.bias + white, s.gyro_lsb)
        self.bias = self.bias + walk
        if s.encoder_lsb > 0.0:
            true = q[7:].copy()
            read = quantise(true, s.encoder_lsb)
            q_m[7:] = read
            if self._last is not None:
                last_true, last_read = self._last
                v_m[6:] = v[6:] + ((read - last_read) - (true - last_true)) / dt
            self._last = (true, read)
        return q_m, v_m
