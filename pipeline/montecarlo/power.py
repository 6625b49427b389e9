"""The ripple detectors' power against sensor noise (eq. 40): false alarms and missed
detections from Monte Carlo samples of a mission that rings and of one that does not, at each
noise level, each sample its own noise stream.

```yaml
description: …
ripple: omega_ripple_sampled          # ω_b rings period-2 here
quiet: omega_ripple_sampled_dt010     # and not here
set: {mission.duration: 10.0}
seed: 40
samples: 20                           # per mission and noise level
noise: gyro_arw                       # the field of mission.plant.sensors swept
levels: [0.0, 1.0e-3, 1.0e-2, 0.1]    # its values
fixed: {encoder_lsb: 0.0}             # the other sensor fields (optional)
```

Sample i at level j of a mission gets ``mission.plant.sensors = {**fixed, noise: level,
seed: s}``, s drawn from ``SeedSequence([seed, j, i])``: the same noise stream for the mission
that rings and the one that does not. A detector's **false-alarm rate** at a level is the share
of the quiet mission's samples it calls ringing, its **missed-detection rate** the share of the
ringing mission's it does not (:mod:`pipeline.analysis.detection`, on ω_b as measured over the
analysis window). The **crossing** is the least level at which the missed-detection rate
reaches one half, interpolated linearly in log(level) between the levels either side: above
it the detector misses the ripple more often than not. A run that does not complete is no
judgement: counted, never a detection or a miss.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from pipeline.atomic_files import atomic_write_text
from pipeline.budget import Budget, check_mission, check_samples
from pipeline.errors import LogError, RunFailed, SpecError
from pipeline.montecarlo.plan import resolve_montecarlo
from pipeline.montecarlo.sealed import sealed_json, unseal
from pipeline.spec import Seed, Sensors, Spec, load_spec, with_overrides
from pipeline.yamlfile import read_yaml

if TYPE_CHECKING:  # pandas, Dask and the simulator where a study runs, not to check its file
    import pandas as pd

TABLE_NAME = "power.parquet"
RESULT_NAME = "power.json"
DETECTORS = ("lag1", "spectral")
CASES = ("ripple", "quiet")
NOISE_FIELDS = tuple(f for f in Sensors.model_fields if f != "seed")


class PowerFile(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    description: str = ""
    ripple: str
    quiet: str
    set: dict[str, Any] = Field(default_factory=dict)
    seed: Seed
    samples: Annotated[int, Field(gt=0)]
    noise: str
    levels: Annotated[list[Annotated[float, Field(ge=0, allow_inf_nan=False)]],
                      Field(min_length=2)]
    fixed: dict[str, float] = Field(default_factory=dict)


@dataclass(frozen=True)
class PowerSample:
    name: str
    case: str
    level_index: int
    index: int
    spec: Spec


@dataclass(frozen=True)
class PowerPlan:
    name: str
    path: Path
    config: PowerFile
    samples: list[PowerSample]
    seconds: float = 0.0  # the runs' flights by the budget's estimate (pipeline.budget)


def read_power_file(path: Path) -> PowerFile:
    """A power file, validated (SpecError naming the field)."""
    try:
        return PowerFile.model_validate(read_yaml(path))
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(x) for x in err["loc"]) or "file"
        msg = "unknown key" if err["type"] == "extra_forbidden" else err["msg"]
        raise SpecError(f"{path}: field {where}: {msg}") from None


def plan_power(ref: str | Path, samples: int | None = None) -> PowerPlan:
    """Read and validate a power file and build every sample's spec (SpecError naming the
    field); nothing runs. ``samples`` overrides the file's runs per mission and level (the
    first runs of each: a run's seed depends on its level and index alone)."""
    path = resolve_montecarlo(ref)
    config = read_power_file(path)
    if samples is not None:
        config = config.model_copy(update={"samples": samples})
    if config.noise not in NOISE_FIELDS:
        raise SpecError(f"{path}: field noise: {config.noise!r} is not a sensor field (one of "
                        f"{', '.join(NOISE_FIELDS)})")
    bad = sorted(set(config.fixed) - set(NOISE_FIELDS))
    if bad:
        raise SpecError(f"{path}: field fixed.{bad[0]}: not a sensor field (one of "
                        f"{', '.join(NOISE_FIELDS)})")
    if sorted(config.levels) != list(config.levels) or len(set(config.levels)) < len(
            config.levels):
        raise SpecError(f"{path}: field levels: give them increasing, each once")
    check_samples(len(CASES) * len(config.levels) * config.samples,
                  f"{path}: field samples" if samples is None else f"--samples {samples}")
    here = path.resolve().parent
    bases = {case: load_spec(getattr(config, case), here) for case in CASES}
    budget = Budget.from_environment()
    seconds = 0.0
    samples = []
    for case in CASES:
        for j, level in enumerate(config.levels):
            for i in range(config.samples):
                seed = int(np.random.SeedSequence([config.seed, j, i]).generate_state(1)[0])
                sensors = {**config.fixed, config.noise: float(level), "seed": seed}
                name = f"{path.stem}__{case}__{j:02d}__{i:03d}"
                try:
                    spec = with_overrides(bases[case], {**config.set,
                                                        "mission.plant.sensors": sensors}, name)
                except SpecError as exc:
                    raise SpecError(f"{path}: {case} mission {bases[case].name}: {exc}") from None
                seconds += check_mission(spec, budget, f"{path}: {case} run {name}").seconds
                samples.append(PowerSample(name, case, j, i, spec))
    return PowerPlan(path.stem, path, config, samples, seconds)


