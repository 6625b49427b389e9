"""YAML files of the project (specs, claims registers, the seed note) read one way: YAML 1.2.

PyYAML implements YAML 1.1, which reads ``1e-2`` as a string and ``yes`` as true; ruamel.yaml's
safe loader reads YAML 1.2, where ``1e-2`` is a float and ``yes`` a string. Duplicate keys are
refused (YAML forbids them; a silent last-one-wins would hide a typo), and so is an empty file:
an empty spec is a mistake, not a request for defaults. Every error is a one-line SpecError
naming the file and, where the parser knows it, the line.
"""

from __future__ import annotations

import copy
import functools
from pathlib import Path
from typing import Any

from ruamel.yaml import YAML
from ruamel.yaml.constructor import DuplicateKeyError
from ruamel.yaml.error import MarkedYAMLError, YAMLError

from pipeline.bounded_read import read_at_most
from pipeline.errors import SpecError

# A spec, a register, a mapping or a study file is a few kB: a file past this is not one
# (``/dev/zero`` would otherwise be read until memory runs out).
YAML_MAX_BYTES = 16 << 20


def _loader() -> YAML:
    y = YAML(typ="safe", pure=True)
    y.allow_duplicate_keys = False
    return y


def _where(exc: MarkedYAMLError) -> str:
    mark = exc.problem_mark or exc.context_mark
    return f" (line {mark.line + 1})" if mark is not None else ""


@functools.lru_cache(maxsize=512)
def _parse(text: str) -> Any:
    # A run of the claims reads the same specs and registers some seventy times, and the
    # pure-Python parser takes tens of milliseconds a file: each text is parsed once per
    # process. Callers get a copy (they may change it); errors are not cached.
    return _loader().load(text)


def load_text(text: str, source: str, what: str = "YAML file") -> Any:
    """The document in ``text``; ``source`` names it in errors."""
    try:
        return copy.deepcopy(_parse(text))
    except DuplicateKeyError as exc:
        key = (exc.problem or "").split('"')[1] if '"' in (exc.problem or "") else "?"
        raise SpecError(f"{source}: duplicate key {key!r}{_where(exc)} in the {what}") from None
    except MarkedYAMLError as exc:
        raise SpecError(f"{source}: broken YAML{_where(exc)}: {exc.problem}") from None
    except YAMLError as exc:
        first = (str(exc).strip().splitlines() or ["?"])[0]
        raise SpecError(f"{source}: broken YAML: {first}") from None


def read_yaml(path: Path | str, what: str = "YAML file") -> dict:
    """A YAML file that must hold a mapping (a spec, a claims register, the note)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            raw = read_at_most(fh, YAML_MAX_BYTES)
    except OSError as exc:
        raise SpecError(f"{path}: cannot read the {what}: {exc.strerror}") from None
    if len(raw) > YAML_MAX_BYTES:
        raise SpecError(f"{path}: the {what} is longer than {YAML_MAX_BYTES >> 20} MiB (a "
                        "device or a stream?): not a YAML file of this project")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise SpecError(f"{path}: the {what} is not UTF-8 text") from None
    data = load_text(text, str(path), what)
    if data is None:
        raise SpecError(f"{path}: the {what} is empty")
    if not isinstance(data, dict):
        raise SpecError(f"{path}: a {what} must be a mapping, got {type(data).__name__}")
    return data


def parse_scalar(text: str) -> Any:
    """A YAML 1.2 value from a command-line string (``0.01`` and ``1e-2`` floats, ``20`` an
    int, ``imex`` a string, ``[0, 1]`` a list); text that is not YAML stays text."""
    try:
        return _loader().load(text)
    except YAMLError:
        return text
