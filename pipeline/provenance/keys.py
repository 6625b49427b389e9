"""The version of each artefact kind's code: a hash of the sources it runs and the versions of
the libraries it calls (the table in :mod:`pipeline.provenance`). Imports nothing of the
pipeline but :mod:`pipeline.paths`, so that a key never depends on the code that checks it.
"""

from __future__ import annotations

import ast
import hashlib
import importlib.metadata as md
import json
import platform
from collections.abc import Iterable
from functools import cache
from pathlib import Path

from pipeline.paths import PACKAGE_DIR

# The libraries whose versions key each artefact (a release may move the last bits).
SIM_LIBRARIES = ("numpy", "scipy", "pinocchio", "numba", "pyarrow")
ANALYSIS_LIBRARIES = ("numpy", "scipy", "pinocchio", "numba", "pyarrow", "pandas")
REPORT_LIBRARIES = ("matplotlib", "jinja2")
_DISTRIBUTION = {"pinocchio": "pin"}  # the distribution that provides the module

SIM_ENTRY = ("pipeline.sim.run",)
ANALYSIS_ENTRY = ("pipeline.analysis.stages", "pipeline.analysis.record")
REPORT_ENTRY = ("pipeline.reports.render",)
IMPORT_ENTRY = ("pipeline.importer.run",)
SAMPLE_ENTRY = ("pipeline.montecarlo.sample", "pipeline.sim.run")
SEARCH_ENTRY = ("pipeline.montecarlo.search", "pipeline.montecarlo.plan")
IMPORT_LIBRARIES = ("numpy", "scipy", "pinocchio", "numba", "pyarrow", "pandas", "rosbags")
TEMPLATES = PACKAGE_DIR / "reports" / "templates"


def library_versions(libraries: Iterable[str] = SIM_LIBRARIES) -> dict[str, str]:
    """Python's version and each library's (``absent`` when not installed)."""
    out = {"python": platform.python_version()}
    for lib in libraries:
        try:
            out[lib] = md.version(_DISTRIBUTION.get(lib, lib))
        except md.PackageNotFoundError:
            out[lib] = "absent"
    return out


def _module_file(name: str) -> Path | None:
    rel = Path(*name.split("."))
    for cand in (PACKAGE_DIR.parent / rel.with_suffix(".py"),
                 PACKAGE_DIR.parent / rel / "__init__.py"):
        if cand.is_file():
            return cand
    return None


def _imports(path: Path) -> frozenset[str]:
    """The ``pipeline`` modules a file imports anywhere in it (functions included)."""
    st = path.stat()
    return _imports_of(path, st.st_mtime_ns, st.st_size)


@cache
def _imports_of(path: Path, mtime_ns: int, size: int) -> frozenset[str]:
    # Parsed once per version of the file in a process: the keys of the simulator, the
    # analysis and the reports walk mostly the same modules (a second each, unshared).
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out |= {f"{node.module}.{a.name}" for a in node.names}
    return frozenset(n for n in out if n.split(".")[0] == "pipeline")


def source_closure(entries: Iterable[str]) -> list[Path]:
    """The files of ``entries`` and of every ``pipeline`` module they import, transitively
    (with each package's ``__init__``), sorted."""
    seen: dict[str, Path] = {}
    todo = list(entries)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        path = _module_file(name)
        if path is None:  # ``from pipeline.x import function``: not a module
            continue
        seen[name] = path
        parts = name.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]
        todo += sorted(_imports(path))
    return sorted(set(seen.values()))


def _digest(files: Iterable[Path], extra: dict) -> str:
    h = hashlib.sha256()
    for p in files:
        h.update(p.relative_to(PACKAGE_DIR.parent).as_posix().encode() + b"\0")
        h.update(p.read_bytes() + b"\0")
    h.update(json.dumps(extra, sort_keys=True).encode())
    return h.hexdigest()[:16]


@cache
def sim_version() -> str:
    """The key of a log's code: the simulator's sources and the numerical libraries."""
    return _digest(source_closure(SIM_ENTRY), library_versions(SIM_LIBRARIES))


@cache
def analysis_version() -> str:
    """The key of an analysis' code: the analysis' sources and the numerical libraries."""
    return _digest(source_closure(ANALYSIS_ENTRY), library_versions(ANALYSIS_LIBRARIES))


@cache
def sample_version() -> str:
    """The key of a Monte Carlo sample's record: the simulator's, the analysis stages' and the
    sample's own sources, and the numerical libraries."""
    return _digest(source_closure(SAMPLE_ENTRY), library_versions(ANALYSIS_LIBRARIES))


@cache
def search_version() -> str:
    """The key of a least-change search's code: the search and the Monte Carlo's plan, which
    draws the samples at each value of the knob (the samples' own code is in their key)."""
    return _digest(source_closure(SEARCH_ENTRY), {})


@cache
def import_version() -> str:
    """The key of an imported log's code: the importer's sources and the libraries it reads
    and checks with (an import made by other code is made again, not reused)."""
    return _digest(source_closure(IMPORT_ENTRY), library_versions(IMPORT_LIBRARIES))


@cache
def report_version() -> str:
    """The key of the reports' code: the renderer's sources, templates and libraries."""
    files = [*source_closure(REPORT_ENTRY), *sorted(TEMPLATES.glob("*"))]
    return _digest(files, library_versions(REPORT_LIBRARIES))


@cache
def source_version() -> str:
    """Every source of the package (the equation cross-check inspects them all)."""
    files = sorted(p for p in PACKAGE_DIR.rglob("*")
                   if p.suffix in (".py", ".j2") and "__pycache__" not in p.parts)
    return _digest(files, {})


def file_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
