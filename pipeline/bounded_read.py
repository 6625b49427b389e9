"""A file read in chunks up to a bound (issue 49): ``fh.read(n)`` reserves n bytes before it
reads one, so a read bounded by the memory budget reserved the whole budget (and failed under
an address-space limit below it), and an unbounded read of a device never ended."""

from __future__ import annotations

from typing import BinaryIO

READ_CHUNK = 1 << 20


def read_at_most(fh: BinaryIO, limit: int) -> bytes:
    """At most ``limit`` + 1 bytes of the open binary file ``fh``, read in chunks: a caller
    that gets more than ``limit`` refuses the file, and no buffer larger than the data read
    so far is reserved (``read(n)`` reserves n bytes before it reads one)."""
    parts, size = [], 0
    while size <= limit:
        chunk = fh.read(min(READ_CHUNK, limit + 1 - size))
        if not chunk:
            break
        parts.append(chunk)
        size += len(chunk)
    return b"".join(parts)
