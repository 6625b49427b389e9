"""The package's structure: no import cycles among its modules (module-level imports)."""

from __future__ import annotations

import ast

from pipeline.paths import PROJECT_ROOT

PKG = PROJECT_ROOT / "pipeline"


def _module(path) -> str:
    rel = path.relative_to(PROJECT_ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def import_graph(lazy: bool = False) -> dict[str, set[str]]:
    """Module → the pipeline modules it imports at module level (``lazy``: inside functions
    and ``TYPE_CHECKING`` blocks too)."""
    modules = {_module(p): p for p in PKG.rglob("*.py") if "__pycache__" not in p.parts}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for mod, path in modules.items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree) if lazy else tree.body:
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            graph[mod] |= {n for n in names if n in modules and n != mod}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                return [*stack[stack.index(n):], n]
            if n not in state and (c := visit(n)):
                return c
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (c := visit(m)):
            return c
    return None


def test_no_import_cycles():
    """None at import time, and none through the imports a function makes when it runs or a
    type checker reads (two modules that need each other are one idea, or a third's)."""
    for lazy in (False, True):
        cycle = find_cycle(import_graph(lazy))
        assert cycle is None, " -> ".join(cycle)


def test_the_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


# The layers, lowest first: a unit may import (anywhere in its files, lazy imports included)
# only units of its own layer or below. Data flows up: sim writes logs, analysis reads them,
# claims and verify measure, reports render, the CLI drives (docs/architecture.md §1).
LAYERS = (
    ("errors", "atomic_files", "bounded_read", "paths", "artefact_paths", "log_layout",
     "shapes", "yamlfile", "merge_patch", "version", "progress", "provenance", "platform",
     "orphans"),
    ("spec", "budget", "joint_ranges"),
    ("logs",),
    ("sim", "importer"),
    ("analysis",),
    ("store",),
    ("verify", "sweep", "montecarlo"),
    ("claims",),
    ("reports",),
    ("bench", "bench_linalg", "validate", "compile", "cli", "__main__"),
)
RANK = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}


def _unit(module: str) -> str:
    parts = module.split(".")[1:] or ["__init__"]
    two = ".".join(parts[:2])
    return two if two in RANK else parts[0]


def test_imports_go_down_the_layers():
    upward = []
    for path in PKG.rglob("*.py"):
        if "__pycache__" in path.parts or (path.name == "__init__.py" and path.parent == PKG):
            continue
        me = _unit(_module(path))
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for name in names:
                if name.startswith("pipeline."):
                    other = _unit(name)
                    if RANK[other] > RANK[me]:
                        upward.append(f"{_module(path)} imports {name}")
    assert not upward, "; ".join(sorted(upward))


def test_every_unit_has_a_layer():
    units = {_unit(_module(p)) for p in PKG.rglob("*.py")
             if "__pycache__" not in p.parts and p != PKG / "__init__.py"}
    assert units <= set(RANK), sorted(units - set(RANK))


# The log format's readers (pipeline/logs.py). Outside the format itself, only the artefact
# store opens a log (it verifies it once and hands it out); the modules below read logs on
# their own, each for a reason that is not "reuse or make" and is written here.
LOG_READERS = {"read_columns", "iter_columns", "read_meta", "read_footer", "num_rows",
               "verify_log", "file_metadata", "require_columns"}
READS_LOGS_ITSELF = {
    "pipeline.store.door": "the door: verifies each log once and hands it out",
    "pipeline.store.validity": "the door's predicate reads a log's footer to decide reuse",
    "pipeline.claims.baselines": "compares pinned logs with their re-runs as files, bitwise "
                                 "and column by column (pinned logs are not the store's)",
    "pipeline.bench": "writes the benchmark's long log from a short one (a writer's read)",
}
# Reuse is decided by the door alone: these predicates are called nowhere else.
REUSE_PREDICATES = {"current_log", "current_analysis"}


def _imported_names(path) -> set[tuple[str, str]]:
    """(module, name) of every ``from pipeline.X import name`` in a file, lazy ones included."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out |= {(node.module, a.name) for a in node.names}
    return out


def test_only_the_door_opens_a_log_or_decides_reuse():
    offenders = []
    for path in PKG.rglob("*.py"):
        mod = _module(path)
        if "__pycache__" in path.parts or mod == "pipeline.logs":
            continue
        for module, name in _imported_names(path):
            if (module == "pipeline.logs" and name in LOG_READERS
                    and mod not in READS_LOGS_ITSELF):
                offenders.append(f"{mod} imports {name}")
            if (module == "pipeline.store.validity" and name in REUSE_PREDICATES
                    and mod != "pipeline.store.door"):
                offenders.append(f"{mod} decides reuse with {name}")
    assert not offenders, "; ".join(sorted(offenders))


def test_the_door_check_sees_an_offender(tmp_path, monkeypatch):
    """The check above finds a reader imported where it should not be."""
    f = tmp_path / "x.py"
    f.write_text("def f():\n    from pipeline.logs import read_columns\n")
    assert ("pipeline.logs", "read_columns") in _imported_names(f)


def test_the_packages_pyproject_lists_are_the_package_folders():
    """pyproject.toml lists the packages (the shipped specs/ mapped in as pipeline.specs): a new
    package folder missing from the list would be missing from an installed copy."""
    import tomllib

    cfg = tomllib.loads((PROJECT_ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    folders = {_module(p.parent / "__init__.py") for p in PKG.rglob("__init__.py")
               if "__pycache__" not in p.parts}
    assert set(cfg["packages"]) == folders | {"pipeline.specs"}
    assert cfg["package-dir"] == {"pipeline.specs": "specs"}
    assert (PROJECT_ROOT / "specs" / "nominal.yaml").is_file()
