"""The docs the code cites are in the repository, and say what the code cites them for."""

from __future__ import annotations

import re

from pipeline.paths import PROJECT_ROOT

PKG = PROJECT_ROOT / "pipeline"


def _sources() -> str:
    return "\n".join(p.read_text() for p in PKG.rglob("*.py") if "__pycache__" not in p.parts)


def test_every_architecture_citation_has_its_section():
    page = (PROJECT_ROOT / "docs" / "architecture.md").read_text()
    sections = set(re.findall(r"^## (\d+)\. ", page, re.M))
    cited = set(re.findall(r"architecture\s+§(\d+)", _sources()))
    cited |= {n for group in re.findall(r"architecture\s+§\d+(?:,\s*§\d+)+", _sources())
              for n in re.findall(r"§(\d+)", group)}
    assert cited, "the code cites the architecture page"
    assert cited <= sections, f"cited sections missing: {sorted(cited - sections)}"


def test_no_citation_of_a_file_outside_the_repository():
    assert "DESIGN §" not in _sources()
