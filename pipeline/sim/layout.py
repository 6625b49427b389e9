"""Flat vectors with named fields: the compiled step's boundary (architecture §7).

A layout is a tuple of (field, size) pairs. Python packs and reads vectors by name
(:func:`pack`, :func:`offsets`); compiled code reads them through :func:`field_places`, a
namedtuple of each field's place held in a module constant, which Numba freezes into the
kernels as compile-time constants.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

Layout = tuple[tuple[str, int], ...]


def offsets(fields: Layout) -> dict[str, slice]:
    """Each field's slice of a vector laid out as ``fields``."""
    out, i = {}, 0
    for name, n in fields:
        out[name] = slice(i, i + n)
        i += n
    return out


def field_places(name: str, fields: Layout) -> tuple:
    """A namedtuple ``name`` with one entry per field: the field's index for a one-value field
    (a scalar reads as one), its slice otherwise."""
    return places(namedtuple(name, [f for f, _ in fields]), fields)


def places(cls: type, fields: Layout) -> tuple:
    """The namedtuple class ``cls`` (its fields those of ``fields``, in order) holding each
    field's index for a one-value field, its slice otherwise."""
    if tuple(cls._fields) != tuple(f for f, _ in fields):
        raise ValueError(f"{cls.__name__} has fields {cls._fields}, the layout {fields}")
    at = [sl.start if sl.stop - sl.start == 1 else sl for sl in offsets(fields).values()]
    return cls(*at)


def pack(fields: Layout, values: dict) -> np.ndarray:
    """A flat vector laid out as ``fields`` from named values (arrays, numbers or booleans);
    fields not given are zero."""
    unknown = set(values) - {name for name, _ in fields}
    if unknown:
        raise ValueError(f"no field {sorted(unknown)} in the layout")
    out = np.zeros(sum(n for _, n in fields))
    for name, sl in offsets(fields).items():
        if name in values:
            a = np.asarray(values[name], dtype=float).ravel()
            if a.size != sl.stop - sl.start:
                raise ValueError(f"{name}: {a.size} values for {sl.stop - sl.start} places")
            out[sl] = a
    return out


def unpack(fields: Layout, vector: np.ndarray) -> dict[str, np.ndarray]:
    """The fields of a vector laid out as ``fields``, by name (copies)."""
    return {name: np.array(vector[sl]) for name, sl in offsets(fields).items()}
