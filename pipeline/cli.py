"""Command line: ``python -m pipeline STAGE …``, one subcommand per stage.

Exit codes: 0 success; 1 a check, claim or run failed; 2 bad input (one line, no traceback).
This is the one place where the pipeline's error kinds become exit codes.
"""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
import warnings
from pathlib import Path

from pipeline.errors import PipelineError, RunFailed


def _cmd_validate(a: argparse.Namespace) -> int:
    from pipeline.validate import validate_command

    return validate_command(a.spec, a.explain)


def _cmd_run(a: argparse.Namespace) -> int:
    from pipeline.paths import display_path
    from pipeline.spec import load_spec

    # Every spec and its robot file checked before anything runs or prints: bad input is
    # one line (exit 2), not a stage that started and failed; a spec's error before the
    # simulator, the robot parsers and the store are imported (a second and a half).
    specs = [load_spec(s) for s in a.spec]
    from pipeline.sim.robot_file import load_spec_robot

    for spec in specs:
        load_spec_robot(spec)
    from pipeline.store.door import ArtefactStore

    store = ArtefactStore(a.out)
    for spec in specs:
        # A stored run that failed fails again, unrun: the simulation is deterministic.
        run = store.run(spec, expect="complete", force=a.force)
        if run.reused:
            print(f"{spec.name}: up to date (complete, same spec, robot and simulator) "
                  f"-> {display_path(run.path)}")
        else:
            print(f"{spec.name}: {run.log.rows} steps, complete -> {display_path(run.path)}")
    return 0


def _cmd_analyze(a: argparse.Namespace) -> int:
    from pipeline.analysis.summary import summary_lines
    from pipeline.paths import display_path
    from pipeline.spec import load_spec
    from pipeline.store.door import ArtefactStore

    controller = load_spec(a.controller) if a.controller else None
    store = ArtefactStore(out=a.out)
    log = store.open_log(a.log)
    other = store.open_log(a.against) if a.against else None
    done = store.analysis(log, other, a.window_start, force=a.force, quiet=True,
                          controller=controller, s_min_G_target=a.at_s_min_G)
    if done.reused:
        print(f"{log.spec.name}: up to date (same log and analysis code) -> "
              f"{display_path(done.path)}")
        return 0
    for line in summary_lines(done.record, done.path):
        print(line)
    return 0


def _cmd_import(a: argparse.Namespace) -> int:
    from pipeline.importer.mapping import import_spec, load_mapping, robot_block
    from pipeline.paths import display_path
    from pipeline.sim.robot_file import load_spec_robot

    def columns(text: str | None) -> str | list[str] | None:
        """A column, key or selection (``states.x[:, 0:13]``: its comma is the selection's),
        or scalar columns separated by commas."""
        if text is None or "," not in re.sub(r"\[[^\]]*\]", "", text):
            return text
        return text.split(",")

    mapping_file = Path(a.mapping) if a.mapping else None
    given = {"format": a.format, "robot": a.robot, "time_unit": a.time_unit, "dt": a.dt,
             "q": columns(a.q), "v": columns(a.v), "quaternion": a.quaternion,
             "velocity_frame": a.velocity_frame, "linear_velocity": a.linear_velocity,
             "angle_unit": a.angle_unit, "length_unit": a.length_unit,
             "allow_pickle": a.allow_pickle or None, "time": a.time,
             "max_jitter": a.max_jitter}
    options = {k: v for k, v in given.items() if v is not None}
    if a.time == "none":  # a log without stamps: its step is --dt
        options["time"] = None
    mapping = load_mapping(mapping_file, options)
    source = Path(a.source)
    name = a.name or (source.stem if source.suffix else source.name)
    here = mapping_file.resolve().parent if mapping_file else None
    # The options, the mapping and the robot are checked before the log is read and before
    # the importer's libraries load: a bad robot file is refused in about validate's time.
    robot, _, robot_here = robot_block(mapping, here)
    spec = import_spec(name, robot, 1.0, 1, robot_here, str(source))[0]
    load_spec_robot(spec)
    from pipeline.store.door import import_log

    done = import_log(source, mapping, name, a.out, a.resample, here, force=a.force)
    if done.reused:
        print(f"{name}: up to date ({done.rows} rows: the same source, mapping, robot and "
              f"importer as the log there; --force imports it again) -> "
              f"{display_path(done.path)}")
        return 0
    tb = done.time
    resampled = (f", resampled from {tb.resampled_from} rows" if tb.resampled_from else
                 f", stamps within {tb.max_deviation:.2g} s of t0 + k·dt")
    print(f"{name}: {done.rows} rows at dt {tb.dt:.6g} s{resampled}; robot from {done.robot};"
          f" q and v agree ({done.conventions}: median residual "
          f"{done.median_ratio:.2g}× its bound) -> {display_path(done.path)}")
    return 0


