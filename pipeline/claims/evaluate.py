"""The claims register evaluated: run what is missing, measure every metric, compare, and
write ``claims.json`` (the reports render it as CLAIMS.md).

Statuses: PASS (a ``hold`` claim holds), FAIL (a ``hold`` claim does not: exit 1), OPEN (an
``open`` claim does not hold yet: listed with its measured value and reason, no failure),
NOW HOLDS (an ``open`` claim that holds: like a strict xfail, exit 1 until it is promoted to
``expect: hold``) and DEFERRED (a claim that reads a study, a Monte Carlo or a power study,
of which no current result of its file's full N exists: neither PASS nor FAIL, no failure;
it names the N that ran and the most confidence that N can show, docs/montecarlo.md). The
comparator is a table of operators; nothing is evaluated as code.

Studies (``studies``): ``read`` (the decision, `make all`) flies none and reads the current
result of each at its file's N where one exists; ``run`` (`make studies`, `make claims-ci`)
flies each at the N its register entry asks (its kept records reused), then reads it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.analysis.schema import AnalysisRecord, to_json, value_at
from pipeline.analysis.signals import lag1_autocorrelation
from pipeline.artefact_paths import IMPORTED_FOLDER, log_path
from pipeline.claims.record import CheckEval, ClaimEval, read_claims_json, write_claims_json
from pipeline.claims.register import (
    LOG_GROUPS,
    NUMERIC_OPS,
    OPERATORS,
    ClaimsFile,
    load_claims,
    montecarlo_path,
    needed_montecarlos,
    needed_runs,
    needed_sweeps,
    note_path,
    split_metric,
)
from pipeline.errors import SpecError
from pipeline.montecarlo.studies import FOLDERS, StudyResult, study_result
from pipeline.paths import display_path
from pipeline.provenance.keys import source_version
from pipeline.spec import load_spec, resolve_spec_path
from pipeline.store.door import ArtefactStore, StoredRun

if TYPE_CHECKING:
    from pipeline.verify.cross_check import CrossCheck


def log_statistic(run: StoredRun, start: int, group: str, stat: str) -> float:
    """A statistic of the logged reduced velocity v̆ over the analysis window.

    ripple: the largest period-2 amplitude of a component, RMS(Δ²x)/4 (an alternating
    a(−1)^k has Δ²x = 4a(−1)^k, a smooth signal almost none); step_rms: the largest RMS of
    Δx; rms; lag1_min / lag1_max: the extreme lag-1 autocorrelations (eq. 25) of the components.
    """
    x = run.log.columns(["v_breve"], start)["v_breve"][:, LOG_GROUPS[group]]
    if x.shape[1] == 0:
        raise SpecError(f"metric log.{group}.{stat}: the log {run.log.path} has no {group} "
                        "components (a six-joint arm has no null space)")
    if stat == "ripple":
        return float(np.max(np.sqrt(np.mean(np.diff(x, 2, axis=0) ** 2, axis=0)) / 4))
    if stat == "step_rms":
        return float(np.max(np.sqrt(np.mean(np.diff(x, axis=0) ** 2, axis=0))))
    if stat == "rms":
        return float(np.max(np.sqrt(np.mean(x**2, axis=0))))
    r1 = lag1_autocorrelation(x)
    return float(np.min(r1) if stat == "lag1_min" else np.max(r1))


def dig(obj: Any, path: str, what: str) -> Any:
    """:func:`pipeline.analysis.schema.value_at`, a missing key a SpecError naming ``what``."""
    try:
        value = value_at(obj, path)
    except KeyError as exc:
        raise SpecError(f"no key {exc.args[0]!r} in {what}") from None
    # A leaf as it is; a part of a record (a dataclass) as the JSON analysis.json holds.
    return to_json(value) if dataclasses.is_dataclass(value) else value


class Context:
    """Resolves metrics, running and analysing what the claims need, once."""

    def __init__(self, cf: ClaimsFile, out_dir: Path, studies: str = "read"):
        self.cf, self.out = cf, Path(out_dir)
        self.studies = studies
        self.logs = Path(cf.logs)  # relative to the working directory, like --out
        self.here = Path(cf.source).resolve().parent
        self.store = ArtefactStore(self.logs, self.out)
        self.runs: dict[str, StoredRun] = {}
        self.analyses: dict[str, AnalysisRecord] = {}
        self._cross: dict | None = None
        # The CrossCheck itself, for a report in this process (`pipeline all`).
        self.cross_check_result: CrossCheck | None = None
        self._baselines: dict | None = None
        self._sweeps: dict[str, tuple[dict, dict]] = {}
        self._jobs: dict = {}  # alias -> sweep.background.SweepJob, started by start_sweeps
        self._mc_jobs: dict = {}  # "kind:alias" -> sweep.background.BackgroundJob (a study)
        self._studies: dict[str, StudyResult] = {}
        self._note = None
        # Every artefact read or made, in order: with the outputs, the claims' key
        # (pipeline.store.validity.current_claims).
        self.files: list[Path] = []

    def _spec(self, name: str):
        return load_spec(self.cf.runs[name].spec, self.here)

    def prepare(self) -> None:
        for name in needed_runs(self.cf):
            ref = self.cf.runs[name]
            if ref.imported is not None:  # a log another tool wrote: opened, never made
                path = log_path(self.logs / IMPORTED_FOLDER, ref.imported)
                self.runs[name] = StoredRun(self.store.open_log(path), True)
                if self.runs[name].meta.origin != "imported":
                    raise SpecError(f"{self.cf.source}: run {name}: {path} is not an "
                                    f"imported log")
            else:
                self.runs[name] = self.store.run(self._spec(name), ref.expect)
            self.files.append(self.runs[name].path)
        for name in needed_runs(self.cf):
            ref = self.cf.runs[name]
            dep = ref.against
            controller = load_spec(ref.controller, self.here) if ref.controller else None
            done = self.store.analysis(
                self.runs[name].log, self.runs[dep].log if dep else None,
                against_record=self.analyses.get(dep) if dep else None,
                controller=controller, s_min_G_target=self._target(name))
            self.analyses[name] = done.record
            self.files.append(done.path)

    def _target(self, name: str) -> float | None:
        """Run ``name``'s at_s_min_G as a number: as given, or read from its source (the note,
        or a run analysed before it: needed_runs orders them)."""
        at = self.cf.runs[name].at_s_min_G
        if at is None or isinstance(at, float):
            return at
        value, _ = self.value(at)
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise SpecError(f"{self.cf.source}: run {name}: at_s_min_G {at!r} reads {value!r}, "
                            f"not a σ above 0")
        return float(value)

    def note(self):
        """The seed note's published values (the claims file's ``note:``), or None."""
        from pipeline.claims.seed_note import load_note

        if self.cf.note is None:
            return None
        if self._note is None:
            self._note = load_note(note_path(self.cf, self.cf.source))
        return self._note

    def cross_check(self) -> dict:
        if self._cross is None:
            from pipeline.progress import stage
            from pipeline.verify.cross_check import build_cross_check, write_cross_check_json
            from pipeline.verify.sources import EQUATIONS_MD

            with stage("cross-check", "(equations against code)"):
                cc = build_cross_check()
                self.files.append(write_cross_check_json(self.out, cc))
            self.cross_check_result = cc
            self.files += [EQUATIONS_MD] if EQUATIONS_MD.is_file() else []
            self._cross = {**cc.summary(), "source_version": cc.source_version}
        return self._cross

    def baselines(self) -> dict:
        if self._baselines is None:
            from pipeline.claims.baselines import (
                PINNED,
                TOLERANCES,
                baseline_names,
                ensure_report,
            )

            self._baselines = ensure_report(self.out)
            tolerances = [PINNED / TOLERANCES] if (PINNED / TOLERANCES).is_file() else []
            self.files += [self.out / "baselines.json", *tolerances,
                           *(log_path(PINNED, n) for n in baseline_names())]
        return self._baselines

    def start_sweeps(self) -> None:
        """Start every sweep the claims use that is not current, in the background (each its
        own process and Dask cluster), before the missions: they need only the kernels."""
        from pipeline.sweep.background import start_sweep

        for alias in needed_sweeps(self.cf):
            ref = self.cf.sweeps[alias]
            spec = str(resolve_spec_path(ref.spec, self.here))
            self._jobs[alias] = start_sweep(spec, ref.set, ref.name, self.logs / "sweeps",
                                            self.out / "sweeps", ref.workers)

    def start_montecarlos(self) -> None:
        """Start every Monte Carlo and power study the claims use in the background (each its
        own process and Dask cluster; the samples whose records are kept are not run again),
        when this evaluation flies the studies (``studies == "run"``)."""
        from pipeline.montecarlo.background import start_montecarlo

        if self.studies != "run":
            return
        for kind in FOLDERS:
            for alias in needed_montecarlos(self.cf, kind):
                ref = getattr(self.cf, kind)[alias]
                self._mc_jobs[f"{kind}:{alias}"] = start_montecarlo(
                    montecarlo_path(self.cf, ref), ref.samples, self.logs / FOLDERS[kind],
                    self.out / FOLDERS[kind], ref.workers, stage=kind)

    def stop_sweeps(self) -> None:
        for job in [*self._jobs.values(), *self._mc_jobs.values()]:
            job.stop()

    def study(self, alias: str, kind: str = "montecarlo") -> StudyResult:
        """A study of the claims (a Monte Carlo, or a power study): its current result of
        the N its entry asks, waited for when this evaluation flies it, or none (deferred)."""
        job = f"{kind}:{alias}"
        if job not in self._studies:
            from pipeline.montecarlo.background import wait_study

            ref = getattr(self.cf, kind)[alias]
            if job in self._mc_jobs:
                wait_study(self._mc_jobs[job])
            st = study_result(kind, montecarlo_path(self.cf, ref), ref.samples, self.out)
            self._studies[job] = st
            self.files += st.files
        return self._studies[job]

    def deferral(self, metric: str) -> str | None:
        """Why a claim reading ``metric`` is deferred (a study without a current result of its
        file's N), or None."""
        source, path = split_metric(metric)
        if source not in FOLDERS:
            return None
        st = self.study(path.partition(".")[0], source)
        return st.deferral() if st.deferred else None

    def sweep(self, alias: str) -> tuple[dict, dict]:
        if alias not in self._sweeps:
            from pipeline.sweep.background import finish_sweep

            ref = self.cf.sweeps[alias]
            self._sweeps[alias] = finish_sweep(self._jobs[alias], ref.key, ref.lag,
                                               ref.predicted, ref.unstable)
            self.files.append(Path(self._sweeps[alias][1]["file"]))  # the sweep's table
        return self._sweeps[alias]

    def value(self, metric: str) -> tuple[Any, dict]:
        """The value of ``SOURCE:PATH`` and its provenance."""
        source, path = split_metric(metric)
        if source == "note":
            key, _, column = path.partition(".")
            note = self.note()
            return note.value(key, column), {"source": source, "version": "—",
                                             "file": display_path(note.source)}
        if source == "sweep":
            alias, _, key = path.partition(".")
            bracket, prov = self.sweep(alias)
            return dig(bracket, key, f"the stability bracket of sweep {alias}"), prov
        if source in FOLDERS:
            alias, _, key = path.partition(".")
            st = self.study(alias, source)
            if st.result is None:  # deferred: nothing measured
                return None, st.provenance
            try:
                return dig(st.result, key, f"the {source} result {alias}"), st.provenance
            except SpecError:
                # Fewer samples than the file's N may not reach an entry (no failure yet to
                # count by part): not measured, the claim deferred. A field the result does
                # not have is the register's error, whatever ran.
                if st.deferred and key.split(".")[0] in st.result:
                    return None, st.provenance
                raise
        if source == "cross_check":
            cc = self.cross_check()
            prov = {"source": source, "version": cc["source_version"],
                    "file": display_path(self.out / "GNC" / "cross_check.json")}
            return dig(cc, path, "the cross-check summary"), prov
        if source == "baselines":
            b = self.baselines()
            prov = {"source": source, "version": b["sim_version"],
                    "file": display_path(self.out / "baselines.json")}
            return dig(b, path, "baselines.json"), prov
        run, record = self.runs[source], self.analyses[source]
        imp = run.meta.imported
        origin = ({} if imp is None else {
            "origin": f"imported {imp['format']} {imp['source']} (SHA-256 "
                      f"{imp['source_sha256'][:12]}…)"})
        prov = {"source": source, **origin, "spec": run.spec.name,
                "spec_hash": run.meta.spec_hash,
                "sim_version": run.meta.sim_version,
                "analysis_version": record.analysis_version,
                "log": display_path(run.path),
                "versions": ", ".join(f"{k} {v}" for k, v in
                                      sorted((run.meta.versions or {}).items()))}
        head, _, rest = path.partition(".")
        if head == "spec":
            return dig(run.spec.model_dump(mode="json"), rest, f"the spec of {source}"), prov
        if head == "log":
            group, stat = rest.split(".")
            start = record.window.start_step
            return log_statistic(run, start, group, stat), prov
        return dig(record, path, f"the analysis.json of {source}"), prov


def compare_values(op: str, value: Any, threshold: Any, rel_tol: float | None = None) -> bool:
    """Whether ``value op threshold`` holds; NaN never holds, nor does a number the data left
    undetermined (None: a lag-1 of a series without motion). ``close``: |value − threshold| ≤
    rel_tol·|threshold|."""
    fn = OPERATORS[op][0]
    if op in NUMERIC_OPS and (value is None or threshold is None):
        return False
    if op in ("eq", "ne"):
        return bool(fn(value, threshold))
    for x, what in ((value, "measured value"), (threshold, "threshold")):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise SpecError(f"operator {op} needs numbers, the {what} is "
                            f"{type(x).__name__} {x!r}"[:160])
    if math.isnan(value) or math.isnan(threshold):
        return False
    if op == "close":
        return bool(abs(value - threshold) <= rel_tol * abs(threshold))
    return bool(fn(value, threshold))


def evaluate(cf: ClaimsFile, ctx: Context) -> list[ClaimEval]:
    out = []
    for claim in cf.claims:
        evals, prov, deferred = [], [], []
        for k, chk in enumerate(claim.checks, 1):
            try:
                deferred += filter(None, (ctx.deferral(m) for m in
                                          (chk.metric, chk.threshold_metric) if m))
                value, p = ctx.value(chk.metric)
                prov.append(p)
                thr = chk.threshold
                if chk.threshold_metric:
                    thr, p2 = ctx.value(chk.threshold_metric)
                    prov.append(p2)
                ok = compare_values(chk.op, value, thr, chk.rel_tol)
            except SpecError as exc:
                raise SpecError(f"{cf.source}: claim {claim.id}: check {k}: metric "
                                f"{chk.metric}: {exc}") from None
            evals.append(CheckEval(chk, value, thr, ok))
        unique = [dict(t) for t in dict.fromkeys(tuple(sorted(p.items())) for p in prov)]
        why = "; ".join(dict.fromkeys(deferred))
        out.append(ClaimEval(claim, evals, unique,
                             f"deferred to `make studies`: {why}" if why else ""))
    return out


def seed_table(ctx: Context, claims: list[dict]) -> tuple[list, list]:
    """The note's evidence table beside the claims' runs of its columns (by run name: today's
    nominal and dt010, and the note's regime, issue 50), each cell judged by the evaluated
    ``claims`` (claims.json's), and where each column's theory was taken."""
    from pipeline.claims.seed_note import TABLE_COLUMNS, column_regimes, note_table

    note = ctx.note()
    if note is None:
        return [], []
    records = {c: ctx.analyses[c] for c in TABLE_COLUMNS if c in ctx.analyses}
    return note_table(note, records, claims), column_regimes(records)


@dataclass(frozen=True)
class ClaimsOutcome:
    """An evaluated register: what the reports render and the CLI reports."""

    claims_file: ClaimsFile
    results: list[ClaimEval]
    note_rows: list
    note_regimes: list  # seed_note.ColumnRegime: where each column's theory was taken
    # Claim id → the runs its checks read that left a joint range (eq. 42), in words.
    range_marks: dict[str, str]
    source_version: str
    record: Path  # claims.json
    files: tuple[Path, ...]  # every artefact the evaluation read or made (Context.files)
    cross_check: CrossCheck | None = None  # when a claim read it (`pipeline all` reuses it)

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.results)


