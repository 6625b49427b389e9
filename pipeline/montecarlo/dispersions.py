"""What a Monte Carlo disperses and how one sample draws it (eq. 39).

A dispersion perturbs a nominal value: ``rel`` multiplies it by (1 + ε), ``sd`` (normal) or
``half_width`` (uniform) adds ε, ``low``/``high`` draws the value itself (uniform), ``values``
picks one (choice), ``seed`` draws a fresh integer seed for a noise or jitter stream of the
sample's own (``mission.plant.timing.seed``, ``mission.plant.sensors.seed``); a normal ε may be
truncated at ``truncate`` standard deviations
(redrawn until inside). A vector field (``mission.initial_omega_b``, a body's ``com``) draws
each component. A body's rotational inertia (``body.<bus|payload>.inertia``) is dispersed in its
principal frame: each principal moment by its own (1 + ε) (``rel``: one for all, or three,
matched to the body axes nearest the principal ones), and the principal axes turned by an
angle (``axes_deg``, about an axis drawn uniformly on the sphere). The result must be a rigid
body's (:func:`pipeline.sim.inertial.physical_problem`): a draw outside is redrawn, and the
redraws are counted, so the sample's distribution is the stated one restricted to physical
bodies.

Every sample draws from its own stream, ``SeedSequence([seed, index])``, keys in sorted order:
a sample is drawn again alone, bit for bit, without the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pipeline.sim.inertial import inertia_matrix, inertia_six, physical_problem

Finite = Annotated[float, Field(allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
# A physical draw is redrawn at most this often before the dispersion is called unphysical.
MAX_REDRAWS = 1000


class Dispersion(BaseModel):
    """One dispersed field's distribution (eq. 39); see the module docstring."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    dist: Literal["uniform", "normal", "choice", "seed"]
    rel: NonNegative | list[NonNegative] | None = None
    sd: NonNegative | list[NonNegative] | None = None
    half_width: NonNegative | list[NonNegative] | None = None
    low: Finite | None = None
    high: Finite | None = None
    # At least a tenth of a standard deviation: ε is drawn by rejection, and below it the
    # draws a sample needs grow without bound (1e-300 never ends).
    truncate: Annotated[float, Field(ge=0.1, allow_inf_nan=False)] | None = None
    values: list[Finite] | None = None
    axes_deg: NonNegative | None = None  # a body's inertia only

    @model_validator(mode="after")
    def _one_form(self) -> Dispersion:
        given = [k for k in ("rel", "sd", "half_width", "low", "values", "axes_deg")
                 if getattr(self, k) is not None]
        allowed = {"uniform": ("rel", "half_width", "low", "axes_deg"),
                   "normal": ("rel", "sd", "axes_deg"), "choice": ("values",),
                   "seed": ()}[self.dist]
        wrong = [k for k in given if k not in allowed]
        if wrong:
            raise ValueError(f"{wrong[0]} does not go with dist: {self.dist} (use "
                             f"{', '.join(allowed)})")
        if (self.low is None) != (self.high is None):
            raise ValueError("low and high go together")
        if self.low is not None and not self.low < self.high:
            raise ValueError(f"low {self.low:g} must be below high {self.high:g}")
        spread = [k for k in given if k != "axes_deg"]
        if len(spread) > 1:
            raise ValueError(f"give one of {', '.join(spread)}, not both")
        if not given and self.dist != "seed":
            raise ValueError(f"dist: {self.dist} needs one of {', '.join(allowed)}")
        if self.truncate is not None and self.dist != "normal":
            raise ValueError("truncate goes with dist: normal")
        if self.values is not None and not self.values:
            raise ValueError("values: empty")
        return self


def _epsilon(d: Dispersion, scale: float, rng: np.random.Generator) -> float:
    """One ε of spread ``scale`` (a standard deviation or a half-width)."""
    if d.dist == "uniform":
        return float(rng.uniform(-scale, scale))
    while True:
        e = float(rng.standard_normal())
        if d.truncate is None or abs(e) <= d.truncate:
            return e * scale