def _report(out: Path, force: bool = False, cross_check=None) -> int:
    """The report stage; ``cross_check``: a CrossCheck this process already built."""
    from pipeline.progress import stage
    from pipeline.store.validity import REPORT_KEY_FILE, current_report

    # Current reports are said so before the renderer (matplotlib, the figures) is imported:
    # the second `make all` should take seconds.
    if not force and out.is_dir() and current_report(out, out / REPORT_KEY_FILE):
        print(f"report: up to date (same inputs and renderer) -> {out / 'index.html'}")
        return 0
    from pipeline.reports.render import render_all

    with stage("report", f"-> {out}"):
        render_all(out, force=force, cross_check=cross_check)
    return 0


def _cmd_report(a: argparse.Namespace) -> int:
    return _report(Path(a.out), a.force)


def _claims(claims: str, out: Path, force: bool = False, studies: str = "read"):
    """The claims stage: its exit code and, when it evaluated, its ClaimsOutcome (None when
    the register was current). ``studies``: read the current studies (the decision) or fly
    them at the register's N first (:mod:`pipeline.claims.evaluate`)."""
    from pipeline.atomic_files import atomic_write_text
    from pipeline.claims.record import (
        RECORD_NAME,
        exit_code,
        failure_lines,
        kind_counts,
        read_claims_json,
        status_counts,
        summary_lines,
    )
    from pipeline.claims.register import load_claims, register_sources, study_sources
    from pipeline.paths import display_path
    from pipeline.progress import say, stage
    from pipeline.spec import resolve_spec_path
    from pipeline.store.validity import CLAIMS_KEY_FILE, claims_key, current_claims

    stamp, page = out / CLAIMS_KEY_FILE, out / "CLAIMS.md"
    cf = load_claims(resolve_spec_path(claims))  # a bad register is one line, before any stage
    sources = {**register_sources(cf), **study_sources(cf, out), "studies": studies}
    outcome = None
    # Current claims are said so before the simulator, the analysis or the renderer is
    # imported: the second `make all` should take seconds.
    if not force and current_claims(stamp, sources):
        data = read_claims_json(out / RECORD_NAME)
        say(f"claims: up to date ({status_counts(data)}; same register, specs, artefacts and "
            f"code) -> {display_path(page)}")
    else:
        from pipeline.claims.evaluate import run_claims
        from pipeline.reports.claims_page import render_claims

        # Runs, analyses, sweeps and checks are stages of their own, as they start.
        with stage("claims", f"({claims}: what is missing is made first)") as st:
            outcome = run_claims(claims, out, studies)
            page = render_claims(outcome, out)
            made = [outcome.record, page, page.with_suffix(".html")]
            atomic_write_text(stamp, claims_key(sources, [*outcome.files, *made]))
            data = read_claims_json(outcome.record)
            st.done(status_counts(data))
    print(f"claims by kind: {kind_counts(data)}")
    for line in summary_lines(data):
        print(line)
    for line in failure_lines(data):
        print(line, file=sys.stderr)
    print(f"-> {display_path(page)}")
    return exit_code(data), outcome


def _cmd_claims(a: argparse.Namespace) -> int:
    return _claims(a.claims, Path(a.out), a.force, a.studies)[0]


def _import_later_stages() -> None:
    """Import what the claims and the reports will (the simulator, the analysis, Dask,
    matplotlib: seconds, most of it reading and byte-compiling modules the first time), while
    the kernels' last unit leaves a core free. Only imports: nothing here compiles a kernel.
    It runs in a thread and must not raise: a module that fails to import fails again, with
    its one-line error, where its stage imports it."""
    try:
        import pipeline.claims.evaluate
        import pipeline.reports.claims_page
        import pipeline.reports.render
        import pipeline.sweep.driver  # noqa: F401
    except Exception:
        pass


def _cmd_all(a: argparse.Namespace, compiled: bool = False) -> int:
    """compile, claims, report in one process (`make all`): the libraries are imported once
    and the report reuses the claims' check of the equations against the code. A claim or a
    run that fails still leaves the reports rendered, then the exit code is the claims' (1);
    bad input stops at once (2)."""
    from pipeline.compile import compile_kernels

    out = Path(a.out)
    if not compiled:
        compile_kernels(a.processes, when_idle=_import_later_stages)
    try:
        code, outcome = _claims(a.claims, out)
    except PipelineError as exc:
        if exc.exit_code == 2:
            raise
        print(f"error: {exc}", file=sys.stderr)
        code, outcome = exc.exit_code, None
    try:
        report = _report(out, cross_check=outcome.cross_check if outcome is not None else None)
    except PipelineError as exc:
        if not code:
            raise
        # The claims' failure is the news; the report's own error (say, nothing to report
        # after the first mission failed) is said, and the exit code stays the claims'.
        print(f"error: {exc}", file=sys.stderr)
        report = exc.exit_code
    return code or report


