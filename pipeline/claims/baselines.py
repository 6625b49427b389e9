"""Pinned baseline logs: ``python -m pipeline.claims.baselines {check,repin,tolerances}``.

The baselines are the specs ``specs/baseline_*.yaml`` (short missions), pinned as
``logs/baselines/<name>/run.parquet``. ``check`` re-runs each into a temporary folder and
compares every logged column of the new log with the pinned one, array against array (the
metadata differs by design: it holds the code version), under the reproducibility contract
(docs/reproducibility.md): when the pin was made on this platform (the same
:meth:`pipeline.platform.Platform.key`), bitwise, max_abs_diff = 0.000e+00; when it was made on
another platform, or on one it does not record, every column within its measured tolerance of
``logs/baselines/tolerances.json`` (:mod:`pipeline.claims.tolerances`). Either way NaN, a
missing or extra column and a changed shape fail. The result is written to
``generated_reports/baselines.json`` (the claims use it) and ``baselines.md``, each baseline
with the comparison made and why. ``repin`` re-runs them, says what changed, and replaces the
pinned logs; ``tolerances`` measures the tolerances file again.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.artefact_paths import log_path
from pipeline.atomic_files import atomic_write_bytes, atomic_write_text
from pipeline.claims.tolerances import load_tolerances, measure, write_tolerances
from pipeline.errors import CheckFailed, PipelineError
from pipeline.logs import LogError, read_meta
from pipeline.paths import SHIPPED_SPECS, display_path
from pipeline.platform import Platform, describe, differences, fingerprint
from pipeline.provenance.keys import file_digest, sim_version
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec
from pipeline.store.validity import current_baselines

# Relative to the working directory, like every output: make runs from the checkout's root.
PINNED = Path("logs") / "baselines"
REPORTS = Path("generated_reports")
TOLERANCES = "tolerances.json"  # beside the pinned logs


def baseline_names() -> list[str]:
    return sorted(p.stem for p in SHIPPED_SPECS.glob("baseline_*.yaml"))


def _arrays(path: Path) -> dict[str, np.ndarray]:
    table = pq.read_table(path)
    out = {}
    for name in table.column_names:
        col = table.column(name).combine_chunks()
        if pa.types.is_fixed_size_list(col.type):
            out[name] = col.flatten().to_numpy(zero_copy_only=False).reshape(
                len(col), col.type.list_size)
        else:
            out[name] = col.to_numpy(zero_copy_only=False)
    return out


def compare_logs(pinned: Path, fresh: Path) -> dict:
    """max |fresh − pinned| over every column (booleans as 0/1), the worst column, each
    column's, and notes (columns, shapes, NaN: each a failure, max_abs_diff then inf)."""
    return compare_columns(_arrays(pinned), _arrays(fresh))


