"""The lock of an artefact folder and the clean-up of a killed writer's files.

Making a log or an analysis runs under an exclusive ``flock`` on ``<folder>/.lock``, so two
processes sharing a folder (two sweeps sharing a point, a rescheduled task meeting its
predecessor, ``make`` and a sweep) never make it twice at once; the second waits, then finds
it current. The kernel drops the lock of a killed process, so a stale lock cannot block.
Holding the lock, a maker removes the temporary files a killed writer of this folder left.
"""

from __future__ import annotations

import errno
import fcntl
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from pipeline.atomic_files import cannot_write

LOCK_NAME = ".lock"


def _make_folder(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; the ones created, deepest first. A path in
    the way that is a file, or a folder that cannot be written, is an OutputError naming it."""
    made = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise cannot_write(folder, exc) from None
    return made


@contextmanager
def folder_lock(folder: Path) -> Iterator[None]:
    """Exclusive lock on ``folder/.lock`` (``flock``; released by the kernel if we die).

    The lock file is removed on release; a waiter that then holds a lock on the removed file
    notices (inode changed) and locks the new one. Folders the lock created and the holder
    left empty (a refused run, a failed analysis) are removed on release: nothing is left
    where nothing was written. On a file system without ``flock`` the holder runs unlocked
    (the atomic rename still rules out a torn file).
    """
    folder = Path(folder)
    path = folder / LOCK_NAME
    made: list[Path] = []
    while True:
        made += [p for p in _make_folder(folder) if p not in made]
        try:
            fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o644)
        except FileNotFoundError:  # a holder removed the empty folder meanwhile
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.ENOLCK, errno.ENOSYS, errno.EOPNOTSUPP, errno.EINVAL):
                yield
                return
            raise
        try:
            st = os.stat(path)
            held = (st.st_ino, st.st_dev) == (os.fstat(fd).st_ino, os.fstat(fd).st_dev)
        except FileNotFoundError:
            held = False
        if held:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
        yield
    finally:
        with suppress(FileNotFoundError):
            os.unlink(path)
        os.close(fd)
        for p in made:  # deepest first; a folder with anything in it stays
            try:
                p.rmdir()
            except OSError:
                break


def remove_stale_temps(folder: Path) -> list[str]:
    """Delete the ``.*.tmp`` files of a dead writer (call only while holding the lock)."""
    gone = []
    for p in folder.glob(".*.tmp"):
        with suppress(FileNotFoundError):
            p.unlink()
            gone.append(p.name)
    return gone


def clear_unheld(folder: Path) -> list[str]:
    """After a stopped sweep: if no live process holds ``folder``'s lock, delete the temporary
    files a killed writer left and the stale lock file; a point still held (its task runs on
    a worker that outlives the sweep) is left to its holder. Returns what was deleted."""
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:
        return remove_stale_temps(folder) if folder.is_dir() else []
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return []  # held by a live task, or no flock here: not ours to touch
        gone = remove_stale_temps(folder)
        with suppress(FileNotFoundError):
            os.unlink(path)
        return [*gone, LOCK_NAME]
    finally:
        os.close(fd)
