"""Pinned baseline logs: ``python -m pipeline.claims.baselines {check,repin}``.

The baselines are the specs ``pipeline/specs/baseline_*.yaml`` (short missions), pinned as
``logs/baselines/<name>/run.parquet``. ``check`` re-runs each into a temporary folder and
compares every logged column of the new log with the pinned one, array against array (the
metadata differs by design: it holds the code version). Bitwise determinism gives
max_abs_diff = 0.000e+00. The result is written to ``generated_reports/baselines.json`` (the
claims use it) and ``baselines.md``. ``repin`` re-runs them, says what changed, and replaces
the pinned logs.
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

from pipeline.errors import CheckFailed, PipelineError
from pipeline.logs import LogError, atomic_write_bytes, atomic_write_text, read_meta
from pipeline.paths import SHIPPED_SPECS, display_path
from pipeline.provenance.keys import file_digest, sim_version
from pipeline.provenance.validity import current_baselines
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec

# Relative to the working directory, like every output: make runs from the checkout's root.
PINNED = Path("logs") / "baselines"
REPORTS = Path("generated_reports")


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
    """max |fresh − pinned| over every column (booleans as 0/1), the worst column, and notes."""
    a, b = _arrays(pinned), _arrays(fresh)
    notes = []
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
        if d > worst:
            worst, worst_col = d, name
    if notes and worst == 0.0:
        worst = float("inf")
    return {"max_abs_diff": worst, "worst_column": worst_col, "notes": notes}


def _run_fresh(name: str, tmp: Path) -> tuple[Path, str]:
    spec = load_spec(name)
    out = run_spec(spec, tmp, raise_on_failure=False)
    return out.path, spec.spec_hash


def check(out_dir: Path = REPORTS, pinned_dir: Path | None = None) -> dict:
    """Re-run every baseline and compare with its pinned log; write baselines.{json,md}."""
    from tqdm import tqdm

    from pipeline.progress import interactive

    pinned_dir = PINNED if pinned_dir is None else pinned_dir
    results = {}
    with tempfile.TemporaryDirectory(prefix="baselines-") as tmp:
        for name in tqdm(baseline_names(), disable=not interactive(), unit="log",
                         desc="baselines", file=sys.stderr, leave=False):
            fresh, spec_hash = _run_fresh(name, Path(tmp))
            pinned = Path(pinned_dir) / name / "run.parquet"
            entry = {"pinned": display_path(pinned), "spec_hash": spec_hash}
            if not pinned.is_file():
                entry |= {"max_abs_diff": float("inf"), "worst_column": "",
                          "notes": ["not pinned yet: run make repin"]}
            else:
                meta = read_meta(pinned)
                entry |= compare_logs(pinned, fresh)
                entry |= {"pinned_sha256": file_digest(pinned),
                          "pinned_sim_version": meta.sim_version,
                          "pinned_spec_hash": meta.spec_hash}
                if meta.spec_hash != spec_hash:
                    entry["notes"].append("the spec changed since pinning")
            results[name] = entry
    diffs = [r["max_abs_diff"] for r in results.values()]
    report = {"sim_version": sim_version(), "count": len(results),
              "max_abs_diff": max(diffs) if diffs else float("inf"),
              "all_zero": bool(diffs) and all(d == 0.0 for d in diffs), "baselines": results}
    write_report(report, Path(out_dir))
    return report


def write_report(report: dict, out_dir: Path) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "baselines.json",
                      json.dumps(report, indent=1, default=str, allow_nan=True) + "\n")
    lines = ["# Baselines", "",
             f"Pinned logs re-run by simulator version {report['sim_version']}; every logged "
             "column compared array against array. Bitwise determinism gives 0.000e+00.", "",
             "| Baseline | max_abs_diff | Worst column | Pinned log | Notes |",
             "|---|---|---|---|---|"]
    for name, r in report["baselines"].items():
        lines.append(f"| {name} | {r['max_abs_diff']:.3e} | {r.get('worst_column') or '–'} | "
                     f"`{r['pinned']}` | {'; '.join(r.get('notes', [])) or '–'} |")
    atomic_write_text(out_dir / "baselines.md", "\n".join(lines) + "\n")


def ensure_report(out_dir: Path, pinned_dir: Path | None = None) -> dict:
    """baselines.json of this code version and these pinned files, re-checked if stale."""
    pinned_dir = PINNED if pinned_dir is None else pinned_dir
    old = current_baselines(Path(out_dir) / "baselines.json", baseline_names(), pinned_dir)
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
            pinned = Path(pinned_dir) / name / "run.parquet"
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
    p.add_argument("action", choices=("check", "repin"))
    p.add_argument("--out", default=str(REPORTS), help="where baselines.json goes (check)")
    a = p.parse_args(argv)
    try:
        if a.action == "repin":
            for line in repin():
                print(line)
            print(f"re-pinned {len(baseline_names())} baselines under {display_path(PINNED)}; "
                  "commit logs/baselines/ with the change that moved them")
            return 0
        report = check(Path(a.out))
        for name, r in report["baselines"].items():
            notes = f"  ({'; '.join(r['notes'])})" if r.get("notes") else ""
            print(f"{name:<20} max_abs_diff {r['max_abs_diff']:.3e}{notes}")
        print(f"-> {display_path(Path(a.out) / 'baselines.json')}")
        if not report["all_zero"]:
            bad = [n for n, r in report["baselines"].items() if r["max_abs_diff"] != 0.0]
            raise CheckFailed(f"baselines differ from their pinned logs: {', '.join(bad)}")
        return 0
    except PipelineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())
