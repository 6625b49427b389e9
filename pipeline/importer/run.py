"""Import a foreign log: ``<logs>/imported/<name>/run.parquet`` (``python -m pipeline import``).

The steps, each refusing with a one-line SpecError naming the field or the file (exit 2):
read t, q and v as the mapping says (:mod:`pipeline.importer.readers`); check that q and v
describe one motion in the declared conventions and in no better one
(:mod:`pipeline.importer.consistency`, eq. 33); convert to the project's conventions
(:mod:`pipeline.importer.conventions`); check the time base, or resample on request
(:mod:`pipeline.importer.timebase`); rebuild the conditioning columns from q with the
robot's own kernels; write the log atomically. The artefact store runs them under its rules
(:meth:`pipeline.store.door.ArtefactStore.import_log`: one lock per name, the same import
reused, another refused without ``--force``); the source's hash is of the bytes parsed.

An imported log holds ``step``, ``t`` (k·dt), ``q``, ``v`` and the rebuilt σ columns
(``s_min_G``, ``kappa_G``, ``s_min_J``, ``kappa_J``), never a controller's column: what the
controller did is not in the data. Its metadata spec holds the robot block and the step
only, and ``pipeline.origin = imported`` with the import record (the source file's hash and
format, the mapping, the conventions, the time base, the consistency check).
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline import artefact_paths
from pipeline.errors import SpecError
from pipeline.importer.bags import read_bag
from pipeline.importer.consistency import check_conventions
from pipeline.importer.conventions import Conventions
from pipeline.importer.mapping import ImportMapping, import_spec, robot_block
from pipeline.importer.plausibility import check_joint_limits
from pipeline.importer.readers import READERS, RawLog, read_bytes
from pipeline.importer.timebase import TimeBase, even_time_base, resample
from pipeline.joint_ranges import JointRanges, outside
from pipeline.log_layout import JOINT_EXCESS, OUTSIDE_JOINT_RANGE
from pipeline.logs import S_MIN_G_REBUILT, S_MIN_G_SOURCE, LogMeta, log_metadata, write_table
from pipeline.paths import display_path
from pipeline.provenance.keys import (
    SIM_LIBRARIES,
    file_digest,
    import_version,
    library_versions,
)
from pipeline.shapes import RobotShape
from pipeline.sim.linalg import svd_right_sequence
from pipeline.sim.robot import GiordanoRobot
from pipeline.sim.robot_file import robot_shape
from pipeline.spec import RobotSpec, Spec, spec_hash_of

NAME = re.compile(r"[A-Za-z0-9_.-]+")
IMPORTED_VERSION = "imported"  # a log's sim_version when no simulator of this project made it
SIGMA_COLUMNS = ("s_min_G", "kappa_G", "s_min_J", "kappa_J")


@dataclass(frozen=True)
class ImportOutcome:
    """What an import wrote, or found already written (``reused``), as the CLI reports it."""

    path: Path
    rows: int
    time: TimeBase
    conventions: str  # the declared conventions, described
    median_ratio: float  # the consistency check's median residual over its bound (eq. 33)
    robot: str  # where the robot block came from
    reused: bool = False

    @classmethod
    def of_record(cls, path: Path, rows: int, record: dict, reused: bool) -> ImportOutcome:
        return cls(path, rows, TimeBase(**record["time"]),
                   Conventions(**record["conventions"]).describe(),
                   record["consistency"]["median_ratio"], record["robot_from"], reused)


def imported_log_path(logs: Path | str, name: str) -> Path:
    return artefact_paths.log_path(Path(logs) / artefact_paths.IMPORTED_FOLDER, name)


def _stamps(raw_t: np.ndarray | None, mapping: ImportMapping, n: int, source: Path
            ) -> tuple[np.ndarray, float]:
    if raw_t is not None:
        if mapping.dt is not None:
            raise SpecError(f"{source}: field dt: the log has time stamps ({mapping.time}); "
                            f"give dt only for a log without them (time: null)")
        return raw_t, 0.0
    if mapping.dt is None:
        raise SpecError(f"{source}: field time: the log has no time stamps: give its step "
                        f"(--dt)")
    return np.arange(n) * mapping.dt, 0.0


MAX_NAME = 100


@dataclass(frozen=True)
class PreparedImport:
    """A foreign log read and keyed, not yet checked or written (:func:`prepare_import`)."""

    source: Path
    name: str
    fmt: str
    mapping: ImportMapping
    robot: RobotSpec
    robot_from: str
    robot_here: Path | None
    model_robot: GiordanoRobot
    raw: RawLog
    source_sha256: str
    resample_dt: float | None
    key: str  # what the imported log is made from (:func:`import_key`)


def prepare_import(source: Path | str, mapping: ImportMapping, name: str,
                   resample_dt: float | None = None, here: Path | None = None
                   ) -> PreparedImport:
    """Read ``source`` as the mapping says and key what its import would be made from;
    ``here``: the mapping file's folder (a robot file named in it is looked for there). The
    artefact store decides whether to write it (:meth:`pipeline.store.door.ArtefactStore.
    import_log`)."""
    source = Path(source)
    check_name(name)
    fmt = mapping.source_format(source)
    robot, robot_from, robot_here = robot_block(mapping, here)
    # The robot's model, for the reader (a bag's joints by name) and the checks; its step
    # (here 1 s) is not the model's: the spec is made again with the log's below.
    model_spec = import_spec(name, robot, 1.0, 1, robot_here, str(source))[0]
    model_robot = GiordanoRobot(model_spec)
    raw, source_sha256 = read_source(source, mapping, fmt, robot_shape(model_robot.model))
    key = import_key(source_sha256, fmt, mapping, model_spec, resample_dt)
    return PreparedImport(source, name, fmt, mapping, robot, robot_from, robot_here,
                          model_robot, raw, source_sha256, resample_dt, key)


def write_import(prep: PreparedImport, path: Path) -> ImportOutcome:
    """Check, convert and write the prepared import as the log ``path`` (atomically)."""
    time, q, v, record = _converted(prep.source, prep.raw, prep.mapping, prep.model_robot,
                                    prep.resample_dt)
    n = len(q)
    spec, content = import_spec(prep.name, prep.robot, time.dt, n, prep.robot_here,
                                str(prep.source))
    sigma = _sigmas(prep.model_robot, q)
    if prep.raw.s_min_G is not None:  # the source's own: the provenance check is a check
        sigma[:, 0] = prep.raw.s_min_G
    record = {"source": display_path(prep.source.resolve()),
              "source_sha256": prep.source_sha256, "format": prep.fmt,
              "mapping": prep.mapping.record(), "robot_from": prep.robot_from,
              "import_key": prep.key,
              "s_min_G_from": (S_MIN_G_REBUILT if prep.raw.s_min_G is None else
                               S_MIN_G_SOURCE), **record}
    meta = LogMeta(spec={"name": prep.name, **content}, spec_hash=spec_hash_of(content),
                   sim_version=IMPORTED_VERSION, robot_file=display_path(spec.robot_path),
                   robot_hash=file_digest(spec.robot_path), status="complete",
                   failed_step=None, error="", rows=n,
                   versions=library_versions(SIM_LIBRARIES), imported=record)
    excess = JointRanges.of(prep.model_robot.model).excess(q)  # eq. 42, as a run's log
    columns = {"step": np.arange(n, dtype=np.int64), "t": np.arange(n) * time.dt, "q": q,
               "v": v, **{c: sigma[:, i] for i, c in enumerate(SIGMA_COLUMNS)},
               JOINT_EXCESS: excess, OUTSIDE_JOINT_RANGE: outside(excess)}
    write_table(path, columns, log_metadata(meta))
    return ImportOutcome.of_record(path, n, record, reused=False)


def check_name(name: str) -> None:
    """SpecError unless ``name`` is a log's name that keeps its folder under imported/."""
    if not NAME.fullmatch(name) or name.startswith("."):
        raise SpecError(f"--name {name!r}: a log's name is letters, digits, '_', '-' and '.' "
                        f"(not first), so its folder stays under imported/")
    if len(name) > MAX_NAME:  # a folder name: most file systems stop at 255 bytes
        raise SpecError(f"--name {name[:20]}…: {len(name)} characters, a log's name is at most "
                        f"{MAX_NAME}")


