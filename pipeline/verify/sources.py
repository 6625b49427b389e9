"""Where each equation lives: the numbered equations of ``docs/equations.md`` and the code sites
that cite them, both found by reading the files at render time (nothing typed by hand).

An equation is a heading ``### (N) Title`` (N a number with an optional sub-label letter,
``13`` or ``15a``). A code site is a function, method, class or dataclass field of the
``pipeline`` package whose docstring or comment cites ``eq. N``, ``eqs. N–M`` or
``eqs. N, M``; its file and line come from the abstract syntax tree. The report package itself
is not scanned: its checks cite equations too, and must not pair with themselves.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.paths import PROJECT_ROOT

PACKAGE = PROJECT_ROOT / "pipeline"
EQUATIONS_MD = PROJECT_ROOT / "docs" / "equations.md"
EXCLUDED = ("reports",)  # sub-packages of pipeline/ that are not scanned

_HEADING = re.compile(
    r"^#{2,4}\s*(?:\(\s*(?:eqs?\.?\s*)?(?P<a>\d+[a-z]?)\s*\)|(?:eq(?:uation)?\.?\s*)"
    r"(?P<b>\d+[a-z]?)[.:)]?)\s*[:.–-]?\s*(?P<title>.*?)\s*#*\s*$",
    re.IGNORECASE,
)
_CITE = re.compile(r"\beqs?\.\s*(?P<list>\d+[a-z]?(?:\s*(?:[–—-]|,|and|&)\s*\d+[a-z]?)*)")
_LABEL = re.compile(r"(\d+)([a-z]?)")


@dataclass(frozen=True)
class Equation:
    """One numbered equation of docs/equations.md."""

    number: str  # "13", "15a"
    title: str
    body: str  # the first code block under the heading ('' if none)
    line: int  # line of the heading in equations.md


@dataclass(frozen=True)
class Site:
    """A piece of code that cites equations."""

    path: str  # relative to the project root, POSIX
    line: int
    qualname: str  # module.Class.method, module.function, module.Class.field or module
    kind: str  # "function", "class", "field", "comment", "module"
    cites: tuple[str, ...]  # equation labels cited there, e.g. ("13", "20") or ("15a",)

    @property
    def where(self) -> str:
        return f"{self.path}:{self.line}"

    @property
    def short_name(self) -> str:
        """The qualified name without the package prefix: ``sim.robot.gamma_matrix``."""
        return self.qualname.removeprefix("pipeline.")


@dataclass
class CodeIndex:
    """All code sites of the package, with lookups by qualified name and by equation."""

    sites: list[Site] = field(default_factory=list)

    def by_qualname(self, qualname: str) -> list[Site]:
        return [s for s in self.sites if s.qualname == qualname]

    def citing(self, number: str, headings: set[str]) -> list[Site]:
        """Sites that cite equation ``number``; module-level ranges only as a fallback."""
        fine = [s for s in self.sites if s.kind != "module" and label_matches(number, s.cites,
                                                                              headings)]
        if fine:
            return fine
        return [s for s in self.sites if s.kind == "module"
                and label_matches(number, s.cites, headings)]


def parse_citations(text: str) -> tuple[str, ...]:
    """Equation labels cited in a text: 'eq. 6' → (6), 'eqs. 13–16' → (13, 14, 15, 16)."""
    out: list[str] = []
    for m in _CITE.finditer(text):
        parts = re.split(r"\s*(,|and|&)\s*", m.group("list"))
        for part in parts:
            if part in (",", "and", "&") or not part:
                continue
            rng = re.split(r"\s*[–—-]\s*", part)
            if len(rng) == 2 and rng[0].isdigit() and rng[1].isdigit():
                lo, hi = int(rng[0]), int(rng[1])
                out.extend(str(i) for i in range(lo, hi + 1) if hi - lo < 50)
            else:
                out.extend(p for p in rng if _LABEL.fullmatch(p))
    return tuple(dict.fromkeys(out))


def label_matches(number: str, cites: tuple[str, ...], headings: set[str]) -> bool:
    """Does a site citing ``cites`` implement heading ``number``?

    Exact labels match; a sub-label (13a) also belongs to its parent heading (13) when the
    document has no heading of its own for it.
    """
    for c in cites:
        if c == number:
            return True
        m = _LABEL.fullmatch(c)
        if m and m.group(2) and m.group(1) == number and c not in headings:
            return True
    return False


def parse_equations(path: Path = EQUATIONS_MD) -> list[Equation]:
    """The numbered headings of equations.md in document order, each with its first code block.

    Tolerant of heading depth (## to ####) and of '(N) Title', '(eq. N) Title' and
    'Eq. N: Title' forms; a repeated number keeps its first heading.
    """
    if not Path(path).is_file():
        return []
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    heads = []
    in_fence = False
    for i, line in enumerate(lines):
        if line.lstrip().startswith("```"):
            in_fence = not in_fence
            continue
        if in_fence:
            continue
        if re.match(r"^#{1,6}\s", line):
            m = _HEADING.match(line)
            heads.append((i, (m.group("a") or m.group("b")) if m else None,
                          m.group("title").strip() if m else ""))
    out, seen = [], set()
    for j, (i, number, title) in enumerate(heads):
        if number is None or number in seen:
            continue
        seen.add(number)
        stop = heads[j + 1][0] if j + 1 < len(heads) else len(lines)
        out.append(Equation(number, title, _first_code_block(lines[i + 1:stop]), i + 1))
    return out


def _first_code_block(lines: list[str]) -> str:
    block, inside = [], False
    for line in lines:
        if line.lstrip().startswith("```"):
            if inside:
                break
            inside = True
            continue
        if inside:
            block.append(line.rstrip())
    return "\n".join(block).strip("\n")


def _module_name(path: Path) -> str:
    rel = path.relative_to(PROJECT_ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


class _Scopes(ast.NodeVisitor):
    """Every def/class with its qualified name and line range; class-body annotated fields."""

    def __init__(self) -> None:
        self.scopes: list[tuple[int, int, str, ast.AST]] = []
        self.fields: dict[int, str] = {}
        self._stack: list[str] = []

    def _scoped(self, node) -> None:
        qual = ".".join([*self._stack, node.name])
        self.scopes.append((node.lineno, node.end_lineno or node.lineno, qual, node))
        if isinstance(node, ast.ClassDef):
            for stmt in node.body:
                if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
                    self.fields[stmt.lineno] = f"{qual}.{stmt.target.id}"
        self._stack.append(node.name)
        self.generic_visit(node)
        self._stack.pop()

    visit_FunctionDef = visit_AsyncFunctionDef = visit_ClassDef = _scoped

    def innermost(self, line: int) -> tuple[str, int] | None:
        best = None
        for lo, hi, qual, _ in self.scopes:
            if lo <= line <= hi and (best is None or lo >= best[1]):
                best = (qual, lo)
        return best


def _decorated_line(node: ast.AST) -> int:
    """The line of ``def``/``class`` itself (decorators excluded)."""
    return node.lineno


def scan_file(path: Path) -> list[Site]:
    """The code sites of one Python file."""
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    mod = _module_name(path)
    rel = path.relative_to(PROJECT_ROOT).as_posix()
    scopes = _Scopes()
    scopes.visit(tree)
    sites: list[Site] = []
    doc = ast.get_docstring(tree)
    if doc and parse_citations(doc):
        sites.append(Site(rel, 1, mod, "module", parse_citations(doc)))
    for _, _, qual, node in scopes.scopes:
        doc = ast.get_docstring(node)
        cites = parse_citations(doc or "")
        if cites:
            kind = "class" if isinstance(node, ast.ClassDef) else "function"
            sites.append(Site(rel, _decorated_line(node), f"{mod}.{qual}", kind, cites))
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type != tokenize.COMMENT:
            continue
        cites = parse_citations(tok.string)
        if not cites:
            continue
        line = tok.start[0]
        if line in scopes.fields:
            sites.append(Site(rel, line, f"{mod}.{scopes.fields[line]}", "field", cites))
            continue
        inner = scopes.innermost(line)
        qual = f"{mod}.{inner[0]}" if inner else mod
        sites.append(Site(rel, line, qual, "comment", cites))
    return sites


def scan_package(root: Path = PACKAGE) -> CodeIndex:
    """Scan every module of the package (except the excluded sub-packages)."""
    index = CodeIndex()
    for path in sorted(Path(root).rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[0] in EXCLUDED or "__pycache__" in rel.parts:
            continue
        index.sites.extend(scan_file(path))
    return index
