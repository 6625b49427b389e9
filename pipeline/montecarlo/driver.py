"""``python -m pipeline montecarlo FILE``: draw the samples, run them on Dask, write the table
and the verdict; ``--sample I`` runs one sample alone and writes its log (eqs. 38, 39)."""

from __future__ import annotations

import argparse
import signal
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING

from pipeline.atomic_files import atomic_write_text
from pipeline.errors import RunFailed
from pipeline.montecarlo.dispersions import Dispersion
from pipeline.montecarlo.plan import MonteCarlo, plan_montecarlo, result_key

# The samples' task and the verdict import the simulator and the analysis (two seconds):
# imported where a sample runs or a verdict is judged, after the file is checked, so that a
# bad file's one-line error does not wait for them.
if TYPE_CHECKING:
    from pipeline.montecarlo.verdict import MonteCarloVerdict, RequirementWords


def describe(d: Dispersion) -> str:
    """A dispersion in words, for the table of the report."""
    if d.dist == "choice":
        return f"one of {', '.join(f'{v:g}' for v in d.values)}, equally likely"
    if d.dist == "seed":
        return "a seed of the sample's own, from its stream"
    cut = f", truncated at ±{d.truncate:g}σ" if d.truncate else ""
    if d.low is not None:
        return f"uniform on [{d.low:g}, {d.high:g}]"
    if d.rel is not None:
        spread = d.rel if isinstance(d.rel, list) else [d.rel]
        text = ", ".join(f"{r:g}" for r in spread)
        form = (f"×(1 ± [{text}])" if d.dist == "uniform" else f"×(1 + N(0, [{text}]²))")
    else:
        spread = d.sd if d.dist == "normal" else d.half_width
        s = spread if isinstance(spread, list) else [spread]
        text = ", ".join(f"{x:g}" for x in s)
        form = f"+ U(±[{text}])" if d.dist == "uniform" else f"+ N(0, [{text}]²)"
    turn = f", principal axes turned {d.axes_deg:g}°" if d.axes_deg else ""
    return f"{d.dist} {form}{cut}{turn}"


def requirement_of(mc: MonteCarlo) -> RequirementWords:
    from pipeline.montecarlo.verdict import RequirementWords

    r, plant = mc.base.requirements, mc.base.mission.plant
    drawn = any(k == "mission.plant.delay_steps" or k.startswith("mission.plant.timing.")
                for k in mc.config.dispersions)
    timed = plant.timing is not None or "mission.plant.timing" in mc.config.set
    delay = ("the delay as drawn" + (" (its longest, eq. 41)" if timed else "") if drawn
             else f"{plant.delay_steps} step(s) of delay")
    loop = ("the simulator's update (reduced plant)" if plant.model == "reduced" else
            f"the sampled-data plant, {delay}")
    if plant.model == "sampled" and (drawn or plant.delay_steps or timed):
        loop += ("; the whole steps of delay held in steps (a computation delay of one period)"
                 + (f", the arrival and jitter in seconds (a transport latency, counted in "
                    f"steps of {1e3 * mc.config.latency_step:g} ms)" if mc.config.latency_step
                    else ", the arrival and jitter in steps" if timed else ""))
    return RequirementWords(r.gain_margin_db, r.phase_margin_deg, r.delay_margin_steps,
                            mc.config.ripple_max, loop)


def run_montecarlo(mc: MonteCarlo, root: Path, client, progress: bool = False,
                   worker_timeout: float = 300.0, jobs=None) -> list[dict]:
    """Every sample on ``client`` (:func:`pipeline.sweep.driver.execute_tasks`)."""
    from pipeline.montecarlo.task import errored_record, sample_task
    from pipeline.sweep.driver import execute_tasks

    samples = {s.name: s for s in mc.samples}
    ripple = mc.config.ripple_max

    def submit(name: str, topic: str, key: str):
        s = samples[name]
        return client.submit(sample_task, s.spec, s.index, list(s.seed), s.draws, ripple,
                             str(root), topic, pure=False, key=key)

    def failed(name: str, error: str) -> dict:
        s = samples[name]
        return errored_record(name, s.index, list(s.seed), s.spec.spec_hash, s.draws, error)

    return execute_tasks(mc.name, list(samples), submit, failed,
                         lambda rec: rec["status"] != "error", client, progress,
                         worker_timeout, jobs, kind="montecarlo", unit="sample")


