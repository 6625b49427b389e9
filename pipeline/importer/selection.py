"""Which columns of a foreign log hold t, q and v: the mapping's selection grammar.

A field (``time``, ``q``, ``v``) names a column, a key or a path into a pickled object, and
may select columns of what it names, NumPy's way, with every row kept:

    q                     the column or key ``q`` (a vector column, N×13)
    states.x[:, 0:13]     the key ``states``, its attribute ``x`` (N×25), columns 0 to 12
    x[13:25]              a Parquet list column ``x``: elements 13 to 24 of each row
    states.x[:, 0]        one column: a vector of N (a time stamp)
    [1:14]                the file's own columns 1 to 13, by position (CSV, Parquet)

Bounds are integers (negative from the end, either may be left out); a step, a row selection
or anything else is refused naming the field. What a selection leaves is checked like any
other column: its width, that it holds real numbers. The log imported this way records the
selection in its mapping and the source file's own SHA-256: the file is read as written.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import SpecError

_FIELD = re.compile(r"^(?P<path>[^\[\]]*?)\s*(?:\[(?P<sel>[^\[\]]*)\])?$")
_INT = r"\s*(-?\d+)?\s*"
_COLS = re.compile(rf"^{_INT}(?::{_INT})?$")


@dataclass(frozen=True)
class Selection:
    path: str  # a column, key or attribute path; "" for the file's columns by position
    cols: slice | int | None  # the columns kept, every row; None: all of it

    def describe(self) -> str:
        if self.cols is None:
            return self.path
        if isinstance(self.cols, int):
            return f"{self.path}[:, {self.cols}]"
        a, b = self.cols.start, self.cols.stop
        return f"{self.path}[:, {'' if a is None else a}:{'' if b is None else b}]"


def parse_selection(text: str, field: str) -> Selection:
    """A field's text as a :class:`Selection`; SpecError naming the field otherwise."""
    m = _FIELD.match(text.strip())
    bad = (f"field {field}: {text!r} is not a selection (a column or key, a path into an "
           f"object, and at most one [:, a:b] or [a:b] of columns: docs/importing.md)")
    if m is None:
        raise SpecError(bad)
    path, sel = m["path"].strip(), m["sel"]
    if sel is None:
        if not path:
            raise SpecError(bad)
        return Selection(path, None)
    parts = [p.strip() for p in sel.split(",")]
    if len(parts) == 2 and parts[0] == ":":
        parts = parts[1:]
    elif len(parts) == 2:
        raise SpecError(f"field {field}: {text!r}: rows are all kept ([:, …]); a row "
                        f"selection is not a column selection")
    cm = _COLS.match(parts[0]) if len(parts) == 1 else None
    if cm is None or not parts[0]:
        raise SpecError(bad)
    start = int(cm[1]) if cm[1] is not None else None
    if ":" not in parts[0]:
        if start is None:
            raise SpecError(bad)
        return Selection(path, start)
    stop = int(cm[2]) if cm[2] is not None else None
    return Selection(path, slice(start, stop))


def select(source: Path, field: str, text: str, get: Callable[[str], Any],
           positional: Callable[[slice | int], np.ndarray] | None) -> tuple[Selection, Any]:
    """The value a field's selection names: ``get(path)`` with its columns selected, or the
    file's own columns by position (``positional``; None where a file has no columns)."""
    s = parse_selection(text, field)
    if not s.path:
        if positional is None:
            raise SpecError(f"{source}: field {field}: {text!r}: this format has no columns "
                            f"by position: name a key")
        try:
            return s, positional(s.cols)
        except IndexError:
            raise SpecError(f"{source}: field {field}: {text!r}: column {s.cols} is past the "
                            f"file's columns") from None
    value = get(s.path)
    if s.cols is None:
        return s, value
    x = np.asarray(value)
    if x.ndim != 2:
        raise SpecError(f"{source}: field {field}: {text!r}: {s.path} has shape {x.shape}; "
                        f"a column selection needs rows × columns")
    width = x.shape[1]
    if isinstance(s.cols, int) and not -width <= s.cols < width:
        raise SpecError(f"{source}: field {field}: {text!r}: column {s.cols} of {s.path}, "
                        f"which has {width}")
    return s, x[:, s.cols]