def power_file_key(ref: str | Path) -> str:
    """What a power study is made from, for the claims' key: its file and its missions'
    spec hashes and robot files."""
    import hashlib

    from pipeline.provenance.keys import file_digest

    plan_path = resolve_montecarlo(ref)
    plan = plan_power(plan_path)
    specs = hashlib.sha256("".join(sorted(s.spec.spec_hash for s in plan.samples)).encode())
    robots = sorted({file_digest(s.spec.robot_path) for s in plan.samples})
    return f"file {file_digest(plan_path)}, specs {specs.hexdigest()}, robots {robots}"


def result_key(ref: str | Path, samples: int) -> str:
    """The key a power result carries (``power.json``'s ``key``): what it is made from
    (:func:`power_file_key`), the runs per mission and level flown and the samples' code."""
    from pipeline.provenance.keys import sample_version

    return f"{power_file_key(ref)}, samples {samples}, code {sample_version()}"


def power_key(spec: Spec) -> dict:
    from pipeline.provenance.keys import file_digest, sample_version

    return {"spec_hash": spec.spec_hash, "robot": file_digest(spec.robot_path),
            "code": sample_version(), "detector": "power/1"}


RECORD_FIELDS = ("sample", "case", "level_index", "index", "status", "lag1", "lag1_detects",
                 "spectral_detects", "period_steps", "amplitude")


def power_task(spec: Spec, case: str, level_index: int, index: int, root: str,
               topic: str) -> dict:
    """Run one sample's mission (its sensors seeded) and both detectors on ω_b as measured
    over its analysis window; its record kept and reused."""
    from pipeline.analysis.detection import detect_ripple
    from pipeline.analysis.stages import choose_window
    from pipeline.montecarlo.task import keep, kept, worker
    from pipeline.shapes import V
    from pipeline.sim.mission import Mission
    from pipeline.sweep.progress import announce_start

    announce_start(topic, spec.name)
    key = power_key(spec)
    rec = kept(root, spec.name, key, RECORD_FIELDS)
    if rec is not None:
        return {**rec, "ran": False, "worker": worker()}
    result = Mission(spec).run()
    rec = {"sample": spec.name, "case": case, "level_index": level_index, "index": index,
           "status": result.status, "lag1": math.nan, "lag1_detects": False,
           "spectral_detects": False, "period_steps": math.nan, "amplitude": math.nan}
    if result.status == "complete":
        cols = result.columns
        win = choose_window(len(cols["step"]), spec.mission.dt, None, spec.name)
        d = detect_ripple(cols["v"][win.start:win.stop, V.omega_b])
        rec |= {"lag1": math.nan if d.lag1 is None else d.lag1, "lag1_detects": d.lag1_detects,
                "spectral_detects": d.spectral_detects,
                "period_steps": math.nan if d.period_steps is None else d.period_steps,
                "amplitude": d.amplitude}
    keep(root, spec.name, key, rec)
    return {**rec, "ran": True, "worker": worker()}