def run_claims(claims: Path | str, out: Path, studies: str = "read") -> ClaimsOutcome:
    """Load the register (a path, or a name on the spec search path), run and analyse what
    it needs (the studies too when ``studies`` is ``run``), evaluate every claim and write
    ``claims.json``."""
    cf = load_claims(resolve_spec_path(claims))
    ctx = Context(cf, out, studies)
    try:
        ctx.start_sweeps()
        ctx.start_montecarlos()
        ctx.prepare()
        results = evaluate(cf, ctx)
    finally:
        ctx.stop_sweeps()  # one still running when a mission or a claim failed
    version = source_version()
    path = write_claims_json(results, cf, out, version)
    written = read_claims_json(path)
    rows, regimes = seed_table(ctx, written["claims"] if written else [])
    return ClaimsOutcome(cf, results, rows, regimes, range_marks(cf, ctx), version, path,
                         tuple(ctx.files), ctx.cross_check_result)


def range_marks(cf: ClaimsFile, ctx: Context) -> dict[str, str]:
    """Each claim that reads a run which left a joint range of its robot file (eq. 42): the
    mark its verdict carries, a finding on a trajectory the arm cannot fly."""
    from pipeline.analysis.joint_ranges import range_mark

    out = {}
    for claim in cf.claims:
        runs = dict.fromkeys(split_metric(m)[0] for k in claim.checks
                             for m in (k.metric, k.threshold_metric) if m)
        marks = [range_mark(run, ctx.analyses[run].joint_ranges) for run in runs
                 if run in ctx.analyses and hasattr(ctx.analyses[run], "joint_ranges")]
        if any(marks):
            out[claim.id] = "".join(marks).strip()
    return out

