"""``python -m pipeline report``: every report under the report folder, and the index page.

Reads each ``<out>/<name>/analysis.json`` (and the log it names), then writes the figures
(``figures/*.png``), the equation cross-check (``GNC/cross_check.{md,html}``), one mechanism
report per analysed pair (``<name>/mechanism.{md,html}``) and ``index.html`` linking them all,
with the claims register, baselines, benchmark and sweep pages when they exist.

Rendering is skipped when the reports are current (:func:`pipeline.store.validity.
current_report`: the same inputs, renderer and templates as last time; ``.report-key``).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

from pipeline.analysis.joint_ranges import excursion_words
from pipeline.analysis.record import read_analysis
from pipeline.analysis.schema import DivergedRecord, ImportedRecord
from pipeline.artefact_paths import ANALYSIS_FILE, CLAIMS_FILE, IMPORTED_FOLDER
from pipeline.atomic_files import atomic_write_text
from pipeline.claims.record import KIND_NAMES, kind_counts, read_claims_json
from pipeline.errors import LogError
from pipeline.orphans import exit_with_parent
from pipeline.provenance.keys import report_version
from pipeline.reports import figures as fg
from pipeline.reports.fixes import decisions, fix_tables
from pipeline.reports.mechanism import mechanism_context
from pipeline.reports.templating import rel, render
from pipeline.store.door import ArtefactStore
from pipeline.store.validity import REPORT_KEY_FILE, current_report, report_key
from pipeline.verify.cross_check import CrossCheck, build_cross_check, write_cross_check_json

KEY_FILE = REPORT_KEY_FILE  # the key of the last complete rendering
FIGURE_PROCESSES = 2


def load_runs(out: Path) -> list[fg.RunData]:
    """Every ``<out>/<run>/analysis.json``, read whole or refused (LogError naming the file and
    the key, exit 2): a damaged record is never dropped in silence. Each record's log, and its
    comparison's, through the artefact store: verified, and only the log it was made from."""
    store = ArtefactStore()
    runs = []
    for path in sorted(Path(out).glob("*/analysis.json")):
        rec = read_analysis(path)
        log = store.recorded_log(rec)
        comparison = getattr(rec, "comparison", None)
        against = store.recorded_log(comparison.other) if comparison is not None else None
        spec = log.meta.spec if log is not None else {}
        runs.append(fg.RunData(rec.spec_name, rec, log, spec, path.parent.name, against))
    return runs


def load_imported(out: Path) -> list[fg.RunData]:
    """Every ``<out>/imported/<name>/analysis.json`` (an imported log's record), read whole or
    refused like :func:`load_runs`; each named ``<name> (imported)`` wherever it is drawn."""
    store = ArtefactStore()
    runs = []
    for path in sorted((Path(out) / IMPORTED_FOLDER).glob(f"*/{ANALYSIS_FILE}")):
        rec = read_analysis(path)
        if not isinstance(rec, ImportedRecord):
            raise LogError(f"{path}: not an imported log's record (key origin missing)")
        log = store.recorded_log(rec)
        runs.append(fg.RunData(f"{rec.spec_name} (imported)", rec, log,
                               log.meta.spec if log is not None else {},
                               f"{IMPORTED_FOLDER}/{path.parent.name}"))
    return runs


def joint_range_rows(runs: list[fg.RunData]) -> list[dict]:
    """Each analysed run's time outside its joint ranges (eq. 42), with the spectral radius of
    its loop's map where it has one: a run that left a range is marked, and whether its loop
    is stable by its own map says whether the instability can be what drove it out."""
    rows = []
    for r in runs:
        th = getattr(r.record, "theory", None) or getattr(r.record, "damping", None)
        rho = getattr(th, "spectral_radius", None)
        rows.append({"name": r.name, "folder": r.folder, "left": r.record.joint_ranges.left,
                     "rho": rho, "words": excursion_words(r.record.joint_ranges)})
    return rows


def render_imported(out: Path, runs: list[fg.RunData]) -> list[Path]:
    """One page per imported log (``imported/<name>/imported.{md,html}``): its origin, what
    the data say, the declared controller's theory if any, and which stages ran and why."""
    written = []
    for r in runs:
        ctx = {"rec": r.record, "o": r.record.origin, "code_version": report_version(),
               "log_missing": r.log is None,
               "ranges": excursion_words(r.record.joint_ranges)}
        written += [render("imported.md.j2", out / r.folder / "imported.md", **ctx),
                    render("imported.html.j2", out / r.folder / "imported.html", **ctx)]
    return written