def summary_text(v: MonteCarloVerdict, table: Path) -> str:
    lines = [f"montecarlo {v.name}: {v.statement}",
             f"  requirement: GM ≥ {v.requirement.gain_margin_db:g} dB, PM ≥ "
             f"{v.requirement.phase_margin_deg:g}°, DM ≥ {v.requirement.delay_margin_steps:g} "
             f"step, no unstable mode, ω_b period-2 amplitude ≤ {v.requirement.ripple_max:g} "
             f"rad/s, on {v.requirement.loop}"]
    if v.fails_by_part:
        lines.append("  failing: " + ", ".join(f"{k} {n}" for k, n in
                                               sorted(v.fails_by_part.items())))
    from pipeline.montecarlo.verdict import file_ref

    lines.append("  worst samples (re-run one alone: python -m pipeline montecarlo "
                 f"{file_ref(v)} --sample I):")
    for w in v.worst[:5]:
        draws = ", ".join(f"{k} {int(x) if k.endswith('.seed') else f'{x:.4g}'}"
                          for k, x in w.draws.items() if not k.endswith(".redraws"))
        lines.append(f"    {w.index}: {'pass' if w.passes else 'FAIL (' + '; '.join(w.fails) + ')'}"
                     f", least GM {w.gain_margin_db:.3g} dB ({w.worst_mode}), seed {w.seed}; "
                     f"{draws}")
    lines.append(f"  {v.samples} samples ({v.simulated} run now, the others kept), "
                 f"{v.wall_s:.1f} s wall -> {table}")
    return "\n".join(lines)


def _prepare(args: argparse.Namespace, mc: MonteCarlo):
    """(the records' folder, the results' folder, the cluster's options) of a command that
    flies ``mc``'s samples, both folders checked writable and owned (before the cluster
    starts: a refusal touches nothing)."""
    from pipeline.montecarlo.owner import check_start
    from pipeline.sweep.cluster import WORKER_TIMEOUT, ClusterOptions
    from pipeline.sweep.driver import check_writable

    root = Path(args.logs).resolve() / mc.name
    out = Path(args.out).resolve() / mc.name
    for folder in (root, out):
        check_writable(folder)
    options = ClusterOptions(
        scheduler=args.scheduler, workers=args.workers, slurm=args.slurm,
        slurm_log_dir=root.parent / ".slurm",
        worker_timeout=args.worker_timeout or WORKER_TIMEOUT, lifetime=args.lifetime)
    check_start("montecarlo", mc.name, mc.path, (root, out), options, mc.seconds,
                [s.spec.name for s in mc.samples], args.force)
    return root, out, options


