"""The analysis record (``analysis.json``, its schema ``record.SCHEMA``): its typed structure,
its one serialisation, and the check of a record read from disk.

The record is a tree of frozen dataclasses (:class:`CompleteRecord` for a complete log,
:class:`DivergedRecord` for a diverged one). The stages build it, the store writes and reads
it, and the claims and the reports read its fields by name:

- :func:`to_json` / :func:`from_json`: the one serialisation, fields in declaration order
  (which is the order of ``analysis.json``); a field marked :data:`ABSENT_WHILE_NONE` is
  left out while it is None (a theory evaluated outside a window has no window counts; a run
  compared with no other has no comparison);
- :func:`check_record`: a record read from disk holds every field its kind must hold, with
  the type it must have, and no other (a LogError naming the file and the field otherwise);
- :func:`field_type`: whether a dotted path names a field (``dominant.lag1``,
  ``theory.fastest_mode.axis``, ``directions.0.lag1``) and its type: the claims register's
  paths are checked against it when the register is loaded, not when a claim is evaluated;
- :func:`value_at`: the value such a path names.

A field typed ``dict[str, float]`` (keyed by a name the data decides, such as a mode's) takes
any key. Numbers: an ``int`` is a ``float`` field's value too (JSON does not keep the
difference), a ``bool`` is not a number; NaN and ±inf are floats.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Union

from pipeline.analysis.harm import Harm, RollSmear
from pipeline.analysis.verdict import ModeLoop, Prediction
from pipeline.sim.margins import Complex, Requirement, RequirementFix
from pipeline.sim.robot_file import RobotCard

_OPTIONAL = "optional"
ABSENT_WHILE_NONE = {_OPTIONAL: True}  # a field's metadata: None in some records, then absent


@dataclass(frozen=True)
class Window:
    start_step: int
    stop_step: int
    rule: str


@dataclass(frozen=True)
class Provenance:
    max_abs_s_min_G: float
    worst_step: int
    max_rel_kappa_G: float
    tolerance: float


@dataclass(frozen=True)
class Direction:
    direction: int
    sigma: float
    rms: float
    step_rms: float
    lag1: float | None  # None: undetermined, the series holds no motion above its round-off


@dataclass(frozen=True)
class Dominant:
    index: int
    sigma: float
    lag1: float | None
    step_rms: float
    step_energy_share: float | None  # None: no step-to-step motion in any direction


@dataclass(frozen=True)
class LatencyRecord:
    """The command's arrival within the step and its jitter (eq. 41): the delay the margins
    and the map judge (the longest, each margin falling as the delay grows), and the jittered
    loop's mean-square radius (eq. 41c) with its verdict."""

    delay_fraction: float  # steps: the earliest arrival beyond delay_steps
    jitter_steps: float  # the arrival's spread (uniform)
    judged_delay_steps: float  # delay_steps + delay_fraction + jitter_steps
    earliest_radius: float  # ρ of the map at the earliest arrival
    mean_square_radius: float  # √ρ(E[Φ ⊗ Φ]): < 1 is stable in mean square
    verdict: str
    rule: str


@dataclass(frozen=True)
class NoteOrder:
    rule: str
    eig_dominant: Complex
    spectral_radius: float


@dataclass(frozen=True)
class Eigenvalues:
    real: list[float]
    imag: list[float]


@dataclass(frozen=True)
class SpectrumRecord:
    eig_dominant: Complex
    spectral_radius: float
    eigenvalues: Eigenvalues


@dataclass(frozen=True)
class Maps:
    explicit: SpectrumRecord
    imex: SpectrumRecord


@dataclass(frozen=True)
class FastestMode:
    name: str
    mu: float
    dt_mu: float
    axis: int
    is_bus_yaw: bool
    gain_block: str
    share: float
    gain: float
    dt_stable: float
    dt_margin: float
    gain_stable: float | None
    gain_margin: float | None


