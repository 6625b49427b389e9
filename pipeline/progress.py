"""What the user sees while the pipeline works: one line when a stage starts, one when it ends
(with its wall time), on stderr; a progress bar only on a terminal.

    compile: started (2 processes) -> pipeline/sim/__pycache__/numba-…
    compile: done in 41.2 s
    mission nominal: started (2000 steps) -> logs/nominal/run.parquet
    mission nominal: done in 3.4 s (complete)

Off a terminal (CI logs, a pipe) the lines are all there is, so a log reads as a list of stages
with their times; on a terminal the long stages (missions, the compile, the sweeps) also draw a
tqdm bar, which ends before the stage's last line.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager


def interactive() -> bool:
    """Whether progress bars are drawn: stderr is a terminal."""
    return sys.stderr.isatty()


def say(line: str) -> None:
    """One progress line on stderr, flushed (make and a pipe show it at once)."""
    print(line, file=sys.stderr, flush=True)


class Stage:
    """A running stage: ``done`` sets the note of its end line (e.g. a run's status)."""

    def __init__(self, name: str):
        self.name = name
        self.note = ""
        self.t0 = time.perf_counter()

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self.t0

    def done(self, note: str) -> None:
        self.note = note


@contextmanager
def stage(name: str, detail: str = "") -> Iterator[Stage]:
    """``name: started (detail)`` now, ``name: done in S s (note)`` at the end, or ``name:
    failed after S s`` if the block raises (the exception goes on)."""
    say(f"{name}: started" + (f" {detail}" if detail else ""))
    s = Stage(name)
    try:
        yield s
    except BaseException:
        say(f"{name}: failed after {s.seconds:.1f} s")
        raise
    say(f"{name}: done in {s.seconds:.1f} s" + (f" ({s.note})" if s.note else ""))
