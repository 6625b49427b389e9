"""The damping modes judged one by one (eqs. 35, 36): each mode's loop as flown (its root,
regime, period and margins against the requirement), what its coordinate does in the data, and
whether the two agree.

A mode the theory calls unstable (its root on or outside the unit circle) must ring in its own
modal coordinate, η_i = w_iᵀ M̆ ν̆ (w_i M̆-normalised, ν̆ = Γ(q) v rebuilt from the log); a mode
it calls stable must not ring there over the analysis window, which starts after the start-up
transients. The run agrees only if every mode does. A ring is held by a limit when the mode's
gain block sits at one of its bounds (eq. 16) on most steps of the window: its acceleration
bound (each step moves the block by dt·a_max) or its rate bound. An acceleration bound acts as
a relay: its describing function puts the cycle at the loop's phase crossover, period
2π/ω_180 = 2(2d + 1) steps (eq. 35; 2 undelayed, 6 with one step of delay, whatever the linear
root's period), of size (P/2)·dt·a_max peak to peak; a rate bound holds 2·w_max.

The relay's estimate is a first harmonic's: the cycle is held by the limit, as the record says,
only when the measured period is within 5 % of the estimate and the measured size within
``HELD_SIZE`` = 10 % of it (``HeldBy.explains``); at the bound on most steps with another cycle
is reported as that, with both ratios.

A mode called stable that rings at the period of a mode called unstable (within 5 %), with a
smaller modal amplitude than that one's (η²/2 is a mode's kinetic energy, so this compares
energies), is driven by it: a stable mode forced by another's cycle answers at its period, and
the cycle reaches it through the coupling terms the linear modes leave out (M̆(q) changes along
the window while w is the representative step's; the limits of eq. 16 bound the norm of a
3-block, which couples that block's axes). It is listed as driven, with its driver, and is no
disagreement; a stable mode that rings alone, or louder than every unstable mode of its period,
is one. Without delay every unstable mode rings at period 2, so there the period test admits
any period-2 ring and the energy test carries the rule (the seed's driven modes measure 10⁻³ to
10⁻⁶ of the bus yaw's modal amplitude).

The mode loops drop the stiffness (eq. 35); the map of eq. 34 keeps it. Where the two disagree
on whether the loop is stable (a step within a fraction of a percent of the bound, where the
stiffness tips it), the modes cannot say what must ring, and the run does not agree whatever
the data do (``Prediction.theory_consistent``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.analysis.ringing import MIN_STEPS, MOST, NON_FINITE, SHORT, Ring, ring
from pipeline.shapes import BREVE
from pipeline.sim import margins as mg
from pipeline.sim.stability import (
    GAIN_BLOCKS,
    REDUCED_SYMBOLS,
    axis_symbol,
    block_slices,
    damping_modes,
)

# The limit names of each gain block's 3-block of ν̆ (eq. 16), and its units.
BLOCK_LIMITS = BREVE._fields  # omega_b, nu_e_lin, nu_e_ang, null_space
BLOCK_UNITS = ("rad/s", "m/s", "rad/s", "rad/s")
AT_BOUND_REL = 0.01  # a step or a rate within 1 % of its bound is at the bound (as eq. 16's C16)
SAME_PERIOD = 0.05  # relative: two rings of one period (the periodogram's peaks)
HELD_SIZE = 0.10  # relative: a relay cycle's size as its describing function estimates it


@dataclass(frozen=True)
class ModeLoop:
    """One damping mode's loop as flown (eq. 35)."""

    name: str
    symbol: str  # its reduced coordinate's symbol (ω_b,z)
    axis: int  # the reduced coordinate it is named by
    gain_block: str  # the block whose damping gain sets it (its largest share)
    share: float
    mu: float
    dt_mu: float
    omega_n: float  # √(wᵀ K̆ w), rad/s: the mode's undamped frequency under the block stiffness
    damping_ratio: float | None  # μ/(2 ω_n): > 1 overdamped; None without stiffness
    loop_gain: float  # g of eq. 35
    root: mg.Complex
    modulus: float
    period_steps: float | None  # None: a real positive root, no oscillation
    regime: str
    rings: bool  # the linear loop sustains it: the root on or outside the unit circle
    margins: mg.Margins
    vector: list[float]  # w (9), M̆-normalised


