"""The seed note's published evidence (``pipeline/specs/seed_note.yaml``) beside ours.

The note's numbers are data, read and validated here; each row pairs a value the note prints
with the path of our value in a run's analysis.json. :func:`note_table` lays them side by side
with the difference, for the mechanism report and CLAIMS.md; the claims compare against the
same values through the ``note:`` metric source.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from pipeline.errors import SpecError
from pipeline.paths import SHIPPED_SPECS
from pipeline.yamlfile import read_yaml

COLUMNS = ("nominal", "dt010")
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


class SeedNote(_Strict):
    note: str
    runs: dict[str, str]
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
    return note


def _dig(record: dict, path: str) -> float | None:
    node = record
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return float(node) if isinstance(node, int | float) and not isinstance(node, bool) else None


@dataclass(frozen=True)
class Cell:
    """One column of one row: the note's value, ours, and our other readings."""

    column: str
    note: float | None
    ours: float | None
    also: tuple[tuple[str, float | None], ...]

    @property
    def rel_diff(self) -> float | None:
        """(ours − note)/|note|, None where either is missing or the note's value is 0."""
        if self.note is None or self.ours is None or self.note == 0:
            return None
        return (self.ours - self.note) / abs(self.note)


@dataclass(frozen=True)
class TableRow:
    key: str
    row: str
    ours_label: str
    cells: tuple[Cell, ...]


def note_table(note: SeedNote, records: dict[str, dict]) -> list[TableRow]:
    """The note's rows beside our values from ``records`` (column → analysis record); a column
    without a record shows the note's value alone."""
    out = []
    for r in note.rows:
        cells = []
        for col in COLUMNS:
            rec = records.get(col)
            ours = _dig(rec, r.ours) if rec else None
            also = tuple((label, _dig(rec, p) if rec else None) for label, p in r.also.items())
            cells.append(Cell(col, getattr(r, col), ours, also))
        out.append(TableRow(r.key, r.row, r.ours_label, tuple(cells)))
    return out


def fmt(x: float | None) -> str:
    """A table cell: '—' for no value, 4 significant digits otherwise."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    return f"{x:.4g}"
