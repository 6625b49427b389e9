"""The Monte Carlo's table and its verdict at a stated confidence (eqs. 38, 39).

The table (``montecarlo.parquet``) holds one row per sample: its record (what it did, its
margins, its ripple, whether it passes and why not) and its draws (``draw:<key>``). The
verdict counts the samples that pass, bounds the pass probability from below at the stated
confidence (Clopper–Pearson, eq. 38a), says whether that shows the target (38c) and how many
samples a demonstration with none failing needs (38b), and lists the worst samples: the
failing ones first, then by least gain margin, each with its draws and seed, re-runnable alone.
A sample whose task did not finish is no judgement: with any, there is no verdict.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.analysis.confidence import confidence_verdict, samples_needed
from pipeline.errors import LogError
from pipeline.montecarlo.sealed import sealed_json, unseal

TABLE_NAME = "montecarlo.parquet"
VERDICT_NAME = "verdict.json"
DRAW = "draw:"
WORST = 10  # samples listed
RECORD_COLUMNS = ["sample", "index", "status", "error", "steps", "passes", "fails", "step",
                  "spectral_radius", "mean_square_radius", "dt_mu_max", "gain_margin_db",
                  "phase_margin_deg", "delay_margin_steps", "worst_mode", "ripple",
                  "bus_rate_lag1", "log_digest", "seed", "spec_hash", "ran", "attempts",
                  "seconds", "worker"]


@dataclass(frozen=True)
class WorstSample:
    sample: str
    index: int
    seed: list[int]
    passes: bool
    fails: list[str]
    gain_margin_db: float
    phase_margin_deg: float
    delay_margin_steps: float
    spectral_radius: float
    ripple: float
    worst_mode: str
    draws: dict[str, float]


@dataclass(frozen=True)
class RequirementWords:
    gain_margin_db: float
    phase_margin_deg: float
    delay_margin_steps: float
    ripple_max: float
    loop: str  # the plant and delay the samples flew


@dataclass(frozen=True)
class MonteCarloVerdict:
    """What the samples show (eqs. 38, 39); ``shown`` None: no verdict (a task errored)."""

    name: str
    description: str
    mission: str
    seed: int
    samples: int
    passes: int
    errored: int
    pass_fraction: float
    target_p: float
    confidence: float
    lower_bound: float | None
    needed: int  # samples, none failing, that show target_p at confidence (eq. 38b)
    shown: bool | None
    statement: str
    requirement: RequirementWords
    failures: int  # samples judged and failing (samples − passes − errored)
    fails_by_part: dict[str, int]
    failing_modes: dict[str, int]  # the mode of least gain margin of each failing sample
    mean_square_radius_max: float | None  # the largest over the judged samples (eq. 41c); None:
    # no sample's loop was jittered
    dispersions: dict[str, str]
    worst: list[WorstSample]
    simulated: int  # samples run by this invocation (the others: kept records)
    wall_s: float
    key: str = ""  # what it is made from (pipeline.montecarlo.studies.study_key); "": unknown
    file: str = ""  # the Monte Carlo file it flew (absolute), to check the key against
    # The nominal's loop (loop_key): a run of that loop is what it judges; "": unknown (a
    # verdict written before the key), a study of no run's loop.
    nominal_loop: str = ""


def file_ref(v: MonteCarloVerdict) -> str:
    """How a command names the Monte Carlo file a verdict flew: its name where that is the
    shipped file (``specs/montecarlo/<name>.yaml``), else its path (a fix's file)."""
    from pipeline.errors import SpecError
    from pipeline.montecarlo.plan import resolve_montecarlo

    try:
        shipped = resolve_montecarlo(v.name).resolve() == Path(v.file).resolve()
    except SpecError:
        shipped = False
    return v.name if shipped or not v.file else v.file


def loop_key(spec: dict) -> str:
    """Which loop a resolved spec (``Spec.model_dump(mode="json")``) flies, as a digest: its
    robot, controller, step, plant (delay, arrival and jitter, sensors) and requirement. A run
    and a Monte Carlo whose nominal share it fly the same loop, so the study speaks for the
    run's loop (the decision box names a fix only where one shows it). The mission's length,
    start and path are not the loop, nor the seeds of its noise and jitter streams; an arrival
    with no fraction and no jitter is no timing at all (eq. 41)."""
    mission = spec.get("mission") or {}
    plant = dict(mission.get("plant") or {})
    for part in ("timing", "sensors"):
        block = plant.get(part)
        if isinstance(block, dict):
            plant[part] = {k: x for k, x in block.items() if k != "seed"}
    timing = plant.get("timing")
    if timing is not None and not timing.get("delay_fraction") and not timing.get("jitter"):
        plant["timing"] = None
    loop = {"robot": spec.get("robot"), "controller": spec.get("controller"),
            "dt": mission.get("dt"), "plant": plant, "requirements": spec.get("requirements")}
    return hashlib.sha256(json.dumps(loop, sort_keys=True).encode()).hexdigest()[:16]


def make_table(records: list[dict]) -> pd.DataFrame:
    """One row per sample, in sample order: the record's columns, then ``draw:<key>``."""
    keys = sorted({k for r in records for k in r.get("draws", {})})
    rows = []
    for r in records:
        row = {c: r.get(c) for c in RECORD_COLUMNS}
        row["fails"] = "; ".join(r.get("fails") or [])
        row["seed"] = json.dumps(r.get("seed"))
        row |= {DRAW + k: float(r.get("draws", {}).get(k, math.nan)) for k in keys}
        rows.append(row)
    df = pd.DataFrame(rows, columns=[*RECORD_COLUMNS, *(DRAW + k for k in keys)])
    df["attempts"] = df["attempts"].fillna(0).astype(int)
    return df


def read_table(path: Path | str) -> pd.DataFrame:
    path = Path(path)
    try:
        return pq.read_table(path).to_pandas()
    except (pa.ArrowInvalid, OSError) as exc:
        raise LogError(f"{path}: not a readable Monte Carlo table "
                       f"({str(exc).splitlines()[0]})") from None


def draw_keys(df: pd.DataFrame) -> list[str]:
    """The dispersed parameters that vary (a draw constant over the samples, such as a
    redraw count of zero, says nothing)."""
    return [c[len(DRAW):] for c in df.columns if c.startswith(DRAW)
            and df[c].nunique(dropna=True) > 1]


def _order(df: pd.DataFrame) -> pd.DataFrame:
    """Failing first, then by least gain margin (NaN, a run that did not finish, first)."""
    gm = df["gain_margin_db"].astype(float).fillna(-np.inf)
    return df.assign(_gm=gm).sort_values(["passes", "_gm", "index"], kind="stable")


def worst_samples(df: pd.DataFrame, count: int = WORST) -> list[WorstSample]:
    """The ``count`` worst samples (failing first, then by least gain margin), each with the
    draws that vary over the Monte Carlo."""
    varying = {DRAW + k for k in draw_keys(df)}
    out = []
    for d in _order(df).head(count).drop(columns="_gm").to_dict("records"):
        out.append(WorstSample(
            sample=d["sample"], index=int(d["index"]), seed=json.loads(d["seed"]),
            passes=bool(d["passes"]), fails=[f for f in d["fails"].split("; ") if f],
            gain_margin_db=float(d["gain_margin_db"]),
            phase_margin_deg=float(d["phase_margin_deg"]),
            delay_margin_steps=float(d["delay_margin_steps"]),
            spectral_radius=float(d["spectral_radius"]), ripple=float(d["ripple"]),
            worst_mode=d["worst_mode"],
            draws={k[len(DRAW):]: float(v) for k, v in d.items() if k in varying}))
    return out


def mission_words(base, config) -> str:
    """The mission the samples fly: the spec dispersed and the file's fixed overrides (a
    ``set: {mission.dt: …}`` makes another loop than the spec's name says)."""
    fixed = ", ".join(f"{k} = {v}" for k, v in sorted(config.set.items()))
    return f"{base.name} with {fixed}" if fixed else base.name


def judge(df: pd.DataFrame, name: str, config, base, dispersions: dict[str, str],
          requirement: RequirementWords, wall_s: float) -> MonteCarloVerdict:
    """The verdict of the table (eqs. 38, 39); see the module docstring."""
    from pipeline.montecarlo.plan import nominal_spec

    n = len(df)
    errored = int((df["status"] == "error").sum())
    passes = int(df["passes"].sum())
    p, c = config.target.p, config.target.confidence
    needed = samples_needed(p, c)
    fails: dict[str, int] = {}
    for text in df["fails"]:
        for part in (f for f in text.split("; ") if f):
            fails[part] = fails.get(part, 0) + 1
    judged_failing = df[(~df["passes"].astype(bool)) & (df["status"] != "error")]
    modes: dict[str, int] = {}
    for mode in judged_failing["worst_mode"]:
        modes[mode or "none (the run did not complete)"] = modes.get(
            mode or "none (the run did not complete)", 0) + 1
    if errored:
        bound, shown = None, None
        statement = (f"no verdict: {errored} of {n} samples did not finish (their task "
                     "errored); run the same command again to finish them")
    else:
        v = confidence_verdict(passes, n, p, c)
        bound, shown = v.lower_bound, v.meets
        statement = (f"{passes} of {n} samples meet the requirement "
                     f"({100 * passes / n:.2f} %); the pass probability is at least "
                     f"{bound:.5f} at {100 * c:g} % confidence (Clopper–Pearson), "
                     + ("at or above" if shown else "below") + f" the target {p:g}: "
                     + ("shown" if shown else "NOT shown")
                     + ("" if shown or passes < n else
                        f" ({needed} samples, none failing, would show it)"))
    return MonteCarloVerdict(
        name=name, description=config.description, mission=mission_words(base, config),
        seed=config.seed,
        samples=n, passes=passes, errored=errored, pass_fraction=passes / n if n else math.nan,
        target_p=p, confidence=c, lower_bound=bound, needed=needed, shown=shown,
        statement=statement, requirement=requirement, failures=len(judged_failing),
        fails_by_part=fails, failing_modes=modes,
        mean_square_radius_max=(float(ms.max()) if len(ms := df["mean_square_radius"].dropna())
                                else None),
        dispersions=dispersions, worst=worst_samples(df), simulated=int(df["ran"].sum()),
        wall_s=wall_s, nominal_loop=loop_key(nominal_spec(base, config).model_dump(mode="json")))


def verdict_json(v: MonteCarloVerdict) -> str:
    """The verdict as JSON, sealed by its content's SHA-256 (:mod:`pipeline.montecarlo.sealed`)."""
    return sealed_json(asdict(v), indent=1)


def read_verdict(path: Path | str) -> MonteCarloVerdict:
    path = Path(path)
    try:
        d = unseal(path.read_text())
        d["requirement"] = RequirementWords(**d["requirement"])
        d["worst"] = [WorstSample(**w) for w in d["worst"]]
        return MonteCarloVerdict(**d)
    except (OSError, ValueError, TypeError, KeyError) as exc:
        raise LogError(f"{path}: not a readable Monte Carlo verdict ({exc})") from None
