"""Processes that end with the command that started them, ``kill -9`` included.

A worker the pipeline starts (a figure process of ``report``, a compile process, a sweep run
in the background by ``claims``) watches the process that started it and exits as soon as
that process is gone: a killed command leaves no worker drawing, compiling or simulating on
its own, holding memory and writing files nobody asked for. (Dask's own worker processes
already exit when the process holding their nanny dies.)
"""

from __future__ import annotations

import os
import threading
import time

PARENT_ENV = "BREVE_PARENT_PID"  # set for a child command that should end with its parent
PERIOD_S = 0.2  # how often a worker looks: a killed command's workers are gone within it


def exit_with_parent(parent: int) -> None:
    """End this process (``os._exit``, no clean-up: the work is abandoned) as soon as the
    process ``parent`` is no longer its parent, checked every :data:`PERIOD_S` by a daemon
    thread. Call it first thing in a worker; it returns at once."""
    if os.getppid() != parent:  # gone already
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PERIOD_S)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def child_environment() -> dict[str, str]:
    """The environment of a child command that is to end with this process (see
    :func:`watch_from_environment`)."""
    return {**os.environ, PARENT_ENV: str(os.getpid())}


def watch_from_environment() -> None:
    """In a command started with :func:`child_environment`: end with the process that started
    it. The variable names one process; a grandchild (whose parent is another) ignores it."""
    text = os.environ.get(PARENT_ENV, "")
    if text.isdigit() and int(text) == os.getppid():
        exit_with_parent(int(text))
