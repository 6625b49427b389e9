"""Command line: ``python -m pipeline {run,analyze,report,claims,sweep,bench}``.

Exit codes: 0 success; 1 a check, claim or run failed; 2 bad input (one line, no traceback).
This is the one place where the pipeline's error kinds become exit codes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.errors import PipelineError, RunFailed


def _cmd_run(a: argparse.Namespace) -> int:
    from pipeline.paths import display_path
    from pipeline.provenance.validity import current_log
    from pipeline.sim.run import log_path, run_spec
    from pipeline.spec import load_spec

    specs = [load_spec(s) for s in a.spec]  # every spec checked before anything runs
    for spec in specs:
        path = log_path(spec, Path(a.out))
        meta = None if a.force else current_log(path, spec)
        if meta is not None:
            print(f"{spec.name}: up to date ({meta.status}, same spec, robot and simulator) "
                  f"-> {display_path(path)}")
            if meta.status != "complete":  # the same outcome as running it again
                raise RunFailed(f"{spec.name}: run {meta.status} at {meta.error}; log marked "
                                f"{meta.status}: {display_path(path)}")
            continue
        out = run_spec(spec, a.out, progress=sys.stderr.isatty())
        for w in out.warnings:
            print(f"warning: {w}", file=sys.stderr)
        print(f"{spec.name}: {out.n_steps} steps, {out.status} -> {display_path(out.path)}")
    return 0


def _cmd_analyze(a: argparse.Namespace) -> int:
    from pipeline.analysis.cli import analyze_command
    from pipeline.logs import verify_log
    from pipeline.paths import display_path
    from pipeline.provenance.validity import current_analysis

    if a.window_start is None and not a.force:
        log = verify_log(a.log)
        other = verify_log(a.against) if a.against else None
        path = Path(a.out) / log.spec.name / "analysis.json"
        if current_analysis(path, log.path, log.meta,
                            None if other is None else (other.path, other.meta)):
            print(f"{log.spec.name}: up to date (same log and analysis code) -> "
                  f"{display_path(path)}")
            return 0
    return analyze_command(Path(a.log), Path(a.against) if a.against else None, Path(a.out),
                           a.window_start)


def _cmd_report(a: argparse.Namespace) -> int:
    from pipeline.reports.render import render_all

    render_all(Path(a.out), force=a.force)
    return 0


def _cmd_claims(a: argparse.Namespace) -> int:
    from pipeline.claims.evaluate import run_claims, summary_lines
    from pipeline.paths import display_path
    from pipeline.reports.claims_page import render_claims

    outcome = run_claims(a.claims, Path(a.out))
    page = render_claims(outcome, Path(a.out))
    for line in summary_lines(outcome):
        print(line)
    for r in outcome.results:
        if r.status == "FAIL":
            print(f"claim {r.claim.id} fails: {r.claim.statement}", file=sys.stderr)
        elif r.status == "NOW HOLDS":
            print(f"claim {r.claim.id} now holds: promote it to expect: hold "
                  f"({r.claim.statement})", file=sys.stderr)
    print(f"-> {display_path(page)}")
    return outcome.exit_code


def _cmd_sweep(a: argparse.Namespace) -> int:
    from pipeline.sweep import sweep_command

    return sweep_command(a)


def _cmd_bench(a: argparse.Namespace) -> int:
    from pipeline.bench import bench_command

    return bench_command(a)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pipeline", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="simulate a mission spec into DIR/<name>/run.parquet")
    r.add_argument("spec", nargs="+",
                   help="spec names (on the spec search path: beside, BREVE_SPEC_PATH, the "
                        "shipped specs) or paths to .yaml files")
    r.add_argument("--out", default="logs", help="log folder (default: logs)")
    r.add_argument("--force", action="store_true",
                   help="run even when the log is current (same spec, robot and simulator)")
    r.set_defaults(func=_cmd_run)

    an = sub.add_parser("analyze", help="analyse a log into DIR/<name>/analysis.json")
    an.add_argument("log")
    an.add_argument("--against", help="a second log to compare with (e.g. the dt010 run)")
    an.add_argument("--out", default="generated_reports")
    an.add_argument("--window-start", type=float, default=None,
                    help="analysis window start in seconds (default: half the mission)")
    an.add_argument("--force", action="store_true",
                    help="analyse even when the record is current (same logs and analysis code)")
    an.set_defaults(func=_cmd_analyze)

    rp = sub.add_parser("report", help="render the reports under generated_reports/")
    rp.add_argument("--out", default="generated_reports")
    rp.add_argument("--force", action="store_true",
                    help="render even when the reports are current (same inputs and renderer)")
    rp.set_defaults(func=_cmd_report)

    c = sub.add_parser("claims", help="evaluate the claims register")
    c.add_argument("--claims", default="claims",
                   help="claims register: a name on the spec search path or a .yaml path "
                        "(default: claims, the shipped register)")
    c.add_argument("--out", default="generated_reports")
    c.set_defaults(func=_cmd_claims)

    s = sub.add_parser("sweep", help="run a grid of overrides of one spec on Dask")
    s.add_argument("spec")
    s.add_argument("--set", action="append", default=[], metavar="KEY=V1,V2,...")
    s.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    s.add_argument("--workers", type=int, default=2)
    s.add_argument("--slurm", action="store_true", help="start workers through dask-jobqueue")
    s.add_argument("--name", default=None, help="sweep name (default: from spec and keys)")
    s.add_argument("--logs", default="logs/sweeps")
    s.add_argument("--out", default="generated_reports/sweeps")
    s.set_defaults(func=_cmd_sweep)

    b = sub.add_parser("bench", help="measure simulator and analysis cost against the floor")
    b.add_argument("--out", default="generated_reports")
    b.add_argument("--quick", action="store_true", help="fewer repeats and shorter logs")
    b.set_defaults(func=_cmd_bench)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except PipelineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