def figure_jobs(out: Path, runs: list[fg.RunData], imported: list[fg.RunData] = ()
                ) -> tuple[list[tuple[fg.Figure, Callable]], list[str]]:
    """Every figure of the report and the function that draws it (a picklable partial that
    takes the PNG's path), and what is left out and why. Imported logs are drawn where their
    data suffice (the lag-1 of each direction), named as imported."""
    jobs: list[tuple[fg.Figure, Callable]] = []
    skipped: list[str] = []
    # A diverged run (its analysis has no per-direction stage) gets its own growth figure,
    # not a place in the others, whose scales its runaway would swamp.
    diverged = [r for r in runs if isinstance(r.record, DivergedRecord)]
    runs = [r for r in runs if r not in diverged]
    logged = [r for r in runs if r.log is not None]
    # One palette for the whole report: a run is drawn alike in every figure.
    styles = fg.palette([r.name for r in [*runs, *diverged, *imported]])
    if len(logged) < len(runs):
        skipped.append("time-series figures leave out runs whose analysed log is missing, "
                       "damaged or re-run since (not the bytes the analysis read): "
                       + ", ".join(r.name for r in runs if r.log is None))
    global_figs = [
        (fg.Figure("figures/rates.png", "Bus angular rate and camera roll rate",
                   "‖ω_b‖ over the mission of the runs in which a mode rings (top), the bus "
                   "yaw rate v̆[2] and the camera roll rate v̆[8] over each run's last second, "
                   "per run: on the seed robot the period-2 ripple is in ω_b (the bus yaw), "
                   "on the servicer in the camera roll; with one step of delay both ring over "
                   "six steps."),
         partial(fg.rates, logged, styles=styles), logged),
        (fg.Figure("figures/lag1.png", "Lag-1 per direction",
                   "Lag-1 autocorrelation of each singular direction of Γ (★ the dominant one): "
                   "period-2 reads −1, smooth +1."
                   + (" Rows marked (imported) are logs another tool wrote, imported with "
                      "their origin recorded (their pages in imported/)." if imported else "")),
         partial(fg.lag1_directions, [*runs, *imported], styles=styles), [*runs, *imported]),
        (fg.Figure("figures/gamma_ramp.png", "γ ramp with the logged s_min_G",
                   "scale_by_svd with the spec's controller.base.conditioning knobs and the "
                   "logged (s_min_G, γ) of each step."),
         partial(fg.gamma_ramp, logged, styles=styles), logged),
        (fg.Figure("figures/conditioning.png", "Conditioning over the mission",
                   "σ_min of Γ and J⊕ and κ(Γ) per step, as logged."),
         partial(fg.conditioning, logged, styles=styles), logged),
        (fg.Figure("figures/dt_mu.png", "dt·μ_max over the mission",
                   "The online guard's dt·μ_max per step, with the forward-Euler bound 2."),
         partial(fg.dt_mu, logged, styles=styles), logged),
    ]
    global_figs.append((fg.Figure(
        "figures/stability_region.png", "Stability region and the eigenvalue locus",
        "Left: the (dt, μ) plane of one damping mode: unstable above dt·μ = 2 without delay "
        "and above dt·μ = 1 with one step of it; each run's fastest mode, marked by its loop "
        "(★ explicit, ◆ explicit with one step of delay, ✚ imex) and labelled by name, and "
        "every sweep point (μ_max at its dt, red squares where its measured lag-1 is "
        "negative). Right: the eigenvalues of the map as flown (eq. 34) as dt varies "
        "(colour), one locus per robot and loop, its own dt marked ×: without delay the "
        "dominant one leaves the unit circle at −1, with one step of it as a complex pair."),
        partial(fg.stability_region, runs,
                        sorted(Path(out).glob("sweeps/*/sweep.parquet")), styles=styles),
        runs))
    jobs += [(fig, draw) for fig, draw, inputs in global_figs if inputs]
    for r in diverged:
        if r.log is None:
            skipped.append(f"growth of {r.name}: its analysed log is missing, damaged or "
                           f"re-run since")
            continue
        jobs.append((fg.Figure(
            f"figures/growth_{r.folder}.png", f"Divergence of {r.name}",
            "The per-step change of ω_b on a log scale until the run was stopped, with the "
            "growth Φ's dominant eigenvalue predicts under each update order; the measured "
            "slope is the simulator's."), partial(fg.divergence_growth, r)))
    for r in [*runs, *diverged]:
        jobs.append((fg.Figure(
            f"figures/eig_{r.folder}.png", f"Discrete-map eigenvalues, {r.name}",
            f"Eigenvalues of the map of the loop as flown (eq. 34: its plant and delay) at "
            f"step {r.record.theory.step} of {r.name}, explicit and imex, against the unit "
            f"circle."), partial(fg.eigenvalues, r)))
    for r in runs:
        jobs.append((fg.Figure(
            f"figures/margins_{r.folder}.png", f"Margins of the fastest mode, {r.name}",
            "The fastest damping mode's loop as flown, L(z) = g z^−d/(z − 1), on the unit "
            "circle (a Nyquist plot) with its gain and phase margins against −1 (eq. 35), and "
            "the z-plane roots of every mode's loop."), partial(fg.mode_margins, r)))
    for r in runs:
        against = fg.against_log(r)
        if against is None:
            continue
        comp = r.record.comparison
        jobs.append((fg.Figure(
            f"figures/startup_{r.folder}.png", f"Start-up of the fastest mode, {r.name}",
            f"The fastest damping mode's coordinate over the first half-second of {r.name} and "
            f"of {comp.against}, and its alternating part on a log scale against the growth "
            f"Φ's dominant eigenvalue predicts per step, until the saturation holds it."),
            partial(fg.startup_growth, r, against, styles=styles)))
        jobs.append((fg.Figure(
            f"figures/psd_{r.folder}.png", f"Spectrum of the fastest mode, {r.name}",
            f"Power spectral density of the fastest damping mode's coordinate over the window "
            f"of {r.name} and of {comp.against}, with each run's Nyquist frequency: a "
            f"period-2 ripple is a peak at it."), partial(fg.mode_psd, r, against, styles=styles)))
    jobs += montecarlo_figure_jobs(out)
    for table in sorted(Path(out).glob("sweeps/*/sweep.parquet")):
        name = table.parent.name
        if fg.sweep_key(table) == "robot.bus_inertia_scale":
            jobs.append((fg.Figure(
                f"figures/sweep_{name}.png", f"Bus-inertia sweep, {name}",
                "Lag-1 of ω_b's dominant step component and ω_b's period-2 amplitude against "
                "the bus rigid body's I_zz,bus; the dashed line is the predicted crossing "
                "I_zz,bus = dt·D_b/2, where dt·μ_bus = 2 (the closed form's: drawn only where "
                "the bus CoM is on the first joint's axis)."), partial(fg.inertia_map, table)))
            continue
        jobs.append((fg.Figure(
            f"figures/sweep_{name}.png", f"dt-sweep stability map, {name}",
            f"Dominant lag-1 and dt·μ_max against mission.dt over sweep {name}; red squares are "
            "points above the bound 2, the dashed line dt*."), partial(fg.sweep_map, table)))
    return jobs, skipped


