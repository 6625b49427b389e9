"""The Jinja2 environment of the reports: templates under ``templates/``, HTML autoescaped.

Templates named ``*.html.j2`` are autoescaped (every value from a spec, a log or an analysis is
escaped); Markdown templates (``*.md.j2``) are not, and use the ``cell`` filter, which also
neutralises ``|`` and angle brackets inside table cells.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from urllib.parse import quote

from jinja2 import Environment, FileSystemLoader, StrictUndefined

from pipeline.atomic_files import atomic_write_text

TEMPLATES = Path(__file__).resolve().parent / "templates"


def _autoescape(name: str | None) -> bool:
    return name is None or name.endswith((".html.j2", ".html"))


def num(x, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; booleans and text as they are; None (a
    number the data could not determine) as "undetermined"."""
    if x is None:
        return "undetermined"
    if isinstance(x, bool):
        return str(x)
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        if x == 0:
            return "0"
        return f"{x:.{digits}g}"
    return str(x)


def sci(x, digits: int = 3) -> str:
    """Scientific notation (for differences and tolerances): 0.000e+00."""
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return f"{float(x):.{digits}e}"
    return str(x)


def val(x) -> str:
    """A measured value or threshold: numbers to 4 significant digits, mappings compact."""
    if isinstance(x, (dict, list)):
        text = json.dumps(x, separators=(", ", ": "), default=str)
        return text if len(text) <= 80 else text[:77] + "..."
    return num(x)


def complex_num(z) -> str:
    """A complex value (``Complex``: real, imag) as ``num`` writes its parts: the real part,
    then the imaginary one with its sign, none when it is zero."""
    if not z.imag:
        return num(z.real)
    return f"{num(z.real)} {'+' if z.imag > 0 else '−'} {num(abs(z.imag))}j"


_TAGLIKE = re.compile(r"<[A-Za-z/!?]")


def cell(x) -> str:
    """Text safe inside a Markdown table cell."""
    s = str(x).replace("\n", " ").replace("|", "\\|")
    return _TAGLIKE.sub(lambda m: "&lt;" + m.group(0)[1:], s)


_SENTENCE_END = re.compile(r"\.\s+(?=[A-Z(])")


def first_sentence(text: str) -> str:
    """The first sentence of ``text``: up to a full stop followed by a capital (an
    abbreviation such as "eq. 31" does not end one), without the stop."""
    return _SENTENCE_END.split(str(text), maxsplit=1)[0].rstrip(".")


def href(path: str) -> str:
    """A relative link with each path segment percent-encoded."""
    return "/".join(quote(part) for part in str(path).split("/"))


def rel(path) -> str:
    """A path relative to the project root when it lies inside it."""
    from pipeline.paths import display_path

    return display_path(path)


def environment() -> Environment:
    env = Environment(loader=FileSystemLoader(str(TEMPLATES)), autoescape=_autoescape,
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                      keep_trailing_newline=True)
    from pipeline.analysis.verdict import measured_words

    env.filters.update(num=num, complex_num=complex_num, sci=sci, cell=cell, href=href, val=val,
                       rel=rel, first_sentence=first_sentence, measured_words=measured_words)
    return env


def render(template: str, path: Path, **context) -> Path:
    """Render a template into ``path`` atomically."""
    text = environment().get_template(template).render(**context).rstrip("\n") + "\n"
    atomic_write_text(Path(path), text)
    return Path(path)