def montecarlo_command(args: argparse.Namespace) -> int:
    if args.sample is not None:
        return run_one(args)
    mc = plan_montecarlo(args.file, args.samples)
    from pipeline.montecarlo.owner import claim_folders
    from pipeline.montecarlo.task import cached_record
    from pipeline.montecarlo.verdict import (
        TABLE_NAME,
        VERDICT_NAME,
        judge,
        make_table,
        verdict_json,
    )
    from pipeline.provenance.keys import sample_version
    from pipeline.sweep.cluster import open_client
    from pipeline.sweep.driver import _raise_stop, _Stop
    from pipeline.sweep.results import write_table

    root, out, options = _prepare(args, mc)
    t0 = time.perf_counter()
    previous = {s: signal.signal(s, _raise_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with open_client(options) as session:
            # Claimed once the cluster answers: a bad --scheduler leaves no folder behind.
            claim_folders("montecarlo", mc.name, mc.path, (root, out), args.force)
            records = run_montecarlo(mc, root, session.client, sys.stderr.isatty(),
                                     options.worker_timeout, session.jobs)
    except _Stop as stop:
        from pipeline.sweep.driver import Interrupted

        kept = sum(cached_record(root, s.spec, mc.config.ripple_max) is not None
                   for s in mc.samples)
        name = signal.Signals(stop.signum).name
        raise Interrupted(f"montecarlo {mc.name}: stopped by {name}: {kept} of "
                          f"{len(mc.samples)} samples have a kept record in {root}, which the "
                          "same command reuses; no table written", stop.signum) from None
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    wall = time.perf_counter() - t0
    df = make_table(records)
    v = replace(judge(df, mc.name, mc.config, mc.base,
                      {k: describe(d) for k, d in sorted(mc.config.dispersions.items())},
                      requirement_of(mc), wall),
                key=result_key(mc.path, len(mc.samples)), file=str(Path(mc.path).resolve()))
    out.mkdir(parents=True, exist_ok=True)
    meta = {"pipeline.montecarlo": mc.name, "pipeline.mission": mc.base.name,
            "pipeline.base_spec_hash": mc.base.spec_hash, "pipeline.sample_version":
            sample_version(), "pipeline.log_dir": str(root)}
    # The verdict last: a table without its verdict is seen as unfinished.
    table = write_table(df, out / TABLE_NAME, meta)
    atomic_write_text(out / VERDICT_NAME, verdict_json(v))
    print(summary_text(v, table))
    if v.errored:
        raise RunFailed(f"montecarlo {mc.name}: {v.errored} of {v.samples} samples did not "
                        "finish; no verdict")
    return 0


def run_one(args: argparse.Namespace) -> int:
    """One sample alone (``--sample I``): drawn from its own stream, run into a log through
    the artefact store, judged, and its log's digest set beside the kept record's."""
    from pipeline.montecarlo.plan import draw_one

    mc, s = draw_one(args.file, args.sample)
    from pipeline.montecarlo.owner import claim_folders
    from pipeline.montecarlo.sample import judge_columns, log_digest
    from pipeline.montecarlo.task import cached_record, damaged
    from pipeline.store.door import ArtefactStore

    root = Path(args.logs).resolve() / mc.name
    claim_folders("montecarlo", mc.name, mc.path, (root,), args.force)
    store = ArtefactStore(root)
    run = store.run(s.spec, expect=None)
    cols = run.log.columns(run.log.column_names())
    digest = log_digest(cols)
    rec = judge_columns(s, cols, run.log.meta.status, run.log.meta.error or "",
                        mc.config.ripple_max)
    kept = cached_record(root, s.spec, mc.config.ripple_max)
    print(f"montecarlo {mc.name} sample {s.index} (seed {list(s.seed)}): "
          f"{'passes' if rec.passes else 'FAILS: ' + '; '.join(rec.fails)}; least GM "
          f"{rec.gain_margin_db:.4g} dB ({rec.worst_mode}), PM {rec.phase_margin_deg:.4g}°, "
          f"DM {rec.delay_margin_steps:.4g} steps, ρ {rec.spectral_radius:.6g}, ω_b ripple "
          f"{rec.ripple:.3g} rad/s -> {run.path}")
    print("  draws: " + ", ".join(f"{k} {x!r}" for k, x in s.draws.items()))
    if kept is None:
        why = damaged(root, s.spec.name)
        if why is not None:
            raise RunFailed(f"montecarlo {mc.name} sample {s.index}: its kept record cannot be "
                            f"compared with ({why})")
        print(f"  log digest {digest[:16]}…; no kept record of this sample to compare with")
        return 0
    same = kept["log_digest"] == digest
    print(f"  log digest {digest[:16]}… {'=' if same else '≠'} the Monte Carlo's record "
          f"{kept['log_digest'][:16]}…: " + ("the same bits" if same else "NOT the same bits"))
    if not same:
        raise RunFailed(f"montecarlo {mc.name} sample {s.index}: its log is not the bits the "
                        "Monte Carlo recorded")
    return 0


def search_command(args: argparse.Namespace) -> int:
    """``python -m pipeline search FILE --knob KNOB``: the least change of the knob that every
    sample of the Monte Carlo meets, on its own draws (eq. 43), written to
    ``<out>/<montecarlo>/search-<knob>.json``."""
    from pipeline.errors import SpecError
    from pipeline.montecarlo.plan import nominal_spec, nominal_value
    from pipeline.montecarlo.search import KNOBS

    if args.knob not in KNOBS:
        raise SpecError(f"--knob {args.knob}: not a knob the search moves (one of "
                        f"{', '.join(KNOBS)})")
    mc = plan_montecarlo(args.file, args.samples)
    drawn = mc.config.dispersions.get(args.knob)
    if drawn is not None and drawn.rel is None:
        # Each sample's draw would replace the knob's value: every value flies the same.
        raise SpecError(f"{mc.path}: field dispersions.{args.knob}: the search moves this knob's "
                        "nominal, which a draw of its own (not relative to it) overrides")
    nominal = float(nominal_value(nominal_spec(mc.base, mc.config), args.knob,
                                  f"--knob {args.knob}"))
    return _search(args, mc, nominal)


def _least_step(mc: MonteCarlo, knob: str):
    """Where the knob is the step and the latency is held in seconds (``latency_step``), the
    least step each sample's arrival and jitter fit in (eq. 41: the command arrives within the
    step), a billionth above; None otherwise (any step)."""
    if knob != "mission.dt" or mc.config.latency_step is None:
        return None
    by_index = {s.index: s.spec for s in mc.samples}

    def least(i: int) -> float:
        timing = by_index[i].mission.plant.timing
        if timing is None:
            return 0.0
        return (timing.delay_fraction + timing.jitter) * by_index[i].mission.dt * (1 + 1e-9)
    return least


def _search(args: argparse.Namespace, mc: MonteCarlo, nominal: float) -> int:
    from pipeline.montecarlo.owner import claim_folders
    from pipeline.montecarlo.plan import derive
    from pipeline.montecarlo.sealed import sealed_json
    from pipeline.montecarlo.search import (
        KNOBS,
        Outcome,
        SearchResult,
        least_change,
        search_key,
        statement,
    )
    from pipeline.montecarlo.verdict import judge, make_table
    from pipeline.sweep.cluster import open_client

    knob = args.knob
    root, out, options = _prepare(args, mc)
    searched = root / f"search-{knob}"
    by_index = {s.index: s for s in mc.samples}
    t0 = time.perf_counter()
    with open_client(options) as session:
        claim_folders("montecarlo", mc.name, mc.path, (root, out), args.force)

        def fly(value: float, which: list[int]) -> dict:
            if value == nominal:  # the Monte Carlo's own samples and kept records
                sub, folder = replace(mc, samples=[by_index[i] for i in which]), root
            else:
                name = f"{mc.name}@{value:.9g}"
                sub, folder = derive(mc, {knob: value}, name, which), searched / name
            records = run_montecarlo(sub, folder, session.client, sys.stderr.isatty(),
                                     options.worker_timeout, session.jobs)
            bad = [r for r in records if r["status"] == "error"]
            if bad:
                raise RunFailed(f"search {mc.name} {knob} = {value:.9g}: sample "
                                f"{bad[0]['index']} did not finish ({bad[0]['error']}); the "
                                "same command resumes from the kept records")
            fails = sum(not r["passes"] for r in records)
            print(f"search {mc.name}: {knob} = {value:.9g}: {len(records)} samples, {fails} "
                  "failing", file=sys.stderr)
            return {int(r["index"]): Outcome(bool(r["passes"]), float(r["gain_margin_db"]))
                    for r in records}

        found = replace(least_change(nominal, sorted(by_index),
                                     mc.base.requirements.gain_margin_db, fly,
                                     seed=mc.config.seed, floor=_least_step(mc, knob)),
                        knob=knob)
        p, c = mc.target.p, mc.target.confidence
        certified, words, cost = statement(found, p, c)
        verification = ""
        if found.chosen is not None and not found.monotone:
            fresh = derive(mc, {knob: found.chosen}, f"{mc.name}@{found.chosen:.9g}-fresh",
                           seed=mc.config.seed + 1)
            recs = run_montecarlo(fresh, searched / fresh.name, session.client,
                                  sys.stderr.isatty(), options.worker_timeout, session.jobs)
            v = judge(make_table(recs), fresh.name, fresh.config, fresh.base, {},
                      requirement_of(fresh), 0.0)
            verification = (f"a fresh Monte Carlo at {knob} = {found.chosen:.6g} (seed "
                            f"{fresh.config.seed}): {v.statement}")
            certified = bool(v.shown)
    result = SearchResult(
        montecarlo=mc.name, knob=knob, knob_words=KNOBS[knob], loop=requirement_of(mc).loop,
        required_gain_margin_db=mc.base.requirements.gain_margin_db, target_p=p,
        confidence=c, risk=found.risk(p), certified=certified, statement=words, cost=cost,
        verification=verification, search=found, wall_s=time.perf_counter() - t0,
        key=search_key(result_key(mc.path, len(mc.samples)), knob),
        file=str(Path(mc.path).resolve()))
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"search-{knob}.json"
    atomic_write_text(target, sealed_json(asdict(result), indent=1))
    print(f"search {mc.name} {knob}: {words}" + (f"; cost: {cost}" if cost else "")
          + (f"; {verification}" if verification else "") + f" -> {target}")
    return 0


def fixes_command(args: argparse.Namespace) -> int:
    """``python -m pipeline fixes FILE``: each fix of the Monte Carlo's loop flown through its
    samples (:mod:`pipeline.montecarlo.fixes`), after the Monte Carlo and its searches."""
    from pipeline.errors import SpecError
    from pipeline.montecarlo.fixes import (
        FIXES_NAME,
        FixesResult,
        FixRecord,
        fix_changes,
        judged,
        recommend,
        write_fix_file,
        write_fixes,
    )
    from pipeline.montecarlo.search import current_searches
    from pipeline.montecarlo.studies import is_current
    from pipeline.montecarlo.verdict import VERDICT_NAME, read_verdict
    from pipeline.provenance.keys import file_digest

    mc = plan_montecarlo(args.file, args.samples)
    out = Path(args.out).resolve()
    verdict_path = out / mc.name / VERDICT_NAME
    v = read_verdict(verdict_path) if verdict_path.is_file() else None
    if v is None or not is_current("montecarlo", v.name, v.key, v.samples, v.file) or \
            v.samples != len(mc.samples):
        raise SpecError(f"{verdict_path}: no current verdict of {len(mc.samples)} samples; "
                        f"fly it first: python -m pipeline montecarlo {args.file}"
                        + (f" --samples {args.samples}" if args.samples else ""))
    if v.shown:
        print(f"fixes {mc.name}: its verdict shows the target as flown: nothing to fix")
        return 0
    key = result_key(mc.path, len(mc.samples))
    records, flown = [], []
    for fix in fix_changes(mc, current_searches(out / mc.name, key)):
        path = write_fix_file(mc, fix, out / mc.name / "fixes")
        montecarlo_command(argparse.Namespace(**{**vars(args), "file": str(path),
                                                 "sample": None}))
        record = FixRecord(fix, path.stem, str(path), file_digest(path))
        records.append(record)
        flown.append(judged(record, read_verdict(out / path.stem / VERDICT_NAME)))
    write_fixes(out / mc.name / FIXES_NAME, FixesResult(mc.name, key, records))
    for f in flown:
        gm = ("none" if f.worst_gain_margin_db is None else
              f"{f.worst_gain_margin_db:.3g} dB ({f.worst_mode})")
        print(f"fix {f.words}: {'shown' if f.shown else 'NOT shown'}: {f.statement}; worst "
              f"sample's least gain margin {gm}; {f.steps_per_s:.4g} control steps per second")
    best = recommend(flown)
    print(f"fixes {mc.name}: " + (f"recommended: {best.words}" if best else
                                  "no fix flown shows the target across the dispersions")
          + f" -> {out / mc.name / FIXES_NAME}")
    return 0