def montecarlo_tables(out: Path) -> list[Path]:
    """The Monte Carlo tables under ``out`` that have their verdict (a table without one is
    unfinished: the command writes the verdict last)."""
    return [t for t in sorted(Path(out).glob("montecarlo/*/montecarlo.parquet"))
            if (t.parent / "verdict.json").is_file()]


def _montecarlo_figures(table: Path) -> list[tuple[fg.Figure, Callable]]:
    from pipeline.reports import montecarlo_figures as mf

    name = table.parent.name
    searches = [(fg.Figure(
        f"figures/mc_{name}_{r.stem}.png", f"Least change of {r.stem[7:]}, Monte Carlo {name}",
        "The fraction of the samples that fail at each value of the knob, between the samples "
        "flown failing at or below it and those not yet flown meeting it there, with the "
        "least change every sample meets (eq. 43) and the fraction the target allows."),
        partial(mf.least_change, r)) for r in _current_search_files(table)]
    return [
        *searches,
        (fg.Figure(f"figures/mc_{name}_ecdf.png", f"Least gain margin, Monte Carlo {name}",
                   "The empirical distribution of each sample's least gain margin over its "
                   "damping modes (eq. 35), with the requirement: the fraction left of the "
                   "line misses it."), partial(mf.ecdf, table)),
        (fg.Figure(f"figures/mc_{name}_params.png", f"Margins by parameter, Monte Carlo {name}",
                   "Each sample's least gain, phase and delay margins (rows) against each "
                   "dispersed parameter (columns), passing samples blue, failing red crosses, "
                   "the requirement dashed."), partial(mf.parameters, table)),
        (fg.Figure(f"figures/mc_{name}_map.png", f"Pass/fail map, Monte Carlo {name}",
                   "Passing and failing samples over the two dispersed parameters the least "
                   "gain margin follows most (Spearman's rank correlation)."),
         partial(mf.pass_fail_map, table)),
    ]