def import_key(source_sha256: str, fmt: str, mapping: ImportMapping, spec: Spec,
               resample_dt: float | None) -> str:
    """What an imported log is made from: the source's bytes, how they are read (format,
    mapping), the robot (its block and file), the resampling and the importer's code."""
    parts = {"source_sha256": source_sha256, "format": fmt, "mapping": mapping.record(),
             "robot": spec.robot.model_dump(mode="json"),
             "robot_file": file_digest(spec.robot_path), "resample": resample_dt,
             "importer": import_version()}
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()


def _converted(source: Path, raw: RawLog, mapping: ImportMapping, model_robot: GiordanoRobot,
               resample_dt: float | None) -> tuple[TimeBase, np.ndarray, np.ndarray, dict]:
    """The log's time base, q and v in the project's conventions, and the import record's
    account of the conventions, the time base and the consistency check (eq. 33)."""
    n = len(raw.q)
    if len(raw.v) != n or (raw.t is not None and len(raw.t) != n):
        raise SpecError(f"{source}: t, q and v have {len(raw.t) if raw.t is not None else n}, "
                        f"{n} and {len(raw.v)} rows: not one log")
    if raw.s_min_G is not None and len(raw.s_min_G) != n:
        raise SpecError(f"{source}: s_min_G has {len(raw.s_min_G)} rows, q {n}: not one log")
    if raw.s_min_G is not None and resample_dt is not None:
        raise SpecError(f"{source}: --resample with the source's s_min_G: its values are of "
                        f"the source's instants, not the resampled ones (map it, or resample)")
    for field, x in (("q", raw.q), ("v", raw.v)):
        bad = np.flatnonzero(~np.isfinite(x).all(axis=1))
        if bad.size:
            raise SpecError(f"{source}: {field}: row {bad[0]} is not finite")
    t, _ = _stamps(raw.t, mapping, n, source)
    res = raw.t_resolution if raw.t_resolution is not None else 0.0
    steps = np.diff(t)
    if n < 3 or np.any(steps <= 0):
        even_time_base(t, res, str(source), mapping.max_jitter)  # names the problem
    dt_rel = 0.0
    if mapping.max_jitter > 0:  # stamped as published: one row per step of the nominal dt,
        nominal = (t[-1] - t[0]) / (n - 1)  # known to the two end stamps' jitter
        steps = np.full(n - 1, nominal)
        dt_rel = 2 * (mapping.max_jitter * nominal + float(np.max(res))) / (t[-1] - t[0])
    check, converted = check_conventions(model_robot.model, raw.q, raw.v,
                                         mapping.conventions, steps, dt_rel)
    # Before the consistency verdict: a joint in degrees in both q and v is one motion still,
    # and this names it where the check would name a symptom.
    check_joint_limits(model_robot.model, converted.q, mapping.angle_unit, source)
    problem = check.problem()
    if problem is not None:
        raise SpecError(f"{source}: {problem}")

    q, v = converted.q, converted.v
    if raw.t is None:
        if resample_dt is not None:
            raise SpecError(f"{source}: --resample: the log has no time stamps to resample "
                            f"from (its step is --dt {mapping.dt:g})")
        time = TimeBase(0.0, float(mapping.dt), 0.0, 0.0)
    else:
        try:
            time = even_time_base(t, res, str(source), mapping.max_jitter)
        except SpecError:
            if resample_dt is None:
                raise
            time, q, v = resample(model_robot.model, t, q, v, resample_dt, res)
        else:
            if resample_dt is not None:
                time, q, v = resample(model_robot.model, t, q, v, resample_dt, res)
    record = {
        "conventions": mapping.conventions.__dict__, "time": time.record(),
        "quat_norm_error": converted.quat_norm_error,
        "consistency": {"median_ratio": check.declared.residuals.median_ratio,
                        "median_relative": check.declared.residuals.median_relative,
                        "share_within": check.declared.residuals.share_within,
                        "alternatives": {check.declared.conventions.differences(
                            a.conventions)[1]: a.residuals.median_ratio
                            for a in check.alternatives}},
    }
    return time, q, v, record