@dataclass(frozen=True)
class LevelRates:
    level: float
    judged: dict[str, int]  # runs completed, by case
    false_alarm: dict[str, float]  # by detector (quiet mission)
    missed: dict[str, float]  # by detector (ringing mission)
    ripple_amplitude: float  # rad/s: the ringing mission's median ω_b period-2 amplitude
    lag1_median: dict[str, float]  # by mission: the median lag-1 the lag-1 detector read


@dataclass(frozen=True)
class PowerResult:
    name: str
    description: str
    ripple: str
    quiet: str
    noise: str
    unit: str
    samples: int
    lag1_threshold: float
    period2_max: float
    levels: list[LevelRates]
    crossing: dict[str, float | None]  # by detector; None: never reaches one half
    false_alarm_max: dict[str, float]  # by detector, over the levels
    not_judged: int
    statement: str
    wall_s: float
    key: str = ""  # what it is made from (pipeline.montecarlo.studies.study_key); "": unknown
    file: str = ""  # the power file it flew (absolute), to check the key against


UNITS = {"gyro_arw": "rad/√s", "gyro_bias": "rad/s", "gyro_bias_walk": "rad/s/√s",
         "gyro_lsb": "rad/s", "encoder_lsb": "rad"}


def crossing(levels: list[float], missed: list[float]) -> float | None:
    """The least level at which ``missed`` reaches ½, interpolated in log(level) between the
    levels either side (linear in level when the one below is 0); None if it never does."""
    for j, m in enumerate(missed):
        if m >= 0.5:
            if j == 0:
                return levels[0]
            lo, hi, m0 = levels[j - 1], levels[j], missed[j - 1]
            w = (0.5 - m0) / (m - m0)
            if lo <= 0.0:
                return lo + w * (hi - lo)
            return float(math.exp(math.log(lo) + w * (math.log(hi) - math.log(lo))))
    return None


def rates(df: pd.DataFrame, plan: PowerPlan, wall_s: float) -> PowerResult:
    from pipeline.analysis.detection import LAG1_THRESHOLD, PERIOD2_MAX

    c = plan.config
    done = df[df["status"] == "complete"]
    levels = []
    for j, level in enumerate(c.levels):
        at = done[done["level_index"] == j]
        q, r = at[at["case"] == "quiet"], at[at["case"] == "ripple"]
        levels.append(LevelRates(
            level=float(level), judged={"ripple": len(r), "quiet": len(q)},
            false_alarm={d: float(q[f"{d}_detects"].mean()) if len(q) else math.nan
                         for d in DETECTORS},
            missed={d: float(1.0 - r[f"{d}_detects"].mean()) if len(r) else math.nan
                    for d in DETECTORS},
            ripple_amplitude=float(r["amplitude"].median()) if len(r) else math.nan,
            lag1_median={"ripple": float(r["lag1"].median()) if len(r) else math.nan,
                         "quiet": float(q["lag1"].median()) if len(q) else math.nan}))
    cross = {d: crossing([x.level for x in levels], [x.missed[d] for x in levels])
             for d in DETECTORS}
    fa_max = {d: float(np.nanmax([x.false_alarm[d] for x in levels])) for d in DETECTORS}
    unit = UNITS.get(c.noise, "")
    words = []
    for d in DETECTORS:
        where = (f"misses the ripple in half the runs from {c.noise} = {cross[d]:.3g} {unit}"
                 if cross[d] is not None else
                 f"sees the ripple in most runs at every level up to {c.levels[-1]:g} {unit}")
        alarms = [x for x in levels if x.false_alarm[d] > 0]
        fa = ("and raises no false alarm on the quiet mission at any level" if not alarms else
              f"and raises false alarms on the quiet mission in up to "
              f"{100 * fa_max[d]:.3g} % of its runs (first at {alarms[0].level:g} {unit})")
        words.append(f"the {d} detector {where}, {fa}")
    return PowerResult(
        name=plan.name, description=c.description, ripple=c.ripple, quiet=c.quiet,
        noise=c.noise, unit=unit, samples=c.samples, lag1_threshold=LAG1_THRESHOLD,
        period2_max=PERIOD2_MAX, levels=levels, crossing=cross, false_alarm_max=fa_max,
        not_judged=int((df["status"] != "complete").sum()),
        statement="; ".join(words), wall_s=wall_s)


