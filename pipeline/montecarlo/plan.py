"""A Monte Carlo's file and its samples (eq. 39): what is dispersed, how many samples, the
target they are judged against; each sample's draws and its validated mission spec.

```yaml
description: …
mission: omega_ripple_sampled_delay_dt0035     # the mission spec dispersed
set: {mission.duration: 10.0}                  # fixed overrides of every sample
seed: 35
target: {p: 0.9973, confidence: 0.90}          # samples: the N of eq. 38b unless given
ripple_max: 1.0e-3                             # rad/s: ω_b's period-2 amplitude allowed
dispersions:
  body.bus.inertia: {dist: uniform, rel: [0, 0, 0.2]}
  controller.gains.bus.D: {dist: uniform, rel: 0.1}
  mission.plant.delay_steps: {dist: choice, values: [0, 1]}
```

A key is a dotted field of the mission spec holding a number or a list of numbers, or a body's
inertial parameter, ``body.<bus|payload>.<mass|com|inertia>`` (the sample's
``robot.inertial``). Everything is validated before anything runs: every sample's spec is
built (a SpecError names the field), so a bad key or a draw the spec refuses fails at once.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from pipeline.analysis.confidence import samples_needed
from pipeline.budget import Budget, check_mission, check_samples
from pipeline.errors import SpecError
from pipeline.montecarlo.dispersions import Dispersion, draw_inertia, draw_value
from pipeline.paths import SHIPPED_SPECS
from pipeline.spec import INERTIAL_BODIES, Seed, Spec, load_spec, with_overrides
from pipeline.yamlfile import read_yaml

Probability = Annotated[float, Field(gt=0, lt=1, allow_inf_nan=False)]
BODY_KEY = re.compile(r"^body\.([a-z_]+)\.(mass|com|inertia)$")
MONTECARLO_DIR = "montecarlo"  # beside the shipped specs


class Target(BaseModel):
    """The requirement's pass probability p to show at confidence C (eq. 38)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    p: Probability = 0.9973
    confidence: Probability = 0.90


class MonteCarloFile(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    description: str = ""
    mission: str
    set: dict[str, Any] = Field(default_factory=dict)
    seed: Seed
    target: Target = Target()
    samples: Annotated[int, Field(gt=0)] | None = None
    ripple_max: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    dispersions: dict[str, Dispersion]
    # The step (s) in which the command's arrival within the step and its jitter
    # (mission.plant.timing, as set or drawn) are counted: a transport latency, held in seconds
    # when a fix or a search changes the step (eq. 41), the whole-step delay held in steps (a
    # computation delay of one period). None: all of it in steps of the step flown.
    latency_step: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None


@dataclass(frozen=True)
class Sample:
    """One dispersed sample: its index, name, seed, draws (flat: column → value) and spec."""

    index: int
    name: str
    seed: tuple[int, int]
    draws: dict[str, float]
    spec: Spec


@dataclass(frozen=True)
class MonteCarlo:
    name: str
    path: Path
    config: MonteCarloFile
    base: Spec
    samples: list[Sample]
    seconds: float = 0.0  # the samples' flights by the budget's estimate (pipeline.budget)

    @property
    def target(self) -> Target:
        return self.config.target


def nominal_spec(base: Spec, config: MonteCarloFile) -> Spec:
    """The spec the samples are drawn about: the mission with the file's fixed overrides."""
    return with_overrides(base, config.set) if config.set else base


def resolve_montecarlo(ref: str | Path) -> Path:
    """A Monte Carlo file: a path, or a name under specs/montecarlo/."""
    path = Path(ref)
    if path.is_file():
        return path
    shipped = SHIPPED_SPECS / MONTECARLO_DIR / f"{ref}.yaml"
    if shipped.is_file():
        return shipped
    raise SpecError(f"montecarlo {ref}: no such file, nor {shipped}")


def read_montecarlo(path: Path) -> MonteCarloFile:
    raw = read_yaml(path)
    try:
        return MonteCarloFile.model_validate(raw)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(x) for x in err["loc"]) or "file"
        msg = "unknown key" if err["type"] == "extra_forbidden" else err["msg"]
        raise SpecError(f"{path}: field {where}: {msg}") from None


def _dig(data: dict, key: str) -> Any:
    node: Any = data
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise KeyError(part)
        node = node[part]
    return node


def nominal_value(base: Spec, key: str, where: str) -> float | list[float]:
    """The number (or list of numbers) at the dotted field ``key`` of ``base``; a SpecError
    beginning with ``where`` (the file and field, or the option, that names it) otherwise."""
    try:
        value = _dig(base.model_dump(mode="json"), key)
    except KeyError as exc:
        raise SpecError(f"{where}: the mission spec has no field {exc.args[0]!r}") from None
    numeric = (isinstance(value, int | float) and not isinstance(value, bool)) or (
        isinstance(value, list) and value and all(isinstance(x, int | float) for x in value))
    if not numeric:
        raise SpecError(f"{where}: not a number or a list of numbers ({value!r})")
    return value


