"""Command line: ``python -m pipeline {run,analyze,report,claims,sweep,bench}``.

Exit codes: 0 success; 1 a check, claim or run failed; 2 bad input (one line, no traceback).
This is the one place where the pipeline's error kinds become exit codes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.errors import PipelineError


def _cmd_run(a: argparse.Namespace) -> int:
    from pipeline.sim.run import run_spec
    from pipeline.spec import load_spec

    spec = load_spec(a.spec)
    out = run_spec(spec, a.out, progress=sys.stderr.isatty())
    for w in out.warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"{spec.name}: {out.n_steps} steps, {out.status} -> {out.path}")
    return 0


def _cmd_analyze(a: argparse.Namespace) -> int:
    from pipeline.analysis.cli import analyze_command

    return analyze_command(Path(a.log), Path(a.against) if a.against else None, Path(a.out),
                           a.window_start)


def _cmd_report(a: argparse.Namespace) -> int:
    from pipeline.reports.render import render_all

    render_all(Path(a.out))
    return 0


def _cmd_claims(a: argparse.Namespace) -> int:
    from pipeline.reports.claims import claims_command

    return claims_command(Path(a.claims), Path(a.out))


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
    r.add_argument("spec", help="spec name under specs/ or path to a .yaml file")
    r.add_argument("--out", default="logs", help="log folder (default: logs)")
    r.set_defaults(func=_cmd_run)

    an = sub.add_parser("analyze", help="analyse a log into DIR/<name>/analysis.json")
    an.add_argument("log")
    an.add_argument("--against", help="a second log to compare with (e.g. the dt010 run)")
    an.add_argument("--out", default="generated_reports")
    an.add_argument("--window-start", type=float, default=None,
                    help="analysis window start in seconds (default: half the mission)")
    an.set_defaults(func=_cmd_analyze)

    rp = sub.add_parser("report", help="render the reports under generated_reports/")
    rp.add_argument("--out", default="generated_reports")
    rp.set_defaults(func=_cmd_report)

    c = sub.add_parser("claims", help="evaluate the claims register")
    c.add_argument("--claims", default="specs/claims.yaml")
    c.add_argument("--out", default="generated_reports")
    c.set_defaults(func=_cmd_claims)

    s = sub.add_parser("sweep", help="run a grid of overrides of one spec on Dask")
    s.add_argument("spec")
    s.add_argument("--set", action="append", default=[], metavar="KEY=V1,V2,...")
    s.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    s.add_argument("--workers", type=int, default=2)
    s.add_argument("--slurm", action="store_true", help="start workers through dask-jobqueue")
    s.add_argument("--worker-timeout", type=float, default=None, metavar="S",
                   help="fail (exit 2) if no worker joins within S s (default 300)")
    s.add_argument("--lifetime", type=float, default=None, metavar="S",
                   help="SLURM workers retire after S s (default: from the walltime; 0: never)")
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