def mode_loops(M_breve: np.ndarray, D_breve: np.ndarray, dt: float, integrator: str,
               delay: int, req: mg.Requirement, K_breve: np.ndarray | None = None,
               fraction: float = 0.0) -> list[ModeLoop]:
    """Every damping mode of M̆⁻¹D̆, fastest first, with its loop as flown (eqs. 21, 35; its
    command arriving ``fraction`` of a step after the ``delay`` steps, eq. 41);
    with the block stiffness K̆, each mode's undamped frequency and damping ratio (the
    stiffness projected on the mode: the bandwidth and damping a gain cut changes)."""
    out = []
    for m in damping_modes(M_breve, D_breve):
        g = mg.loop_gain(dt * m.mu, integrator)
        z = mg.dominant_root(g, delay, fraction)
        wn = (float(np.sqrt(max(m.vector @ K_breve @ m.vector, 0.0)))
              if K_breve is not None else 0.0)
        out.append(ModeLoop(
            name=m.name, symbol=axis_symbol(m.axis), axis=m.axis,
            gain_block=GAIN_BLOCKS[m.block],
            share=float(m.shares[m.block]), mu=m.mu, dt_mu=dt * m.mu, omega_n=wn,
            damping_ratio=m.mu / (2 * wn) if wn > 0 else None, loop_gain=g,
            root=mg.Complex.of(z), modulus=abs(z), period_steps=mg.period_steps(z),
            regime=mg.root_regime(z, "the mode's own loop"), rings=bool(abs(z) >= mg.UNIT),
            margins=mg.margins(g, delay, dt, req, fraction), vector=m.vector.tolist()))
    return out


@dataclass(frozen=True)
class HeldBy:
    """The limit of the mode's block at its bound on most steps, and the size it allows."""

    limit: str  # a key of controller.limits
    bound: float
    at_bound_share: float
    period_estimate: float | None  # steps: the describing function's, 2π/ω_180 = 2(2d + 1)
    size_estimate: float  # peak to peak: (P/2)·dt·a_max for an acceleration bound, 2·w_max
    period_ratio: float | None  # measured over estimated
    size_ratio: float  # measured over estimated
    explains: bool  # the measured cycle is the estimate's (period 5 %, size 10 %)
    rule: str


@dataclass(frozen=True)
class ModeJudgement:
    mode: str
    symbol: str
    predicted_rings: bool
    predicted_period_steps: float | None
    measured: Ring
    modal_peak_to_peak: float | None  # of η itself, the mode's own scale (√(2·energy))
    held_by: HeldBy | None
    driven_by: str | None  # a stable mode ringing with an unstable one of its period
    agrees: bool | None  # None: the data cannot say (undetermined)


@dataclass(frozen=True)
class Prediction:
    """The theory's modes against the data, one by one (eq. 36)."""

    rule: str
    modes: list[ModeJudgement]
    omega_b: list[Ring]  # each component of the bus rate, for what rings there
    undetermined: int
    theory_consistent: bool | None  # the mode loops and the map of eq. 34 agree on stability
    # True: every mode agrees; False: a mode disagrees, or the modes and the map do; None:
    # undetermined (no mode disagrees but the data cannot judge one), never False.
    agrees: bool | None
    undetermined_why: str | None = None  # what leaves it undetermined, in words
    # A window too short (eq. 36): the least mission steps that would determine it with the
    # analysis' window rule; None when the length is not what leaves it undetermined.
    least_mission_steps: int | None = None


RULE = ("each damping mode of the loop as flown: predicted to ring when its root (eq. 35) is on "
        "or outside the unit circle; measured to ring when most of its modal coordinate's "
        "motion over the window is at periods of at most 20 steps and most of that is one "
        "spectral line (eq. 36); a stable mode's ring that decays over the window is its "
        "transient; a stable mode ringing at an unstable one's period with less "
        "modal energy is driven by it, no disagreement; agrees only if every "
        "mode does and the modes' stability is the map's (eq. 34)")


def omega_b_rings(nu_breve: np.ndarray) -> list[Ring]:
    """What each component of ω_b = ν̆[0:3] does over the window (eq. 36)."""
    return [ring(nu_breve[:, i], REDUCED_SYMBOLS[i], "rad/s") for i in range(3)]