def body_nominals(base: Spec, bodies: set[str], path: Path) -> dict[str, dict[str, Any]]:
    """The bodies' inertial parameters as the mission's robot has them (eq. 39)."""
    from pipeline.sim.inertial import body_joint, inertia_six
    from pipeline.sim.robot_file import camera_frame_id, load_spec_robot

    if not bodies:
        return {}
    unknown = sorted(bodies - set(INERTIAL_BODIES))
    if unknown:
        raise SpecError(f"{path}: field dispersions.body.{unknown[0]}: unknown body (use "
                        f"{' or '.join(INERTIAL_BODIES)})")
    if "bus" in bodies and base.robot.bus_inertia_scale != 1.0:
        raise SpecError(f"{path}: field dispersions.body.bus: the mission scales the bus "
                        f"inertia (robot.bus_inertia_scale {base.robot.bus_inertia_scale:g}); "
                        "disperse one or the other")
    model = load_spec_robot(base)
    camera = camera_frame_id(model, base.robot.camera_frame, base.robot_path)
    out = {}
    for body in sorted(bodies):
        inertia = model.inertias[body_joint(model, body, camera)]
        out[body] = {"mass": float(inertia.mass), "com": [float(x) for x in inertia.lever],
                     "inertia": inertia_six(inertia.inertia)}
    return out


def _flat(key: str, value: float | list[float]) -> dict[str, float]:
    if isinstance(value, list):
        return {f"{key}[{i}]": float(x) for i, x in enumerate(value)}
    return {key: float(value)}


def _as_field(value: float | list[float], nominal: Any) -> Any:
    """An integer field keeps integers (a choice of delay steps)."""
    if isinstance(nominal, int) and not isinstance(nominal, bool) and float(value).is_integer():
        return int(value)
    return value


def draw_sample(mc_name: str, config: MonteCarloFile, fixed: Spec, index: int,
                nominals: dict[str, dict[str, Any]], path: Path) -> Sample:
    """Sample ``index``: its draws from its own stream and its validated spec (eq. 39), on
    ``fixed``, the mission spec with the file's fixed overrides (``set``)."""
    seed = (config.seed, index)
    rng = np.random.default_rng(np.random.SeedSequence(list(seed)))
    draws: dict[str, float] = {}
    overrides: dict[str, Any] = {}
    base = fixed
    bodies = {b: dict(p) for b, p in nominals.items()}
    for key in sorted(config.dispersions):
        d = config.dispersions[key]
        m = BODY_KEY.match(key)
        try:
            if m and m.group(2) == "inertia":
                got = draw_inertia(d, bodies[m.group(1)]["inertia"], rng, key)
                bodies[m.group(1)]["inertia"] = got.inertia
                draws |= {f"{key}.{a}": x for a, x in zip(("I_xx", "I_yy", "I_zz"),
                                                          got.inertia[:3], strict=True)}
                if d.axes_deg:
                    draws[f"{key}.axes_deg"] = got.axes_angle_deg
                draws[f"{key}.redraws"] = float(got.redraws)
            elif m:
                value = draw_value(d, bodies[m.group(1)][m.group(2)], rng, key)
                bodies[m.group(1)][m.group(2)] = value
                draws |= _flat(key, value)
            else:
                nominal = nominal_value(base, key, f"{path}: field dispersions.{key}")
                value = draw_value(d, nominal, rng, key)
                overrides[key] = _as_field(value, nominal)
                draws |= _flat(key, value)
        except ValueError as exc:
            raise SpecError(f"{path}: field dispersions.{key}: {exc}") from None
    for body, params in bodies.items():
        overrides[f"robot.inertial.{body}"] = params
    name = f"{mc_name}__{index:05d}"
    try:
        spec = with_overrides(base, _nested_inertial(overrides), name)
        spec = _latency_held(spec, config.latency_step)
    except SpecError as exc:
        raise SpecError(f"{path}: sample {index}: {exc}") from None
    return Sample(index, name, seed, draws, spec)


def _latency_held(spec: Spec, latency_step: float | None) -> Spec:
    """The sample's arrival and jitter (eq. 41), counted in steps of ``latency_step``, in steps
    of the step it flies: the same seconds (a transport latency). Unchanged at that step."""
    timing, dt = spec.mission.plant.timing, spec.mission.dt
    if latency_step is None or timing is None or dt == latency_step:
        return spec
    scale = latency_step / dt
    fraction, jitter = timing.delay_fraction * scale, timing.jitter * scale
    if fraction >= 1.0 or fraction + jitter > 1.0:
        ms = 1e3 * latency_step
        raise SpecError(
            f"field latency_step: the arrival {timing.delay_fraction:g} + jitter "
            f"{timing.jitter:g} steps of {latency_step:g} s ({timing.delay_fraction * ms:.4g} + "
            f"{timing.jitter * ms:.4g} ms) reach past a step of {dt:g} s, a whole step later, "
            "which the plant's hold does not model (the arrival stays within the step); fly a "
            f"step of at least {(timing.delay_fraction + timing.jitter) * latency_step:.4g} s")
    return with_overrides(spec, {"mission.plant.timing": {
        "delay_fraction": fraction, "jitter": jitter, "seed": timing.seed}}, spec.name)