@dataclass(frozen=True)
class Theory:
    """Stage 4 at the representative step (eqs. 21–24)."""

    rule: str
    step: int
    t: float
    s_min_G: float
    gamma: float
    mu: list[float]
    mu_max: float
    dt_mu_max: float
    dt_star_damping: float
    dt_star_map: float | None
    regime: str
    eig_dominant: Complex
    spectral_radius: float
    period_steps: float | None
    update_order: str
    note_order: NoteOrder
    maps: Maps
    fastest_mode: FastestMode
    integrator: str
    dt: float
    plant: str
    delay_steps: int
    requirement: Requirement
    modes: list[ModeLoop]
    requirement_fixes: list[RequirementFix]
    M_breve: list[list[float]]
    D_breve: list[list[float]]
    K_breve: list[list[float]]
    J_x: list[list[float]]
    K_x: list[list[float]]
    # the window's counts: in a complete log's record only
    window_steps_below_floor: int | None = field(default=None, metadata=ABSENT_WHILE_NONE)
    at_or_above_floor: bool | None = field(default=None, metadata=ABSENT_WHILE_NONE)
    # a command arriving within the step, and its jitter (eq. 41): in such a run's record only
    latency: LatencyRecord | None = field(default=None, metadata=ABSENT_WHILE_NONE)
    # the σ_min(Γ) the step was chosen nearest (analyze --at-s-min-G; issue 50), else absent
    s_min_G_target: float | None = field(default=None, metadata=ABSENT_WHILE_NONE)


@dataclass(frozen=True)
class Alignment:
    abs_cos: float
    theory_direction: list[float]
    data_direction: list[float]


@dataclass(frozen=True)
class VelocityJump:
    median: float
    max: float


@dataclass(frozen=True)
class BusRateData:
    """The bus rate's statistics from the data alone (eq. 25)."""

    lag1: float | None
    std: float
    step_rms: float
    alternating_rms: float
    step_median: float


@dataclass(frozen=True)
class BusRate(BusRateData):
    """... and its step against the acceleration saturation (eq. 16)."""

    step_bound: float
    step_ratio: float
    at_bound_share: float


@dataclass(frozen=True)
class Metrics:
    pointing_err_deg_max: float
    boresight_err_deg_max: float
    coverage_final: float
    dt_mu_max_window_max: float
    limit_share: dict[str, float]


@dataclass(frozen=True)
class JointExcursion:
    """One arm joint's time beyond one side of its range over the whole log (eq. 42)."""

    joint: str
    side: str  # "above" its upper limit or "below" its lower
    limit: float  # the limit it passed (rad)
    max_excess: float  # the largest |e_j| on that side (rad)
    steps: int
    seconds: float
    first_step: int


@dataclass(frozen=True)
class JointRangeRecord:
    """Whether the run left the arm's joint ranges (eq. 42), over every logged step."""

    left: bool
    steps_outside: int
    seconds_outside: float
    max_excess: float  # the largest |e| of any joint (rad), 0 inside
    joints: list[JointExcursion]


@dataclass(frozen=True)
class BusMode:
    """The bus-yaw damping mode (eq. 21) with the card's rate that holds (RobotCard.mu_bus)."""

    dt_mu_bus: float
    critical_I_zz: float | None  # I_zz,bus at dt·D_b/I_zz,bus = 2; None: off the axis


@dataclass(frozen=True)
class MuMaxAlong:
    min: float
    max: float
    closed_form: float
    max_rel_dev: float
    worst_step: int
    steps: int
    s_min_J_min: float
    s_min_G_min: float
    floor: float
    steps_below_floor: int


@dataclass(frozen=True)
class ModesAlong:
    samples: int
    share: dict[str, float]
    dt_mu_max: float
    step_of_max: int
    name_at_max: str
    dt_mu_min: float


@dataclass(frozen=True)
class Divergence:
    rule: str
    direction: list[float]
    first_limit_step: int
    fit_steps: list[int]
    alternating: bool
    growth_factor: float
    predicted: float
    predicted_note_order: float
    ratio: float
    ratio_note_order: float


