"""Files written whole or not at all: a temporary file in the same folder, fsynced, then
renamed over the target (every stage's outputs; the log writer builds on the same two steps).
A target that cannot be written is an OutputError naming it, and nothing is left there.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from pipeline.errors import OutputError

_UMASK = os.umask(0)
os.umask(_UMASK)


def cannot_write(path: Path, exc: OSError) -> OutputError:
    return OutputError(f"{path}: cannot write: {exc.strerror or exc} (nothing written there)")


def atomic_target(path: Path) -> Path:
    """A fresh temporary file beside ``path``, readable as an ordinary file would be.
    An output folder that is a file, read-only or full is an OutputError naming the path."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise cannot_write(path, exc) from None
    os.fchmod(fd, 0o666 & ~_UMASK)  # mkstemp makes 0600; the final file should not be
    os.close(fd)
    return Path(tmp)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write bytes to ``path`` atomically (temporary file, fsync, rename); on failure the
    temporary file is removed and ``path`` is as it was."""
    path = Path(path)
    tmp = atomic_target(path)
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        raise cannot_write(path, exc) from None
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())
