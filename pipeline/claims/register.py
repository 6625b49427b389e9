"""The claims register file (``specs/claims.yaml``): schema, ``extends`` and validation.

    logs: logs                       # where runs are written (relative to the project root)
    runs:                            # run names used in metric paths
      nominal: {spec: nominal, against: dt010}
      dt010:   {spec: omega_ripple_dt010}
    claims:
      - id: C1
        statement: …
        kind: physics                # or note, identity, software (claims.yaml's header)
        expect: hold                 # or open, with a reason
        checks:                      # all must hold
          - {metric: "nominal:dominant.lag1", op: lt, threshold: -0.5}

A metric is ``SOURCE:PATH``. SOURCE is a run name (PATH a dotted path into its analysis.json,
or ``spec.…`` into its resolved spec, or ``log.GROUP.STAT`` for a statistic of its logged
reduced velocity), ``cross_check``, ``baselines``, ``sweep`` (PATH: a name under ``sweeps:``
then a key of that sweep's stability bracket, e.g. ``sweep:dt.holds``), ``montecarlo`` (PATH: a
name under ``montecarlo:`` then a key of its verdict, e.g. ``montecarlo:seed.lower_bound``),
``power`` (PATH: a name under ``power:`` then a key of its detector-power result, e.g.
``power:gyro.crossing.spectral``) or
``note`` (PATH:
ROW.COLUMN of the seed note's published values, the file named by ``note:``, e.g.
``note:dt_mu_max.nominal``). A threshold is a literal or ``{metric: SOURCE:PATH}``. The
operator ``close`` holds when |value − threshold| ≤ rel_tol·|threshold| (``rel_tol`` given
with it). A run expected to diverge says ``expect: diverged``. A run may be a log another tool
wrote, imported by name (``{imported: NAME}``: ``<logs>/imported/NAME/run.parquet``, with
``controller: SPEC`` when its controller is declared); its PATHs are its record's
(``ImportedRecord``): it has no spec but its robot and step, and no controller's columns.
A file may ``extends:`` another
(by path relative to itself), as a JSON Merge Patch of it (RFC 7386, :mod:`pipeline.merge_patch`):
its ``runs``, ``sweeps``, ``montecarlo`` and ``power`` entries merge into the parent's by name
and key by key, ``null`` deletes an inherited entry or key, and a ``claims`` list replaces the
parent's whole (left out, the parent's claims are inherited).
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from pipeline.errors import SpecError
from pipeline.merge_patch import merge_patch
from pipeline.yamlfile import read_yaml


def _abs(f: Callable[[float, float], bool]) -> Callable[[Any, Any], bool]:
    return lambda a, b: f(abs(a), b)


OPERATORS: dict[str, tuple[Callable[[Any, Any], bool], str]] = {
    "lt": (operator.lt, "<"), "le": (operator.le, "≤"), "gt": (operator.gt, ">"),
    "ge": (operator.ge, "≥"), "eq": (operator.eq, "="), "ne": (operator.ne, "≠"),
    "abs_lt": (_abs(operator.lt), "|·| <"), "abs_le": (_abs(operator.le), "|·| ≤"),
    "abs_gt": (_abs(operator.gt), "|·| >"), "abs_ge": (_abs(operator.ge), "|·| ≥"),
    "close": (lambda a, b: True, "≈"),  # with rel_tol: see compare_values in claims.py
}
# /2: each claim carries its kind (physics, note, identity, software), which the reports read.
# /3: a claim may be DEFERRED, with the reason in "deferred".
CLAIMS_SCHEMA = "breve-claims/3"  # the version of the claims.json the register writes
NUMERIC_OPS = {k for k in OPERATORS if k not in ("eq", "ne")}
FIXED_SOURCES = ("cross_check", "baselines", "sweep", "montecarlo", "power", "note")
# v_breve is its task part; null_space a redundant arm's null-space velocities (eq. 37).
LOG_GROUPS = {"omega_b": slice(0, 3), "nu_e_lin": slice(3, 6), "nu_e_ang": slice(6, 9),
              "camera_roll": slice(8, 9), "v_breve": slice(0, 9), "null_space": slice(9, None)}
LOG_STATS = ("ripple", "step_rms", "lag1_min", "lag1_max", "rms")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ClaimCheck(_Strict):
    metric: str
    op: str
    threshold: Any = None
    rel_tol: float | None = Field(default=None, gt=0, allow_inf_nan=False)

    @model_validator(mode="after")
    def _finite_threshold(self) -> ClaimCheck:
        t = self.threshold
        if isinstance(t, float) and not math.isfinite(t):
            raise ValueError(f"threshold {t!r} is not a finite number")
        return self

    @property
    def threshold_metric(self) -> str | None:
        t = self.threshold
        return t["metric"] if isinstance(t, dict) and set(t) == {"metric"} else None


# What a claim is (claims.yaml's header): a physics finding, a row of the seed note, the
# restatement of an input, or a check of the software and its inputs.
CLAIM_KINDS = ("physics", "note", "identity", "software")


class Claim(_Strict):
    id: str = Field(min_length=1)
    statement: str = Field(min_length=1)
    kind: Literal["physics", "note", "identity", "software"] | None = None
    expect: Literal["hold", "open"]
    reason: str = ""
    checks: list[ClaimCheck] = Field(min_length=1)

    @model_validator(mode="after")
    def _open_needs_reason(self) -> Claim:
        if self.expect == "open" and not self.reason.strip():
            raise ValueError("an open claim needs a reason")
        return self


class RunRef(_Strict):
    spec: str | None = None
    imported: str | None = Field(default=None, pattern=r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")
    controller: str | None = None  # an imported log's declared controller (a spec)
    against: str | None = None
    expect: Literal["complete", "diverged"] = "complete"
    # The theory at the window's step of s_min_G nearest this (issue 50): a number, or a
    # metric SOURCE:PATH (the note's value, or another run's record) read before the analysis.
    at_s_min_G: float | str | None = None

    @model_validator(mode="after")
    def _one_source(self) -> RunRef:
        if (self.spec is None) == (self.imported is None):
            raise ValueError("a run is a spec or an imported log's name: give one of spec, "
                             "imported")
        if self.imported is not None and (self.against is not None
                                          or self.expect != "complete"):
            raise ValueError("an imported log is analysed alone and complete: no against or "
                             "expect")
        if self.controller is not None and self.imported is None:
            raise ValueError("controller declares an imported log's controller; a spec's run "
                             "has its own")
        if self.at_s_min_G is not None and self.imported is not None:
            raise ValueError("at_s_min_G chooses a simulated run's representative step; an "
                             "imported log's theory is its declared controller's")
        if isinstance(self.at_s_min_G, float) and not (math.isfinite(self.at_s_min_G)
                                                      and self.at_s_min_G > 0.0):
            raise ValueError("at_s_min_G: a finite σ above 0, or a metric SOURCE:PATH")
        return self

    def at_source(self) -> str | None:
        """The run or source whose value ``at_s_min_G`` reads, if it is a metric."""
        return split_metric(self.at_s_min_G)[0] if isinstance(self.at_s_min_G, str) else None


class SweepRef(_Strict):
    """A sweep the claims use: ``python -m pipeline sweep SPEC --set … --name NAME``, and how
    its stability bracket reads the table: the swept ``key`` (a column), the ``lag`` column
    whose sign flips and the ``predicted`` column of the predicted crossing in ``key`` units."""

    spec: str
    set: list[str] = Field(min_length=1)
    name: str
    workers: int = Field(default=2, gt=0)
    key: str = "mission.dt"
    lag: str = "dominant_lag1"
    predicted: str = "dt_star_damping"
    unstable: Literal["above", "below"] = "above"


class MonteCarloRef(_Strict):
    """A Monte Carlo the claims use: ``python -m pipeline montecarlo FILE [--samples N]`` (a
    path relative to the claims file, or a name under specs/montecarlo/)."""

    file: str
    samples: int | None = Field(default=None, gt=0)
    workers: int = Field(default=2, gt=0)


class ClaimsFile(_Strict):
    logs: str = "logs"
    note: str | None = None  # the seed note's values (seed_note.yaml), relative to here
    runs: dict[str, RunRef] = Field(default_factory=dict)
    sweeps: dict[str, SweepRef] = Field(default_factory=dict)
    montecarlo: dict[str, MonteCarloRef] = Field(default_factory=dict)
    power: dict[str, MonteCarloRef] = Field(default_factory=dict)  # samples: unused
    claims: list[Claim] = Field(min_length=1)
    source: str = ""


def split_metric(metric: str) -> tuple[str, str]:
    source, sep, path = metric.partition(":")
    if not sep or not source or not path:
        raise ValueError(f"metric {metric!r} is not SOURCE:PATH")
    return source, path


def _read(path: Path, chain: tuple[Path, ...] = ()) -> dict:
    path = path.resolve()
    if path in chain:
        raise SpecError(f"{path}: cycle in extends")
    if not path.is_file():
        raise SpecError(f"{path}: claims file not found")
    data = read_yaml(path, "claims file")
    parent = data.pop("extends", None)
    if parent is None:
        return data
    base = _read(path.parent / str(parent), (*chain, path))
    if "note" in base and "note" not in data:  # the parent's note file, seen from here
        base["note"] = str((path.parent / str(parent)).resolve().parent / base["note"])
    return merge_patch(base, data)


def _where(loc: tuple, data: dict) -> str:
    """'claim C3: check 2: field op' from a pydantic error location."""
    parts, node = [], data
    for i, x in enumerate(loc):
        if x == "claims" and i + 1 < len(loc) and isinstance(loc[i + 1], int):
            try:
                node = data["claims"][loc[i + 1]]
                parts.append(f"claim {node.get('id', loc[i + 1])}")
            except (IndexError, KeyError, TypeError, AttributeError):
                parts.append(f"claim #{loc[i + 1] + 1}")
        elif x == "checks" and i + 1 < len(loc) and isinstance(loc[i + 1], int):
            parts.append(f"check {loc[i + 1] + 1}")
        elif not isinstance(x, int) and (i == 0 or loc[i - 1] not in ("claims", "checks")):
            parts.append(f"field {x}")
    return ": ".join(parts) or "<root>"


def load_claims(path: Path) -> ClaimsFile:
    """Read, merge and validate a claims file; every error is one line naming what is wrong."""
    path = Path(path)
    data = _read(path)
    try:
        cf = ClaimsFile.model_validate({**data, "source": str(path)})
    except ValidationError as exc:
        err = exc.errors()[0]
        msg = "unknown key" if err["type"] == "extra_forbidden" else err["msg"]
        raise SpecError(f"{path}: {_where(err['loc'], data)}: {msg}") from None
    validate(cf, path)
    return cf


def validate(cf: ClaimsFile, path: Path) -> None:
    """Operators, sources, run names and log statistics, before anything runs."""
    ids = [c.id for c in cf.claims]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise SpecError(f"{path}: duplicate claim id {dup[0]}")
    for name, run in cf.runs.items():
        if run.against is not None and run.against not in cf.runs:
            raise SpecError(f"{path}: run {name}: against {run.against!r} is not a run name "
                            f"(runs: {', '.join(cf.runs)})")
        if isinstance(run.at_s_min_G, str):
            try:
                source = run.at_source()
            except ValueError as exc:
                raise SpecError(f"{path}: run {name}: at_s_min_G: {exc}") from None
            if source == name or (source not in cf.runs and source != "note"):
                raise SpecError(f"{path}: run {name}: at_s_min_G {run.at_s_min_G!r}: its "
                                f"source is the note or another run (runs: "
                                f"{', '.join(cf.runs)})")
    _ordered(cf, list(cf.runs), path)  # no cycle through against and at_s_min_G
    sources = ", ".join([*cf.runs, *FIXED_SOURCES])
    for claim in cf.claims:
        for k, chk in enumerate(claim.checks, 1):
            where = f"{path}: claim {claim.id}: check {k}"
            if chk.op not in OPERATORS:
                raise SpecError(f"{where}: unknown operator {chk.op!r} "
                                f"(one of {', '.join(OPERATORS)})")
            if (chk.op == "close") != (chk.rel_tol is not None):
                raise SpecError(f"{where}: rel_tol goes with operator close, and close needs "
                                f"it")
            for metric in filter(None, (chk.metric, chk.threshold_metric)):
                try:
                    source, mpath = split_metric(metric)
                except ValueError as exc:
                    raise SpecError(f"{where}: {exc}") from None
                if source not in cf.runs and source not in FIXED_SOURCES:
                    raise SpecError(f"{where}: unknown metric path {metric!r}: no source "
                                    f"{source!r} (one of {sources})")
                imported = source in cf.runs and cf.runs[source].imported is not None
                if imported and mpath.split(".")[0] in ("log", "spec"):
                    raise SpecError(f"{where}: metric {metric!r}: {source} is an imported log: "
                                    f"it has no spec but its robot and step, and no "
                                    f"controller's columns; read its analysis record")
                if imported:
                    _check_record_path(metric, mpath, "imported", where)
                elif source in cf.runs and mpath.startswith("log."):
                    _check_log_path(metric, mpath, where)
                elif source in cf.runs and not mpath.startswith("spec."):
                    _check_record_path(metric, mpath, cf.runs[source].expect, where)
                if source == "note":
                    _check_note_path(cf, path, metric, mpath, where)
                if source == "sweep" and mpath.split(".")[0] not in cf.sweeps:
                    raise SpecError(f"{where}: unknown metric path {metric!r}: no sweep "
                                    f"{mpath.split('.')[0]!r} (sweeps: "
                                    f"{', '.join(cf.sweeps) or 'none'})")
                for kind in ("montecarlo", "power"):
                    refs = getattr(cf, kind)
                    if source == kind and mpath.split(".")[0] not in refs:
                        raise SpecError(f"{where}: unknown metric path {metric!r}: no {kind} "
                                        f"{mpath.split('.')[0]!r} ({kind}: "
                                        f"{', '.join(refs) or 'none'})")


def note_path(cf: ClaimsFile, claims_path: Path | str) -> Path:
    """The note file of a claims file, resolved against the claims file's folder."""
    p = Path(cf.note or "")
    return p if p.is_absolute() else Path(claims_path).resolve().parent / p


