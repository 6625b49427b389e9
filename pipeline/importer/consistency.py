"""Do a log's q and v describe the same motion? The import's consistency check (eq. 33).

Between rows k and k+1 the configuration moves by the constant body twist

    d_k = log(q_k⁻¹ q_{k+1}) / dt = pin.difference(q_k, q_{k+1}) / dt,

on the manifold (Pinocchio's free-flyer: the bus's SE(3) twist in its own frame, the joints'
differences). Any integrator that is consistent to first order puts d_k on or near the chord
between the logged velocities: forward Euler at v_k, the semi-implicit step the simulator
runs at v_{k+1}, a sampled continuous plant near the mean of the velocity over the step.
The residual is the distance from d_k to that chord,

    r_k = min_{λ∈[0,1]} ‖d_k − (v_k + λ (v_{k+1} − v_k))‖,

and its bound comes from the data's own step, not from a tuned number:

- curvature: the mean of a velocity over a step differs from the chord by at most
  dt²/12 · max‖v̈‖ (the trapezoid rule's error); v̈ is estimated by the second differences
  Δ²v/dt² at the two rows of the step, so the term is max‖Δ²v‖/12;
- the group: on SE(3) the constant twist of a step whose twist varies linearly differs from
  its mean by (dt/12)·[ξ_k, ξ_{k+1}] (the first Baker–Campbell–Hausdorff term), the bracket
  of the bus twists ξ = (v_b, ω_b): (ω_k × v_{k+1} − ω_{k+1} × v_k, ω_k × ω_{k+1});
- rounding: d_k is the SE(3) log of two stored configurations: ROUNDING_ULPS ulps of the
  larger of their norms and 1, over dt (the log's own error, measured, see below).

The step is consistent when r_k is within the sum of the three; the log is when its median
step is (a share of steps, such as dropped telemetry messages, may be outliers; a wrong
convention moves nearly every step). A wrong quaternion order turns the bus rotation into
another one, a world-frame velocity read as a bus-frame one is off by the attitude: both
move d_k away from v by the size of the motion itself.

A velocity in the wrong unit stays on its chord's line, and a ripple's long chords can hold
it; so each block of v (the bus's linear velocity, its angular velocity, the joint rates) is
also fitted as d_k ≈ α v_k + β v_{k+1} by least squares over every step. Any integrator's
weights sum to one; a block logged s times too large sums to 1/s. The block is consistent
when |α + β − 1| times the RMS of d is within the RMS the fit leaves plus the rounding term:
a deviation the fit's own residual could not explain is a scale error, named with its factor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.importer.conventions import Conventions, Converted, to_project
from pipeline.importer.timebase import GAP_STEPS
from pipeline.shapes import V

# pin.difference(q, pin.integrate(q, ξ)) − ξ, measured over 4 800 random configurations
# (positions 0.1 to 100 m) and twists of 1e-4 to 0.1 per step (2026-12-03, Pinocchio 4.1): at
# most 413 ulps of max(‖q‖∞, 1), in a band of rotations of 0.003 to 0.03 rad per step where
# the SE(3) log changes formula (elsewhere below 40, median 0.2 to 3). Taken as 1024.
ROUNDING_ULPS = 1024


BLOCKS = (("the bus's linear velocity", V.v_b), ("the bus's angular velocity", V.omega_b),
          ("the joint rates", V.joints))


@dataclass(frozen=True)
class BlockScale:
    """One block of v fitted as d ≈ α v_k + β v_{k+1} (eq. 33)."""

    block: str
    weight_sum: float  # α + β: 1 for any integrator, 1/s for a block logged s times too large
    deviation: float  # |α + β − 1| · RMS(d) over the block
    allowance: float  # the fit's residual RMS plus the rounding term
    rms: float  # RMS(d) over the block

    @property
    def uncertainty(self) -> float:
        """How far α + β may be from its value and the fit still explain the data."""
        return self.allowance / self.rms if self.rms > 0 else float("inf")

    @property
    def consistent(self) -> bool:
        return bool(self.deviation <= self.allowance)


@dataclass(frozen=True)
class Residuals:
    """The consistency of q and v (eq. 33) over every step of a log."""

    residual: np.ndarray  # r_k, per step k = 0 … n−2 (mixed units, like ‖Δv‖)
    bound: np.ndarray  # its bound from the data's own step
    speed: np.ndarray  # ‖v_k‖, for relative figures
    blocks: tuple[BlockScale, ...] = ()

    @property
    def median_ratio(self) -> float:
        """The median of r_k / bound_k: at most 1 for consistent q and v."""
        return float(np.median(self.residual / self.bound))

    @property
    def share_within(self) -> float:
        return float(np.mean(self.residual <= self.bound))

    @property
    def median_relative(self) -> float:
        """The median residual relative to the median speed (inf for a log at rest)."""
        speed = float(np.median(self.speed))
        return float(np.median(self.residual)) / speed if speed > 0 else float("inf")

    @property
    def consistent(self) -> bool:
        return bool(self.median_ratio <= 1.0) and all(b.consistent for b in self.blocks)

    def scale_problem(self) -> str | None:
        """The first block whose weights do not sum to one, with the factor it is off by; when
        every block is off by one factor, the time (its unit, or the step) is the likely
        error, not a block's unit."""
        off = [b for b in self.blocks if not b.consistent]
        if not off:
            return None
        b = off[0]
        factor = 1.0 / b.weight_sum if b.weight_sum else float("inf")
        same = all(abs(c.weight_sum - d.weight_sum) <= c.uncertainty + d.uncertainty
                   for c in self.blocks for d in self.blocks)
        off_by = (f"{_off_one(factor)} times what q's motion says (the weights in the step "
                  f"sum to {_off_one(b.weight_sum)}, not 1, by {b.deviation / b.rms:.2g} where "
                  f"the fit explains {b.uncertainty:.2g})")
        if len(off) == len(self.blocks) and same:
            return (f"every block of v is {off_by}: the time's unit or the step? "
                    f"(--time-unit, --dt)")
        return f"{b.block}: {off_by}: a unit or scale error? (--angle-unit, --length-unit)"


