"""The seed note's published evidence (``specs/seed_note.yaml``) beside ours.

The note's numbers are data, read and validated here; each row pairs a value the note prints
with the path of our value in a run's analysis.json. :func:`note_table` lays them side by side
with the difference, for the mechanism report and CLAIMS.md; the claims compare against the
same values through the ``note:`` metric source. Given the evaluated claims (claims.json's
``claims``), each cell also carries its judgement: the claim whose check reads our value,
that check's condition (the tolerance) and its outcome. A row of round-off values (the note's
``roundoff: true``) is shown as round-off, without a relative difference between two
rounding errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from pipeline.analysis.schema import AnalysisRecord, field_type, value_at
from pipeline.errors import SpecError
from pipeline.paths import SHIPPED_SPECS
from pipeline.yamlfile import read_yaml

COLUMNS = ("nominal", "dt010")
# The note's regime (issue 50): the register's runs measured where the note measured, "at a
# representative near-singular step (s_min_G ~ 0.032)", each beside the note's column it is
# compared with. The table shows them after today's rows on nominal and dt010.
REGIME_COLUMNS = {"reach_note": "nominal", "reach_dt010": "dt010"}
TABLE_COLUMNS = (*COLUMNS, *REGIME_COLUMNS)


def note_column(column: str) -> str:
    """The note's column (nominal or dt010) a table column is compared with."""
    return REGIME_COLUMNS.get(column, column)
NOTE_FILE = SHIPPED_SPECS / "seed_note.yaml"  # the mechanism reports' note


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class NoteRow(_Strict):
    key: str = Field(pattern=r"^[A-Za-z0-9_]+$")
    row: str = Field(min_length=1)
    nominal: float | None
    dt010: float | None
    ours: str = Field(min_length=1)
    ours_label: str = ""
    also: dict[str, str] = Field(default_factory=dict)
    roundoff: bool = False  # both values are floating-point rounding: no relative difference


class SeedNote(_Strict):
    note: str
    runs: dict[str, str]
    # The specs of the note's regime columns (REGIME_COLUMNS), for the mechanism page.
    regime_runs: dict[str, str] = Field(default_factory=dict)
    rows: list[NoteRow] = Field(min_length=1)
    source: str = ""

    def value(self, key: str, column: str) -> float:
        """The note's published value of row ``key`` in ``column``; SpecError if none."""
        for r in self.rows:
            if r.key == key:
                if column not in COLUMNS:
                    raise SpecError(f"{self.source}: no column {column!r} (one of "
                                    f"{', '.join(COLUMNS)})")
                v = getattr(r, column)
                if v is None:
                    raise SpecError(f"{self.source}: row {key} publishes no {column} value")
                return v
        raise SpecError(f"{self.source}: no row {key!r} (rows: "
                        f"{', '.join(r.key for r in self.rows)})")


def load_note(path: Path | str) -> SeedNote:
    """Read and validate the note file; every error is one line naming the file."""
    path = Path(path)
    data = read_yaml(path, "note file")
    try:
        note = SeedNote.model_validate({**data, "source": str(path)})
    except ValidationError as exc:
        err = exc.errors()[0]
        field = ".".join(str(x) for x in err["loc"])
        raise SpecError(f"{path}: field {field}: {err['msg']}") from None
    keys = [r.key for r in note.rows]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise SpecError(f"{path}: duplicate row key {dup[0]}")
    missing = [c for c in COLUMNS if c not in note.runs]
    if missing:
        raise SpecError(f"{path}: field runs: no run for column {missing[0]}")
    for i, r in enumerate(note.rows):  # our values' paths name fields of the record, now
        for where, record_path in (("ours", r.ours), *((f"also.{k}", v)
                                                        for k, v in r.also.items())):
            try:
                field_type(record_path)
            except KeyError as exc:
                raise SpecError(f"{path}: field rows.{i}.{where}: {record_path!r} has no "
                                f"field {exc.args[0]!r} in the analysis record") from None
    return note


def _number_at(record: AnalysisRecord, path: str) -> float | None:
    """Our number at ``path`` of a record, or None where the record has none."""
    try:
        node = value_at(record, path)
    except KeyError:
        return None
    return float(node) if isinstance(node, int | float) and not isinstance(node, bool) else None


@dataclass(frozen=True)
class Judgement:
    """What the register says of one cell: the claim whose check reads our value, the check's
    condition on it and the outcome."""

    claim: str  # the claim's id
    status: str  # the claim's status (PASS, FAIL, OPEN, NOW HOLDS)
    tolerance: str  # the check's condition, e.g. "within 2 %" or "< -0.9"
    ok: bool  # whether that check holds
    reason: str  # the claim's reason when it is expected open