def compare_columns(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> dict:
    """:func:`compare_logs` of two logs' columns, pinned ``a`` and fresh ``b``."""
    notes, columns = [], {}
    if set(a) != set(b):
        notes.append(f"columns differ: only pinned {sorted(set(a) - set(b))}, only new "
                     f"{sorted(set(b) - set(a))}")
    worst, worst_col = 0.0, ""
    for name in sorted(set(a) & set(b)):
        x, y = a[name].astype(float), b[name].astype(float)
        if x.shape != y.shape:
            notes.append(f"{name}: shape {x.shape} pinned vs {y.shape} new")
            worst, worst_col = float("inf"), name
            continue
        # NaN is a failure, never "no difference": not even a NaN pinned against a NaN.
        nan = np.isnan(x) | np.isnan(y)
        if nan.any():
            row = int(np.flatnonzero(nan.reshape(len(x), -1).any(axis=1))[0])
            notes.append(f"{name}: NaN at row {row}")
            worst, worst_col = float("inf"), name
            continue
        d = float(np.max(np.abs(x - y), initial=0.0))
        columns[name] = d
        if d > worst:
            worst, worst_col = d, name
    if notes and worst == 0.0:
        worst = float("inf")
    return {"max_abs_diff": worst, "worst_column": worst_col, "notes": notes,
            "columns": columns}


def judge(cmp: dict, pinned_platform: dict | None, here: Platform,
          tolerances: dict[str, float] | None) -> dict:
    """The contract's verdict on one comparison (:func:`compare_logs`): which comparison was
    made and why, whether it holds, and the columns over their tolerance.

    Pinned on this platform (equal keys): bitwise, every column's difference 0. Pinned on
    another platform or an unknown one: every column within ``tolerances`` (column → largest
    |difference| allowed; None: none measured for this baseline, which fails). Notes of the
    comparison (NaN, columns, shapes) fail either way.
    """
    try:
        pinned = None if pinned_platform is None else Platform.from_dict(pinned_platform)
    except (KeyError, TypeError):
        pinned = None
    if pinned is not None and pinned.key() == here.key():
        return {"comparison": "bitwise",
                "why": f"bitwise: same platform ({here.summary()}; key {here.key()})",
                "holds": not cmp["notes"] and cmp["max_abs_diff"] == 0.0, "exceeding": []}
    differ = (f"; differs in {', '.join(differences(pinned, here))}" if pinned is not None
              else "")
    # Equal bits on another platform are the contract's best case, and worth saying: the
    # simulator's own kernels are meant to give exactly that (docs/reproducibility.md).
    bitwise = " (bitwise all the same)" if not cmp["notes"] and cmp["max_abs_diff"] == 0.0 else ""
    why = (f"within tolerance{bitwise}: pinned on {describe(pinned_platform)}, here "
           f"{here.summary()}{differ}")
    if tolerances is None:
        return {"comparison": "tolerance", "why": why, "holds": False, "exceeding": [],
                "worst_ratio": float("inf"),
                "missing": "no measured tolerances for this baseline (make tolerances)"}
    exceeding, worst_ratio = [], 0.0
    for column, d in sorted(cmp["columns"].items()):
        tol = tolerances.get(column)
        if tol is None or d > tol:
            exceeding.append({"column": column, "diff": d, "tolerance": tol})
        if tol is None or (tol == 0.0 and d > 0.0):
            worst_ratio = float("inf")
        elif tol > 0.0:
            worst_ratio = max(worst_ratio, d / tol)
    return {"comparison": "tolerance", "why": why,
            "holds": not cmp["notes"] and not exceeding, "exceeding": exceeding,
            "worst_ratio": worst_ratio}


def _run_fresh(name: str, tmp: Path) -> tuple[Path, str]:
    spec = load_spec(name)
    out = run_spec(spec, tmp, raise_on_failure=False)
    return out.path, spec.spec_hash


def check(out_dir: Path = REPORTS, pinned_dir: Path | None = None) -> dict:
    """Re-run every baseline and compare with its pinned log; write baselines.{json,md}."""
    from tqdm import tqdm

    from pipeline.progress import interactive

    pinned_dir = PINNED if pinned_dir is None else pinned_dir
    tolerances_file = Path(pinned_dir) / TOLERANCES
    tolerances = load_tolerances(tolerances_file)
    here = fingerprint()
    results = {}
    with tempfile.TemporaryDirectory(prefix="baselines-") as tmp:
        for name in tqdm(baseline_names(), disable=not interactive(), unit="log",
                         desc="baselines", file=sys.stderr, leave=False):
            fresh, spec_hash = _run_fresh(name, Path(tmp))
            pinned = log_path(pinned_dir, name)
            entry = {"pinned": display_path(pinned), "spec_hash": spec_hash}
            if not pinned.is_file():
                entry |= {"max_abs_diff": float("inf"), "worst_column": "",
                          "notes": ["not pinned yet: run make repin"], "holds": False,
                          "comparison": "none", "why": "not pinned"}
            else:
                meta = read_meta(pinned)
                entry |= compare_logs(pinned, fresh)
                table = None if tolerances is None else tolerances["table"].get(name)
                entry |= judge(entry, meta.platform, here, table)
                entry |= {"pinned_sha256": file_digest(pinned),
                          "pinned_sim_version": meta.sim_version,
                          "pinned_spec_hash": meta.spec_hash,
                          "pinned_platform": meta.platform}
                if meta.spec_hash != spec_hash:
                    entry["notes"].append("the spec changed since pinning")
                if entry["comparison"] == "tolerance" and tolerances is not None:
                    entry["notes"] += _stale_tolerances(tolerances, name, spec_hash)
                if "missing" in entry:
                    entry["notes"].append(entry.pop("missing"))
            results[name] = entry
    diffs = [r["max_abs_diff"] for r in results.values()]
    failures = [n for n, r in results.items() if not r["holds"]]
    report = {"sim_version": sim_version(), "count": len(results),
              "max_abs_diff": max(diffs) if diffs else float("inf"),
              "all_zero": bool(diffs) and all(d == 0.0 for d in diffs),
              "failures": len(failures) if results else 1, "failed": failures,
              "all_hold": bool(results) and not failures,
              "platform_key": here.key(), "platform_summary": here.summary(),
              "platform": here.to_dict(), "tolerances_file": display_path(tolerances_file),
              "tolerances_sha256": (file_digest(tolerances_file) if tolerances_file.is_file()
                                    else None),
              "baselines": results}
    write_report(report, Path(out_dir))
    return report


def _stale_tolerances(tolerances: dict, name: str, spec_hash: str) -> list[str]:
    """Notes (not failures) when the tolerances were measured on other code or spec."""
    notes = []
    if tolerances["spec_hashes"].get(name) not in (None, spec_hash):
        notes.append("the spec changed since the tolerances were measured (make tolerances)")
    if tolerances["sim_version"] not in (None, sim_version()):
        notes.append(f"tolerances measured with simulator version "
                     f"{tolerances['sim_version']}, this is {sim_version()} (make tolerances)")
    return notes


def write_report(report: dict, out_dir: Path) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "baselines.json",
                      json.dumps(report, indent=1, default=str, allow_nan=True) + "\n")
    lines = ["# Baselines", "",
             f"Pinned logs re-run by simulator version {report['sim_version']} on "
             f"{report['platform_summary']} (platform key {report['platform_key']}); every "
             "logged column compared array against array under the reproducibility contract "
             "(docs/reproducibility.md): bitwise (0.000e+00) when the pin was made on this "
             "platform, else each column within its measured tolerance of "
             f"`{report['tolerances_file']}`. {report['count'] - report['failures']} of "
             f"{report['count']} hold.", "",
             "| Baseline | Holds | max_abs_diff | Worst column | Comparison | Pinned log | Notes |",
             "|---|---|---|---|---|---|---|"]
    for name, r in report["baselines"].items():
        over = [f"{e['column']} {e['diff']:.3e} > {e['tolerance']}" for e in r.get("exceeding", [])]
        lines.append(f"| {name} | {'yes' if r.get('holds') else '**no**'} | "
                     f"{r['max_abs_diff']:.3e} | {r.get('worst_column') or '–'} | "
                     f"{r.get('why', '–')} | `{r['pinned']}` | "
                     f"{'; '.join([*r.get('notes', []), *over]) or '–'} |")
    atomic_write_text(out_dir / "baselines.md", "\n".join(lines) + "\n")


