"""What the ripple does to the actuators and the bus attitude (eqs. 30–32).

The pointing error of z_b cannot see a ripple about z_b, so the harm of a period-2 loop is
judged on what it moves: the generalized force the plant receives (the log's ``u_applied``:
the bus wrench [f_b; τ_b] in the bus frame, then the joint torques, eq. 29), the joint rates,
and the bus attitude between two control instants. Every statistic is over the analysis
window and reads the same for any dt where it measures a physical quantity (a torque in N·m,
reversals per second).

- period-2 amplitude of a series, a = RMS(Δ²x)/4 (eq. 30): an alternating a(−1)^k has
  Δ²x = 4a(−1)^k; a smooth series, almost none;
- reversal share, the fraction of consecutive steps whose values have opposite signs (eq. 31):
  1 for a period-2 about zero, 0 for a series of one sign, ½ for a random sign; its rate
  per second is share/dt;
- bus attitude jitter (eq. 32): the period-2 amplitude of the attitude at the control
  instants, ¼‖δ_k − δ_{k−1}‖ with δ_k = log(R_tb,kᵀ R_tb,k+1) the bus frame's rotation over
  step k (an attitude θ_k = θ̄_k + A(−1)^k about a fixed axis reads A), plus its excursion
  between them (the log's ``attitude_excursion_deg``: the largest angle from the geodesic
  between two instants, which the plant measures). The reduced update (eq. 15) turns the bus
  at a constant rate over a step, so its ripple sits at the instants; under a held torque
  (eq. 29) the rate ramps and the instants fall on the oscillation's zero crossings, its
  amplitude between them. The sum is the continuous attitude's period-2 amplitude in both
  cases, and a bound on it otherwise;
- short-period peak to peak (eq. 30b): max − min of a series' short-period part (eq. 36's
  band, periods up to ``BAND_STEPS``), largest over the torque's channels, and for the bus
  attitude at the instants (θ_k = Σ_{j<k} δ_j, the bus frame's rotations summed, per axis)
  plus twice the largest excursion between them. A period-2 amplitude reads a period-2 cycle
  only: the relay cycle of a delayed loop, over some six steps, moves the bus several times
  more than its period-2 part says, and this statistic sees it (a period-2 cycle of
  amplitude a reads 2a).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.shapes import Q, U, V

BUS_TORQUE_AXES = ("x_b", "y_b", "z_b")


@dataclass(frozen=True)
class ChannelHarm:
    """One group of actuator channels (the bus torque's three axes, or the joints)."""

    rms: float  # RMS over the window of the channels' norm
    channel: str  # the channel of largest period-2 amplitude
    period2_amplitude: float  # its a = RMS(Δ²x)/4 (eq. 30)
    # The largest short-period peak to peak over the channels (eq. 30b) and its channel, which
    # a cycle longer than two steps may put elsewhere; None: a window too short to judge, or
    # not finite.
    short_period_peak_to_peak: float | None
    short_period_channel: str | None
    reversal_share: float  # its share of sign reversals between consecutive steps (eq. 31)
    reversals_per_s: float  # reversal_share / dt


@dataclass(frozen=True)
class AttitudeHarm:
    """The bus attitude's period-2 motion (eq. 32), degrees, RMS over the window."""

    jitter_deg: float  # at the instants plus between them
    jitter_deg_max: float
    at_instants_deg: float
    between_instants_deg: float
    step_deg_median: float  # the median rotation of the bus over one step
    # The attitude's short-period peak to peak (eq. 30b): at the instants, largest over the bus
    # axes, plus twice the largest excursion between them (the continuous attitude's, or a
    # bound on it, as eq. 32's jitter); None: a window too short to judge, or not finite.
    short_period_peak_to_peak_deg: float | None


@dataclass(frozen=True)
class Harm:
    """The harm record of one run (eqs. 30–32), units in the field names' comments."""

    bus_torque: ChannelHarm  # N·m, the plant's received τ_b (u_applied's U.tau_b)
    joint_torque: ChannelHarm  # N·m, the plant's received joint torques (U.joints)
    joint_rate: ChannelHarm  # rad/s, q̇ (v's V.joints)
    attitude: AttitudeHarm


def period2_amplitude(x: np.ndarray) -> np.ndarray:
    """a = RMS(Δ²x)/4 along axis 0 (eq. 30)."""
    return np.sqrt(np.mean(np.diff(np.asarray(x, dtype=float), 2, axis=0) ** 2, axis=0)) / 4


def short_period_peak_to_peak(x: np.ndarray) -> np.ndarray | None:
    """max − min of the short-period part (eq. 36's band) along axis 0 (eq. 30b); None when
    the series is too short for the band's filter (``MIN_STEPS``) or not finite."""
    from pipeline.analysis.ringing import MIN_STEPS, short_period_part

    x = np.asarray(x, dtype=float)
    if len(x) < MIN_STEPS or not np.all(np.isfinite(x)):
        return None
    columns = x.reshape(len(x), -1).T  # one series at a time: the part trims its ends
    return np.array([np.ptp(short_period_part(c)) for c in columns]).reshape(x.shape[1:])


def reversal_share(x: np.ndarray) -> np.ndarray:
    """The share of k with x_k·x_{k+1} < 0, along axis 0 (eq. 31); an exact zero reverses
    nothing."""
    x = np.asarray(x, dtype=float)
    return np.mean(x[:-1] * x[1:] < 0, axis=0)


def channel_harm(x: np.ndarray, dt: float, names: tuple[str, ...]) -> ChannelHarm:
    """The statistics of eqs. 30 and 31 of the N×k channels x, on the channel of largest
    period-2 amplitude."""
    amp = period2_amplitude(x)
    i = int(np.argmax(amp))
    share = float(reversal_share(x[:, i]))
    pp = short_period_peak_to_peak(x)
    j = None if pp is None else int(np.argmax(pp))
    return ChannelHarm(rms=float(np.sqrt(np.mean(np.sum(x * x, axis=1)))), channel=names[i],
                       period2_amplitude=float(amp[i]),
                       short_period_peak_to_peak=None if j is None else float(pp[j]),
                       short_period_channel=None if j is None else names[j],
                       reversal_share=share, reversals_per_s=share / dt)


def attitude_steps(quat_tb: np.ndarray) -> np.ndarray:
    """δ_k = log(R_tb,kᵀ R_tb,k+1), the bus frame's rotation over each step, in the bus frame
    (rad, (N−1)×3), from the logged unit quaternions (x, y, z, w) (eq. 32)."""
    r = Rotation.from_quat(quat_tb)
    return (r[:-1].inv() * r[1:]).as_rotvec()


def attitude_jitter(quat_tb: np.ndarray) -> np.ndarray:
    """The bus attitude's period-2 amplitude at each inner step, ¼‖δ_k − δ_{k−1}‖ (rad,
    eq. 32)."""
    return np.linalg.norm(np.diff(attitude_steps(quat_tb), axis=0), axis=1) / 4


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def harm(u_applied: np.ndarray, v: np.ndarray, q: np.ndarray, excursion_deg: np.ndarray,
         dt: float) -> Harm:
    """The harm record of one run's window (eqs. 30–32): N rows of the log's ``u_applied``,
    ``v``, ``q`` and ``attitude_excursion_deg``, N ≥ 3."""
    n_joints = u_applied.shape[1] - 6
    joints = tuple(f"joint {j + 1}" for j in range(n_joints))
    at_instants = np.degrees(attitude_jitter(q[:, Q.quat_tb]))  # instants 1 … N−2
    between = np.asarray(excursion_deg, dtype=float)
    jitter = at_instants + between[1:-1]
    delta = attitude_steps(q[:, Q.quat_tb])
    steps = np.degrees(np.linalg.norm(delta, axis=1))
    # The attitude at the instants from the steps' rotations summed: exact about a fixed
    # axis, and off by products of the slow turn and the ripple otherwise; the motion between
    # the instants (a held torque's arcs) adds at most twice its largest excursion.
    theta = np.vstack([np.zeros(3), np.cumsum(delta, axis=0)])
    pp = short_period_peak_to_peak(theta)
    pp_deg = (None if pp is None or not np.all(np.isfinite(between)) else
              float(np.degrees(pp.max()) + 2.0 * between.max()))
    return Harm(bus_torque=channel_harm(u_applied[:, U.tau_b], dt, BUS_TORQUE_AXES),
                joint_torque=channel_harm(u_applied[:, U.joints], dt, joints),
                joint_rate=channel_harm(v[:, V.joints], dt, joints),
                attitude=AttitudeHarm(jitter_deg=_rms(jitter), jitter_deg_max=float(jitter.max()),
                                      at_instants_deg=_rms(at_instants),
                                      between_instants_deg=_rms(between),
                                      step_deg_median=float(np.median(steps)),
                                      short_period_peak_to_peak_deg=pp_deg))


@dataclass(frozen=True)
class RollSmear:
    """The camera's roll about its boresight over the window, and the smear it makes at the
    image corner (eq. 32): None where the window is too short to judge (eq. 36)."""

    rate_peak_to_peak: float | None  # rad/s: the short-period part of ω_e,z
    angle_peak_to_peak_deg: float | None  # its integral, the roll angle's short-period part
    resolution_px: int  # the stated image size (square), px
    fov_deg: float
    smear_px: float | None  # the corner's motion: the angle × half the diagonal, px


def roll_smear(roll_rate: np.ndarray, dt: float, resolution_px: int, fov_deg: float
               ) -> RollSmear:
    """The camera roll's smear (eq. 32): θ_k = dt Σ ω_e,z up to k (the roll at the instants),
    its short-period part's peak to peak (periods up to 20 steps, eq. 36), times the corner's
    distance from the image centre, resolution/√2 px: a roll about the boresight turns the
    image about its centre, and moves the corner most."""
    from pipeline.analysis.ringing import MIN_STEPS, short_period_part

    rate = np.asarray(roll_rate, dtype=float)
    if rate.size < MIN_STEPS or not np.all(np.isfinite(rate)):
        return RollSmear(None, None, resolution_px, fov_deg, None)
    angle = short_period_part(np.cumsum(rate) * dt)
    fast = short_period_part(rate)
    pp = float(angle.max() - angle.min())
    return RollSmear(rate_peak_to_peak=float(fast.max() - fast.min()),
                     angle_peak_to_peak_deg=float(np.degrees(pp)), resolution_px=resolution_px,
                     fov_deg=fov_deg, smear_px=float(pp * resolution_px / np.sqrt(2.0)))

