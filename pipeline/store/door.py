"""The one door to logs and analyses: reuse if current, else make, written once.

An :class:`ArtefactStore` serves one command (a CLI stage, a claims evaluation, a sweep point,
a report): logs under ``logs``, analyses under ``out``.

- :meth:`~ArtefactStore.open_log`: a log verified (:func:`pipeline.logs.verify_log`) and
  hashed once per store, handed out as a :class:`~pipeline.logs.VerifiedLog` whose table is
  read lazily through the handle that was verified;
- :meth:`~ArtefactStore.run`: the log of a spec, reused when current
  (:func:`pipeline.store.validity.current_log`), else simulated under the folder's lock;
- :meth:`~ArtefactStore.analysis`: the analysis record of a log, compared with a run of the
  same robot when asked, reused when made from those logs by this code
  (:func:`pipeline.store.validity.current_analysis`), else computed and written under the
  folder's lock;
- :meth:`~ArtefactStore.import_log`: a foreign log imported under ``imported/<name>``, under
  the name's lock: the same import reused (:func:`pipeline.store.validity.import_is_current`),
  another refused unless forced.

No artefact is written through a symbolic link out of its folder (``logs``, ``out``).

A store keeps what it verified and hashed for its own life, one command: the files it hands
out are its inputs, not expected to change under it. A file it writes replaces its entry.
"""

from __future__ import annotations

import sys
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path

from pipeline.analysis.imported import analyze_imported, controller_key
from pipeline.analysis.record import write_analysis
from pipeline.analysis.schema import AnalysisRecord, CompleteRecord
from pipeline.analysis.stages import analyze_log, compare
from pipeline.artefact_paths import IMPORTED_FOLDER, analysis_path, check_contained, log_path
from pipeline.errors import LogError, PipelineError, RunFailed, SpecError
from pipeline.importer.mapping import ImportMapping
from pipeline.importer.run import (
    ImportOutcome,
    check_name,
    imported_log_path,
    prepare_import,
    write_import,
)
from pipeline.logs import VerifiedLog, verify_log
from pipeline.paths import display_path
from pipeline.progress import interactive, stage
from pipeline.provenance.keys import file_digest
from pipeline.spec import Spec
from pipeline.store.locks import folder_lock, remove_stale_temps
from pipeline.store.validity import (
    current_analysis,
    current_log,
    import_is_current,
    log_is_current,
)


@dataclass(frozen=True)
class StoredRun:
    """A verified log and whether it was reused (else simulated by this store)."""

    log: VerifiedLog
    reused: bool

    @property
    def spec(self) -> Spec:
        """The spec the log's metadata records (the claims read run parameters from it)."""
        return self.log.spec

    @property
    def path(self) -> Path:
        return self.log.path

    @property
    def meta(self):
        return self.log.meta


@dataclass(frozen=True)
class StoredAnalysis:
    """An analysis record (the content of analysis.json), where it is, whether reused."""

    record: AnalysisRecord
    path: Path
    reused: bool


def same_robot_key(log: VerifiedLog) -> tuple:
    """What makes two logs the same robot: the robot file's content, the camera frame the task
    is defined on, and the bus-inertia knob (it changes the model, architecture §2)."""
    r = log.meta.spec.get("robot", {})
    return log.meta.robot_hash, r.get("camera_frame"), r.get("bus_inertia_scale", 1.0)


def check_same_robot(log: VerifiedLog, against: VerifiedLog) -> None:
    """SpecError (exit 2) when ``against`` is a run of another robot: its lag-1 or ‖Δv‖ says
    nothing about this robot's step, so the comparison would mean nothing."""
    if same_robot_key(log) != same_robot_key(against):
        a, b = log.meta, against.meta
        ra, rb = a.spec.get("robot", {}), b.spec.get("robot", {})
        raise SpecError(
            f"--against {against.path}: a run of another robot ({b.robot_file}, bus inertia × "
            f"{rb.get('bus_inertia_scale', 1.0):g}, camera frame {rb.get('camera_frame')!r}, "
            f"file hash {b.robot_hash[:12]}) than {log.path} ({a.robot_file}, × "
            f"{ra.get('bus_inertia_scale', 1.0):g}, {ra.get('camera_frame')!r}, "
            f"{a.robot_hash[:12]}); compare runs of one robot")


def _check_end(log: VerifiedLog, expect: str | None) -> None:
    """RunFailed naming the log unless the run ended as ``expect`` (None: any end)."""
    m = log.meta
    if expect is not None and m.status != expect:
        raise RunFailed(f"{m.name}: expected a {expect} run, got {m.status}"
                        + (f" at {m.error}" if m.error else "")
                        + f"; log marked {m.status}: {display_path(log.path)}")


