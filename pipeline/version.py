"""Code version: a hash of the package's source, so a cache never outlives a code change."""

from __future__ import annotations

import hashlib
from functools import cache
from pathlib import Path

_PKG = Path(__file__).resolve().parent


@cache
def code_version() -> str:
    """SHA-256 (first 16 hex digits) over every ``pipeline/**/*.py`` and template, by path."""
    h = hashlib.sha256()
    for p in sorted(_PKG.rglob("*")):
        if p.suffix in (".py", ".j2", ".html", ".md") and "__pycache__" not in p.parts:
            h.update(p.relative_to(_PKG).as_posix().encode())
            h.update(b"\0")
            h.update(p.read_bytes())
            h.update(b"\0")
    return h.hexdigest()[:16]


def package_version() -> str:
    """The release of the installed package (pyproject.toml's ``version``), or ``unknown``
    when the package runs from a checkout that was never installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("breve-pipeline")
    except PackageNotFoundError:
        return "unknown"