def power_results(out: Path) -> list[Path]:
    """The detector-power results under ``out`` (``power/<name>/power.json``)."""
    return sorted(Path(out).glob("power/*/power.json"))


def _power_figure(result: Path) -> tuple[fg.Figure, Callable]:
    from pipeline.reports import montecarlo_figures as mf

    name = result.parent.name
    return (fg.Figure(f"figures/power_{name}.png", f"Detector power, {name}",
                      "Left: each detector's missed detections on the mission that rings and "
                      "false alarms on the one that does not, against the noise level (dotted: "
                      "where the missed detections reach one half). Right: the ringing "
                      "mission's ω_b period-2 amplitude as measured."),
            partial(mf.detector_power, result))


def montecarlo_figure_jobs(out: Path) -> list[tuple[fg.Figure, Callable]]:
    return ([job for table in montecarlo_tables(out) for job in _montecarlo_figures(table)]
            + [_power_figure(r) for r in power_results(out)])


def render_montecarlo(out: Path, figs: list[fg.Figure]) -> tuple[list[Path], list[dict]]:
    """One page per Monte Carlo (``montecarlo/<name>/montecarlo.{md,html}``), and the index's
    entries (its verdict and its page)."""
    from pipeline.montecarlo.studies import current_key
    from pipeline.montecarlo.verdict import file_ref, read_verdict

    drawn = {f.file for f in figs}
    written, entries = [], []
    for table in montecarlo_tables(out):
        v = read_verdict(table.parent / "verdict.json")
        now = current_key("montecarlo", v.name, v.samples, v.file)  # its file as it is now
        own = [{"file": f"../../{f.file}", "title": f.title, "caption": f.caption}
               for f, _ in _montecarlo_figures(table) if f.file in drawn]
        ctx = {"v": v, "figures": own, "table": rel(table),
               "verdict_file": rel(table.parent / "verdict.json"),
               "searches": _searches(table.parent, now),
               "fixes": _fixes(table.parent, out, now),
               "ref": file_ref(v),
               "code_version": report_version()}
        folder = table.parent
        written += [render("montecarlo.md.j2", folder / "montecarlo.md", **ctx),
                    render("montecarlo.html.j2", folder / "montecarlo.html", **ctx)]
        entries.append({"v": v, "page": folder.relative_to(out).as_posix() + "/montecarlo.html",
                        "current": bool(v.key) and v.key == now})
    return written, entries


def _current_search_files(table: Path) -> list[Path]:
    """The current search results beside a Monte Carlo's table (none if its verdict is
    damaged)."""
    from pipeline.montecarlo.studies import current_key
    from pipeline.montecarlo.verdict import read_verdict

    try:
        v = read_verdict(table.parent / "verdict.json")
    except LogError:
        return []
    now = current_key("montecarlo", v.name, v.samples, v.file)
    return [Path(d["path"]) for d in _searches(table.parent, now)]


def _searches(folder: Path, now: str | None) -> list[dict]:
    """The search results beside a Monte Carlo's verdict (``search-<knob>.json``) made for it
    as it is now (``now``: its current result key; None, its file gone: none)."""
    from pipeline.montecarlo.search import current_searches

    if now is None:
        return []
    return [{**d, "file": rel(Path(d["path"]))} for d in current_searches(folder, now)]


