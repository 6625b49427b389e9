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


def _spec_fields(model: type, prefix: str = "") -> list[str]:
    """The dotted path of every leaf field of the spec models."""
    from pydantic import BaseModel

    out = []
    for name, field in model.model_fields.items():
        ann = field.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            out += _spec_fields(ann, f"{prefix}{name}.")
        else:
            out.append(prefix + name)
    return out


def _reference_rows(page: str) -> dict[str, list[str]]:
    return {m.group(1): [c.strip() for c in m.group(2).split(" | ")]
            for m in re.finditer(r"^\| `([a-z_A-Z.]+)` \| (.*) \|$", page, re.M)}


def _reference_problems(page: str) -> list[str]:
    """What spec_reference.md (``page``) gets wrong about the models of pipeline/spec.py: a
    field missing or extra, a default other than the code's, a row without unit or meaning."""
    import json

    from pipeline.spec import Spec

    rows = _reference_rows(page)
    fields = _spec_fields(Spec)
    wrong = [f"{f}: not on the page" for f in fields if f not in rows]
    wrong += [f"{r}: on the page, not in the code" for r in set(rows) - set(fields) - {"extends"}]
    defaults = Spec.model_validate({"name": "x"}).model_dump(mode="json")
    for path in fields:
        if path == "name" or path not in rows:
            continue
        value = defaults
        for part in path.split("."):
            value = value[part]
        _type, default, unit, meaning = rows[path]
        if default != f"`{json.dumps(value, ensure_ascii=False)}`":
            wrong.append(f"{path}: page says {default}, code {value!r}")
        if not unit or not meaning:
            wrong.append(f"{path}: no unit or meaning")
    return wrong


def _reference_page() -> str:
    return (PROJECT_ROOT / "docs" / "spec_reference.md").read_text()


def test_spec_reference_lists_every_field_with_the_code_default():
    from pipeline.spec import Spec

    assert len(_spec_fields(Spec)) > 50
    assert _reference_problems(_reference_page()) == []


def test_spec_reference_check_can_fail():
    """A missing row and a stale default are both caught."""
    page = _reference_page()
    no_dt = "\n".join(ln for ln in page.splitlines() if not ln.startswith("| `mission.dt`"))
    assert _reference_problems(no_dt) == ["mission.dt: not on the page"]
    stale = page.replace("| `mission.duration` | number, > 0, finite | `60.0` |",
                         "| `mission.duration` | number, > 0, finite | `30.0` |")
    assert _reference_problems(stale) == ["mission.duration: page says `30.0`, code 60.0"]