class ArtefactStore:
    """Logs under ``logs`` and analyses under ``out`` (the same folder for a sweep's points),
    for one command; see the module docstring."""

    def __init__(self, logs: Path | str = "logs", out: Path | str | None = None):
        self.logs = Path(logs)
        self.out = self.logs if out is None else Path(out)
        self._verified: dict[Path, VerifiedLog] = {}
        self._digests: dict[Path, str] = {}

    # -- reading --------------------------------------------------------------------------

    def digest(self, path: Path) -> str:
        """The SHA-256 of a file this store reads (a robot file), once per store."""
        key = Path(path).resolve()
        if key not in self._digests:
            self._digests[key] = file_digest(key)
        return self._digests[key]

    def open_log(self, path: Path | str) -> VerifiedLog:
        """The log at ``path``, verified against its own metadata and hashed, once per store:
        a LogError (exit 2) or LogDamaged (exit 1) naming the file otherwise."""
        key = Path(path).resolve()
        if key not in self._verified:
            self._verified[key] = verify_log(Path(path), digest=self.digest)
        return self._verified[key]

    def recorded_log(self, record: AnalysisRecord) -> VerifiedLog | None:
        """The log an analysis record names, verified, if it is still the one the record was
        made from (its SHA-256); None when it is gone, damaged or another log (re-run since):
        what is drawn from it would not be the analysed data."""
        path = Path(record.log)
        if not path.is_file():
            return None
        try:
            log = self.open_log(path)
        except PipelineError:
            return None
        return log if log.sha256 == record.log_sha256 else None

    def _forget(self, path: Path) -> None:
        self._verified.pop(Path(path).resolve(), None)

    # -- logs -----------------------------------------------------------------------------

    def log_path(self, spec: Spec) -> Path:
        return log_path(self.logs, spec.name)

    def current_run(self, spec: Spec) -> VerifiedLog | None:
        """The stored log of ``spec`` if it is current (this spec, robot and simulator, a
        finished run) and whole, verified; else None (a damaged one is made again)."""
        path = self.log_path(spec)
        if current_log(path, spec, self.digest) is None:
            return None
        try:
            log = self.open_log(path)
        except PipelineError:  # damaged since it was made: not current, made again
            self._forget(path)
            return None
        # The key again on the file that was verified: the path may have been replaced
        # between the footer's read and the verification.
        return log if log_is_current(log.meta, log.rows, spec, self.digest) else None

    def run(self, spec: Spec, expect: str | None = "complete", force: bool = False,
            quiet: bool = False) -> StoredRun:
        """The log of ``spec``, reused when current (unless ``force``), else simulated under
        the run folder's lock (a second process waits, then reuses). A run that did not end
        as ``expect`` (None: any end) is a RunFailed naming its log; the simulation is
        deterministic, so a reused run is not run again to fail the same way."""
        path = self.log_path(spec)
        check_contained(self.logs, path.parent)
        log = None if force else self.current_run(spec)
        reused = log is not None
        warnings: list[str] = []
        if log is None:
            with folder_lock(path.parent):
                remove_stale_temps(path.parent)
                log = None if force else self.current_run(spec)  # made meanwhile?
                reused = log is not None
                if log is None:
                    log, warnings = self._simulate(spec, quiet, expect)
        _check_end(log, expect)
        for w in warnings if not quiet else []:
            print(f"warning: {w}", file=sys.stderr)
        return StoredRun(log, reused)

    def _simulate(self, spec: Spec, quiet: bool, expect: str | None
                  ) -> tuple[VerifiedLog, list[str]]:
        """Run ``spec`` into its log; the log, verified, and the run's warnings. A run that
        did not end as ``expect`` fails its stage."""
        from pipeline.sim.run import run_spec

        path = self.log_path(spec)
        self._forget(path)
        with (nullcontext() if quiet else
              stage(f"mission {spec.name}", f"({spec.n_steps} steps) -> {display_path(path)}")
              ) as st:
            out = run_spec(spec, self.logs, progress=not quiet and interactive(),
                           raise_on_failure=False)
            log = self.open_log(out.path)
            _check_end(log, expect)
            if st is not None:
                st.done(out.status)
        return log, out.warnings

    # -- imports --------------------------------------------------------------------------

    def import_log(self, source: Path | str, mapping: ImportMapping, name: str,
                   resample_dt: float | None = None, here: Path | None = None,
                   force: bool = False) -> ImportOutcome:
        """Import ``source`` as ``<logs>/imported/<name>/run.parquet`` (pipeline.importer):
        read and keyed first, then under the name's lock (a second import of the name waits)
        the log there reused if it is this import and whole, refused (SpecError naming it) if
        it is another unless ``force``, else written; a killed import's temporary files are
        removed. ``here``: the mapping file's folder."""
        check_name(name)  # before the name makes a path
        path = imported_log_path(self.logs, name)
        check_contained(self.logs, path.parent)
        prep = prepare_import(source, mapping, name, resample_dt, here)
        with folder_lock(path.parent):
            remove_stale_temps(path.parent)
            held = None if force or not path.exists() else self._held_import(path)
            if held is not None and import_is_current(held, prep.key):
                return ImportOutcome.of_record(path, held.rows, held.meta.imported, True)
            if held is not None:
                imp = held.meta.imported or {}
                what = (f"an import of {imp['source']} (SHA-256 {imp['source_sha256'][:12]}…)"
                        if imp else "a log that is not an import")
                raise SpecError(f"--name {name}: {display_path(path)} holds {what}, not this "
                                f"one (another source, mapping, robot or importer): give "
                                f"--force to replace it, or another --name")
            self._forget(path)
            return write_import(prep, path)

    def _held_import(self, path: Path) -> VerifiedLog | None:
        """The log at ``path``, verified; None when it is damaged (made again in its place)."""
        try:
            return self.open_log(path)
        except PipelineError:
            self._forget(path)
            return None

    # -- analyses -------------------------------------------------------------------------

    def analysis_root(self, log: VerifiedLog) -> Path:
        """The folder of the log's analysis folder: ``out``, or ``out/imported`` for an
        imported log."""
        return self.out / IMPORTED_FOLDER if log.meta.origin == "imported" else self.out

    def analysis_path(self, log: VerifiedLog) -> Path:
        return analysis_path(self.analysis_root(log), log.spec.name)

    def current_analysis(self, log: VerifiedLog, against: VerifiedLog | None = None,
                         controller: Spec | None = None,
                         s_min_G_target: float | None = None) -> AnalysisRecord | None:
        """The stored analysis record of ``log`` (compared with ``against``, of an imported
        log with ``controller``, each exactly when one is given) if this analysis code made
        it from these logs, else None."""
        return current_analysis(self.analysis_path(log), log, against,
                                controller_key(controller) if controller is not None else None,
                                s_min_G_target)

    def analysis(self, log: VerifiedLog, against: VerifiedLog | None = None,
                 window_start: float | None = None, force: bool = False,
                 against_record: CompleteRecord | None = None, quiet: bool = False,
                 controller: Spec | None = None,
                 s_min_G_target: float | None = None) -> StoredAnalysis:
        """The analysis record of ``log``, compared with ``against`` (a run of the same robot,
        else a SpecError before any work), reused when current, else computed and written
        under the folder's lock. A chosen ``window_start`` is always computed (the stored
        record is of the default window). ``against_record``: ``against``'s own record, when
        the caller has it, so it is not analysed twice. ``controller``: the controller that
        flew an imported log, declared by the user (its data stages run without one).
        ``s_min_G_target``: the theory taken at the window's step of s_min_G nearest it (the
        note's regime, issue 50) instead of the median's; the record says so, and is current
        only for the same target (a default request after it analyses again, and replaces
        it: give such a run a spec of its own)."""
        imported = log.meta.origin == "imported"
        if controller is not None and not imported:
            raise SpecError(f"--controller: {log.path} is a simulated log, its controller is "
                            f"its spec's; a controller is declared for an imported log only")
        if imported and against is not None:
            raise LogError(f"{log.path}: an imported log is analysed alone (--against compares "
                           f"simulated runs; compare imported logs by their records)")
        if against is not None and against.meta.origin == "imported":
            raise LogError(f"--against {against.path}: an imported log is analysed alone")
        if against is not None:
            check_same_robot(log, against)
            for one in (log, against):
                if one.meta.status == "diverged":
                    raise LogError(f"{one.path}: a diverged log is not compared (--against): "
                                   f"only its divergence stage runs")
        path = self.analysis_path(log)
        check_contained(self.out, path.parent)
        if s_min_G_target is not None and imported:
            raise SpecError("--at-s-min-G: an imported log's theory is its declared "
                            "controller's, at its own representative step")
        fresh = force or window_start is not None
        old = None if fresh else self.current_analysis(log, against, controller, s_min_G_target)
        if old is not None:
            return StoredAnalysis(old, path, True)
        with folder_lock(path.parent):
            remove_stale_temps(path.parent)
            old = None if fresh else self.current_analysis(log, against, controller,
                                                           s_min_G_target)
            if old is not None:
                return StoredAnalysis(old, path, True)
            title = f"(against {against.spec.name})" if against is not None else ""
            with nullcontext() if quiet else stage(f"analysis {log.spec.name}", title):
                record = (analyze_imported(log, controller, window_start) if imported else
                          self._analyse(log, against, window_start, against_record,
                                        s_min_G_target))
            write_analysis(record, self.analysis_root(log))
        return StoredAnalysis(record, path, False)

    @staticmethod
    def _analyse(log: VerifiedLog, against: VerifiedLog | None, window_start: float | None,
                 against_record: CompleteRecord | None,
                 s_min_G_target: float | None = None) -> AnalysisRecord:
        record = analyze_log(log, window_start, s_min_G_target=s_min_G_target)
        if against is not None:
            other = (against_record if against_record is not None and window_start is None
                     else analyze_log(against, window_start))
            record = replace(record, comparison=compare(record, other, log.meta.spec,
                                                        against.meta.spec))
        return record


def import_log(source: Path | str, mapping: ImportMapping, name: str,
               logs: Path | str = "logs", resample_dt: float | None = None,
               here: Path | None = None, force: bool = False) -> ImportOutcome:
    """``python -m pipeline import``: :meth:`ArtefactStore.import_log` with a store of its own."""
    return ArtefactStore(logs).import_log(source, mapping, name, resample_dt, here, force)