def _check_note_path(cf: ClaimsFile, path: Path, metric: str, mpath: str, where: str) -> None:
    from pipeline.claims.seed_note import load_note

    if cf.note is None:
        raise SpecError(f"{where}: metric {metric!r} needs a `note:` file in the claims file")
    key, _, column = mpath.partition(".")
    load_note(note_path(cf, path)).value(key, column)


def _check_log_path(metric: str, mpath: str, where: str) -> None:
    parts = mpath.split(".")
    if len(parts) != 3 or parts[1] not in LOG_GROUPS or parts[2] not in LOG_STATS:
        raise SpecError(f"{where}: unknown metric path {metric!r}: log statistics are "
                        f"log.GROUP.STAT with GROUP in {', '.join(LOG_GROUPS)} and STAT in "
                        f"{', '.join(LOG_STATS)}")


def _check_record_path(metric: str, mpath: str, expect: str, where: str) -> None:
    """A path into a run's analysis record names a field of the record of its kind (a
    diverged run's, an imported log's, else a complete run's: pipeline/analysis/schema.py)."""
    from pipeline.analysis.schema import (
        CompleteRecord,
        DivergedRecord,
        ImportedRecord,
        field_type,
    )

    kind = {"diverged": DivergedRecord, "imported": ImportedRecord}.get(expect, CompleteRecord)
    try:
        field_type(mpath, kind)
    except KeyError as exc:
        raise SpecError(f"{where}: unknown metric path {metric!r}: no field {exc.args[0]!r} "
                        f"there in the analysis record of a {expect} run") from None