@dataclass(frozen=True, kw_only=True)
class Identity:
    """What every record holds: which log, which code. ``schema`` is set when the record is
    written (:mod:`pipeline.analysis.record`), and absent from a compared run's record."""

    schema: str | None = field(default=None, metadata=ABSENT_WHILE_NONE)
    # The SHA-256 of the written record's other fields (pipeline.analysis.record): set when
    # written, checked when read; absent from a compared run's record, like ``schema``.
    record_sha256: str | None = field(default=None, metadata=ABSENT_WHILE_NONE)
    spec_name: str
    log: str
    log_sha256: str
    spec_hash: str
    sim_version: str
    analysis_version: str
    integrator: str
    dt: float
    n_steps: int


@dataclass(frozen=True, kw_only=True)
class CompleteRecord(Identity):
    """The record of a complete log: stages 1–6, and stage 7 when compared.
    ``directions_sha256``: the hash of the ``directions.parquet`` written with it, set when
    the record is written."""

    window: Window
    provenance: Provenance
    directions: list[Direction]
    dominant: Dominant
    theory: Theory
    alignment: Alignment
    velocity_jump: VelocityJump
    bus_rate: BusRate
    metrics: Metrics
    harm: Harm
    camera_roll: RollSmear
    prediction: Prediction
    versions: dict[str, str]
    robot: RobotCard
    bus_mode: BusMode
    mu_max_log: MuMaxAlong
    modes_along: ModesAlong
    joint_ranges: JointRangeRecord
    comparison: Comparison | None = field(default=None, metadata=ABSENT_WHILE_NONE)
    directions_sha256: str | None = field(default=None, metadata=ABSENT_WHILE_NONE)


def same_duration(a: Identity, b: Identity) -> bool:
    """Whether two runs flew the same length of mission, to within a step of the coarser
    (a run's steps are its duration over its dt, rounded to a whole step)."""
    return abs(a.n_steps * a.dt - b.n_steps * b.dt) <= max(a.dt, b.dt)


def same_mission(a: Identity, b: Identity, differs: list[str]) -> bool:
    """Whether two runs flew the same mission: their specs differ in the knobs of a causal
    test alone (``differs``: the other keys, stage 7's ``mission_differs``) and both flew it
    whole (:func:`same_duration`)."""
    return not differs and same_duration(a, b)


@dataclass(frozen=True)
class Comparison:
    """Stage 7: this run against another of the same robot (``other``: its whole record, as
    analysed, without the fields only a written record has). ``mission_differs``: the keys at
    which the two resolved specs differ besides the step and the integrator, the knobs a
    causal test varies (empty: the same mission). ``coverage_diff_pp`` is None unless both
    flew the same mission whole (:func:`same_duration`): coverage grows along the orbit and
    depends on the posture, so another mission's would measure those, not the ripple."""

    against: str
    against_log: str
    lag1_flip: bool
    amplitude_ratio: float
    mission_differs: list[str]
    coverage_diff_pp: float | None
    table: list[dict[str, Any]]
    other: CompleteRecord


@dataclass(frozen=True, kw_only=True)
class DivergedRecord(Identity):
    """The record of a diverged log: the divergence stage only (no directions table: its
    ``directions_sha256`` is null)."""

    status: str
    diverged_step: int
    error: str
    note: str
    provenance: Provenance
    divergence: Divergence
    joint_ranges: JointRangeRecord
    theory: Theory
    robot: RobotCard
    directions_sha256: str | None = None


@dataclass(frozen=True)
class Origin:
    """Where an imported log came from (its import record, :mod:`pipeline.importer`)."""

    source: str
    source_sha256: str
    format: str
    robot_from: str
    robot_file: str  # the robot file the log was imported against, and its SHA-256: two
    robot_sha256: str  # imports of one source against two robots are two different logs
    conventions: dict[str, str]
    consistency_median_ratio: float  # the consistency check's median residual/bound (eq. 33)


@dataclass(frozen=True)
class StageRun:
    stage: str
    ran: bool
    why: str


@dataclass(frozen=True)
class Conditioning:
    """σ_min and κ along the whole log (eq. 19) and the steps below the damped floor (eq. 6)."""

    s_min_G_min: float
    s_min_G_median: float
    kappa_G_max: float
    s_min_J_min: float
    floor: float
    steps_below_floor: int


