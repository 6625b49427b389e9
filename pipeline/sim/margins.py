"""One damping mode's loop as flown, in the terms a review uses (eq. 35): its characteristic
root, and its gain, phase and delay margins against the spec's requirement.

In damping mode i (M̆⁻¹D̆ w = μ w, eq. 21) the velocity error obeys, with the stiffness dropped
(slow beside the damping, as in eqs. 23–24), e_{k+1} = e_k + u_{k−d} with the controller's
velocity increment u_k = −g e_k, where

    g = dt·μ                 explicit (eq. 15a)
    g = dt·μ / (1 + dt·μ)    imex (eq. 15b: e_cmd = e/(1 + dt·μ))

and d the plant's computation delay in steps (eq. 29; the simulator's update has none). Both
plants give the velocity this map: the update of eq. 22 sets e_{k+1} to the command, and the
zero-order hold of eq. 29 moves it there at a constant acceleration. The loop, broken at the
command, is

    L(z) = g z^{−d} / (z − 1),        closed loop:  z^d (z − 1) + g = 0.

Its margins have closed forms (∠(e^{jω} − 1) = π/2 + ω/2, |e^{jω} − 1| = 2 sin(ω/2)):

    phase crossover  ω_180 = π/(2d + 1),      gain margin  GM = 2 sin(π/(2(2d + 1))) / g
    gain crossover   ω_c = 2 arcsin(g/2)  (g ≤ 2),   phase margin  PM = π/2 − (d + ½) ω_c

and no gain crossover when g > 2 (|L| > 1 at every frequency). The delay margin is the
smallest further input delay τ ≥ 0, a fraction of a step included, that puts a root on the
unit circle: with the command held (zero-order hold) and applied τ later, a step receives the
command of n = ⌊d + τ/dt⌋ instants before for the last (1 − δ) of it and the one before that
for the first δ (δ = frac(d + τ/dt)), so

    z^{n+1} (z − 1) + g ((1 − δ) z + δ) = 0,

solved for its roots and bisected in τ, up to a horizon (PM/ω_c, the phase-lag estimate, is
not exact for a held command: for d = 0 and 1 ≤ g < 2 the exact margin is dt/g, the estimate
smaller).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.sim.jit import jit
from pipeline.sim.stability import (
    GAIN_BLOCKS,
    GAIN_FIELDS,
    block_slices,
    damping_modes,
    fastest_in_block,
    with_gain,
)

UNIT = 1.0  # a root of this modulus is on the unit circle: marginal


@dataclass(frozen=True)
class Latency:
    """The delay of the command as flown (eqs. 29, 41), in steps: ``steps`` whole ones
    (mission.plant.delay_steps), then the arrival within the step, uniform on
    [``fraction``, ``fraction`` + ``jitter``) (mission.plant.timing)."""

    steps: int = 0
    fraction: float = 0.0
    jitter: float = 0.0

    @classmethod
    def of(cls, plant) -> Latency:
        """The latency of a spec's ``mission.plant`` block (none under the reduced plant)."""
        if plant.model != "sampled":
            return cls()
        t = plant.timing
        return cls(plant.delay_steps, *((0.0, 0.0) if t is None else (t.delay_fraction,
                                                                       t.jitter)))

    @property
    def worst(self) -> tuple[int, float]:
        """(n, δ): the longest delay, n + δ steps (δ in [0, 1)): the frozen loop the margins
        judge, each margin falling as the delay grows."""
        total = self.steps + self.fraction + self.jitter
        n = math.floor(total)
        return n, total - n

    def words(self) -> str:
        """The latency in a review's words."""
        if not self.fraction and not self.jitter:
            return f"{self.steps} step(s) of delay"
        spread = (f" to {self.steps + self.fraction + self.jitter:.3g} (jitter "
                  f"{self.jitter:.3g} step)" if self.jitter else "")
        return f"{self.steps + self.fraction:.3g}{spread} steps of delay"


@dataclass(frozen=True)
class Complex:
    real: float
    imag: float

    @classmethod
    def of(cls, z: complex) -> Complex:
        return cls(z.real, z.imag)


def loop_gain(dt_mu: float, integrator: str) -> float:
    """g, the mode's velocity increment per step per unit error (eq. 35)."""
    if integrator == "explicit":
        return float(dt_mu)
    if integrator == "imex":
        return float(dt_mu / (1.0 + dt_mu))
    raise ValueError(f"unknown integrator {integrator!r}")