def _component(spread: float | list[float] | None, i: int, n: int, key: str) -> float:
    if isinstance(spread, list):
        if len(spread) != n:
            raise ValueError(f"{key}: {len(spread)} spreads for {n} components")
        return float(spread[i])
    return float(spread or 0.0)


def draw_value(d: Dispersion, nominal: float | list[float], rng: np.random.Generator,
               key: str) -> float | list[float]:
    """The dispersed value of a scalar or vector field from its nominal (eq. 39)."""
    if d.dist == "seed":
        if isinstance(nominal, list) or isinstance(nominal, float):
            raise ValueError(f"{key}: dist: seed draws an integer seed, the field is not one")
        return int(rng.integers(2**31))
    if d.dist == "choice":
        if isinstance(nominal, list):
            raise ValueError(f"{key}: dist: choice picks a scalar, the field is a vector")
        return d.values[int(rng.integers(len(d.values)))]
    vector = isinstance(nominal, list)
    nom = [float(x) for x in nominal] if vector else [float(nominal)]
    out = []
    for i, x in enumerate(nom):
        if d.low is not None:
            out.append(float(rng.uniform(d.low, d.high)))
        elif d.rel is not None:
            out.append(x * (1.0 + _epsilon(d, _component(d.rel, i, len(nom), key), rng)))
        else:
            spread = d.sd if d.dist == "normal" else d.half_width
            out.append(x + _epsilon(d, _component(spread, i, len(nom), key), rng))
    return out if vector else out[0]


def _principal_frame(I: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(moments, R) with I = R diag(moments) Rᵀ, column j of R the principal axis nearest the
    body's axis j (a diagonal tensor: the body's axes themselves, whatever its equal
    moments)."""
    off = abs(I[0, 1]) + abs(I[0, 2]) + abs(I[1, 2])
    if off <= 1e-12 * np.trace(I):
        return np.diag(I).copy(), np.eye(3)
    w, V = np.linalg.eigh(I)
    order = np.argmax(np.abs(V), axis=0)  # the body axis each principal axis is nearest
    if sorted(order) != [0, 1, 2]:
        return w, V
    R = np.empty((3, 3))
    moments = np.empty(3)
    for j, axis in enumerate(order):
        R[:, axis], moments[axis] = V[:, j], w[j]
    return moments, R


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation of ``angle`` rad about the unit ``axis``."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


@dataclass(frozen=True)
class InertiaDraw:
    inertia: list[float]  # the six numbers (eq. 39)
    factors: list[float]  # each principal moment's (1 + ε), body axes x, y, z
    axes_angle_deg: float  # the principal axes' turn
    redraws: int  # draws refused as unphysical before this one


def draw_inertia(d: Dispersion, nominal: list[float], rng: np.random.Generator,
                 key: str) -> InertiaDraw:
    """A body's dispersed rotational inertia, physical (eq. 39; the module docstring)."""
    if d.dist == "choice" or d.low is not None or (d.rel is None and d.axes_deg is None):
        raise ValueError(f"{key}: a body's inertia takes rel (the principal moments' factor) "
                         "and axes_deg (the principal axes' turn)")
    moments, R = _principal_frame(inertia_matrix(nominal))
    for redraws in range(MAX_REDRAWS):
        factors = [1.0 + _epsilon(d, _component(d.rel, i, 3, key), rng) for i in range(3)]
        angle = 0.0
        if d.axes_deg:
            axis = rng.standard_normal(3)
            axis /= np.linalg.norm(axis)
            angle = _epsilon(d, math.radians(d.axes_deg), rng)
            turned = _rotation(axis, angle) @ R
        else:
            turned = R
        I = turned @ np.diag(moments * np.asarray(factors)) @ turned.T
        I = 0.5 * (I + I.T)
        if physical_problem(I) is None:
            return InertiaDraw(inertia_six(I), factors, math.degrees(angle), redraws)
    raise ValueError(f"{key}: {MAX_REDRAWS} draws in a row were not a rigid body's inertia: "
                     "the dispersion is wider than the body allows")
