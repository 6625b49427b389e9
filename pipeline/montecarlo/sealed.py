"""JSON the Monte Carlo keeps and reads back, sealed by its content's SHA-256 (eq. 39).

A kept sample record, a verdict and a detector-power result are read again by later runs, the
reports and the claims. Each is written with ``content_sha256``, the SHA-256 of its canonical
JSON (sorted keys, no spaces, NaN as JSON's NaN), and checked on reading: an edited or damaged
file (a ``passes: false`` turned true, a truncated write) does not match, so a record is run
again and a verdict or result is refused, naming the file, instead of being counted as if
whole. A float reads back from JSON to the same value, so the digest of what was written is
the digest of what is read.
"""

from __future__ import annotations

import hashlib
import json

CONTENT_KEY = "content_sha256"


def content_digest(body: dict) -> str:
    """SHA-256 of ``body``'s canonical JSON, its own digest left out."""
    text = json.dumps({k: v for k, v in body.items() if k != CONTENT_KEY}, sort_keys=True,
                      separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def sealed_json(body: dict, indent: int | None = None) -> str:
    """``body`` as JSON with its ``content_sha256``."""
    return json.dumps({**body, CONTENT_KEY: content_digest(body)}, indent=indent,
                      allow_nan=True)


def unseal(text: str) -> dict:
    """The JSON object of ``text`` without its digest; ValueError if it is not an object or
    its digest is missing or does not match its content."""
    data = json.loads(text)
    if not isinstance(data, dict):
        raise ValueError("not a JSON object")
    if CONTENT_KEY not in data:
        raise ValueError(f"no {CONTENT_KEY}: not written by this version, or altered")
    if data[CONTENT_KEY] != content_digest(data):
        raise ValueError(f"its {CONTENT_KEY} does not match its content: altered or damaged")
    return {k: v for k, v in data.items() if k != CONTENT_KEY}