def characteristic(g: float, delay: int, fraction: float = 0.0) -> np.ndarray:
    """Coefficients (highest power first) of z^{n+1}(z − 1) + g((1 − δ)z + δ), n = delay,
    δ = fraction: the mode's closed loop with a held command applied delay + fraction steps
    late (eq. 35)."""
    c = np.zeros(delay + 3)
    c[0], c[1] = 1.0, -1.0  # z^{n+2} − z^{n+1}
    c[-2] += g * (1.0 - fraction)
    c[-1] += g * fraction
    return c if fraction else c[:-1]  # without a fraction the polynomial is z^{n}(z − 1) + g


@jit
def schur_stable(c: np.ndarray) -> bool:
    """Whether every root of the polynomial ``c`` (highest power first, c[0] ≠ 0) lies
    strictly inside the unit circle, without its roots: the Schur–Cohn step-down. With
    A_m(z) = Σ a_i z^{−i} (a_0 = 1), k_m = a_m and a_{m−1,i} = (a_i − k_m a_{m−i})/(1 − k_m²),
    the roots are inside exactly when every |k_m| < 1 (E. I. Jury, *Theory and Application
    of the z-Transform Method*, 1964). Compiled: the delay margins' bisections test hundreds
    of polynomials per fix table."""
    a = c / c[0]
    m = a.size - 1
    while m > 0:
        k = a[m]
        if not abs(k) < 1.0:
            return False
        scale = 1.0 - k * k
        b = np.empty(m)
        for i in range(m):
            b[i] = (a[i] - k * a[m - i]) / scale
        a = b
        m -= 1
    return True


def dominant_root(g: float, delay: int, fraction: float = 0.0) -> complex:
    """The root of largest modulus (then largest imaginary part) of :func:`characteristic`."""
    roots = np.roots(characteristic(g, delay, fraction))
    return complex(max(roots, key=lambda z: (round(abs(z), 14), z.imag)))


def period_steps(z: complex) -> float | None:
    """The oscillation period of a root in steps, 2π/|arg z| (2 for a negative real root);
    None for a positive real one (no oscillation)."""
    angle = abs(math.atan2(z.imag, z.real))
    return None if angle == 0.0 else 2.0 * math.pi / angle


def root_regime(z: complex, loop: str = "the linear loop") -> str:
    """The behaviour a dominant root gives its loop (eqs. 23, 35): ``loop`` names which, the
    whole map's (the default) or one mode's scalar loop, whose growth differs from the whole
    map's where the stiffness couples the modes. 'Unstable' is the linear loop's: what holds
    the motion, and whether it grows, is the data's to say."""
    m, period = abs(z), period_steps(z)
    kind = ("monotone" if period is None else "period-2" if abs(z.imag) <= 1e-12 * m
            else f"oscillation over {period:.3g} steps")
    if math.isclose(m, UNIT, rel_tol=0.0, abs_tol=1e-12):
        return f"marginal ({kind})"
    if m > UNIT:
        return f"unstable: {kind}, ×{m:.3g} per step in {loop}"
    if period is None:
        return "stable: monotone decay"
    return "stable: decaying 2-cycle" if kind == "period-2" else f"stable: decaying {kind}"


@dataclass(frozen=True)
class Margins:
    """The margins of one mode's loop as flown (eq. 35) and the requirement's verdict."""

    gain_margin_db: float
    phase_crossover: float  # rad per step
    phase_margin_deg: float | None  # None: no gain crossover (|L| > 1 at every frequency)
    gain_crossover: float | None  # rad per step
    delay_margin_s: float  # the further delay that destabilises it; 0 when unstable as flown
    delay_margin_beyond: bool  # stable over the whole horizon: delay_margin_s is a lower bound
    phase_lag_delay_s: float | None  # PM/ω_c·dt, the phase-lag estimate, for comparison
    meets_gain: bool
    meets_phase: bool
    meets_delay: bool

    @property
    def meets(self) -> bool:
        return self.meets_gain and self.meets_phase and self.meets_delay


def loop_response(g: float, delay: int, fraction: float, w: np.ndarray) -> np.ndarray:
    """L(e^{jω}) = g ((1 − δ) + δ e^{−jω}) e^{−jnω}/(e^{jω} − 1): the mode's loop broken at
    the command, held and applied n + δ steps late (eqs. 35, 41)."""
    z = np.exp(1j * np.asarray(w, dtype=float))
    return g * ((1.0 - fraction) + fraction / z) * z ** (-delay) / (z - 1.0)


