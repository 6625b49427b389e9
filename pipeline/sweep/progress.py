"""What a running sweep shows and remembers: points done, failed, running, and retried.

Tasks announce their start as a Dask event (``announce_start``, on the worker); the driver
subscribes to the sweep's topic, and ``Tracker`` counts the starts of each point (a point
started twice was retried: its first worker died or retired under it) and what is running.
Finished points come from ``distributed.as_completed``. Both arrive on different threads, so
the tracker holds a lock. ``Progress`` shows the counts whenever they change: a bar on a
terminal, otherwise one line per change (CI logs, batch jobs).
"""

from __future__ import annotations

import os
import socket
import sys
import threading
from collections import Counter

from tqdm import tqdm


def worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def announce_start(topic: str, point: str) -> None:
    """On a worker: tell the driver that ``point`` starts here (no-op outside a worker)."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return
    worker.log_event(topic, {"point": point, "worker": worker_id()})


class Tracker:
    """Starts and ends of the points of one sweep, fed from two threads."""

    def __init__(self, names: list[str], progress: Progress) -> None:
        self._lock = threading.Lock()
        self._names = set(names)
        self.starts: Counter[str] = Counter()
        self.running: dict[str, str] = {}  # point → worker that last started it
        self.done = 0
        self.failed = 0
        self.progress = progress

    def started(self, event) -> None:
        """Handler of the sweep's Dask topic: ``event`` is ``(timestamp, message)``."""
        msg = event[1] if isinstance(event, tuple) else event
        point = msg.get("point") if isinstance(msg, dict) else None
        if point not in self._names:
            return
        with self._lock:
            self.starts[point] += 1
            self.running[point] = msg.get("worker", "")
            self._show()

    def finished(self, point: str, ok: bool) -> None:
        with self._lock:
            self.running.pop(point, None)
            self.done += ok
            self.failed += not ok
            self._show()

    def attempts(self, point: str) -> int:
        with self._lock:
            return self.starts[point]

    def _show(self) -> None:
        self.progress.show(self.done, self.failed, len(self.running))


class Progress:
    """A tqdm bar on a terminal, else one line on ``stream`` per change of the counts."""

    def __init__(self, name: str, total: int, terminal: bool, stream=None,
                 kind: str = "sweep", unit: str = "point") -> None:
        self.name, self.total, self.kind = name, total, kind
        self.stream = stream or sys.stderr
        self.last: tuple[int, int, int] | None = None
        self.bar = (tqdm(total=total, unit=unit, desc=name, file=self.stream)
                    if terminal else None)

    def show(self, done: int, failed: int, running: int) -> None:
        now = (done, failed, running)
        if now == self.last:
            return
        prev = self.last or (0, 0, 0)
        self.last = now
        if self.bar is not None:
            self.bar.set_postfix_str(f"done {done}, failed {failed}, running {running}",
                                     refresh=False)
            self.bar.update(done + failed - prev[0] - prev[1])
            self.bar.refresh()
        else:
            print(f"{self.kind} {self.name}: {done + failed}/{self.total} finished "
                  f"({done} done, {failed} failed), {running} running",
                  file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
