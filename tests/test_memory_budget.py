"""The memory budget under the limits clusters set (issue 49 item 2): the least of half the
RAM, the cgroup's limit and what RLIMIT_AS leaves; no read reserves more than its data; a
stream or a device is bounded.

The address-space limit is set in a child process (``ulimit -v`` as a cluster node sets it),
so this process's own limits stay as they are."""

from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
from conftest import run_cli

from pipeline.bounded_read import read_at_most
from pipeline.logs import verify_log
from pipeline.paths import PROJECT_ROOT

QUARTER_RAM = psutil.virtual_memory().total // 4


def _limited(code: str, limit: int, *args: str) -> subprocess.CompletedProcess:
    """``python -c code args`` with RLIMIT_AS at ``limit`` bytes."""
    def preexec() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return subprocess.run([sys.executable, "-c", code, *args], cwd=PROJECT_ROOT,
                          capture_output=True, text=True, timeout=300, preexec_fn=preexec)


def test_the_budget_is_what_the_address_space_limit_leaves():
    """Under RLIMIT_AS the budget is at most the limit less the address space the process
    holds (read from /proc here, not from the code under test), and below half the RAM."""
    r = _limited("import re, sys; from pipeline.budget import Budget; "
                 "b = Budget.from_environment().memory_bytes; "
                 "vm = int(re.search(r'VmSize:\\s+(\\d+) kB', open('/proc/self/status').read())"
                 "[1]) * 1024; print(b, vm)", QUARTER_RAM)
    assert r.returncode == 0, r.stderr
    budget, vm = map(float, r.stdout.split())
    assert 0 < budget <= QUARTER_RAM - vm + 64 * 2**20  # what was reserved between the reads
    assert budget < 0.5 * psutil.virtual_memory().total


def test_the_override_lowers_the_budget_and_never_raises_it(monkeypatch):
    from pipeline.budget import Budget, memory_limit

    monkeypatch.setenv("BREVE_MEMORY_BUDGET_GB", "0.5")
    assert Budget.from_environment().memory_bytes == 0.5 * 2**30
    monkeypatch.setenv("BREVE_MEMORY_BUDGET_GB", "1e6")
    assert Budget.from_environment().memory_bytes == memory_limit()


def test_an_import_of_a_small_file_works_under_a_quarter_of_the_ram(short_logs, tmp_path):
    log = verify_log(short_logs["short_nominal"])
    cols = log.columns(["t", "q", "v"])
    src = tmp_path / "small.npz"
    np.savez(src, t=cols["t"], q=cols["q"], v=cols["v"])
    assert src.stat().st_size < 1_000_000
    r = _limited("import sys; from pipeline.cli import main; sys.exit(main(sys.argv[1:]))",
                 QUARTER_RAM, "import", str(src), "--robot", "short_nominal", "--out",
                 str(tmp_path / "logs"))
    assert r.returncode == 0, r.stderr
    assert "MemoryError" not in r.stderr
    verify_log(tmp_path / "logs" / "imported" / "small" / "run.parquet")


def test_read_at_most_stops_at_its_bound_on_a_device():
    with open("/dev/zero", "rb") as fh:
        data = read_at_most(fh, 3 * 2**20 + 5)
    assert len(data) == 3 * 2**20 + 6 and not any(data)


@pytest.mark.parametrize("args,needle", [
    (["import", "/dev/zero", "--format", "parquet", "--robot", "short_nominal", "--out",
      "{logs}"], "not a regular file"),
    (["import", "{src}", "--robot", "short_nominal", "--mapping", "/dev/zero", "--out",
      "{logs}"], "longer than 16 MiB"),
    (["validate", "{zero_yaml}"], "zero.yaml"),
])
def test_a_device_is_refused_in_one_line_not_read_without_end(tmp_path, args, needle):
    src = tmp_path / "x.npz"
    np.savez(src, t=np.zeros(3))
    (tmp_path / "zero.yaml").symlink_to("/dev/zero")
    t0 = time.perf_counter()
    r = run_cli(*[a.format(src=src, logs=tmp_path / "logs", zero_yaml=tmp_path / "zero.yaml")
                  for a in args])
    assert time.perf_counter() - t0 < 60
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], lines
    assert not (tmp_path / "logs").exists()


def test_no_read_of_a_small_file_reserves_the_budget(tmp_path):
    """The old read reserved budget + 1 bytes before reading one: under an address-space
    limit below the budget's default it died with a MemoryError."""
    src = Path(tmp_path / "small.bin")
    src.write_bytes(b"x" * 1000)
    r = _limited("import sys; from pathlib import Path; from pipeline.importer.readers import "
                 "read_bytes; print(len(read_bytes(Path(sys.argv[1])).data))",
                 QUARTER_RAM, str(src))
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "1000"
