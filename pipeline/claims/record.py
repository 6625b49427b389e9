"""``claims.json``: the evaluated register as the claims stage leaves it. Written once per
evaluation; read back for the summary lines, the counts and the exit code (the same whether
the register was evaluated now or is reused, ``pipeline.store.validity.current_claims``)
and by the reports."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipeline.artefact_paths import CLAIMS_FILE
from pipeline.atomic_files import atomic_write_text
from pipeline.claims.register import CLAIMS_SCHEMA, OPERATORS, Claim, ClaimCheck, ClaimsFile
from pipeline.errors import LogError
from pipeline.paths import display_path

STATUSES = ("PASS", "FAIL", "OPEN", "NOW HOLDS", "DEFERRED")
RECORD_NAME = CLAIMS_FILE


@dataclass
class CheckEval:
    check: ClaimCheck
    value: Any
    threshold: Any
    ok: bool

    @property
    def symbol(self) -> str:
        return OPERATORS[self.check.op][1]


@dataclass
class ClaimEval:
    claim: Claim
    checks: list[CheckEval]
    provenance: list[dict] = field(default_factory=list)
    # Why it cannot be judged yet: a study it reads has no current result of its file's N
    # (pipeline.montecarlo.studies); "" when it can.
    deferred: str = ""

    @property
    def holds(self) -> bool:
        return all(c.ok for c in self.checks)

    @property
    def status(self) -> str:
        if self.deferred:
            return "DEFERRED"
        if self.claim.expect == "hold":
            return "PASS" if self.holds else "FAIL"
        return "NOW HOLDS" if self.holds else "OPEN"


def _jsonable(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


def write_claims_json(results: list[ClaimEval], cf: ClaimsFile, out_dir: Path,
                      version: str) -> Path:
    """``out_dir/claims.json``: each claim's status, checks (value, threshold) and provenance;
    NaN and infinities as strings."""
    path = Path(out_dir) / RECORD_NAME
    data = {"schema": CLAIMS_SCHEMA, "claims_file": display_path(cf.source),
            "source_version": version,
            "claims": [{"id": r.claim.id, "statement": r.claim.statement,
                        "kind": r.claim.kind, "expect": r.claim.expect, "status": r.status,
                        "reason": r.claim.reason, "deferred": r.deferred,
                        "checks": [{"metric": c.check.metric, "op": c.check.op,
                                    "rel_tol": c.check.rel_tol,
                                    "value": _jsonable(c.value),
                                    "threshold": _jsonable(c.threshold),
                                    "threshold_metric": c.check.threshold_metric,
                                    "ok": c.ok}
                                   for c in r.checks],
                        "provenance": r.provenance} for r in results]}
    atomic_write_text(path, json.dumps(data, indent=1, default=str))
    return path


def read_claims_json(path: Path) -> dict | None:
    """The claims register's ``claims.json``, None if there is none; LogError if it is
    damaged or of a schema this code does not read."""
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise LogError(f"{path}: not a readable claims record ({exc})") from None
    if not isinstance(data, dict) or data.get("schema") != CLAIMS_SCHEMA:
        got = data.get("schema") if isinstance(data, dict) else None
        raise LogError(f"{path}: key schema: {got!r} is not a version this code reads "
                       f"({CLAIMS_SCHEMA})")
    if not isinstance(data.get("claims"), list):
        raise LogError(f"{path}: key claims missing")
    return data


def status_counts(data: dict) -> str:
    """``28 PASS, 1 OPEN``: how many claims of each status there are (none: ``no claims``)."""
    counts = [(sum(c["status"] == s for c in data["claims"]), s) for s in STATUSES]
    return ", ".join(f"{n} {s}" for n, s in counts if n) or "no claims"


# How the summaries name each kind of claim (pipeline/claims/register.py's CLAIM_KINDS).
KIND_NAMES = {"physics": "physics findings", "note": "note rows", "identity": "input identities",
              "software": "software checks", None: "unclassified"}
# What each kind is, as the register's sections say it.
KIND_INTROS = {
    "physics": "What the measurements show about the loop: the argument of the reports. Each is "
               "measured on the runs' logs and can fail.",
    "note": "The seed note's published rows, each against our measurement of the same "
            "quantity (the evidence table below lays them side by side).",
    "identity": "These restate an input rather than find anything: μ_bus = D_b/I_zz,bus "
                "(the spec's bus damping gain over the robot file's bus inertia about the "
                "shoulder-pan axis) and what follows from it at the given dt. They are shown "
                "once, here, as the inputs they are, and guard that the inputs are the note's.",
    "software": "The inputs, the code and the artefacts: the cross-check of equations and "
                "code, the baselines' reproducibility, the logs' provenance.",
    None: "Claims without a kind.",
}


def kind_counts(data: dict) -> str:
    """``physics findings 14 (14 PASS); note rows 6 (4 PASS, 2 OPEN); …``: the claims of each
    kind and their statuses, physics first (claims.yaml's header says what the kinds are)."""
    parts = []
    for kind, name in KIND_NAMES.items():
        of_kind = [c for c in data["claims"] if c.get("kind") == kind]
        if of_kind:
            parts.append(f"{name} {len(of_kind)} ({status_counts({'claims': of_kind})})")
    return "; ".join(parts)


def exit_code(data: dict) -> int:
    """1 if a hold claim fails or an open claim now holds, else 0."""
    return int(any(c["status"] in ("FAIL", "NOW HOLDS") for c in data["claims"]))


def summary_lines(data: dict) -> list[str]:
    """One line per claim: its status and each check's value against its threshold (a
    deferred claim: why, and what its study's N can show)."""
    return [f"{c['id']:>4} {c['status']:<9} " + c["deferred"] if c.get("deferred") else
            f"{c['id']:>4} {c['status']:<9} " + "; ".join(
        f"{k['metric']} = {_short(k['value'])} ({OPERATORS[k['op']][1]} {_short(k['threshold'])})"
        for k in c["checks"]) for c in data["claims"]]


def failure_lines(data: dict) -> list[str]:
    """What to do about each failing claim (FAIL) and each open one that now holds."""
    return [f"claim {c['id']} fails: {c['statement']}" if c["status"] == "FAIL" else
            f"claim {c['id']} now holds: promote it to expect: hold ({c['statement']})"
            for c in data["claims"] if c["status"] in ("FAIL", "NOW HOLDS")]


def _short(x: Any) -> str:
    if isinstance(x, float):
        return f"{x:.4g}"
    s = json.dumps(x, default=str) if isinstance(x, (dict, list)) else str(x)
    return s if len(s) <= 60 else s[:57] + "..."