def loop_phase(delay: int, fraction: float, w: np.ndarray) -> np.ndarray:
    """∠L(e^{jω}) unwrapped from −π/2 at ω → 0: −π/2 − ω/2 − nω + ∠((1 − δ) + δ e^{−jω}),
    the last in [−π, 0] and continuous on (0, π] (eq. 41)."""
    w = np.asarray(w, dtype=float)
    return (-0.5 * np.pi - (delay + 0.5) * w
            + np.arctan2(-fraction * np.sin(w), (1.0 - fraction) + fraction * np.cos(w)))


_GRID = 4096  # the frequency scan for a fractional delay's crossovers, then Brent's method


def gain_margin(g: float, delay: int, fraction: float = 0.0) -> tuple[float, float]:
    """(GM, ω_180): the factor on g that makes the loop marginal, at the phase crossover. With
    a fraction of a step (eq. 41) no closed form: the least −1/L(e^{jω}) over the frequencies
    where L is real and negative, found by a scan of ω ∈ (0, π) and Brent's method, and ω = π
    (where L is real: −g (1 − 2δ)(−1)^n/2)."""
    if not fraction:
        w180 = math.pi / (2 * delay + 1)
        return 2.0 * math.sin(w180 / 2.0) / g, w180
    from scipy.optimize import brentq

    def imag(w: float) -> float:
        return float(np.sin(loop_phase(delay, fraction, w)))

    candidates = []
    end = -g * (1.0 - 2.0 * fraction) * (-1) ** delay / 2.0
    if end < 0.0:
        candidates.append((-1.0 / end, math.pi))
    w = np.linspace(0.0, math.pi, _GRID + 1)[1:-1]
    sign = np.sin(loop_phase(delay, fraction, w))
    for i in np.flatnonzero(np.sign(sign[:-1]) != np.sign(sign[1:])):
        wc = brentq(imag, w[i], w[i + 1], xtol=1e-15)
        L = complex(loop_response(g, delay, fraction, wc))
        if L.real < 0.0:
            candidates.append((-1.0 / L.real, wc))
    return min(candidates) if candidates else (math.inf, math.pi)


def phase_margin(g: float, delay: int, fraction: float = 0.0
                 ) -> tuple[float | None, float | None]:
    """(PM in rad, ω_c), or (None, None) when |L| > 1 at every frequency (g > 2 without a
    fraction). Not wrapped into (−π, π]: with d ≥ 2 the crossover's phase can lie more than
    a turn past −π, and the wrapped value (python-control's) then reads positive for an
    unstable loop (d = 2, g = 1.9: +91° wrapped, −269° here, GM −9.75 dB). With a fraction of
    a step (eq. 41) |L| still falls monotonically in ω (its numerator falls, 2 sin(ω/2)
    grows): its one crossover is found by Brent's method."""
    if not fraction:
        if g > 2.0:
            return None, None
        wc = 2.0 * math.asin(g / 2.0)
        return math.pi / 2.0 - (delay + 0.5) * wc, wc
    if g * abs(1.0 - 2.0 * fraction) / 2.0 >= 1.0:
        return None, None
    from scipy.optimize import brentq

    wc = brentq(lambda w: float(abs(loop_response(g, delay, fraction, w))) - 1.0,
                1e-12, math.pi, xtol=1e-15)
    return float(math.pi + loop_phase(delay, fraction, wc)), wc


def _stable(g: float, total: float) -> bool:
    """Whether the mode's loop with ``total`` steps of delay has every root of
    :func:`characteristic` inside the unit circle. A whole number n of steps: the closed form
    0 < g < 2 sin(π/(2(2n + 1))), the gain margin of eq. 35 above 1 (g = 0 leaves the root
    z = 1, marginal); with a fraction of a step, the Schur–Cohn test (:func:`schur_stable`).
    Neither computes a root."""
    n = math.floor(total)
    if total == n:
        return 0.0 < g < 2.0 * math.sin(math.pi / (2.0 * (2 * n + 1)))
    return bool(schur_stable(characteristic(g, n, total - n)))