def _metrics(cf: ClaimsFile) -> list[tuple[str, str]]:
    """Every metric of every check, threshold metrics included, as (SOURCE, PATH)."""
    return [split_metric(m) for claim in cf.claims for chk in claim.checks
            for m in (chk.metric, chk.threshold_metric) if m]


def needed_sweeps(cf: ClaimsFile) -> list[str]:
    """The names under ``sweeps:`` the claims use, in order of first use."""
    return list(dict.fromkeys(path.partition(".")[0] for source, path in _metrics(cf)
                              if source == "sweep"))


def needed_montecarlos(cf: ClaimsFile, kind: str = "montecarlo") -> list[str]:
    """The names under ``montecarlo:`` (or ``power:``) the claims use, in order of first use."""
    return list(dict.fromkeys(path.partition(".")[0] for source, path in _metrics(cf)
                              if source == kind))


def _depends(cf: ClaimsFile, name: str) -> list[str]:
    """The runs a run's analysis needs first: the one it is compared against, the one whose
    record gives its at_s_min_G."""
    run = cf.runs[name]
    return [d for d in (run.against, run.at_source()) if d is not None and d in cf.runs]


def _ordered(cf: ClaimsFile, names: list[str], path: Path | str = "") -> list[str]:
    """``names`` with every run's dependencies (:func:`_depends`) added and placed before it;
    SpecError on a cycle."""
    out: list[str] = []
    state: dict[str, int] = {}  # 1: being placed, 2: placed

    def place(n: str, trail: tuple[str, ...]) -> None:
        if state.get(n) == 2:
            return
        if state.get(n) == 1:
            raise SpecError(f"{path or cf.source}: runs {' -> '.join((*trail, n))}: a cycle "
                            f"through against and at_s_min_G")
        state[n] = 1
        for d in _depends(cf, n):
            place(d, (*trail, n))
        state[n] = 2
        out.append(n)

    for n in names:
        place(n, ())
    return out