@dataclass(frozen=True)
class DampingTheory:
    """Stage 4's damping modes at the representative step, from the declared controller
    (eqs. 21–23): an imported log's theory."""

    controller: str
    controller_hash: str
    rule: str
    step: int
    t: float
    s_min_G: float
    gamma: float
    mu: list[float]
    mu_max: float
    dt_mu_max: float
    dt_star_damping: float
    fastest_mode: FastestMode
    plant: str
    delay_steps: int
    requirement: Requirement
    modes: list[ModeLoop]
    M_breve: list[list[float]]
    D_breve: list[list[float]]


@dataclass(frozen=True, kw_only=True)
class ImportedRecord(Identity):
    """The record of an imported log: its origin, which stages ran and why, the data stages,
    and the damping theory when a controller was declared (:mod:`pipeline.analysis.imported`)."""

    origin: Origin
    stages: list[StageRun]
    window: Window
    # Absent where it would be no check: the σ columns rebuilt from q on import.
    provenance: Provenance | None = field(default=None, metadata=ABSENT_WHILE_NONE)
    directions: list[Direction]
    dominant: Dominant
    velocity_jump: VelocityJump
    bus_rate: BusRateData
    conditioning: Conditioning
    damping: DampingTheory | None
    prediction: Prediction | None
    versions: dict[str, str]
    joint_ranges: JointRangeRecord
    directions_sha256: str | None = field(default=None, metadata=ABSENT_WHILE_NONE)


AnalysisRecord = CompleteRecord | DivergedRecord | ImportedRecord
# The fields a written record always holds.
WRITTEN_ONLY = ("schema", "record_sha256", "directions_sha256")


def record_type(record: dict) -> type:
    """The type of a record as read: an imported log's, a diverged log's, else a complete
    log's."""
    if "origin" in record:
        return ImportedRecord
    return DivergedRecord if record.get("status") == "diverged" else CompleteRecord


# -- the one serialisation ----------------------------------------------------------------

def to_json(value: Any) -> Any:
    """A record (or any part of one) as JSON values: dataclasses as mappings in field order,
    an optional field left out while None."""
    if dataclasses.is_dataclass(value):
        return {f.name: to_json(v) for f in dataclasses.fields(value)
                if (v := getattr(value, f.name)) is not None or not f.metadata.get(_OPTIONAL)}
    if isinstance(value, list | tuple):
        return [to_json(v) for v in value]
    if isinstance(value, dict):
        return {k: to_json(v) for k, v in value.items()}
    return value