# Delay margins are resolved up to this many steps of further delay: beyond, the mode meets any
# requirement a review would set (a slow mode's margin is hundreds of steps, whose roots would
# cost a polynomial of that degree each) and the record says "at least".
DELAY_HORIZON_STEPS = 16
_SCAN = 1.0 / 16.0  # steps: the scan's grid before the bisection


def delay_margin(g: float, delay: float, dt: float, tol: float = 1e-9) -> tuple[float, bool]:
    """(τ, beyond): the smallest further delay τ ≥ 0 (s), fractions of a step included, that
    leaves the mode's loop unstable (eq. 35), 0 when it is unstable as flown; scanned from the
    declared delay on a grid of 1/16 step, then bisected to ``tol`` steps. ``beyond``: stable
    over the whole horizon of ``DELAY_HORIZON_STEPS``, τ is then that horizon (a lower
    bound). ``delay`` is the loop's own, in steps, a fraction included (eq. 41)."""
    if not _stable(g, delay):
        return 0.0, False
    n = math.floor(delay)
    pm, wc = phase_margin(g, n, delay - n)
    # A slow mode: its phase-lag estimate lies beyond the horizon by more than a held command
    # moves it (under a step), and the loop is stable at the horizon: no scan needed.
    if (pm is not None and wc and pm / wc > DELAY_HORIZON_STEPS + 2
            and _stable(g, delay + DELAY_HORIZON_STEPS)):
        return DELAY_HORIZON_STEPS * dt, True
    lo = 0.0
    while _stable(g, delay + lo + _SCAN):
        lo += _SCAN
        if lo >= DELAY_HORIZON_STEPS:
            return DELAY_HORIZON_STEPS * dt, True
    hi = lo + _SCAN
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _stable(g, delay + mid) else (lo, mid)
    return lo * dt, False


@dataclass(frozen=True)
class Requirement:
    """Margins a review asks of every mode (the spec's ``requirements`` block)."""

    gain_margin_db: float
    phase_margin_deg: float
    delay_margin_steps: float


def margins(g: float, delay: int, dt: float, req: Requirement, fraction: float = 0.0
            ) -> Margins:
    """Gain, phase and delay margins of the loop L(z) = g z^{−d}/(z − 1) (eq. 35), or with a
    command arriving ``fraction`` of a step later (:func:`loop_response`, eq. 41), against
    ``req``."""
    gm, w180 = gain_margin(g, delay, fraction)
    pm, wc = phase_margin(g, delay, fraction)
    dm, beyond = delay_margin(g, delay + fraction, dt)
    gm_db = 20.0 * math.log10(gm)
    pm_deg = None if pm is None else math.degrees(pm)
    return Margins(
        gain_margin_db=gm_db, phase_crossover=w180, phase_margin_deg=pm_deg, gain_crossover=wc,
        delay_margin_s=dm, delay_margin_beyond=beyond,
        phase_lag_delay_s=None if pm is None or pm <= 0 else pm / wc * dt,
        meets_gain=bool(gm_db >= req.gain_margin_db),
        meets_phase=bool(pm_deg is not None and pm_deg >= req.phase_margin_deg),
        meets_delay=bool(dm >= req.delay_margin_steps * dt))


@dataclass(frozen=True)
class RequirementFix:
    """One change of the loop and whether every mode then meets the requirement (eq. 35), at
    the run's plant and delay: the theory of a fix, to be flown before it is called one."""

    change: str  # the spec field and the value it takes
    value: float | None  # that value (None: the integrator or the gains, or none suffices)
    gains: dict[str, float]  # the damping gains cut, by block (empty: no cut)
    meets: bool
    worst_mode: str  # the mode of least gain margin after the change
    gain_margin_db: float
    phase_margin_deg: float | None
    delay_margin_s: float
    steps_per_s: float  # cost: control steps per second of mission


def _meets_fast(g: float, delay: int, req: Requirement, fraction: float = 0.0) -> bool:
    """Whether a mode's loop meets ``req``: GM and PM (closed forms without a fraction), and
    stability with the required further delay (the delay margin's test at its one point)."""
    gm, _ = gain_margin(g, delay, fraction)
    pm, _ = phase_margin(g, delay, fraction)
    return bool(20 * np.log10(gm) >= req.gain_margin_db and pm is not None
                and np.degrees(pm) >= req.phase_margin_deg
                and _stable(g, delay + fraction + req.delay_margin_steps))