def ensure_report(out_dir: Path, pinned_dir: Path | None = None) -> dict:
    """baselines.json of this code version and these pinned files, re-checked if stale."""
    pinned_dir = PINNED if pinned_dir is None else pinned_dir
    old = current_baselines(Path(out_dir) / "baselines.json", baseline_names(), pinned_dir,
                            Path(pinned_dir) / TOLERANCES)
    if old is not None:
        return old
    from pipeline.progress import stage

    with stage("baselines", f"({len(baseline_names())} pinned logs re-run)"):
        return check(out_dir, pinned_dir)


def repin(pinned_dir: Path | None = None) -> list[str]:
    """Re-run and replace every pinned baseline; return what changed, one line each."""
    pinned_dir = PINNED if pinned_dir is None else pinned_dir
    changes = []
    names = baseline_names()
    with tempfile.TemporaryDirectory(prefix="baselines-") as tmp:
        for name in names:
            fresh, spec_hash = _run_fresh(name, Path(tmp))
            pinned = log_path(pinned_dir, name)
            if not pinned.is_file():
                changes.append(f"{name}: newly pinned")
            else:
                try:
                    meta = read_meta(pinned)
                    cmp = compare_logs(pinned, fresh)
                    what = [f"max_abs_diff {cmp['max_abs_diff']:.3e}"
                            + (f" (worst column {cmp['worst_column']})"
                               if cmp["max_abs_diff"] else ""), *cmp["notes"]]
                    if meta.spec_hash != spec_hash:
                        what.append("spec changed")
                    if meta.sim_version != sim_version():
                        what.append(f"simulator version {meta.sim_version} -> {sim_version()}")
                except LogError as exc:
                    what = [f"old pin unreadable ({exc})"]
                changes.append(f"{name}: " + ", ".join(what))
            atomic_write_bytes(pinned, fresh.read_bytes())
    for old in sorted(Path(pinned_dir).glob("*/run.parquet")):
        if old.parent.name not in names:
            shutil.rmtree(old.parent)
            changes.append(f"{old.parent.name}: removed (no spec {old.parent.name}.yaml)")
    return changes


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m pipeline.claims.baselines",
                                description="check or re-pin the baseline logs")
    p.add_argument("action", choices=("check", "repin", "tolerances"))
    p.add_argument("--out", default=str(REPORTS), help="where baselines.json goes (check)")
    a = p.parse_args(argv)
    try:
        if a.action == "repin":
            for line in repin():
                print(line)
            print(f"re-pinned {len(baseline_names())} baselines under {display_path(PINNED)}; "
                  "commit logs/baselines/ with the change that moved them, after "
                  "measuring their tolerances again (make tolerances)")
            return 0
        if a.action == "tolerances":
            path = PINNED / TOLERANCES
            write_tolerances(measure(baseline_names(), lambda line: print(line, flush=True)),
                             path)
            print(f"-> {display_path(path)}")
            return 0
        report = check(Path(a.out))
        for name, r in report["baselines"].items():
            notes = f"  ({'; '.join(r['notes'])})" if r.get("notes") else ""
            verdict = "holds" if r["holds"] else "FAILS"
            print(f"{name:<20} max_abs_diff {r['max_abs_diff']:.3e}  {verdict}, "
                  f"{r['why']}{notes}")
        print(f"-> {display_path(Path(a.out) / 'baselines.json')}")
        if not report["all_hold"]:
            raise CheckFailed(f"baselines differ from their pinned logs beyond the "
                              f"contract: {', '.join(report['failed'])}")
        return 0
    except PipelineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())
