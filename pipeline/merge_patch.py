"""``extends`` as JSON Merge Patch (RFC 7386): how a spec or a claims file changes its parent.

A mapping merges key by key, ``null`` deletes the inherited key, and any other value (a number,
a text, a list) replaces it whole. ``{}`` changes nothing. Applied wherever ``extends`` is
read: mission specs (:func:`pipeline.spec.raw_spec`) and claims files
(:mod:`pipeline.claims.register`).
"""

from __future__ import annotations

from typing import Any


def merge_patch(target: Any, patch: Any) -> Any:
    """RFC 7386's MergePatch(target, patch), without changing either argument."""
    if not isinstance(patch, dict):
        return patch
    out = dict(target) if isinstance(target, dict) else {}
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        else:
            out[key] = merge_patch(out.get(key), value)
    return out


def leaf_keys(data: dict, prefix: str = "") -> dict[str, Any]:
    """Every leaf of a nested mapping by its dotted key (an empty mapping is a leaf)."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            out |= leaf_keys(value, f"{name}.")
        else:
            out[name] = value
    return out


def deleted_keys(patch: dict, prefix: str = "") -> list[str]:
    """The dotted keys a patch deletes (its ``null`` values)."""
    out: list[str] = []
    for key, value in patch.items():
        name = f"{prefix}{key}"
        if value is None:
            out.append(name)
        elif isinstance(value, dict):
            out += deleted_keys(value, f"{name}.")
    return out
