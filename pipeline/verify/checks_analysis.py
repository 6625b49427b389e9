"""Checks of the analysis equations (eqs. 25–28) against plain re-implementations."""

from __future__ import annotations

import math

import numpy as np

from pipeline.verify.checks_base import Outcome, check, rng


@check("25", "lag-1 autocorrelation vs an explicit loop over the definition; −1 for an "
       "alternating series", "pipeline.analysis.signals.lag1_autocorrelation")
def _lag1() -> Outcome:
    from pipeline.analysis.signals import lag1_autocorrelation

    g = rng(25)
    X = np.c_[g.standard_normal((500, 2)).cumsum(axis=0), (-1.0) ** np.arange(500)]
    diffs = []
    for i in range(X.shape[1]):
        x = list(X[:, i])
        mean = sum(x) / len(x)
        num = sum((x[k] - mean) * (x[k + 1] - mean) for k in range(len(x) - 1))
        den = sum((xk - mean) ** 2 for xk in x)
        diffs.append(abs(lag1_autocorrelation(X)[i] - num / den))
    return Outcome("two random walks and an alternating series, 500 samples each", max(diffs),
                   1e-12)


@check("26", "y_i = u_iᵀ Γ v from numpy's SVD vs project_chunk (up to the sign convention), "
       "σ_min", "pipeline.analysis.directions.project_chunk")
def _projection() -> Outcome:
    from pipeline.analysis.directions import project_chunk

    g = rng(26)
    G, v = g.standard_normal((8, 12, 12)), g.standard_normal((8, 12))
    part = project_chunk(G, v)
    diffs = []
    for k in range(8):
        U, s, _ = np.linalg.svd(G[k])
        y = U.T @ (G[k] @ v[k])
        diffs += [float(np.max(np.abs(np.abs(part.y[k]) - np.abs(y)))), abs(part.s_min[k] - s[-1])]
    return Outcome("8 random 12×12 Γ_k and v_k", max(diffs), 1e-10)


@check("27", "|cos| vs |a·b|/(‖a‖‖b‖) with math.fsum and math.hypot",
       "pipeline.analysis.signals.abs_cos")
def _abs_cos() -> Outcome:
    from pipeline.analysis.signals import abs_cos

    g, diffs = rng(27), []
    for _ in range(20):
        a, b = g.standard_normal(12), g.standard_normal(12)
        ref = abs(math.fsum(a * b)) / (math.hypot(*a) * math.hypot(*b))
        diffs.append(abs(abs_cos(a, b) - ref))
    return Outcome("20 random pairs of 12-vectors", max(diffs), 1e-14)


@check("28", "‖Δv_k‖ vs a loop of math.hypot over v_{k+1} − v_k",
       "pipeline.analysis.signals.velocity_jumps")
def _velocity_jumps() -> Outcome:
    from pipeline.analysis.signals import velocity_jumps

    v = rng(28).standard_normal((200, 12))
    ref = [math.hypot(*(v[k + 1] - v[k])) for k in range(len(v) - 1)]
    return Outcome("200 random 12-vectors", float(np.max(np.abs(velocity_jumps(v) - ref))),
                   1e-13)


# This module's checks, in the order the cross-check shows them: an explicit list, read by
# :func:`pipeline.verify.suite.all_checks` (no registration by import).
CHECKS = (
    _lag1,
    _projection,
    _abs_cos,
    _velocity_jumps,
)