def _cmd_studies(a: argparse.Namespace) -> int:
    """Fly every study the register names at its entry's N (`make studies`), one after another
    on the cluster asked for, each one's kept records reused and a current one not flown
    again; then the claims and the reports, as `make all`, which now read them."""
    from pipeline.claims.register import load_claims, montecarlo_path, needed_montecarlos
    from pipeline.compile import compile_kernels
    from pipeline.montecarlo.studies import FOLDERS, study_result
    from pipeline.progress import say, stage
    from pipeline.spec import resolve_spec_path

    cf = load_claims(resolve_spec_path(a.claims))
    out, logs = Path(a.out), Path(cf.logs)
    todo = [(kind, alias) for kind in FOLDERS for alias in needed_montecarlos(cf, kind)]
    compile_kernels(a.processes)
    for k, (kind, alias) in enumerate(todo, 1):
        ref = getattr(cf, kind)[alias]
        path = montecarlo_path(cf, ref)
        st = study_result(kind, path, ref.samples, out)
        if st.result is not None:
            say(f"{kind} {st.name}: up to date ({st.ran} samples) -> {st.provenance['file']}")
            continue
        cmd = [sys.executable, "-m", "pipeline", kind, str(path), "--logs",
               str(logs / FOLDERS[kind]), "--out", str(out / FOLDERS[kind]),
               "--workers", str(a.workers)]
        cmd += ["--samples", str(ref.samples)] if ref.samples else []
        cmd += ["--scheduler", a.scheduler] if a.scheduler else []
        cmd += ["--slurm"] if a.slurm else []
        cmd += ["--worker-timeout", str(a.worker_timeout)] if a.worker_timeout else []
        with stage(kind, f"{alias} ({k} of {len(todo)}: {st.full} samples of {path.name}; "
                   "kept records reused)"):
            rc = subprocess.call(cmd)
        if rc:
            raise RunFailed(f"studies: {kind} {path.name} failed (exit {rc}); run `make studies` "
                            "again to finish it (its kept records are reused)")
    _fix_studies(a, cf, out, logs)
    return _cmd_all(a, compiled=True)


def _fix_studies(a: argparse.Namespace, cf, out: Path, logs: Path) -> None:
    """For each Monte Carlo whose current verdict does not show its target, the least change
    of each knob every sample meets (``search``) and each fix flown through the same samples
    (``fixes``), their kept records reused (issue 52)."""
    from pipeline.claims.register import montecarlo_path, needed_montecarlos
    from pipeline.montecarlo.plan import result_key
    from pipeline.montecarlo.search import FIX_KNOBS, current_searches
    from pipeline.montecarlo.studies import study_result
    from pipeline.progress import say, stage

    dask = ["--workers", str(a.workers), *(["--scheduler", a.scheduler] if a.scheduler else []),
            *(["--slurm"] if a.slurm else []),
            *(["--worker-timeout", str(a.worker_timeout)] if a.worker_timeout else [])]
    for alias in needed_montecarlos(cf, "montecarlo"):
        ref = cf.montecarlo[alias]
        path = montecarlo_path(cf, ref)
        st = study_result("montecarlo", path, ref.samples, out)
        if st.result is None or st.result["shown"] is not False:
            continue
        n = st.ran  # the N of its current result: the register's, else the file's
        folder = out / "montecarlo" / st.name
        done = {s["knob"] for s in current_searches(folder, result_key(path, n))}
        where = ["--logs", str(logs / "montecarlo"), "--out", str(out / "montecarlo"),
                 *(["--samples", str(ref.samples)] if ref.samples else [])]
        for knob in FIX_KNOBS:
            if knob in done:
                say(f"search {st.name} {knob}: up to date -> {folder}/search-{knob}.json")
                continue
            with stage("search", f"{alias}: the least {knob} every one of its {n} samples "
                       "meets (eq. 43)"):
                rc = subprocess.call([sys.executable, "-m", "pipeline", "search", str(path),
                                      "--knob", knob, *where, *dask])
            if rc:
                raise RunFailed(f"studies: search {path.name} {knob} failed (exit {rc}); run "
                                "`make studies` again (its kept records are reused)")
        with stage("fixes", f"{alias}: each fix flown through its {n} samples"):
            rc = subprocess.call([sys.executable, "-m", "pipeline", "fixes", str(path), *where,
                                  *dask])
        if rc:
            raise RunFailed(f"studies: fixes {path.name} failed (exit {rc}); run `make "
                            "studies` again (its kept records are reused)")


