"""The grid of a sweep: ``--set KEY=V1,V2,…`` lists, their product, and point names.

Every point is validated (``with_overrides``) while the grid is built, so a bad key or value
fails before anything runs. A point's name is a function of the spec name and its own
overrides only (keys sorted, values as validated), so two sweeps over overlapping grids name a
shared point the same way and share its log.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import re
from dataclasses import dataclass
from typing import Any

from pipeline.errors import SpecError
from pipeline.spec import Spec, with_overrides
from pipeline.yamlfile import parse_scalar

_KEY_RE = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")
_SAFE_RE = re.compile(r"^[A-Za-z0-9_.=+\-]+$")
_UNSAFE = re.compile(r"[^A-Za-z0-9_.=+\-]+")
MAX_NAME = 150  # longer names are cut and get a hash suffix


@dataclass(frozen=True)
class Point:
    """One grid point: its name (also its spec's name), overrides, and the validated spec."""

    name: str
    overrides: dict[str, Any]
    spec: Spec


def split_values(text: str) -> list[str]:
    """Split ``V1,V2,…`` on the commas that are not inside ``[]`` or ``{}``."""
    parts, depth, cur = [], 0, []
    for ch in text:
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        if ch == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    parts.append("".join(cur))
    return [p.strip() for p in parts]


def parse_value(text: str) -> Any:
    """A YAML 1.2 scalar, as in a spec file (``0.01`` and ``1e-2`` floats, ``20`` int,
    ``imex`` string, ``[0, 1]`` list)."""
    return parse_scalar(text)


def parse_sets(sets: list[str]) -> list[tuple[str, list[Any]]]:
    """``["mission.dt=0.01,0.02", …]`` → ``[("mission.dt", [0.01, 0.02]), …]``."""
    if not sets:
        raise SpecError("sweep: give at least one --set KEY=V1,V2,...")
    axes: list[tuple[str, list[Any]]] = []
    for item in sets:
        key, eq, text = item.partition("=")
        key = key.strip()
        if not eq or not _KEY_RE.match(key):
            raise SpecError(f"--set {item}: expected KEY=V1,V2,... with a dotted key "
                            "such as mission.dt")
        if key in (k for k, _ in axes):
            raise SpecError(f"--set {key}: key given twice")
        raw = split_values(text)
        if any(r == "" for r in raw):
            raise SpecError(f"--set {key}: empty value in {text!r}")
        axes.append((key, [parse_value(r) for r in raw]))
    return axes


def _dig(data: dict, key: str) -> Any:
    for part in key.split("."):
        data = data[part]
    return data


def format_value(v: Any) -> str:
    if hasattr(v, "item") and not isinstance(v, list | dict):
        v = v.item()  # a numpy scalar, as read back from a table
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, int | str):
        return str(v)
    return json.dumps(v, separators=(",", ":"), sort_keys=True)


def safe_name(text: str, salt: Any = None) -> str:
    """``text`` if it is filesystem-safe and short; else a cleaned, cut form + a hash suffix."""
    if _SAFE_RE.match(text) and len(text) <= MAX_NAME and not text.startswith("."):
        return text
    digest = hashlib.sha256(json.dumps([text, salt], sort_keys=True).encode()).hexdigest()[:10]
    return f"{_UNSAFE.sub('-', text).lstrip('.')[:MAX_NAME - 11]}-{digest}"


def point_name(spec_name: str, overrides: dict[str, Any]) -> str:
    """``<spec>__<key>=<value>__…`` with keys sorted (deterministic, filesystem-safe)."""
    parts = [f"{k}={format_value(overrides[k])}" for k in sorted(overrides)]
    return safe_name("__".join([spec_name, *parts]), overrides)


def sweep_name(spec_name: str, keys: list[str], name: str | None) -> str:
    if name is not None:
        if not _SAFE_RE.match(name) or name.startswith("."):
            raise SpecError(f"--name {name!r}: use letters, digits and _ . = + - only")
        return name
    return safe_name(f"{spec_name}__{'+'.join(sorted(keys))}")


def build_grid(base: Spec, axes: list[tuple[str, list[Any]]]) -> list[Point]:
    """The product of the axes, each point validated; duplicates (``0.01`` and ``1e-2``) once."""
    keys = [k for k, _ in axes]
    points: dict[str, Point] = {}
    for combo in itertools.product(*(vals for _, vals in axes)):
        spec = with_overrides(base, dict(zip(keys, combo, strict=True)))
        content = spec.model_dump(mode="json")
        canonical = {k: _dig(content, k) for k in keys}
        name = point_name(base.name, canonical)
        if name not in points:
            points[name] = Point(name, canonical, spec.model_copy(update={"name": name}))
    return list(points.values())