def _nested_inertial(overrides: dict[str, Any]) -> dict[str, Any]:
    """``robot.inertial.<body>`` keys as one ``robot.inertial`` mapping (the spec's field)."""
    out = {k: v for k, v in overrides.items() if not k.startswith("robot.inertial.")}
    bodies = {k.rsplit(".", 1)[1]: v for k, v in overrides.items()
              if k.startswith("robot.inertial.")}
    if bodies:
        out["robot.inertial"] = bodies
    return out


def montecarlo_key(ref: str | Path, samples: int | None = None) -> str:
    """What a Monte Carlo is made from, for the claims' key: its file's content, the mission
    spec's hash and robot file, and the sample count asked."""
    from pipeline.provenance.keys import file_digest

    path = resolve_montecarlo(ref)
    config = read_montecarlo(path)
    base = load_spec(config.mission, path.resolve().parent)
    return (f"file {file_digest(path)}, spec {base.spec_hash}, robot "
            f"{file_digest(base.robot_path)}, samples {samples}")


def file_samples(config: MonteCarloFile) -> int:
    """The N a Monte Carlo file declares: its ``samples``, else the success-run count of its
    target (eq. 38b)."""
    return config.samples or samples_needed(config.target.p, config.target.confidence)


def result_key(ref: str | Path, samples: int) -> str:
    """The key a Monte Carlo's verdict carries (``verdict.json``'s ``key``): what it is made
    from (:func:`montecarlo_key`, at the N flown) and the samples' code."""
    from pipeline.provenance.keys import sample_version

    return f"{montecarlo_key(ref, samples)}, code {sample_version()}"


def plan_montecarlo(ref: str | Path, samples: int | None = None) -> MonteCarlo:
    """Read and validate a Monte Carlo file and draw every sample (SpecError on bad input);
    nothing runs, nothing is written. ``samples`` overrides the file's count."""
    return _plan(ref, samples, None)


def draw_one(ref: str | Path, index: int) -> tuple[MonteCarlo, Sample]:
    """The Monte Carlo and its sample ``index`` alone, drawn from its own stream (the others
    are not drawn: a sample does not depend on them)."""
    if index < 0:
        raise SpecError(f"--sample {index}: a sample's index is 0 or more")
    mc = _plan(ref, None, index)
    return mc, mc.samples[0]


def derive(mc: MonteCarlo, changes: dict[str, Any], name: str,
           indices: list[int] | None = None, seed: int | None = None) -> MonteCarlo:
    """The Monte Carlo ``mc`` with ``changes`` added to its fixed overrides (``set``), named
    ``name``, its samples ``indices`` (all of ``mc``'s by default) drawn again: on common random
    numbers, sample i draws what ``mc``'s sample i drew (the same seed, index and streams), now
    about the changed nominal; with ``seed``, fresh draws instead. Nothing runs."""
    config = mc.config.model_copy(update={
        "set": {**mc.config.set, **changes},
        **({"seed": seed} if seed is not None else {})})
    return _plan_config(mc.path, config, name,
                        [s.index for s in mc.samples] if indices is None else indices)


def _plan(ref: str | Path, samples: int | None, only: int | None) -> MonteCarlo:
    path = resolve_montecarlo(ref)
    config = read_montecarlo(path)
    n = samples or file_samples(config)
    check_samples(n, f"{path}: field {'samples' if config.samples else 'target'}"
                  if samples is None else f"--samples {samples}")
    return _plan_config(path, config, path.stem, list(range(n)) if only is None else [only])


def _plan_config(path: Path, config: MonteCarloFile, name: str,
                 indices: list[int]) -> MonteCarlo:
    """Draw samples ``indices`` of the Monte Carlo ``config`` (read from ``path``) under
    ``name``."""
    base = load_spec(config.mission, path.resolve().parent)
    if not config.dispersions:
        raise SpecError(f"{path}: field dispersions: empty; a Monte Carlo disperses something")
    bodies = {m.group(1) for k in config.dispersions if (m := BODY_KEY.match(k))}
    bad = [k for k in config.dispersions if k.startswith("body.") and not BODY_KEY.match(k)]
    if bad:
        raise SpecError(f"{path}: field dispersions.{bad[0]}: a body's key is "
                        "body.<bus|payload>.<mass|com|inertia>")
    nominals = body_nominals(base, bodies, path)
    # The nominals are the fixed overrides' (a block the file sets, as mission.plant.timing,
    # can then be dispersed).
    fixed = nominal_spec(base, config)
    drawn = [draw_sample(name, config, fixed, i, nominals, path) for i in indices]
    budget = Budget.from_environment()  # each sample's mission within it, as `run` judges
    seconds = sum(check_mission(s.spec, budget, f"{path}: sample {s.index}").seconds
                  for s in drawn)
    return MonteCarlo(name, path, config, base, drawn, seconds)