def from_json(tp: Any, value: Any) -> Any:
    """The typed value of ``value`` (JSON, already checked by :func:`check_record`) for type
    ``tp``; numbers are kept as read, so a record read and written again is the same text."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None:
            return None
        return from_json(next(a for a in args if a is not type(None)), value)
    if dataclasses.is_dataclass(tp):
        hints = _hints(tp)
        return tp(**{f.name: from_json(hints[f.name], value[f.name])
                     for f in dataclasses.fields(tp) if f.name in value})
    if origin is list:
        return [from_json(args[0], v) for v in value]
    if origin is dict:
        return {k: from_json(args[1], v) for k, v in value.items()}
    return value


def record_from_json(record: dict) -> AnalysisRecord:
    """A checked record read from JSON, typed by its kind."""
    return from_json(record_type(record), record)


# -- checking a record --------------------------------------------------------------------

@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


@functools.cache
def _present_unless_none(cls: type) -> dict[str, bool]:
    """Each field's name: whether it is an optional one, absent while None."""
    return {f.name: bool(f.metadata.get(_OPTIONAL)) for f in dataclasses.fields(cls)}


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _problem(value: Any, tp: Any, where: str) -> str | None:
    """Where and why ``value`` is not of type ``tp``, or None."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        problems = [_problem(value, a, where) for a in args]
        return None if any(p is None for p in problems) else next(p for p in problems if p)
    if tp is type(None):
        return None if value is None else f"{where}: {value!r} is not null"
    if tp is float:
        return None if _is_number(value) else f"{where}: {value!r} is not a number"
    if tp is int:
        return None if isinstance(value, int) and not isinstance(value, bool) else (
            f"{where}: {value!r} is not an integer")
    if tp in (bool, str):
        return None if isinstance(value, tp) else f"{where}: {value!r} is not a {tp.__name__}"
    if tp is Any:
        return None
    if origin is list:
        if not isinstance(value, list):
            return f"{where}: not a list"
        return next((p for i, v in enumerate(value) if (p := _problem(v, args[0],
                                                                      f"{where}.{i}"))), None)
    if origin is dict:
        if not isinstance(value, dict):
            return f"{where}: not a mapping"
        return next((p for k, v in value.items() if (p := _problem(v, args[1],
                                                                   f"{where}.{k}"))), None)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            return f"{where}: not a mapping"
        fields = {f.name: f for f in dataclasses.fields(tp)}
        hints = _hints(tp)
        prefix = f"{where}." if where else ""
        for name, f in fields.items():
            # Every field is required but those absent while None, which are never null: a
            # default of the class (a robot card's) never stands in for a missing value.
            optional = bool(f.metadata.get(_OPTIONAL))
            if name not in value:
                if not optional:
                    return f"{prefix}{name}: missing"
                continue
            if optional and value[name] is None:
                return f"{prefix}{name}: null (absent, not null, when there is none)"
            if (p := _problem(value[name], hints[name], f"{prefix}{name}")) is not None:
                return p
        extra = sorted(set(value) - set(fields))
        return f"{prefix}{extra[0]}: not a field of the record" if extra else None
    raise TypeError(f"no check for type {tp!r}")  # a schema this module cannot read


def check_record(record: dict) -> str | None:
    """Why ``record``, as written to disk, is not an analysis record of its kind (the first
    field that is missing, extra, null where it should be absent, or of the wrong type, by its
    dotted path), or None. A written record holds its schema and its directions table's hash
    (null only for a diverged log's, which has no table)."""
    missing = next((k for k in WRITTEN_ONLY if k not in record), None)
    if missing is not None:
        return f"{missing}: missing"
    return _problem(record, record_type(record), "")


# -- paths into a record --------------------------------------------------------------------

def field_type(path: str, cls: type = CompleteRecord) -> Any:
    """The type of the field a dotted ``path`` names in a record of type ``cls``; a
    KeyError naming the first part that names no field. A list is entered by an index
    (``directions.0``, ``-1`` the last), a ``dict[str, X]`` field by any key."""
    tp: Any = cls
    for part in path.split("."):
        origin, args = typing.get_origin(tp), typing.get_args(tp)
        if origin in (Union, types.UnionType):  # an optional field: the field's own type
            inner = [a for a in args if a is not type(None)]
            tp, origin, args = inner[0], typing.get_origin(inner[0]), typing.get_args(inner[0])
        if dataclasses.is_dataclass(tp):
            hints = _hints(tp)
            if part not in hints:
                raise KeyError(part)
            tp = hints[part]
        elif origin is list and part.lstrip("-").isdigit():
            tp = args[0]
        elif origin is dict:
            tp = args[1]
        else:
            raise KeyError(part)
    return tp


def value_at(obj: Any, path: str | tuple[str, ...]) -> Any:
    """The value a path (dotted, or its parts) names in a record or any JSON value: fields by
    name, mappings by key, lists by index (negative from the end). A KeyError naming the
    first part that names nothing (an optional field that is absent included). The way the
    claims and the reports read a field named by a register's path."""
    for part in path.split(".") if isinstance(path, str) else path:
        if dataclasses.is_dataclass(obj) and part in (names := _present_unless_none(type(obj))):
            if names[part] and getattr(obj, part) is None:
                raise KeyError(part)
            obj = getattr(obj, part)
        elif isinstance(obj, dict) and part in obj:
            obj = obj[part]
        elif (isinstance(obj, list) and isinstance(part, str) and part.lstrip("-").isdigit()
              and -len(obj) <= int(part) < len(obj)):
            obj = obj[int(part)]
        else:
            raise KeyError(part)
    return obj
