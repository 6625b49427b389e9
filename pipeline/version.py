"""The release of the package, for ``--version`` and the citation."""

from __future__ import annotations


def package_version() -> str:
    """The release of the installed package (pyproject.toml's ``version``), or ``unknown``
    when the package runs from a checkout that was never installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("breve-pipeline")
    except PackageNotFoundError:
        return "unknown"