def _fixes(folder: Path, out: Path, now: str | None) -> dict | None:
    """The fixes flown through a Monte Carlo's samples (``fixes.json``), each judged from its
    own verdict as it is now (not current: made from other inputs or code, or its file written
    again since), the recommendation the cheapest current one shown; ``stale`` when the Monte
    Carlo itself has changed since they were flown (``now``: its current result key). None
    when none were flown."""
    from pipeline.montecarlo.fixes import FIXES_NAME, judged, read_fixes, recommend
    from pipeline.montecarlo.studies import is_current
    from pipeline.montecarlo.verdict import read_verdict
    from pipeline.provenance.keys import file_digest

    path = folder / FIXES_NAME
    if not path.is_file():
        return None
    try:
        result = read_fixes(path)
        stale = now is None or result.key != now
    except (OSError, ValueError, KeyError, TypeError):
        return {"rows": [], "recommended": None, "stale": True, "file": rel(path)}
    rows = []
    for r in result.fixes:
        f = None
        try:
            fv = read_verdict(Path(out) / "montecarlo" / r.montecarlo / "verdict.json")
            if (is_current("montecarlo", fv.name, fv.key, fv.samples, fv.file)
                    and file_digest(Path(r.file)) == r.file_digest):
                f = judged(r, fv)
        except (LogError, OSError):
            pass
        rows.append({"r": r.change, "f": f, "page": f"../{r.montecarlo}/montecarlo.html"})
    best = None if stale else recommend([row["f"] for row in rows if row["f"] is not None])
    return {"rows": rows, "recommended": best, "stale": stale, "file": rel(path)}


def render_power(out: Path, figs: list[fg.Figure]) -> tuple[list[Path], list[dict]]:
    """One page per detector-power study (``power/<name>/power.{md,html}``) and the index's
    entries."""
    from pipeline.montecarlo.power import read_power
    from pipeline.montecarlo.studies import is_current

    drawn = {f.file for f in figs}
    written, entries = [], []
    for result in power_results(out):
        r = read_power(result)
        fig, _ = _power_figure(result)
        own = ([{"file": f"../../{fig.file}", "title": fig.title, "caption": fig.caption}]
               if fig.file in drawn else [])
        ctx = {"r": r, "figures": own, "result": rel(result),
               "code_version": report_version()}
        written += [render("power.md.j2", result.parent / "power.md", **ctx),
                    render("power.html.j2", result.parent / "power.html", **ctx)]
        entries.append({"r": r, "page": result.parent.relative_to(out).as_posix()
                        + "/power.html", "current": is_current("power", r.name, r.key,
                                                                 r.samples, r.file)})
    return written, entries


def sweep_files(out: Path) -> list[dict]:
    """Every file of every sweep folder, for the index: the table (``sweep.parquet``, with its
    point count and swept key read from it) and any page beside it."""
    import pyarrow.parquet as pq

    rows = []
    for folder in sorted(p for p in (out / "sweeps").glob("*") if p.is_dir()):
        for f in sorted(folder.iterdir()):
            if not f.is_file() or f.name.startswith("."):
                continue
            what = ""
            if f.suffix == ".parquet":
                try:
                    what = (f"sweep table, {pq.read_metadata(f).num_rows} points over "
                            f"{fg.sweep_key(f) or 'unknown key'}")
                except (OSError, ValueError):
                    what = "sweep table (unreadable)"
            rows.append({"file": f.relative_to(out).as_posix(), "what": what})
    return rows


def _existing(out: Path, *names: str) -> list[str]:
    return [n for n in names if (out / n).is_file()]


def _remove_stale(out: Path, keep: set[Path]) -> None:
    """Reports of runs that no longer have an analysis, and figures not drawn this time."""
    stale = [p for p in out.glob("*/mechanism.*") if p not in keep]
    stale += [p for p in out.glob(f"{IMPORTED_FOLDER}/*/imported.*") if p not in keep]
    stale += [p for p in [*out.glob("montecarlo/*/montecarlo.*"), *out.glob("power/*/power.*")]
              if p not in keep and p.suffix in (".md", ".html")]
    stale += [p for p in (out / "figures").glob("*.png") if p not in keep]
    for p in stale:
        p.unlink(missing_ok=True)


def render_cross_check(out: Path, cc: CrossCheck) -> list[Path]:
    """``out/GNC/cross_check.{md,html,json}``."""
    folder = Path(out) / "GNC"
    ctx = {"cc": cc, "summary": cc.summary()}
    return [render("cross_check.md.j2", folder / "cross_check.md", **ctx),
            render("cross_check.html.j2", folder / "cross_check.html", **ctx),
            write_cross_check_json(out, cc)]