def read_source(source: Path, mapping: ImportMapping, fmt: str, shape: RobotShape
                ) -> tuple[RawLog, str]:
    """The foreign log's t, q and v, read as the mapping says, sized by the robot's ``shape``
    (a bag's reader matches the arm's joints by name), and the SHA-256 of the bytes they were
    read from: a file is read once and parsed from those bytes; a bag (a folder, or an MCAP
    file its reader seeks in) is hashed before and after it is read, and refused if it changed
    meanwhile."""
    if not source.exists():
        raise SpecError(f"{source}: file not found")
    if fmt not in ("rosbag", "mcap"):
        src = read_bytes(source)
        return READERS[fmt](src, mapping, shape), src.sha256
    if mapping.s_min_G is not None:
        raise SpecError(f"{source}: field s_min_G: a {fmt} log's topics hold no σ_min(Γ)")
    before = _bag_digest(source)
    raw = read_bag(source, mapping, fmt, list(shape.joints))
    if _bag_digest(source) != before:
        raise SpecError(f"{source}: changed while it was read (its SHA-256 before and after "
                        f"differ): import it again once it is written")
    return raw, before


def _sigmas(robot: GiordanoRobot, q: np.ndarray, rows: int = 4096) -> np.ndarray:
    """(σ_min, κ) of Γ and of the damped J⊕ at every row of q (N×4, ``SIGMA_COLUMNS``), by the
    simulator's kernels (eq. 19): Γ's SVDs as a run makes them, each from the step before's
    right vectors, the first from the identity (the analysis' chain, so its provenance check
    of a rebuilt σ is exact); ``rows`` at a time."""
    out = np.empty((len(q), 4))
    Vt_last = np.empty((0, 0))
    for a in range(0, len(q), rows):
        S, Vt = svd_right_sequence(robot.gamma_matrices(q[a:a + rows]), Vt_last)
        Vt_last = np.ascontiguousarray(Vt[-1])
        out[a:a + rows, 0] = S[:, -1]
        with np.errstate(divide="ignore", invalid="ignore"):
            out[a:a + rows, 1] = np.where(S[:, -1] > 0, S[:, 0] / S[:, -1], np.inf)
        out[a:a + rows, 2:] = robot.j_oplus_conditioning(q[a:a + rows])
    return out


def _bag_digest(path: Path) -> str:
    """A bag's SHA-256: an MCAP file's, or a bag folder's files', in name order."""
    if not path.is_dir():
        return file_digest(path)
    h = hashlib.sha256()
    for f in sorted(p for p in path.rglob("*") if p.is_file()):
        h.update(f.relative_to(path).as_posix().encode())
        h.update(bytes.fromhex(file_digest(f)))
    return h.hexdigest()