def _off_one(x: float) -> str:
    """``x`` printed with the digits it takes to differ from 1 (4 at least): a weight sum of
    0.99998 is not "1"."""
    digits = 4
    while digits < 17 and float(f"{x:.{digits}g}") == 1.0:
        digits += 1
    return f"{x:.{digits}g}"


def step_twists(model: pin.Model, q: np.ndarray, dt: float | np.ndarray) -> np.ndarray:
    """d_k = pin.difference(q_k, q_{k+1}) / dt_k for k = 0 … n−2 (eq. 33)."""
    d = np.array([pin.difference(model, q[k], q[k + 1]) for k in range(len(q) - 1)])
    return d / np.reshape(dt, (-1, 1)) if np.ndim(dt) else d / dt


def chord_distance(d: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each d_k from the segment [a_k, b_k] (rows)."""
    seg = b - a
    den = np.einsum("ij,ij->i", seg, seg)
    lam = np.divide(np.einsum("ij,ij->i", d - a, seg), den, out=np.zeros(len(d)),
                    where=den > 0)
    return np.linalg.norm(d - (a + np.clip(lam, 0.0, 1.0)[:, None] * seg), axis=1)


def bus_bracket(xi_a: np.ndarray, xi_b: np.ndarray) -> np.ndarray:
    """[ξ_a, ξ_b] of bus twists ξ = (v, ω) in se(3), rows."""
    v_a, w_a = xi_a[:, V.v_b], xi_a[:, V.omega_b]
    v_b, w_b = xi_b[:, V.v_b], xi_b[:, V.omega_b]
    return np.hstack([np.cross(w_a, v_b) - np.cross(w_b, v_a), np.cross(w_a, w_b)])


def residuals(model: pin.Model, q: np.ndarray, v: np.ndarray, dt: float | np.ndarray,
              dt_rel: float = 0.0) -> Residuals:
    """r_k and its bound for every step of (q, v) in the project's conventions (eq. 33);
    ``dt``: the step, or each step's length (N − 1) for stamps that are not even. A gap (a
    step over 1.5 times the median step: rows missing) is not a step of the integrator and is
    left out. ``dt_rel``: how uncertain the step itself is, relative (a nominal step drawn
    from jittered stamps): it scales every d_k alike, so the bound and each block's allowance
    grow by that share of d."""
    n = len(q)
    if n < 3:
        raise ValueError("the consistency check needs at least 3 rows")
    d = step_twists(model, q, dt)
    r = chord_distance(d, v[:-1], v[1:])
    dd = np.zeros(n)
    dd[1:-1] = np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=1)
    dd[0], dd[-1] = dd[1], dd[-2]  # the end rows: their neighbour's estimate
    curvature = np.maximum(dd[:-1], dd[1:]) / 12.0
    group = dt / 12.0 * np.linalg.norm(bus_bracket(v[:-1, :6], v[1:, :6]), axis=1)
    size = np.maximum(np.abs(q[:-1]).max(axis=1), np.abs(q[1:]).max(axis=1))
    rounding = ROUNDING_ULPS * np.finfo(float).eps * np.maximum(size, 1.0) / dt
    bound = curvature + group + rounding + dt_rel * np.linalg.norm(d, axis=1)
    step = np.broadcast_to(np.asarray(dt, dtype=float), r.shape)
    k = step <= GAP_STEPS * np.median(step)
    rounding = np.broadcast_to(rounding, r.shape)
    return Residuals(r[k], bound[k], np.linalg.norm(v[:-1], axis=1)[k],
                     tuple(block_scale(name, d[k, b], v[:-1][k, b], v[1:][k, b],
                                       float(np.sqrt(np.mean(rounding[k] ** 2))), dt_rel)
                           for name, b in BLOCKS))


def block_scale(name: str, d: np.ndarray, a: np.ndarray, b: np.ndarray, rounding: float,
                dt_rel: float = 0.0) -> BlockScale:
    """d ≈ α a + β b by least squares over every step and component of one block; the step's
    own relative uncertainty ``dt_rel`` moves α + β by as much, allowed."""
    A = np.c_[a.reshape(-1), b.reshape(-1)]
    y = d.reshape(-1)
    w = np.linalg.lstsq(A, y, rcond=None)[0]
    rms = float(np.sqrt(np.mean(y**2)))
    resid = float(np.sqrt(np.mean((y - A @ w) ** 2)))
    return BlockScale(name, float(w.sum()), abs(float(w.sum()) - 1.0) * rms,
                      resid + rounding + dt_rel * rms, rms)


# -- which conventions the data support ------------------------------------------------------

# A one-sided sign test: an alternative convention beats the declared one when its residual is
# the smaller on more steps than chance allows at this many standard errors (p < 3e-7): on
# conventions the data cannot tell apart (a bus near the world's axes, world ≈ bus frame) the
# smaller residual is a coin toss, and ties (identical conversions) count for the declared one.
SIGN_TEST_Z = 5.0


@dataclass(frozen=True)
class ConventionFit:
    conventions: Conventions
    residuals: Residuals


@dataclass(frozen=True)
class ConsistencyCheck:
    """The declared conventions' fit and every alternative's (eq. 33)."""

    declared: ConventionFit
    alternatives: list[ConventionFit]

    def better(self) -> list[ConventionFit]:
        """Alternatives that pass the bound and beat the declared conventions step by step
        beyond chance (:data:`SIGN_TEST_Z`), the best first."""
        r0 = self.declared.residuals.residual
        n = len(r0)
        out = []
        for alt in self.alternatives:
            if not alt.residuals.consistent:
                continue
            wins = int(np.sum(alt.residuals.residual < r0))
            if wins > n / 2 + SIGN_TEST_Z * np.sqrt(n) / 2:
                out.append(alt)
        return sorted(out, key=lambda a: a.residuals.median_ratio)

    def problem(self) -> str | None:
        """Why q and v cannot be taken in the declared conventions (one line), or None."""
        dec = self.declared
        better = self.better()
        scale = dec.residuals.scale_problem()
        head = "q and v disagree under the declared conventions"
        if dec.residuals.median_ratio <= 1.0 and not better:
            return None if scale is None else f"{head}: {scale}"
        fit = (f"{head} ({dec.conventions.describe()}): the median step's residual is "
               f"{dec.residuals.median_ratio:.3g}× its bound "
               f"({dec.residuals.median_relative:.3g} of the median speed, "
               f"{100 * dec.residuals.share_within:.0f} % of steps within it)")
        if better:
            best = better[0]
            what, options = dec.conventions.differences(best.conventions)
            return (f"{fit}; with {options} they agree ({best.residuals.median_ratio:.3g}× the "
                    f"bound): the likely convention error is {what}")
        passing = sorted((a for a in self.alternatives if a.residuals.consistent),
                         key=lambda a: a.residuals.median_ratio)
        if passing:
            what, options = dec.conventions.differences(passing[0].conventions)
            return f"{fit}; the likely convention error is {what} ({options})"
        if scale is not None:
            return f"{fit}; {scale}"
        return (f"{fit}, and under every other quaternion order and velocity frame: not q and "
                f"v of one motion at this step (the robot file, the columns or the units?)")


def check_conventions(model: pin.Model, q_raw: np.ndarray, v_raw: np.ndarray,
                      declared: Conventions, dt: float | np.ndarray, dt_rel: float = 0.0
                      ) -> tuple[ConsistencyCheck, Converted]:
    """The consistency of a foreign log's q and v in its declared conventions and in every
    alternative (eq. 33), and the log converted in the declared ones."""
    bus_com = np.asarray(model.inertias[1].lever, dtype=float)

    def fit(conv: Conventions) -> tuple[ConventionFit, Converted]:
        c = to_project(q_raw, v_raw, conv, bus_com)
        return ConventionFit(conv, residuals(model, c.q, c.v, dt, dt_rel)), c

    first, converted = fit(declared)
    others = [fit(c)[0] for c in declared.alternatives(float(np.linalg.norm(bus_com)))]
    return ConsistencyCheck(first, others), converted