def render_all(out: Path, force: bool = False, cross_check: CrossCheck | None = None
               ) -> list[Path]:
    """Render every report into ``out``; returns the files written (index first), none when
    the reports are current and ``force`` is false. ``cross_check``: the equations checked
    against the code earlier in this process (by the claims of ``pipeline all``), else they
    are checked here.

    Refuses (exit 2) a folder that does not exist or holds nothing to report, and a damaged
    analysis.json or claims.json; removes the reports and figures of runs that are gone."""
    out = Path(out)
    if not out.is_dir():
        raise LogError(f"{out}: report folder not found (run `make all` or `python -m "
                       f"pipeline analyze LOG --out {out}` first)")
    if not force and current_report(out, out / KEY_FILE):
        print(f"report: up to date (same inputs and renderer) -> {out / 'index.html'}")
        return []
    key = report_key(out)  # before rendering: the inputs this rendering reads
    runs = load_runs(out)
    claims = read_claims_json(out / CLAIMS_FILE)
    sweep_tables = list(out.glob("sweeps/*/sweep.parquet"))
    if (not runs and not (out / IMPORTED_FOLDER).is_dir() and claims is None and not sweep_tables
            and not montecarlo_tables(out) and not power_results(out)):
        raise LogError(f"{out}: nothing to report: no */analysis.json, claims.json, "
                       f"sweeps/*/sweep.parquet or montecarlo/*/verdict.json")
    imported = load_imported(out)
    jobs, skipped = figure_jobs(out, runs, imported)
    # The figures are drawn on two processes while this one checks the equations against the
    # code and renders the mechanism reports (matplotlib is most of the reports' time; a
    # figure is one task).
    # Each figure process ends with this one, kill -9 included (pipeline.orphans).
    with ProcessPoolExecutor(FIGURE_PROCESSES, mp_context=mp.get_context("spawn"),
                             initializer=exit_with_parent, initargs=(os.getpid(),)) as pool:
        drawing = [(fig, pool.submit(fg.draw_or_why, draw, out / fig.file)) for fig, draw in jobs]
        cc = cross_check if cross_check is not None else build_cross_check()
        written = render_cross_check(out, cc) + render_imported(out, imported)
        tables = fix_tables(runs)
        written += [render("fixes.md.j2", out / "fixes.md", tables=tables,
                           code_version=report_version()),
                    render("fixes.html.j2", out / "fixes.html", tables=tables,
                           code_version=report_version())]
        mechanisms = []
        for r in runs:
            if getattr(r.record, "comparison", None) is None:  # single or diverged: no pair
                continue
            ctx = mechanism_context(r, runs, claims)
            folder = out / r.folder
            written += [render("mechanism.md.j2", folder / "mechanism.md", **ctx),
                        render("mechanism.html.j2", folder / "mechanism.html", **ctx)]
            mechanisms.append({"run": r, "verdict": ctx["verdict"], "against": ctx["names"][1]})
        figs = []
        for fig, fut in drawing:
            why = fut.result()
            figs += [] if why else [fig]
            skipped += [f"{fig.title}: {why}"] if why else []
    mc_written, montecarlos = render_montecarlo(out, figs)
    power_written, powers = render_power(out, figs)
    written += mc_written + power_written
    fig_files = {f.file for f in figs}
    for m in mechanisms:
        m["eig"] = f"figures/eig_{m['run'].folder}.png" in fig_files
    _remove_stale(out, {*written, *(out / f.file for f in figs)})
    pages = _existing(out, "CLAIMS.html", "CLAIMS.md", CLAIMS_FILE, "baselines.md",
                      "baselines.json", "bench.md", "bench.json", "ci/CLAIMS.html",
                      "ci/CLAIMS.md", "ci/claims.json")
    sweeps = sweep_files(out)
    index = render("index.html.j2", out / "index.html", runs=runs, mechanisms=mechanisms,
                   ranges=joint_range_rows([*runs, *imported]),
                   imported=imported, tables=tables, decisions=decisions(
                       runs, [m["v"] for m in montecarlos if m["current"]]),
                   figures=figs, skipped=skipped, cc=cc.summary(), claims=claims,
                   kind_counts=kind_counts(claims) if claims else "", kind_names=KIND_NAMES,
                   pages=pages, sweeps=sweeps, montecarlos=montecarlos, powers=powers,
                   code_version=report_version())
    for s in skipped:
        print(f"note: {s}", file=sys.stderr)
    atomic_write_text(out / KEY_FILE, key)  # last: a rendering cut short is redone
    print(f"report: {len(mechanisms)} mechanism reports, {len(figs)} figures, cross-check "
          f"{cc.summary()['pass']}/{cc.summary()['rows']} PASS -> {index}")
    return [index, *written]