def _cmd_sweep(a: argparse.Namespace) -> int:
    from pipeline.sweep import sweep_command

    return sweep_command(a)


def _cmd_montecarlo(a: argparse.Namespace) -> int:
    from pipeline.montecarlo.driver import montecarlo_command

    return montecarlo_command(a)


def _cmd_search(a: argparse.Namespace) -> int:
    from pipeline.montecarlo.driver import search_command

    return search_command(a)


def _cmd_fixes(a: argparse.Namespace) -> int:
    from pipeline.montecarlo.driver import fixes_command

    return fixes_command(a)


def _cmd_power(a: argparse.Namespace) -> int:
    from pipeline.montecarlo.power import power_command

    return power_command(a)


def _cmd_compile(a: argparse.Namespace) -> int:
    from pipeline.compile import compile_command

    return compile_command(a)


def _cmd_bench(a: argparse.Namespace) -> int:
    from pipeline.bench import bench_command

    return bench_command(a)


SPEC_HELP = ("a spec name on the spec search path (beside, $BREVE_SPEC_PATH, the shipped "
             "specs/) or a path to a .yaml file (e.g. nominal or my/mission.yaml)")

DESCRIPTION = """\
Simulate a free-floating space robot (a spacecraft bus carrying a 6-DoF arm with an
inspection camera) from a mission spec, analyse its logs, and report what they show.
A typical session: validate, run, analyze, report; `all` (`make all`) does every stage."""

EPILOG = """\
examples:
  python -m pipeline validate nominal
  python -m pipeline run nominal
  python -m pipeline analyze logs/nominal/run.parquet --against logs/omega_ripple_dt010/run.parquet
  python -m pipeline report
  python -m pipeline STAGE --help      (the options of one stage)

exit codes: 0 success; 1 a run failed or diverged, a check or a claim failed;
2 bad input (one line naming the field or the file)."""


class _StageFormatter(argparse.RawDescriptionHelpFormatter):
    """Measures the stage names where they are printed: argparse lists a subcommand one indent
    deeper than it measures it, so a stage name longer than the others (``montecarlo``) would
    push its summary to a line of its own."""

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if isinstance(action, argparse._SubParsersAction) and action.choices:
            longest = (max(len(name) for name in action.choices) + self._current_indent
                       + 2 * self._indent_increment)
            self._action_max_length = max(self._action_max_length, longest)


def _formatter(prog: str) -> argparse.HelpFormatter:
    # Raw: the description and the examples keep their lines; wide: help texts on one line.
    return _StageFormatter(prog, max_help_position=32, width=100)


def _sigma(text: str) -> float:
    """A singular value to aim at: a finite number above 0."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(x) and x > 0.0):
        raise argparse.ArgumentTypeError(f"{text}: give a finite σ above 0")
    return x


def _sample_count(text: str) -> int:
    """A count of samples: a whole number of at least 1 (argparse's one-line error, exit 2)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"{n} samples: give 1 or more")
    return n


def _stage(sub, name: str, summary: str, example: str) -> argparse.ArgumentParser:
    """One stage's subcommand: its one-line summary in the top-level list, an example below
    its own options."""
    return sub.add_parser(name, help=summary, description=summary[0].upper() + summary[1:] + ".",
                          epilog=f"example:\n  python -m pipeline {name} {example}",
                          formatter_class=_formatter)


def _decision_options(s: argparse.ArgumentParser, out: str) -> None:
    """The options of `all` and `studies`: the register, the report folder (``out`` says
    what goes there) and the compile's processes."""
    s.add_argument("--claims", default="claims", metavar="FILE",
                   help="claims file, as for `claims` (default: claims, the shipped register; "
                   "e.g. --claims claims_ci)")
    s.add_argument("--out", default="generated_reports", metavar="DIR",
                   help=f"{out} (default: generated_reports; e.g. --out /tmp/reports)")
    s.add_argument("--processes", type=int, default=2, metavar="N",
                   help="processes compiling the kernels, as for `compile` "
                   "(default: 2; e.g. --processes 1)")


def _dask_options(s: argparse.ArgumentParser, lifetime: bool = True) -> None:
    """Where a stage's Dask tasks run (``pipeline.sweep.cluster``): the sweeps', the Monte
    Carlos' and the power studies' options."""
    s.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="address of an existing Dask scheduler (default: "
                   "$DASK_SCHEDULER_ADDRESS, else an embedded LocalCluster; "
                   "e.g. --scheduler tcp://10.0.0.5:8786)")
    s.add_argument("--workers", type=int, default=2, metavar="N",
                   help="workers of the embedded cluster or of SLURM "
                   "(default: 2; e.g. --workers 4)")
    s.add_argument("--slurm", action="store_true",
                   help="start the workers as SLURM jobs through dask-jobqueue "
                   "(default: off; e.g. --slurm --workers 16)")
    s.add_argument("--worker-timeout", type=float, default=None, metavar="S",
                   help="fail (exit 2) if no worker joins within S seconds "
                   "(default: 300; e.g. --worker-timeout 600)")
    if lifetime:
        s.add_argument("--lifetime", type=float, default=None, metavar="S",
                       help="SLURM workers retire after S seconds, before their walltime "
                       "(default: from the walltime; 0: never; e.g. --lifetime 1500)")