def write_power(df: pd.DataFrame, result: PowerResult, out: Path) -> Path:
    """The table, then the result (the result last: a table without it is unfinished)."""
    from pipeline.provenance.keys import sample_version
    from pipeline.sweep.results import write_table

    out.mkdir(parents=True, exist_ok=True)
    write_table(df, out / TABLE_NAME, {"pipeline.power": result.name,
                                       "pipeline.sample_version": sample_version()})
    atomic_write_text(out / RESULT_NAME, sealed_json(asdict(result), indent=1))
    return out / RESULT_NAME


def read_power(path: Path | str) -> PowerResult:
    path = Path(path)
    try:
        d = unseal(path.read_text())
        d["levels"] = [LevelRates(**x) for x in d["levels"]]
        return PowerResult(**d)
    except (OSError, ValueError, TypeError, KeyError) as exc:
        raise LogError(f"{path}: not a readable detector-power result ({exc})") from None


def power_command(args: argparse.Namespace) -> int:
    plan = plan_power(args.file, args.samples)
    import pandas as pd

    from pipeline.montecarlo.owner import check_start, claim_folders
    from pipeline.sweep.cluster import WORKER_TIMEOUT, ClusterOptions, open_client
    from pipeline.sweep.driver import check_writable, execute_tasks

    root = Path(args.logs).resolve() / plan.name
    out = Path(args.out).resolve() / plan.name
    for folder in (root, out):
        check_writable(folder)
    options = ClusterOptions(scheduler=args.scheduler, workers=args.workers, slurm=args.slurm,
                             slurm_log_dir=root.parent / ".slurm",
                             worker_timeout=args.worker_timeout or WORKER_TIMEOUT)
    check_start("power", plan.name, plan.path, (root, out), options, plan.seconds,
                [s.name for s in plan.samples], args.force)
    samples = {s.name: s for s in plan.samples}
    t0 = time.perf_counter()
    with open_client(options) as session:
        client = session.client
        # Claimed once the cluster answers: a bad --scheduler leaves no folder behind.
        claim_folders("power", plan.name, plan.path, (root, out), args.force)

        def submit(name: str, topic: str, key: str):
            s = samples[name]
            return client.submit(power_task, s.spec, s.case, s.level_index, s.index,
                                 str(root), topic, pure=False, key=key)

        def failed(name: str, error: str) -> dict:
            s = samples[name]
            return {"sample": name, "case": s.case, "level_index": s.level_index,
                    "index": s.index, "status": "error", "error": error, "lag1": math.nan,
                    "lag1_detects": False, "spectral_detects": False,
                    "period_steps": math.nan, "amplitude": math.nan, "ran": False,
                    "worker": ""}

        records = execute_tasks(plan.name, list(samples), submit, failed,
                                lambda r: r["status"] != "error", client,
                                __import__("sys").stderr.isatty(), options.worker_timeout,
                                session.jobs, kind="power", unit="sample")
    df = pd.DataFrame(records)
    df["level"] = [plan.config.levels[j] for j in df["level_index"]]
    result = replace(rates(df, plan, time.perf_counter() - t0),
                     key=result_key(plan.path, plan.config.samples),
                     file=str(Path(plan.path).resolve()))
    path = write_power(df.drop(columns=["received"], errors="ignore"), result, out)
    print(power_text(result, path))
    errored = int((df["status"] == "error").sum())
    if errored:
        raise RunFailed(f"power {plan.name}: {errored} samples did not finish; run the same "
                        "command again")
    return 0


def power_text(r: PowerResult, path: Path) -> str:
    lines = [f"power {r.name}: {r.statement}",
             f"  {r.noise} ({r.unit}) | false alarms lag-1, spectral | missed lag-1, spectral "
             f"| ripple amplitude (rad/s)"]
    for x in r.levels:
        lines.append(f"  {x.level:<10.3g} | {100 * x.false_alarm['lag1']:5.1f} %, "
                     f"{100 * x.false_alarm['spectral']:5.1f} % | {100 * x.missed['lag1']:5.1f} %,"
                     f" {100 * x.missed['spectral']:5.1f} % | {x.ripple_amplitude:.3g}")
    lines.append(f"  {r.samples} samples per mission and level, {r.not_judged} not judged, "
                 f"{r.wall_s:.1f} s wall -> {path}")
    return "\n".join(lines)