def _all_meet(mus: np.ndarray, dt: float, integrator: str, delay: int,
              req: Requirement, fraction: float = 0.0) -> bool:
    # Every margin of eq. 35 falls as g grows, and g grows with μ: the fastest mode decides.
    return _meets_fast(loop_gain(dt * float(np.max(mus)), integrator), delay, req, fraction)


def _bisect_largest(ok, lo: float, hi: float, rtol: float = 1e-9) -> float | None:
    """The largest x in [lo, hi] with ok(x), ok falling from true to false once; None if not
    ok(lo)."""
    if ok(hi):
        return hi
    if not ok(lo):
        return None
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def _fix(change: str, value: float | None, M: np.ndarray, D: np.ndarray, dt: float,
         integrator: str, delay: int, req: Requirement,
         gains: dict[str, float] | None = None, fraction: float = 0.0) -> RequirementFix:
    # Every margin of eq. 35 falls as g grows: the fastest mode has the least of each, and
    # every mode meets the requirement exactly when it does.
    fastest = damping_modes(M, D)[0]
    m = margins(loop_gain(dt * fastest.mu, integrator), delay, dt, req, fraction)
    return RequirementFix(change=change, value=value, gains=gains or {}, meets=m.meets,
                          worst_mode=fastest.name, gain_margin_db=m.gain_margin_db,
                          phase_margin_deg=m.phase_margin_deg,
                          delay_margin_s=m.delay_margin_s, steps_per_s=1.0 / dt)


def requirement_fixes(M_breve: np.ndarray, D_breve: np.ndarray, dt: float, integrator: str,
                      delay: int, req: Requirement, fraction: float = 0.0
                      ) -> list[RequirementFix]:
    """The loop as it is, and three changes against the requirement at its plant and delay
    (eq. 35): the implicit damping at this step; the largest step at which every mode meets
    it; the damping gains cut, block by block, to the largest at which every mode that block
    sets (its largest share) meets it. ``fraction``: the command's arrival within the step
    (eq. 41), the loop's delay being ``delay`` + ``fraction`` steps."""
    def mus(D: np.ndarray) -> np.ndarray:
        return np.array([m.mu for m in damping_modes(M_breve, D)])

    base = mus(D_breve)
    out = [_fix("as flown", None, M_breve, D_breve, dt, integrator, delay, req,
                fraction=fraction)]
    if integrator == "explicit":
        out.append(_fix("controller.integrator: imex", None, M_breve, D_breve, dt, "imex",
                        delay, req, fraction=fraction))
    dt_ok = _bisect_largest(lambda h: _all_meet(base, h, integrator, delay, req, fraction),
                            1e-6, dt)
    out.append(_fix(f"mission.dt ≤ {dt_ok:.4g} s" if dt_ok else "mission.dt: none suffices",
                    dt_ok, M_breve, D_breve, dt_ok or dt, integrator, delay, req,
                    fraction=fraction))
    D, cuts = D_breve.copy(), {}
    for b, sl in enumerate(block_slices(len(D_breve))):
        block = GAIN_BLOCKS[b]
        def block_meets(d: float, b: int = b, D: np.ndarray = D) -> bool:
            # The margins fall as g grows: the block's fastest mode decides for the block.
            mu = fastest_in_block(M_breve, with_gain(D, b, d), b)
            return mu is None or _meets_fast(loop_gain(dt * mu, integrator), delay, req,
                                             fraction)

        now = float(D[sl.start, sl.start])
        if block_meets(now):
            continue
        # The spec's damping gains are positive: the search stops a millionth above zero.
        d_ok = _bisect_largest(block_meets, 1e-6 * now, now)
        if d_ok is None:
            cuts = {}
            break
        D, cuts[block] = with_gain(D, b, d_ok), d_ok
    task = ", ".join(f"{k}.D ≤ {v:.4g}" for k, v in cuts.items() if k != "null_space")
    words = "; ".join([*([f"controller.gains: {task}"] if task else []),
                       *([f"{GAIN_FIELDS['null_space']} ≤ {cuts['null_space']:.4g}"]
                         if "null_space" in cuts else [])])
    out.append(_fix(words if cuts else
                    "controller.gains: as they are" if out[0].meets else
                    "controller.gains: no cut of the damping gains suffices",
                    None, M_breve, D if cuts else D_breve, dt, integrator, delay, req,
                    gains=cuts, fraction=fraction))
    return out