def needed_runs(cf: ClaimsFile) -> list[str]:
    """Run names the claims use, with the runs they need first (compared against, or read
    for at_s_min_G), dependencies first."""
    return _ordered(cf, list(dict.fromkeys(source for source, _ in _metrics(cf)
                                           if source in cf.runs)))


def register_sources(cf: ClaimsFile) -> dict[str, str]:
    """What an evaluation of ``cf`` is made from, each by hash: the register's content
    (``extends`` merged), its note file, and each run's and sweep's spec (its content, as the
    evaluation finds it on the search path, ``extends`` merged) with its robot file. With the
    bytes of every artefact the evaluation read and wrote, this is the claims' key
    (:func:`pipeline.store.validity.current_claims`)."""
    import hashlib

    from pipeline.analysis.imported import controller_key
    from pipeline.provenance.keys import file_digest
    from pipeline.spec import load_spec

    here = Path(cf.source).resolve().parent
    out = {"register": hashlib.sha256(cf.model_dump_json().encode()).hexdigest()}
    if cf.note is not None:
        note = note_path(cf, cf.source)
        if not note.is_file():
            raise SpecError(f"{cf.source}: field note: {note}: file not found")
        out["note"] = file_digest(note)
    for kind, refs in (("run", cf.runs), ("sweep", cf.sweeps)):
        for name, ref in refs.items():
            if getattr(ref, "imported", None) is not None:  # the log itself is a file read
                ctrl = (controller_key(load_spec(ref.controller, here)) if ref.controller
                        else None)
                out[f"{kind} {name}"] = f"imported {ref.imported}, controller {ctrl}"
                continue
            spec = load_spec(ref.spec, here)
            out[f"{kind} {name}"] = f"spec {spec.spec_hash}, robot {file_digest(spec.robot_path)}"
    for name, ref in cf.montecarlo.items():
        from pipeline.montecarlo.plan import montecarlo_key

        out[f"montecarlo {name}"] = montecarlo_key(montecarlo_path(cf, ref), ref.samples)
    for name, ref in cf.power.items():
        from pipeline.montecarlo.power import power_file_key

        out[f"power {name}"] = power_file_key(montecarlo_path(cf, ref))
    return out


def study_sources(cf: ClaimsFile, out: Path) -> dict[str, str]:
    """The studies' results under report folder ``out`` as they stand, by hash ("none"
    where there is none): a result made since the last evaluation (`make studies`) makes
    the claims evaluate again, for their key (:func:`pipeline.store.validity.claims_key`)."""
    from pipeline.montecarlo.studies import FOLDERS, result_files
    from pipeline.provenance.keys import file_digest

    out_ = {}
    for kind in FOLDERS:
        for name, ref in getattr(cf, kind).items():
            result = result_files(kind, Path(ref.file).stem, out)[1]
            out_[f"{kind} {name} result"] = file_digest(result) if result.is_file() else "none"
    return out_


def montecarlo_path(cf: ClaimsFile, ref: MonteCarloRef) -> Path:
    """A Monte Carlo file of the claims: beside the claims file, else under
    specs/montecarlo/."""
    from pipeline.montecarlo.plan import resolve_montecarlo

    beside = Path(cf.source).resolve().parent / ref.file
    return beside if beside.is_file() else resolve_montecarlo(ref.file)