def held_by(nu_block: np.ndarray, delay: int, dt: float, limits, measured: Ring
            ) -> HeldBy | None:
    """The bound of a gain block's ν̆ 3-block (``limits``: its acceleration and rate bounds)
    that the data sit at on most steps, or None; for an acceleration bound, the cycle it
    holds as a relay: a describing function puts it at the loop's phase crossover, period
    2π/ω_180 = 2(2d + 1) steps (eq. 35: 2 without delay, 6 with one step), of size
    (P/2)·dt·a_max peak to peak; whether the ``measured`` ring is that cycle."""
    name, a_max, w_max = limits
    steps = np.linalg.norm(np.diff(nu_block, axis=0), axis=1)
    rates = np.linalg.norm(nu_block, axis=1)
    at_acc = float(np.mean(steps >= (1.0 - AT_BOUND_REL) * dt * a_max))
    at_rate = float(np.mean(rates >= (1.0 - AT_BOUND_REL) * w_max))
    if max(at_acc, at_rate) <= MOST:
        return None
    if at_acc >= at_rate:
        p = 2.0 * np.pi / mg.gain_margin(1.0, delay)[1]
        limit, bound, share, size = f"{name}_acc", a_max, at_acc, 0.5 * p * dt * a_max
        rule = ("the acceleration bound as a relay: the cycle at the loop's phase crossover, "
                "period 2π/ω_180, (P/2)·dt·a_max peak to peak")
    else:
        p, limit, bound, share, size = None, f"{name}_rate", w_max, at_rate, 2.0 * w_max
        rule = "the rate at its bound: 2·w_max peak to peak"
    period_ratio = (measured.period_steps / p
                    if p is not None and measured.period_steps is not None else None)
    size_ratio = (measured.peak_to_peak or 0.0) / size
    explains = bool((period_ratio is None or abs(period_ratio - 1.0) <= SAME_PERIOD)
                    and abs(size_ratio - 1.0) <= HELD_SIZE)
    return HeldBy(limit=limit, bound=bound, at_bound_share=share, period_estimate=p,
                  size_estimate=size, period_ratio=period_ratio, size_ratio=size_ratio,
                  explains=explains, rule=rule)


def judge(modes: list[ModeLoop], M_breve: np.ndarray, nu_breve: np.ndarray, dt: float,
          delay: int, limits, map_radius: float | None, null_space=None,
          least_steps: int | None = None) -> Prediction:
    """Each mode of ``modes`` against its modal coordinate in ``nu_breve`` (the window's ν̆,
    N×9) (eq. 36), on a loop of ``delay`` steps of delay. ``limits``: the controller's
    ``limits`` block (and ``null_space``, a redundant arm's ``controller.null_space``: its
    block's bounds); ``map_radius``: the spectral radius of the loop's map (eq. 34), None
    where it cannot be built (an imported log has no x̃); ``least_steps``: the least mission
    steps whose window holds ``MIN_STEPS`` under the analysis' window rule, named when the
    window is too short to judge."""
    blocks = block_slices(nu_breve.shape[1])
    rings = []
    for m in modes:
        w = np.asarray(m.vector)
        eta = nu_breve @ (M_breve @ w)
        b = next(i for i, sl in enumerate(blocks) if sl.start <= m.axis < sl.stop)
        rings.append((ring(eta, m.name, BLOCK_UNITS[b], scale=w[m.axis]),
                      ring(eta, m.name, "√(kg·m²)·rad/s")))
    judged = []
    for m, (measured, modal) in zip(modes, rings, strict=True):
        b = next(i for i, sl in enumerate(blocks) if sl.start <= m.axis < sl.stop)
        name = BLOCK_LIMITS[b]
        bounds = ((name, null_space.acc, null_space.rate) if name == "null_space" else
                  (name, getattr(limits, f"{name}_acc"), getattr(limits, f"{name}_rate")))
        driver = (None if m.rings or not measured.rings else
                  _driver(measured, modal, [(o, r) for o, r in zip(modes, rings, strict=True)
                                            if o.rings]))
        # A driven ring's block is at its bound through its driver's cycle, not its own.
        held = (held_by(nu_breve[:, blocks[b]], delay, dt, bounds, measured)
                if measured.rings and driver is None else None)
        # A stable mode's ring that fades over the window is its transient, what a stable
        # root does (eq. 36's trend); an unstable one's must ring, whatever its trend.
        transient = bool(not m.rings and measured.rings and measured.trend == "decaying")
        agrees = (None if measured.rings is None else
                  True if driver is not None or transient else measured.rings == m.rings)
        judged.append(ModeJudgement(mode=m.name, symbol=m.symbol, predicted_rings=m.rings,
                                    predicted_period_steps=m.period_steps, measured=measured,
                                    modal_peak_to_peak=modal.peak_to_peak, held_by=held,
                                    driven_by=driver, agrees=agrees))
    undetermined = sum(j.agrees is None for j in judged)
    consistent = (None if map_radius is None else
                  bool((map_radius >= mg.UNIT) == any(m.rings for m in modes)))
    disagrees = consistent is False or any(j.agrees is False for j in judged)
    why, least = ((None, None) if disagrees else
                  undetermined_words(judged, nu_breve.shape[0], dt, least_steps))
    agrees = False if disagrees else None if why is not None else True
    return Prediction(rule=RULE, modes=judged, omega_b=omega_b_rings(nu_breve),
                      undetermined=undetermined, theory_consistent=consistent,
                      agrees=agrees, undetermined_why=why, least_mission_steps=least)


