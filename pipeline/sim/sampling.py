"""Startup configuration sampler and the single γ derate ramp (eqs. 19–20).

Two jobs in one small class: rank random arm configurations near q̄ by the conditioning of a
Jacobian-producing function, and ``scale_by_svd``, the one piecewise-linear ramp that maps
σ_min to a derate γ ∈ [floor, 1] and that every derate in the controller consumes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from pipeline.errors import SpecError
from pipeline.sim.jit import jit
from pipeline.sim.linalg import singular_values, svd_right_from
from pipeline.spec import ConfigSampling, Ramp


def sigma_min(A: np.ndarray) -> float | None:
    """Smallest singular value of A, or None if A (or its SVD) is not finite (eq. 19)."""
    A = np.ascontiguousarray(A, dtype=float)
    if not np.all(np.isfinite(A)):
        return None
    s = singular_values(A)
    return float(s[-1]) if np.all(np.isfinite(s)) else None


@jit
def sigma_min_and_cond(A: np.ndarray) -> tuple[float, float]:
    """(σ_min, κ = σ_max/σ_min) from one SVD pass (eq. 19); κ = inf when σ_min = 0.

    One call of the project's one-sided Jacobi SVD without singular vectors
    (:func:`pipeline.sim.linalg.singular_values`), so the simulator reads Γ's conditioning
    inside its compiled per-step kernel, with the same bits on every processor.
    """
    s = singular_values(A)
    smin = s[-1]
    return smin, (s[0] / smin if smin > 0 else np.inf)


@jit
def conditioning_from(A: np.ndarray, Vt_before: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(σ_min, κ, Vᵀ) of the square A (eq. 19), its SVD started from ``Vt_before``, the right
    vectors of the step before (:func:`pipeline.sim.linalg.svd_right_from`; empty: from the
    identity, and σ_min and κ are :func:`sigma_min_and_cond`'s to the bit)."""
    s, Vt = svd_right_from(A, Vt_before)
    smin = s[-1]
    return smin, (s[0] / smin if smin > 0 else np.inf), Vt


@jit
def scale_by_svd(sigma: float, low: float, high: float, floor: float) -> float:
    """The γ ramp (eq. 20).

    γ = floor for σ <= low; 1 for σ >= high; floor + (1 − floor)(σ − low)/(high − low) between.
    """
    if sigma <= low:
        return floor
    if sigma >= high:
        return 1.0
    return floor + (1.0 - floor) * (sigma - low) / (high - low)


@dataclass(frozen=True)
class Sample:
    """One ranked startup sample: the joint offsets drawn, the joint and full configuration."""

    sample: np.ndarray
    q_joint: np.ndarray
    q_full: np.ndarray
    sigma_min: float | None


class Sampling:
    """Config sampler (block ``config_sampling``) and owner of the default ramp knobs."""

    def __init__(self, cfg: ConfigSampling):
        self.cfg = cfg

    def generate_samples(self, q_bar: np.ndarray, num: int | None = None) -> np.ndarray:
        """``num`` joint configurations uniform within ±step_size of q̄, seeded (shape num×n)."""
        num = self.cfg.default.num if num is None else num
        rng = np.random.default_rng(self.cfg.seed)
        h = self.cfg.default.step_size
        q_bar = np.asarray(q_bar, dtype=float)
        return q_bar + rng.uniform(-h, h, size=(num, q_bar.size))

    def sorted_samples(
        self,
        q_bar: np.ndarray,
        func: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
        num: int | None = None,
    ) -> list[Sample]:
        """Samples scored by σ_min(func(q)), ascending; non-finite scores first.

        ``func`` maps a joint configuration to ``(q_full, A)``: the full configuration it
        stands for and the matrix whose conditioning scores it.
        """
        out = []
        for q_joint in self.generate_samples(q_bar, num):
            q_full, A = func(q_joint)
            out.append(Sample(q_joint - np.asarray(q_bar), q_joint, q_full, sigma_min(A)))
        return sorted(out, key=lambda s: -np.inf if s.sigma_min is None else s.sigma_min)

    def best_sample(self, q_bar: np.ndarray, func, num: int | None = None) -> Sample | None:
        """The best-conditioned sample, or None if no sample scored finite."""
        ranked = self.sorted_samples(q_bar, func, num)
        return ranked[-1] if ranked and ranked[-1].sigma_min is not None else None

    def scale_by_svd(self, sigma: float, opts: Ramp | Mapping | None = None) -> float:
        """γ ramp (eq. 20) with ``opts`` or this block's own low/high/floor.

        ``opts`` is a typed block (``Ramp``) or, as the seed note writes it, a mapping
        ``{low, high, floor}``, validated like the spec's block (SpecError naming the key).
        """
        if isinstance(opts, Mapping):
            opts = ramp_from_mapping(opts)
        o = opts or self.cfg
        return scale_by_svd(sigma, o.low, o.high, o.floor)


def ramp_from_mapping(opts: Mapping) -> Ramp:
    """A ``{low, high, floor}`` mapping as the validated ramp block (eq. 20)."""
    from pydantic import ValidationError

    missing = [k for k in ("low", "high", "floor") if k not in opts]
    if missing:
        raise SpecError(f"scale_by_svd opts: key {missing[0]!r} missing (needs low, high, "
                        f"floor)")
    try:
        return Ramp.model_validate(dict(opts))
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(x) for x in err["loc"]) or "opts"
        msg = "unknown key" if err["type"] == "extra_forbidden" else err["msg"]
        raise SpecError(f"scale_by_svd opts: {where}: {msg}") from None