def _study_force(s: argparse.ArgumentParser, kind: str) -> None:
    s.add_argument("--force", action="store_true",
                   help=f"replace the results another {kind} file of the same name keeps in "
                   "DIR/<name>/ of --logs and --out (default: refused in one line, nothing "
                   "touched; e.g. --force)")


def build_parser() -> argparse.ArgumentParser:
    from pipeline.version import package_version

    p = argparse.ArgumentParser(prog="python -m pipeline", description=DESCRIPTION,
                                epilog=EPILOG, formatter_class=_formatter)
    p.add_argument("--version", action="version",
                   version=f"breve-pipeline {package_version()}",
                   help="print the release and exit (e.g. breve-pipeline 0.1.0)")
    sub = p.add_subparsers(dest="command", required=True, title="stages", metavar="STAGE")

    al = _stage(sub, "all", "compile, then the claims (running the missions, analyses and "
                "sweeps they need), then every report, as `make all` does",
                "--claims claims --out generated_reports")
    _decision_options(al, "report folder for the claims and the reports")
    al.set_defaults(func=_cmd_all)

    v = _stage(sub, "validate", "check a spec and print what its run would cost, without "
               "running it", "nominal")
    v.add_argument("spec", help=SPEC_HELP)
    v.add_argument("--explain", action="store_true",
                   help="also print which keys the spec sets, which it inherits through "
                        "extends (and from which spec) and which a null deleted (default: "
                        "off; e.g. --explain)")
    v.set_defaults(func=_cmd_validate)

    r = _stage(sub, "run", "simulate a mission spec into DIR/<name>/run.parquet",
               "nominal --out logs")
    r.add_argument("spec", nargs="+", help=f"one or more specs, each {SPEC_HELP}")
    r.add_argument("--out", default="logs", metavar="DIR",
                   help="log folder; the log is DIR/<spec name>/run.parquet "
                   "(default: logs; e.g. --out /tmp/logs)")
    r.add_argument("--force", action="store_true",
                   help="run even when the log is current: same spec, robot file and "
                   "simulator (default: off; e.g. --force)")
    r.set_defaults(func=_cmd_run)

    an = _stage(sub, "analyze", "analyse a log into DIR/<name>/analysis.json",
                "logs/nominal/run.parquet --against logs/omega_ripple_dt010/run.parquet")
    an.add_argument("log", help="a run's log, as `run` wrote it "
                    "(e.g. logs/nominal/run.parquet)")
    an.add_argument("--against", metavar="LOG2",
                    help="a second log of the same robot to compare with; different dt is "
                    "the point, different durations or windows are named in the output "
                    "(default: none; e.g. --against logs/omega_ripple_dt010/run.parquet)")
    an.add_argument("--out", default="generated_reports", metavar="DIR",
                    help="report folder; writes DIR/<spec name>/analysis.json and "
                    "directions.parquet (default: generated_reports; e.g. --out /tmp/reports)")
    an.add_argument("--window-start", type=float, default=None, metavar="SECONDS",
                    help="analysis window start in seconds, to the end of the log "
                    "(default: half the mission; e.g. --window-start 30)")
    an.add_argument("--at-s-min-G", type=_sigma, default=None, metavar="SIGMA",
                    dest="at_s_min_G",
                    help="take the theory at the window's step of σ_min(Γ) nearest SIGMA "
                    "instead of the median's: the seed note's regime is 0.032 (default: the "
                    "median; e.g. --at-s-min-G 0.032)")
    an.add_argument("--force", action="store_true",
                    help="analyse even when the record is current: same logs and analysis "
                    "code (default: off; e.g. --force)")
    an.add_argument("--controller", metavar="SPEC",
                    help="for an imported log: the spec whose controller (gains, integrator, "
                    "dt) flew it; the damping theory runs only with one (default: none, the "
                    "data stages alone; e.g. --controller nominal)")
    an.set_defaults(func=_cmd_analyze)

    im = _stage(sub, "import", "import a log another simulator or a spacecraft wrote (CSV, "
                "Parquet, .npz, ROS 2 bag, MCAP) into DIR/imported/<name>/run.parquet",
                "states_ur3_1.npz --robot nominal --allow-pickle --time states.t "
                "--q 'states.x[:, 0:13]' --v 'states.x[:, 13:25]'")
    im.add_argument("source", help="the log file, a ROS 2 bag's folder or an MCAP file "
                    "(e.g. npz/states_ur3_1.npz)")
    im.add_argument("--mapping", metavar="FILE",
                    help="YAML mapping of columns, topics, conventions and robot; the options "
                    "below override it (default: none; e.g. --mapping precursor.yaml)")
    im.add_argument("--name", help="the imported log's name (default: the file's stem; "
                    "e.g. --name precursor_run1)")
    im.add_argument("--robot", metavar="SPEC",
                    help="a spec whose robot block the log is of (default: the mapping's; "
                    "e.g. --robot nominal)")
    im.add_argument("--format", choices=("csv", "parquet", "npz", "rosbag", "mcap"),
                    help="the file's format (default: from its suffix; e.g. --format csv)")
    im.add_argument("--time", metavar="COLUMN",
                    help="the time stamps' column or key, `none` for a log without them "
                    "(default: t; e.g. --time states.t)")
    im.add_argument("--time-unit", choices=("s", "ms", "us", "ns"),
                    help="the stamps' unit (default: s; e.g. --time-unit ns)")
    im.add_argument("--dt", type=float, metavar="SECONDS",
                    help="the step of a log without time stamps (default: none; e.g. --dt 0.03)")
    im.add_argument("--q", metavar="COLUMN[,…]", help="q's vector column or key, a selection "
                    "of columns, or its 13 scalar columns comma-separated (default: q; e.g. "
                    "--q 'states.x[:, 0:13]', the precursor's layout)")
    im.add_argument("--v", metavar="COLUMN[,…]", help="v's, 12 wide (default: v; "
                    "e.g. --v 'states.x[:, 13:25]')")
    im.add_argument("--quaternion", choices=("xyzw", "wxyz"),
                    help="the bus quaternion's order (default: xyzw; e.g. --quaternion wxyz)")
    im.add_argument("--velocity-frame", choices=("bus", "world"),
                    help="axes of the bus velocities (default: bus; e.g. --velocity-frame world)")
    im.add_argument("--linear-velocity", choices=("origin", "bus_com"),
                    help="the point whose linear velocity is logged (default: origin, the bus "
                    "frame's; e.g. --linear-velocity bus_com)")
    im.add_argument("--angle-unit", choices=("rad", "deg"),
                    help="of joint angles and angular rates (default: rad; e.g. --angle-unit deg)")
    im.add_argument("--length-unit", choices=("m", "mm"),
                    help="of positions and linear velocities (default: m; e.g. --length-unit mm)")
    im.add_argument("--max-jitter", type=float, metavar="FRACTION",
                    help="stamps may lie this fraction of the step off t0 + k·dt beyond their "
                    "resolution, below 0.25 (telemetry stamped as published): the log is "
                    "analysed at its own instants, one row per step, recorded (default: 0; "
                    "e.g. --max-jitter 0.1)")
    im.add_argument("--resample", type=float, metavar="DT",
                    help="resample onto this fixed step, recorded (default: an uneven time "
                    "base is refused; e.g. --resample 0.03)")
    im.add_argument("--allow-pickle", action="store_true",
                    help="read pickled objects in a .npz: runs code from the file, so only a "
                    "file you trust (default: off; e.g. --allow-pickle)")
    im.add_argument("--out", default="logs", metavar="DIR",
                    help="log folder; writes DIR/imported/<name>/run.parquet (default: logs; "
                    "e.g. --out /tmp/logs)")
    im.add_argument("--force", action="store_true",
                    help="replace a log already imported under the name from another source, "
                    "mapping or robot, or import the same again (default: off: the same "
                    "import is reused, another refused; e.g. --force)")
    im.set_defaults(func=_cmd_import)

    rp = _stage(sub, "report", "render the figures, reports and index.html of a report folder",
                "--out generated_reports")
    rp.add_argument("--out", default="generated_reports", metavar="DIR",
                    help="report folder holding the analyses; the reports are written there "
                    "(default: generated_reports; e.g. --out /tmp/reports)")
    rp.add_argument("--force", action="store_true",
                    help="render even when the reports are current: same inputs and renderer "
                    "(default: off; e.g. --force)")
    rp.set_defaults(func=_cmd_report)

    c = _stage(sub, "claims", "evaluate the claims register, running what is missing",
               "--claims claims_ci --out generated_reports/ci")
    c.add_argument("--claims", default="claims", metavar="FILE",
                   help="claims file: the claims and the runs and sweeps they need; a name on "
                   "the spec search path or a .yaml path (default: claims, the shipped "
                   "register; e.g. --claims claims_ci or --claims my_claims.yaml)")
    c.add_argument("--out", default="generated_reports", metavar="DIR",
                   help="report folder for CLAIMS.md, CLAIMS.html and claims.json "
                   "(default: generated_reports; e.g. --out generated_reports/ci)")
    c.add_argument("--force", action="store_true",
                   help="evaluate again even if the register, its specs and every artefact it "
                   "reads are as they were (default: off; e.g. --force)")
    c.add_argument("--studies", choices=("read", "run"), default="read",
                   help="read: the current results of the studies (Monte Carlos, power "
                   "studies) at their files' N, the claims that need one deferred without it; "
                   "run: fly them first at the N the register asks (default: read; e.g. "
                   "--studies run, as make claims-ci)")
    c.set_defaults(func=_cmd_claims)

    t = _stage(sub, "studies", "fly the studies the claims need (Monte Carlos, power studies) "
               "at their files' full N, then the claims and reports, as `make studies` does",
               "--claims claims --out generated_reports --workers 2")
    _decision_options(t, "report folder: DIR/montecarlo/<name>/, DIR/power/<name>/, the claims "
                      "and the reports")
    _dask_options(t, lifetime=False)
    t.set_defaults(func=_cmd_studies)

    s = _stage(sub, "sweep", "run a grid of overrides of one spec on Dask",
               "nominal --set mission.dt=0.01,0.03 --set mission.duration=20")
    s.add_argument("spec", help=SPEC_HELP)
    s.add_argument("--set", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a spec key and its values, repeatable; the grid is the product of "
                   "the lists (no default: at least one is needed; "
                   "e.g. --set mission.dt=0.01,0.02,0.03)")
    _dask_options(s)
    s.add_argument("--name", default=None,
                   help="sweep name, the folder of its logs and table (default: from the "
                   "spec and the keys; e.g. --name nominal_dt)")
    s.add_argument("--logs", default="logs/sweeps", metavar="DIR",
                   help="log folder; each point's log is DIR/<sweep>/<point>/run.parquet "
                   "(default: logs/sweeps; e.g. --logs /scratch/sweeps)")
    s.add_argument("--out", default="generated_reports/sweeps", metavar="DIR",
                   help="table folder; writes DIR/<sweep>/sweep.parquet "
                   "(default: generated_reports/sweeps; e.g. --out /tmp/sweeps)")
    s.set_defaults(func=_cmd_sweep)

    m = _stage(sub, "montecarlo", "dispersed missions on Dask, judged at a stated confidence",
               "seed_dispersions --samples 40")
    m.add_argument("file", help="a Monte Carlo file: a path, or a name under specs/montecarlo/ "
                   "(e.g. seed_dispersions)")
    m.add_argument("--samples", type=_sample_count, default=None, metavar="N",
                   help="run the first N samples (default: the file's samples, else the count "
                   "that shows its target with none failing, eq. 38b; e.g. --samples 40)")
    m.add_argument("--sample", type=int, default=None, metavar="I",
                   help="run sample I alone, write its log and compare its bits with the kept "
                   "record (default: all samples; e.g. --sample 17)")
    _dask_options(m)
    m.add_argument("--logs", default="logs/montecarlo", metavar="DIR",
                   help="where each sample's record is kept, DIR/<montecarlo>/<sample>.json, "
                   "and a sample run alone writes its log (default: logs/montecarlo; e.g. "
                   "--logs /scratch/montecarlo)")
    m.add_argument("--out", default="generated_reports/montecarlo", metavar="DIR",
                   help="writes DIR/<montecarlo>/montecarlo.parquet and verdict.json "
                   "(default: generated_reports/montecarlo; e.g. --out /tmp/montecarlo)")
    _study_force(m, "montecarlo")
    m.set_defaults(func=_cmd_montecarlo)

    q = _stage(sub, "search", "the least change of one knob that every sample of a Monte Carlo "
               "meets, on its own draws (eq. 43)", "seed_latency_dt0025 --knob mission.dt")
    q.add_argument("file", help="a Monte Carlo file: a path, or a name under specs/montecarlo/ "
                   "(e.g. seed_latency_dt0025)")
    q.add_argument("--knob", default="mission.dt", metavar="FIELD",
                   help="the spec field moved: mission.dt or controller.gains.<bus|cam_pos|"
                   "cam_ori>.D (default: mission.dt; e.g. --knob controller.gains.bus.D)")
    q.add_argument("--samples", type=_sample_count, default=None, metavar="N",
                   help="search over the first N samples (default: the file's N; e.g. "
                   "--samples 40)")
    _dask_options(q)
    q.add_argument("--logs", default="logs/montecarlo", metavar="DIR",
                   help="the Monte Carlo's kept records, reused at the nominal value, and the "
                   "search's, DIR/<montecarlo>/search-<knob>/ (default: logs/montecarlo; e.g. "
                   "--logs /scratch/montecarlo)")
    q.add_argument("--out", default="generated_reports/montecarlo", metavar="DIR",
                   help="writes DIR/<montecarlo>/search-<knob>.json (default: "
                   "generated_reports/montecarlo; e.g. --out /tmp/montecarlo)")
    _study_force(q, "montecarlo")
    q.set_defaults(func=_cmd_search)

    f = _stage(sub, "fixes", "each fix of a Monte Carlo's loop flown through its samples, on "
               "their own draws", "seed_latency_dt0025")
    f.add_argument("file", help="a Monte Carlo file whose verdict is flown: a path, or a name "
                   "under specs/montecarlo/ (e.g. seed_latency_dt0025)")
    f.add_argument("--samples", type=_sample_count, default=None, metavar="N",
                   help="the N its verdict flew (default: the file's N; e.g. --samples 40)")
    _dask_options(f)
    f.add_argument("--logs", default="logs/montecarlo", metavar="DIR",
                   help="where each fix's samples' records are kept, DIR/<montecarlo>+<fix>/ "
                   "(default: logs/montecarlo; e.g. --logs /scratch/montecarlo)")
    f.add_argument("--out", default="generated_reports/montecarlo", metavar="DIR",
                   help="reads DIR/<montecarlo>/verdict.json and search-*.json; writes the fix "
                   "files in DIR/<montecarlo>/fixes/, each fix's verdict in "
                   "DIR/<montecarlo>+<fix>/ and DIR/<montecarlo>/fixes.json (default: "
                   "generated_reports/montecarlo; e.g. --out /tmp/montecarlo)")
    _study_force(f, "montecarlo")
    f.set_defaults(func=_cmd_fixes)

    w = _stage(sub, "power", "the ripple detectors' false alarms and misses against sensor "
               "noise", "detector_power")
    w.add_argument("file", help="a power file: a path, or a name under specs/montecarlo/ "
                   "(e.g. detector_power)")
    w.add_argument("--samples", type=_sample_count, default=None, metavar="N",
                   help="run the first N runs per mission and level (default: the file's "
                   "samples; e.g. --samples 2)")
    _dask_options(w, lifetime=False)
    w.add_argument("--logs", default="logs/power", metavar="DIR",
                   help="where each sample's record is kept (default: logs/power; e.g. --logs "
                   "/scratch/power)")
    w.add_argument("--out", default="generated_reports/power", metavar="DIR",
                   help="writes DIR/<name>/power.parquet and power.json "
                   "(default: generated_reports/power; e.g. --out /tmp/power)")
    _study_force(w, "power")
    w.set_defaults(func=_cmd_power)

    k = _stage(sub, "compile", "compile the Numba kernels into their cache once, on two cores "
               "(every stage also compiles what it needs on first use)", "--processes 2")
    k.add_argument("--processes", type=int, default=2, metavar="N",
                   help="1: one process; 2: two processes compiling disjoint kernels "
                   "(default: 2; e.g. --processes 1)")
    k.set_defaults(func=_cmd_compile)

    b = _stage(sub, "bench", "measure simulator and analysis cost against the Pinocchio floor",
               "--quick")
    b.add_argument("--out", default="generated_reports", metavar="DIR",
                   help="folder for bench.json and bench.md "
                   "(default: generated_reports; e.g. --out /tmp/bench)")
    b.add_argument("--quick", action="store_true",
                   help="fewer repeats and shorter logs (default: off; e.g. --quick)")
    b.set_defaults(func=_cmd_bench)
    return p


def main(argv: list[str] | None = None) -> int:
    from pipeline.orphans import watch_from_environment

    watch_from_environment()  # a command another started in the background ends with it
    args = build_parser().parse_args(argv)
    # Python's warnings are collected (the filters stay as they are: a test's "error" still
    # raises): an error is then its one line, the warnings its bad input raised on the way
    # being symptoms of it; after a success each is one line, never a multi-line dump.
    with warnings.catch_warnings(record=True) as caught:
        try:
            code = args.func(args)
        except PipelineError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return exc.exit_code
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            return 130
    for line in dict.fromkeys(_warning_line(w) for w in caught):
        print(line, file=sys.stderr)
    return code


def _warning_line(w: warnings.WarningMessage) -> str:
    where = f"{Path(w.filename).name}:{w.lineno}"
    text = " ".join(str(w.message).split())
    return f"warning: {w.category.__name__}: {text} ({where})"
