"""One sample as one Dask task, its record cached beside the others (eq. 39).

A sample's record is kept as ``<logs>/<montecarlo>/<sample>.json``, written atomically, with
the key it was made under: the sample's spec hash, its robot file's digest, the code's version
(the simulator, the analysis stages and this package, and the numerical libraries) and the
ripple bound. A current record is reused, so a Monte Carlo stopped at any point resumes where
it was, and a changed dispersion or file runs only the samples it changes. The records are
small (a log is not kept: 852 logs of the seed robot would be gigabytes); the log's digest is,
and ``montecarlo … --sample I`` writes the log of one sample again. A record is sealed by its
content's SHA-256: one edited or damaged is not reused, its sample runs again.
"""

from __future__ import annotations

import math
import os
import socket
from pathlib import Path

from pipeline.atomic_files import atomic_write_text
from pipeline.montecarlo.sample import SampleRecord, record_dict, run_sample
from pipeline.montecarlo.sealed import sealed_json, unseal
from pipeline.provenance.keys import file_digest, sample_version
from pipeline.spec import Spec


def sample_key(spec: Spec, ripple_max: float) -> dict:
    return {"spec_hash": spec.spec_hash, "robot": file_digest(spec.robot_path),
            "code": sample_version(), "ripple_max": ripple_max}


def record_path(root: Path | str, name: str) -> Path:
    return Path(root) / f"{name}.json"


def kept(root: Path | str, name: str, key: dict, fields) -> dict | None:
    """The record kept as ``<root>/<name>.json`` if it was made under ``key``, holds every
    one of ``fields`` and matches its content digest (:mod:`pipeline.montecarlo.sealed`: an
    edited or damaged record is run again, never counted), else None."""
    try:
        data = unseal(record_path(root, name).read_text())
    except (OSError, ValueError):
        return None
    if data.get("key") != key:
        return None
    rec = data.get("record")
    return rec if isinstance(rec, dict) and set(rec) >= set(fields) else None


def damaged(root: Path | str, name: str) -> str | None:
    """Why the record kept as ``<root>/<name>.json`` cannot be read whole (edited, damaged,
    not JSON), or None when it can or there is none."""
    path = record_path(root, name)
    try:
        unseal(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        return f"{path}: {exc}"
    return None


def keep(root: Path | str, name: str, key: dict, record: dict) -> None:
    """Keep ``record`` as ``<root>/<name>.json`` with its key, atomically."""
    Path(root).mkdir(parents=True, exist_ok=True)
    atomic_write_text(record_path(root, name), sealed_json({"key": key, "record": record}))


def worker() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def cached_record(root: Path | str, spec: Spec, ripple_max: float) -> dict | None:
    """The sample's record if one is kept under the current key, else None."""
    return kept(root, spec.name, sample_key(spec, ripple_max), SampleRecord.__dataclass_fields__)


def sample_task(spec: Spec, index: int, seed: list[int], draws: dict[str, float],
                ripple_max: float, root: str, topic: str) -> dict:
    """The task the driver submits: announce the start, reuse the kept record or run the
    sample and keep its record; returns the record (``ran``: run by this task)."""
    from pipeline.sweep.progress import announce_start

    announce_start(topic, spec.name)
    rec = cached_record(root, spec, ripple_max)
    if rec is not None:
        return {**rec, "ran": False, "worker": worker()}
    rec = record_dict(run_sample(spec, index, seed, draws, ripple_max))
    keep(root, spec.name, sample_key(spec, ripple_max), rec)
    return {**rec, "ran": True, "worker": worker()}


def errored_record(name: str, index: int, seed: list[int], spec_hash: str,
                   draws: dict[str, float], error: str) -> dict:
    """The record of a sample whose task did not finish (a bug, its workers died): not a
    judgement of the sample; the verdict refuses to count it."""
    nan = math.nan
    return {"sample": name, "index": index, "seed": list(seed), "spec_hash": spec_hash,
            "status": "error", "error": error, "steps": 0, "passes": False,
            "fails": ["task error"], "step": -1, "spectral_radius": nan,
            "mean_square_radius": nan, "dt_mu_max": nan,
            "gain_margin_db": nan, "phase_margin_deg": nan, "delay_margin_steps": nan,
            "worst_mode": "", "ripple": nan, "bus_rate_lag1": nan, "log_digest": "",
            "seconds": nan, "draws": dict(draws), "ran": False, "worker": ""}
