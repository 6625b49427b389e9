"""Where things are: the shipped specs, the user's spec search path, the kernel cache, and
paths as a user reads them (architecture §8).

The package works the same from a source checkout and installed (``pip install .``). A spec
name (``nominal``) or a file a spec names (``extends``, ``robot.file``) is looked up, in order,
in

1. the folder of the spec file that names it;
2. each folder of ``BREVE_SPEC_PATH`` (``:``-separated, like ``PATH``);
3. the shipped specs: the repository's ``specs/``, which an installed package carries as its
   ``pipeline/specs/`` (package data mapped from there, pyproject.toml).

Outputs (``--out``, ``logs/``) are relative to the working directory, as for any command.
"""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
# The folder above the package: a source checkout's root (its docs/, the tests, make). Only
# the equation cross-check reads from it (docs/equations.md, when present).
PROJECT_ROOT = PACKAGE_DIR.parent
# Installed, the package carries the specs inside it; in a source checkout they are at the top
# of the repository, where the design card and users look for them.
# (A shipped spec marks the installed copy: a checkout updated across the move may keep an
# old pipeline/specs/ folder holding only a user's untracked files.)
SHIPPED_SPECS = (PACKAGE_DIR / "specs" if (PACKAGE_DIR / "specs" / "nominal.yaml").is_file()
                 else PROJECT_ROOT / "specs")
SPEC_PATH_ENV = "BREVE_SPEC_PATH"
CACHE_ENV = "BREVE_CACHE_DIR"


def spec_search_path(here: Path | None = None) -> list[Path]:
    """The folders a spec name or a spec's file reference is looked up in, in order."""
    folders = [Path(here).resolve()] if here is not None else []
    for entry in os.environ.get(SPEC_PATH_ENV, "").split(os.pathsep):
        if entry.strip():
            folders.append(Path(entry).expanduser().resolve())
    folders.append(SHIPPED_SPECS)
    return list(dict.fromkeys(folders))


def find_on_search_path(relative: str, here: Path | None = None) -> Path | None:
    """The first existing file ``relative`` (an absolute path stands for itself)."""
    p = Path(relative).expanduser()
    if p.is_absolute():
        return p if p.is_file() else None
    for folder in spec_search_path(here):
        cand = folder / p
        if cand.is_file():
            return cand.resolve()
    return None


def display_path(path: Path | str) -> str:
    """A path as the user reads it: relative to the working directory when inside it, else
    absolute."""
    p = Path(path).resolve()
    try:
        return p.relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return str(p)


def source_checkout() -> bool:
    """Whether the package runs from a source checkout (editable), not an installed copy."""
    return (PROJECT_ROOT / "pyproject.toml").is_file()


def user_cache_dir() -> Path:
    """The per-user cache of an installed package: ``BREVE_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/breve-pipeline``, else ``~/.cache/breve-pipeline``."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "breve-pipeline"