def undetermined_words(judged: list[ModeJudgement], window: int, dt: float,
                       least_steps: int | None) -> tuple[str | None, int | None]:
    """(what leaves the verdict undetermined, the least mission steps that would determine
    it) for modes ``judged`` over a window of ``window`` steps: too short a window names the
    mission that would do (eq. 36's MIN_STEPS); a still coordinate (no motion above the
    numbers' resolution) or non-finite data name no duration."""
    if not judged:
        return "no damping mode to judge", None
    reasons = [j.measured.undetermined for j in judged if j.agrees is None]
    if not reasons:
        return None, None
    if SHORT in reasons:
        needed = f"the {MIN_STEPS} steps a ring's verdict needs (eq. 36)"
        if least_steps is None:
            return f"the analysis window holds {window} steps, fewer than {needed}", None
        return (f"the analysis window holds {window} steps, fewer than {needed}: a mission of "
                f"at least {least_steps} steps ({least_steps * dt:.4g} s at dt {dt:g} s) "
                f"would determine it", least_steps)
    if NON_FINITE in reasons:
        return (f"{reasons.count(NON_FINITE)} mode(s)' coordinates hold non-finite values "
                f"in the window"), None
    robot = " (a still robot)" if len(reasons) == len(judged) else ""
    return (f"{len(reasons)} of {len(judged)} modes' coordinates show no motion above the "
            f"numbers' resolution{robot}: nothing to determine there, at any duration"), None


def _driver(measured: Ring, modal: Ring, unstable: list[tuple[ModeLoop, tuple[Ring, Ring]]]
            ) -> str | None:
    """The unstable mode that drives a stable one's ring: ringing at its period (within
    ``SAME_PERIOD``) with the larger modal amplitude; the loudest such, or None."""
    louder = [(r[1].peak_to_peak, o.name) for o, r in unstable
              if r[0].rings and r[0].period_steps and measured.period_steps
              and abs(r[0].period_steps / measured.period_steps - 1.0) <= SAME_PERIOD
              and r[1].peak_to_peak > modal.peak_to_peak]
    return max(louder)[1] if louder else None


def measured_words(j: ModeJudgement) -> str:
    """What a mode's coordinate does in the data, in words (eq. 36): the ring's period, size,
    trend, driver and limit, or 'quiet' or 'undetermined'."""
    r = j.measured
    if r.rings is None:
        return "undetermined"
    if not r.rings:
        return "quiet"
    words = (f"rings over {r.period_steps:.3g} steps, {r.peak_to_peak:.3g} {r.unit} peak to "
             f"peak, {r.trend}")
    if not j.predicted_rings and r.trend == "decaying" and j.driven_by is None:
        words += " (the stable mode's transient)"
    if j.driven_by is not None:
        words += f", driven by the {j.driven_by} mode's cycle"
    h = j.held_by
    if h is not None:
        est = (f"estimate {h.size_estimate:.3g}" + (f" over {h.period_estimate:.3g} steps"
                                                    if h.period_estimate else ""))
        words += (f", held by {h.limit} ({100 * h.at_bound_share:.0f} % of steps at it; {est})"
                  if h.explains else
                  f", at {h.limit} on {100 * h.at_bound_share:.0f} % of steps but not its cycle "
                  f"({est}; measured/estimate: size {h.size_ratio:.3g}"
                  + (f", period {h.period_ratio:.3g}" if h.period_ratio else "") + ")")
    return words