@dataclass(frozen=True)
class Cell:
    """One column of one row: the note's value, ours, our other readings, the judgement."""

    column: str
    note: float | None
    ours: float | None
    also: tuple[tuple[str, float | None], ...]
    roundoff: bool = False
    judgement: Judgement | None = None

    @property
    def rel_diff(self) -> float | None:
        """(ours − note)/|note|, None where either is missing, the note's value is 0 or both
        are round-off."""
        if self.roundoff or self.note is None or self.ours is None or self.note == 0:
            return None
        return (self.ours - self.note) / abs(self.note)

    @property
    def verdict(self) -> str:
        """agrees, differs, round-off, no number (in the note) or not judged (by a claim)."""
        j = self.judgement
        if self.roundoff:
            return "round-off" if j is None or j.ok else "differs"
        if self.note is None:
            return "no number"
        if j is None:
            return "not judged"
        return "agrees" if j.ok else "differs"


@dataclass(frozen=True)
class TableRow:
    key: str
    row: str
    ours_label: str
    cells: tuple[Cell, ...]


def _condition(check: dict) -> str:
    if check["op"] == "close":
        return f"within {100 * check['rel_tol']:g} %"
    symbols = {"lt": "<", "le": "≤", "gt": ">", "ge": "≥", "eq": "=", "ne": "≠",
               "abs_lt": "|·| <", "abs_le": "|·| ≤", "abs_gt": "|·| >", "abs_ge": "|·| ≥"}
    return f"{symbols.get(check['op'], check['op'])} {check['threshold']:g}" if isinstance(
        check["threshold"], int | float) else f"{check['op']} {check['threshold']}"


def judgement(claims: list[dict], key: str, column: str, path: str) -> Judgement | None:
    """The claim that judges row ``key``'s cell in ``column`` (claims.json's claims): the
    first with a check of run ``column``'s value at ``path`` against the note's value
    (``note:KEY.COLUMN``), else the first note-row claim with a check of it, else the first
    claim at all; None when no claim reads the value. All its checks of that value make the
    tolerance, and hold together or not."""
    metric = f"{column}:{path}"
    reading = [c for c in claims if any(k["metric"] == metric for k in c["checks"])]
    against_note = [c for c in reading if any(
        k["metric"] == metric
        and k.get("threshold_metric") == f"note:{key}.{note_column(column)}"
        for k in c["checks"])]
    note_rows = [c for c in reading if c.get("kind") == "note"]
    chosen = (against_note or note_rows or reading or [None])[0]
    if chosen is None:
        return None
    checks = [k for k in chosen["checks"] if k["metric"] == metric]
    return Judgement(chosen["id"], chosen["status"], " and ".join(map(_condition, checks)),
                     all(bool(k["ok"]) for k in checks),
                     chosen.get("reason", "") if chosen.get("expect") == "open" else "")


def note_table(note: SeedNote, records: dict[str, AnalysisRecord],
               claims: list[dict] | None = None) -> list[TableRow]:
    """The note's rows beside our values from ``records`` (column → analysis record), each
    cell judged by ``claims`` (claims.json's, whose runs are named as the columns) when
    given; a column without a record shows the note's value alone."""
    # The note's two columns always; a regime column only where its run was analysed.
    columns = [*COLUMNS, *(c for c in REGIME_COLUMNS if c in records)]
    out = []
    for r in note.rows:
        cells = []
        for col in columns:
            rec = records.get(col)
            ours = _number_at(rec, r.ours) if rec else None
            also = tuple((label, _number_at(rec, p) if rec else None)
                         for label, p in r.also.items())
            j = judgement(claims, r.key, col, r.ours) if claims and rec else None
            cells.append(Cell(col, getattr(r, note_column(col)), ours, also, r.roundoff, j))
        out.append(TableRow(r.key, r.row, r.ours_label, tuple(cells)))
    return out


@dataclass(frozen=True)
class ColumnRegime:
    """Where a table column's values were measured: its run, the note's column it is compared
    with, and the representative step's rule, σ_min(Γ), step and time, from the record."""

    column: str
    spec: str
    note_column: str
    rule: str
    s_min_G: float | None
    step: int | None
    t: float | None
    target: float | None  # the σ_min(Γ) the step was chosen nearest, else None (the median)


def column_regimes(records: dict[str, AnalysisRecord]) -> list[ColumnRegime]:
    """Each table column that has a record (TABLE_COLUMNS' order): where its theory was taken."""
    out = []
    for col in TABLE_COLUMNS:
        rec = records.get(col)
        th = getattr(rec, "theory", None)
        if rec is None or th is None:
            continue
        out.append(ColumnRegime(col, rec.spec_name, note_column(col), th.rule, th.s_min_G,
                                th.step, th.t, getattr(th, "s_min_G_target", None)))
    return out


def differences(rows: list[TableRow]) -> list[tuple[str, str, str]]:
    """Where our missions differ from the note's: (claim id, the note's row, the claim's
    reason) for each claim expected open that judges a cell of the table, once each."""
    seen: dict[str, tuple[str, str, str]] = {}
    for r in rows:
        for c in r.cells:
            j = c.judgement
            if j is not None and j.reason and j.claim not in seen:
                seen[j.claim] = (j.claim, r.row, j.reason)
    return list(seen.values())


def fmt(x: float | None) -> str:
    """A table cell: '—' for no value, 4 significant digits otherwise."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    return f"{x:.4g}"
