"""The fault and bad-input suite (issues 36 and 49): the importer, imported and simulated
artefacts, the plant's fields, the studies' counts and seeds, degenerate data and faults, each
case through the command line as a user meets it.

Run from the repository: ``.venv/bin/python scripts/fault_suite.py [--keep DIR]``. It runs the
short nominal mission into a scratch folder, builds every case from that log, and runs every
case twice: as it is, and under an address-space limit of a quarter of the RAM (``ulimit
-v``, as cluster nodes set it). Each command runs under a wall-time cap (``WALL_CAP_S``) and a
memory cap on its process tree (``RSS_CAP``): one that passes either is killed and counted as
a runaway. One line per case and pass, then the totals per pass: cases tried, refused
cleanly (the expected exit code, the last line on stderr the one error naming the file or
field, the lines before it only a stage's progress or argparse's usage, no traceback),
accepted rightly (exit 0 and the data checked against the source), tracebacks, wrong answers
(a refusal where an acceptance was due or the reverse, or accepted data that differ),
runaways, data lost (a file that was there before a refused command and is not, or
changed). Exit 1 if any case is not as expected.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import psutil
import pyarrow as pa
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]


WALL_CAP_S = 180.0  # a command still running after this is a runaway
RSS_CAP = 4 * 2**30  # bytes: a command tree holding more is a runaway
RUNAWAY = -1000  # the exit code the runner gives a command it killed as a runaway
# The address-space limit of the current pass (None: none), set by main().
AS_LIMIT: int | None = None


def _tree_rss(p: psutil.Process) -> int:
    total = 0
    for proc in [p, *p.children(recursive=True)]:
        try:
            total += proc.memory_info().rss
        except psutil.Error:
            pass
    return total


def _kill_tree(p: psutil.Process) -> None:
    for proc in [*p.children(recursive=True), p]:
        try:
            proc.kill()
        except psutil.Error:
            pass


def run_capped(cmd: list[str], cwd: Path | None = None, stdin: bytes | None = None
               ) -> subprocess.CompletedProcess:
    """``cmd`` under the pass's address-space limit, killed with its children as a runaway
    (exit ``RUNAWAY``, stderr saying why) past ``WALL_CAP_S`` or ``RSS_CAP``."""
    def limit() -> None:
        if AS_LIMIT is not None:
            resource.setrlimit(resource.RLIMIT_AS, (AS_LIMIT, AS_LIMIT))

    proc = subprocess.Popen(cmd, cwd=cwd or ROOT, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=limit)
    me, why = psutil.Process(proc.pid), []

    def watch() -> None:
        while proc.poll() is None:
            rss = _tree_rss(me)
            if rss > RSS_CAP:
                why.append(f"RUNAWAY: {rss / 2**30:.1f} GiB held (cap {RSS_CAP / 2**30:.0f})")
                _kill_tree(me)
                return
            time.sleep(0.1)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        out, err = proc.communicate(stdin, timeout=WALL_CAP_S)
    except subprocess.TimeoutExpired:
        why.append(f"RUNAWAY: still running after {WALL_CAP_S:.0f} s")
        _kill_tree(me)
        out, err = proc.communicate()
    watcher.join(timeout=5)
    if why:
        return subprocess.CompletedProcess(cmd, RUNAWAY, out, why[0].encode())
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def cli(*args, cwd: Path | None = None, stdin: bytes | None = None
        ) -> subprocess.CompletedProcess:
    return run_capped([sys.executable, "-m", "pipeline", *map(str, args)], cwd, stdin)


@dataclass
class Case:
    name: str
    run: Callable[[Path], subprocess.CompletedProcess]
    code: int  # the exit code expected
    needle: str = ""  # in stderr (a refusal) or stdout (an acceptance)
    check: Callable[[Path], str | None] | None = None  # a wrong answer's description, or None
    keep: list[str] = field(default_factory=list)  # logs that must survive, relative to the dir


@dataclass
class Outcome:
    case: Case
    code: int
    err: str
    problem: str | None


def _cmdline(p: psutil.Process) -> str:
    """A process's command line; empty for one that has ended (a zombie, or gone)."""
    try:
        return " ".join(p.cmdline())
    except psutil.Error:
        return ""


def _parquet(path: Path, t, q, v) -> Path:
    pq.write_table(pa.table({"t": t, "q": list(q), "v": list(v)}), path)
    return path


def _npz(path: Path, **arrays) -> Path:
    np.savez(path, **arrays)
    return path


def _imp(src, name: str, *extra) -> Callable[[Path], subprocess.CompletedProcess]:
    return lambda d: cli("import", src(d) if callable(src) else src, "--robot", "short_nominal",
                         "--name", name, "--out", d / "logs", *extra)


def build_cases(base: dict, scratch: Path) -> list[Case]:
    t, q, v = base["t"], base["q"], base["v"]
    b = scratch / "src"
    b.mkdir()
    good = _parquet(b / "good.parquet", t, q, v)
    deg_q, deg_v = q.copy(), v.copy()
    deg_q[:, 9], deg_v[:, 8] = np.rad2deg(q[:, 9]), np.rad2deg(v[:, 8])
    scaled = v.copy()
    scaled[:, 6:] *= 1.00001
    keep = np.r_[0:200, 201:len(t)]
    jitter = t + np.where(np.arange(len(t)) == 50, 1e-6, 0.0)
    wander = t + np.random.default_rng(36).uniform(-0.1, 0.1, len(t)) * 0.03
    quat = q.copy()
    quat[:, 3:7] = q[:, [6, 3, 4, 5]]
    files = {
        "empty.csv": b"", "header.csv": b"t,q,v\n", "empty.npz": b"",
        "random.npz": os.urandom(4096), "truncated.npz": None, "noarrays.npz": None,
    }
    for name, data in files.items():
        if data is not None:
            (b / name).write_bytes(data)
    _npz(b / "full.npz", t=t, q=q, v=v)
    (b / "truncated.npz").write_bytes((b / "full.npz").read_bytes()[:5000])
    _npz(b / "noarrays.npz")
    pq.write_table(pa.table({"t": pa.array([], pa.float64()),
                             "q": pa.array([], pa.list_(pa.float64())),
                             "v": pa.array([], pa.list_(pa.float64()))}), b / "empty.parquet")
    _npz(b / "complex.npz", t=t, q=q + 1e-3j, v=v)
    _npz(b / "bool.npz", t=t, q=q, v=v > 0)
    _npz(b / "text.npz", t=t, q=q.astype(str), v=v)
    _parquet(b / "deg_elbow.parquet", t, deg_q, deg_v)
    _parquet(b / "scaled.parquet", t, q, scaled)
    _parquet(b / "quat.parquet", t, quat, v)
    _parquet(b / "gap.parquet", t[keep], q[keep], v[keep])
    _parquet(b / "jitter.parquet", jitter, q, v)
    _parquet(b / "wander.parquet", wander, q, v)
    big = np.array([2**63 + 5 + k * 30_000_000 for k in range(len(t))], dtype=object)
    pq.write_table(pa.table({"t": pa.array(big.astype(np.uint64)), "q": list(q),
                             "v": list(v)}), b / "uint64.parquet")
    other = _parquet(b / "other.parquet", t[:100], q[:100], v[:100])
    pq.write_table(pa.table({"t": [repr(x) for x in t], "q": list(q), "v": list(v)}),
                   b / "text_t.parquet")
    pq.write_table(pa.table({"t": pa.array(t.astype(np.float32), pa.float32()),
                             "q": list(q), "v": list(v)}), b / "float32_t.parquet")
    lines = ["t," + ",".join(f"q{i}" for i in range(13)) + "," + ",".join(
        f"v{i}" for i in range(12))]
    lines += [",".join(repr(float(x)) for x in (tk, *qk, *vk)) for tk, qk, vk in zip(
        t, q, v, strict=True)]
    csv_bytes = ("\n".join(lines) + "\n").encode()
    qcols = ",".join(f"q{i}" for i in range(13))
    vcols = ",".join(f"v{i}" for i in range(12))
    imported = "logs/imported/{}/run.parquet"

    def same_as_source(name: str) -> Callable[[Path], str | None]:
        def check(d: Path) -> str | None:
            got = pq.read_table(d / imported.format(name)).to_pydict()
            if not np.array_equal(np.array(got["q"]), q) or not np.array_equal(
                    np.array(got["v"]), v):
                return "q or v differ from the source"
            return None
        return check

    def pipe(d: Path) -> subprocess.CompletedProcess:
        return cli("import", "/dev/stdin", "--format", "csv", "--q", qcols, "--v", vcols,
                   "--robot", "short_nominal", "--name", "piped", "--out", d / "logs",
                   stdin=csv_bytes)

    def piped_hash(d: Path) -> str | None:
        md = pq.read_schema(d / imported.format("piped")).metadata
        rec = json.loads(md[b"pipeline.import"])
        return (None if rec["source_sha256"] == hashlib.sha256(csv_bytes).hexdigest()
                else "the recorded hash is not of the bytes read")

    def twice(d: Path) -> subprocess.CompletedProcess:
        _imp(good, "twice")(d)
        return _imp(good, "twice")(d)

    def other_name(d: Path) -> subprocess.CompletedProcess:
        _imp(good, "held")(d)
        return _imp(other, "held")(d)

    def forced(d: Path) -> subprocess.CompletedProcess:
        _imp(good, "forced")(d)
        return _imp(other, "forced", "--force")(d)

    def forced_rows(d: Path) -> str | None:
        n = pq.read_metadata(d / imported.format("forced")).num_rows
        return None if n == 100 else f"{n} rows, the forced import's are 100"

    def linked(d: Path) -> subprocess.CompletedProcess:
        (d / "logs" / "imported").mkdir(parents=True, exist_ok=True)
        (d / "elsewhere").mkdir()
        (d / "logs" / "imported" / "linked").symlink_to(d / "elsewhere")
        return _imp(good, "linked")(d)

    def nothing_elsewhere(d: Path) -> str | None:
        return "written through the link" if any((d / "elsewhere").iterdir()) else None

    def stale(d: Path) -> subprocess.CompletedProcess:
        folder = d / "logs" / "imported" / "stale"
        folder.mkdir(parents=True)
        (folder / ".run.parquet.x1.tmp").write_bytes(b"half")
        return _imp(good, "stale")(d)

    def stale_gone(d: Path) -> str | None:
        left = list((d / "logs" / "imported" / "stale").glob(".*.tmp"))
        return f"{left[0].name} left" if left else None

    def out_file(d: Path) -> subprocess.CompletedProcess:
        (d / "afile").write_text("x")
        return cli("import", good, "--robot", "short_nominal", "--out", d / "afile")

    def analysed(d: Path, name: str = "a") -> Path:
        _imp(good, name)(d)
        cli("analyze", d / imported.format(name), "--out", d / "rep")
        return d / "rep" / "imported" / name / "analysis.json"

    def edited_record(d: Path) -> subprocess.CompletedProcess:
        path = analysed(d)
        rec = json.loads(path.read_text())
        rec["dominant"]["lag1"] = 0.99
        path.write_text(json.dumps(rec))
        return cli("report", "--out", d / "rep")

    def edited_log(d: Path) -> subprocess.CompletedProcess:
        _imp(good, "e")(d)
        path = d / imported.format("e")
        table = pq.read_table(path)
        vv = np.array(table.column("v").to_pylist())
        vv[10, 3] += 1e-9
        table = table.set_column(table.schema.get_field_index("v"), "v",
                                 pa.array(list(vv), table.schema.field("v").type))
        pq.write_table(table, path)
        return cli("analyze", path, "--out", d / "rep")

    def gone_log(d: Path) -> subprocess.CompletedProcess:
        analysed(d, "g")
        (d / imported.format("g")).unlink()
        return cli("report", "--out", d / "rep")

    def flagged(d: Path) -> str | None:
        page = (d / "rep" / "imported" / "g" / "imported.md").read_text()
        return None if "Its log is gone" in page else "the page does not say its log is gone"

    def killed_report(d: Path) -> subprocess.CompletedProcess:
        analysed(d, "k")
        proc = subprocess.Popen([sys.executable, "-m", "pipeline", "report", "--out",
                                 str(d / "rep"), "--force"], cwd=ROOT,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        me, workers = psutil.Process(proc.pid), []
        for _ in range(600):
            workers = [c for c in me.children(recursive=True) if "spawn_main" in _cmdline(c)]
            if len(workers) >= 2 or proc.poll() is not None:
                break
            time.sleep(0.1)
        time.sleep(0.5)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        _, alive = psutil.wait_procs(workers, timeout=5)
        alive = [p for p in alive if _cmdline(p)]  # a zombie or gone has none
        for p in alive:
            p.kill()
        return subprocess.CompletedProcess(proc.args, 0 if not alive else 3,
                                           b"", f"{len(alive)} worker(s) left".encode()
                                           if alive else b"")

    def spec(d: Path, text: str) -> Path:
        path = d / "s.yaml"
        path.write_text(text)
        return path

    def static(d: Path) -> subprocess.CompletedProcess:
        n = 300
        src = _parquet(d / "still.parquet", np.arange(n) * 0.03, np.repeat(q[:1], n, 0),
                       np.zeros((n, 12)))
        _imp(src, "still")(d)
        return cli("analyze", d / imported.format("still"), "--out", d / "rep")

    def static_json(d: Path) -> str | None:
        text = (d / "rep" / "imported" / "still" / "analysis.json").read_text()
        return "NaN in analysis.json" if "NaN" in text else None

    # -- issue 49: simulated logs sealed, studies' counts, cluster limits, the import round --

    def simulated(d: Path) -> Path:
        r = cli("run", "short_nominal", "--out", d / "logs")
        assert r.returncode == 0, r.stderr
        return d / "logs" / "short_nominal" / "run.parquet"

    def sim_edited(d: Path) -> subprocess.CompletedProcess:
        path = simulated(d)
        table = pq.read_table(path)
        vv = np.array(table.column("v").to_pylist())
        vv[1::2] *= -1.0  # smooth made period-2, every other check still whole
        table = table.set_column(table.schema.get_field_index("v"), "v",
                                 pa.array(list(vv), table.schema.field("v").type))
        footer = {k: v for k, v in pq.read_metadata(path).metadata.items()
                  if k != b"ARROW:schema"}  # every key the writer left, the old seal too
        pq.write_table(table.replace_schema_metadata(footer), path)
        return cli("analyze", path, "--out", d / "rep")

    def sim_damaged_rerun(d: Path) -> subprocess.CompletedProcess:
        path = simulated(d)
        np.save(d / "v.npy", np.array(pq.read_table(path, columns=["v"]).column("v").to_pylist()))
        data = bytearray(path.read_bytes())
        footer = int.from_bytes(data[-8:-4], "little") + 8
        mid = (len(data) - footer) // 2
        data[mid:mid + 64] = np.random.default_rng(49).bytes(64)
        path.write_bytes(bytes(data))
        return cli("run", "short_nominal", "--out", d / "logs")

    def made_again(d: Path) -> str | None:
        try:
            v_now = pq.read_table(d / "logs" / "short_nominal" / "run.parquet",
                                  columns=["v"]).column("v").to_pylist()
        except (OSError, pa.ArrowException) as exc:
            return f"the damaged log was kept ({exc})"
        return (None if np.array_equal(np.array(v_now), np.load(d / "v.npy"))
                else "the damaged log was kept: its v is not the simulator's")

    mc_text = ("description: fault suite\nmission: omega_ripple_sampled_delay_dt0035\n"
               "set: {{mission.duration: {duration}}}\nseed: {seed}\n{samples}"
               "target: {{p: {p}, confidence: 0.9}}\nripple_max: 1.0e-4\ndispersions:\n"
               "  controller.gains.bus.D: {{dist: normal, sd: {sd}{truncate}}}\n")

    def mc_file(d: Path, folder: str = "a", duration: float = 0.1, seed: int = 7,
                samples: str = "samples: 2\n", p: float = 0.9, sd: float = 0.1,
                truncate: str = "") -> Path:
        (d / folder).mkdir(exist_ok=True)
        path = d / folder / "seed.yaml"
        path.write_text(mc_text.format(duration=duration, seed=seed, samples=samples, p=p,
                                       sd=sd, truncate=truncate))
        return path

    def mc(d: Path, *extra, **fields) -> subprocess.CompletedProcess:
        return cli("montecarlo", mc_file(d, **fields), "--workers", "1", "--logs",
                   d / "logs", "--out", d / "out", *extra)

    def second_mc(d: Path) -> subprocess.CompletedProcess:
        first = mc(d)
        assert first.returncode == 0, first.stderr
        return cli("montecarlo", mc_file(d, folder="b", sd=0.3), "--workers", "1", "--logs",
                   d / "logs", "--out", d / "out")

    def record_folder(d: Path) -> subprocess.CompletedProcess:
        (d / "logs" / "seed" / "seed__00000.json").mkdir(parents=True)
        return mc(d)

    def bad_spec(text: str) -> Callable[[Path], subprocess.CompletedProcess]:
        return lambda d: cli("validate", spec(d, "extends: short_nominal\n" + text))

    def zero_mapping(d: Path) -> subprocess.CompletedProcess:
        return cli("import", good, "--robot", "short_nominal", "--mapping", "/dev/zero",
                   "--out", d / "logs")

    def crc(d: Path) -> subprocess.CompletedProcess:
        import io
        import zipfile

        buf = io.BytesIO()
        np.savez(buf, t=t, q=q, v=v)
        data = bytearray(buf.getvalue())
        with zipfile.ZipFile(io.BytesIO(bytes(data))) as z:
            info = z.getinfo("q.npy")
        at = info.header_offset + 30 + len(info.filename) + len(info.extra) + 200
        data[at:at + 8] = b"\xff" * 8
        (d / "crc.npz").write_bytes(bytes(data))
        return _imp(d / "crc.npz", "x")(d)

    def twice_named(d: Path) -> subprocess.CompletedProcess:
        (d / "cols.csv").write_bytes(csv_bytes)
        return _imp(d / "cols.csv", "x", "--q", ",".join([f"q{i}" for i in range(12)]
                                                         + ["q11"]), "--v", vcols)(d)

    def jitter_fifth(d: Path) -> subprocess.CompletedProcess:
        tt = t.copy()
        tt[5] += 0.199 * 0.03
        tt[6] -= 0.199 * 0.03
        return _imp(_parquet(d / "j.parquet", tt, q, v), "j2", "--max-jitter", "0.2")(d)

    def jitter_controller(d: Path) -> subprocess.CompletedProcess:
        _imp(b / "wander.parquet", "wc", "--max-jitter", "0.15")(d)
        return cli("analyze", d / imported.format("wc"), "--controller", "short_nominal",
                   "--out", d / "rep")

    return [
        Case("empty CSV", _imp(b / "empty.csv", "x"), 2, "empty: no header"),
        Case("CSV header only", _imp(b / "header.csv", "x"), 2, "no rows"),
        Case("empty .npz", _imp(b / "empty.npz", "x"), 2, "not a .npz file"),
        Case("random bytes .npz", _imp(b / "random.npz", "x"), 2, "not a .npz file"),
        Case("truncated .npz", _imp(b / "truncated.npz", "x"), 2, "not a .npz file"),
        Case(".npz without arrays", _imp(b / "noarrays.npz", "x"), 2, "holds no arrays"),
        Case("Parquet of 0 rows", _imp(b / "empty.parquet", "x"), 2, "no rows"),
        Case("complex q", _imp(b / "complex.npz", "x"), 2, "complex numbers"),
        Case("boolean v", _imp(b / "bool.npz", "x"), 2, "booleans"),
        Case("text q in .npz", _imp(b / "text.npz", "x"), 2, "not numbers"),
        Case("elbow in degrees in q and v", _imp(b / "deg_elbow.parquet", "x"), 2,
             "joint elbow_joint"),
        Case("joint rates ×1.00001", _imp(b / "scaled.parquet", "x"), 2, "1.00001 times"),
        Case("quaternion w first", _imp(b / "quat.parquet", "x"), 2, "quaternion order"),
        Case("a dropped row", _imp(b / "gap.parquet", "x"), 2, "gap.parquet: uneven time base"),
        Case("one stamp jittered 1 µs", _imp(b / "jitter.parquet", "x"), 2, "jitter: row 50"),
        Case("stamps jittered ±0.1·dt, --max-jitter 0.15",
             _imp(b / "wander.parquet", "w", "--max-jitter", "0.15"), 0, "rows at dt 0.03",
             same_as_source("w")),
        Case("--max-jitter 0.25", _imp(b / "wander.parquet", "x", "--max-jitter", "0.25"), 2,
             "max_jitter"),
        Case("--resample 1e-9", _imp(b / "gap.parquet", "x", "--resample", "1e-9"), 2,
             "over the memory budget"),
        Case("--resample 1000", _imp(b / "gap.parquet", "x", "--resample", "1000"), 2,
             "at least 3"),
        Case("--name of 300 characters", _imp(good, "n" * 300), 2, "300 characters"),
        Case("--name ../escape", _imp(good, "../escape"), 2, "--name '../escape'"),
        Case("--out is a file", out_file, 2, "cannot write"),
        Case("imported/<name> a link out", linked, 2, "symbolic link out of",
             nothing_elsewhere),
        Case("uint64 ns stamps ≥ 2⁶³", _imp(b / "uint64.parquet", "u", "--time-unit", "ns"), 0,
             "rows at dt 0.03", same_as_source("u")),
        Case("a pipe (/dev/stdin)", pipe, 0, "rows at dt 0.03", piped_hash),
        Case("the same import twice", twice, 0, "up to date", same_as_source("twice")),
        Case("another source, same name", other_name, 2, "--force", same_as_source("held"),
             keep=[imported.format("held")]),
        Case("another source, --force", forced, 0, "100 rows", forced_rows),
        Case("a killed import's .tmp", stale, 0, "rows at dt", stale_gone),
        Case("analysis.json edited by hand", edited_record, 2, "key record_sha256"),
        Case("imported v edited by 1e-9", edited_log, 1, "damaged"),
        Case("report after the log is deleted", gone_log, 0, "", flagged),
        Case("kill -9 of report", killed_report, 0, ""),
        Case("a robot held still", static, 0, "undetermined", static_json),
        Case("mission shorter than a step",
             lambda d: cli("run", spec(d, "extends: short_nominal\nmission: {duration: 0.01}\n"),
                           "--out", d / "logs"), 2, "shorter than one step"),
        Case("reduced plant given delay_steps",
             lambda d: cli("validate", spec(d, "extends: short_nominal\nmission: {plant: "
                                               "{model: reduced, delay_steps: 1}}\n")),
             2, "delay_steps"),
        Case("a 2-step mission analysed",
             lambda d: (cli("run", spec(d, "extends: short_nominal\nmission: {duration: 0.06}\n"),
                            "--out", d / "logs"),
                        cli("analyze", d / "logs" / "s" / "run.parquet", "--out", d / "rep"))[1],
             2, "fewer than the 3"),
        # -- issue 49 --
        Case("a simulated log's v edited", sim_edited, 1, "pipeline.table_sha256"),
        Case("a simulated log byte-damaged, run", sim_damaged_rerun, 0, "short_nominal",
             made_again),
        Case("samples: 10⁹", lambda d: mc(d, samples="samples: 1000000000\n"), 2,
             "over the limit"),
        Case("--samples 10⁹", lambda d: mc(d, "--samples", "1000000000"), 2, "over the limit"),
        Case("target.p 0.9999999999", lambda d: mc(d, samples="", p=0.9999999999), 2,
             "over the limit"),
        Case("--samples 0", lambda d: mc(d, "--samples", "0"), 2, "give 1 or more"),
        Case("--samples -1", lambda d: mc(d, "--samples", "-1"), 2, "give 1 or more"),
        Case("truncate 1e-300", lambda d: mc(d, truncate=", truncate: 1.0e-300"), 2,
             "truncate"),
        Case("Monte Carlo seed -1", lambda d: mc(d, seed=-1), 2, "seed"),
        Case("Monte Carlo duration 10⁶ s", lambda d: mc(d, duration=1.0e6), 2,
             "mission.duration"),
        Case("--workers 1000", lambda d: mc(d, "--workers", "1000"), 2, "--workers 1000"),
        Case("--scheduler 'not an address'", lambda d: mc(d, "--scheduler", "not an address"),
             2, "not a scheduler address"),
        Case("a second Monte Carlo file, same name", second_mc, 2, "--force",
             keep=["out/seed/verdict.json"]),
        Case("a sample's record path a folder", record_folder, 2, "not a file"),
        Case("controller.gains.bus.D 1e308",
             bad_spec("controller: {gains: {bus: {D: 1.0e+308}}}\n"), 2,
             "controller.gains.bus.D"),
        Case("controller.null_space.D 1e-300",
             bad_spec("controller: {null_space: {D: 1.0e-300}}\n"), 2,
             "controller.null_space.D"),
        Case("config_sampling.seed -1", bad_spec("config_sampling: {seed: -1}\n"), 2,
             "config_sampling.seed"),
        Case("timing.seed -5", bad_spec("mission: {plant: {model: sampled, timing: "
                                        "{seed: -5}}}\n"), 2, "seed"),
        Case("import /dev/zero --format parquet",
             lambda d: cli("import", "/dev/zero", "--format", "parquet", "--robot",
                           "short_nominal", "--out", d / "logs"), 2, "not a regular file"),
        Case("--mapping /dev/zero", zero_mapping, 2, "longer than 16 MiB"),
        Case("--time '[5]' past the columns", _imp(good, "x", "--time", "[5]"), 2, "column 5"),
        Case("a damaged .npz member (CRC)", crc, 2, "damaged member"),
        Case("text stamps in Parquet", _imp(b / "text_t.parquet", "x"), 2, "not numbers"),
        Case("float32 stamps", _imp(b / "float32_t.parquet", "f32"), 0, "rows at dt",
             same_as_source("f32")),
        Case("--q naming a column twice", twice_named, 2, "named twice"),
        Case("jitter 0.2·dt, --max-jitter 0.2", jitter_fifth, 0, "rows at dt",
             same_as_source("j2")),
        Case("jittered import analysed with its controller", jitter_controller, 0, ""),
    ]


def _one_error_line(err: str, needle: str) -> bool:
    """The refusal is one line, the last, naming the problem; any line before it is a stage's
    own progress (``report: started``, ``report: failed after 0.5 s``), or argparse's usage
    before its own one line (``python -m pipeline montecarlo: error: argument …``)."""
    lines = err.strip().splitlines()
    argparse_error = bool(lines) and lines[0].startswith("usage:") and ": error: " in lines[-1]
    return (bool(lines) and needle in lines[-1]
            and (lines[-1].startswith(("error:", "claim ", "log ")) or argparse_error)
            and all(not ln.startswith(("error", "warning: Runtime")) for ln in lines[:-1]))


def run_case(case: Case, scratch: Path) -> Outcome:
    d = scratch / "".join(c if c.isalnum() else "_" for c in case.name)
    d.mkdir(parents=True)
    try:
        r = case.run(d)
    except Exception as exc:  # a step before the case's command failed: the case fails
        return Outcome(case, -1, "", f"its set-up failed ({type(exc).__name__}: {exc})")
    out = r.stdout.decode() if isinstance(r.stdout, bytes) else (r.stdout or "")
    err = r.stderr.decode() if isinstance(r.stderr, bytes) else (r.stderr or "")
    problem = None
    if r.returncode == RUNAWAY:
        problem = f"runaway: {err}"
    elif "Traceback" in err:
        problem = "traceback"
    elif r.returncode != case.code:
        problem = f"exit {r.returncode}, expected {case.code}: {err.strip()[:200]}"
    elif case.code != 0 and not _one_error_line(err, case.needle):
        problem = f"not one line naming it: {err.strip()[:300]}"
    elif case.code == 0 and case.needle and case.needle not in out + err:
        problem = f"{case.needle!r} not said: {(out + err).strip()[:300]}"
    elif case.check is not None:
        try:
            problem = case.check(d)
        except Exception as exc:  # what the check reads is not there: a wrong answer
            problem = f"its check failed ({type(exc).__name__}: {exc})"
    for rel in case.keep:
        if not (d / rel).is_file():
            problem = f"data lost: {rel}"
    return Outcome(case, r.returncode, err, problem)


def run_pass(label: str, cases: list[Case], scratch: Path) -> list[Outcome]:
    """Every case once, in a folder of its own under ``scratch``; prints one line each and
    the totals."""
    outcomes = []
    for case in cases:
        t0 = time.perf_counter()
        o = run_case(case, scratch)
        outcomes.append(o)
        status = "ok" if o.problem is None else f"WRONG: {o.problem}"
        print(f"[{label}] {case.name:44s} exit {o.code:5d}  {time.perf_counter() - t0:5.1f} s  "
              f"{status}", flush=True)
    refused = sum(o.problem is None and o.case.code != 0 for o in outcomes)
    accepted = sum(o.problem is None and o.case.code == 0 for o in outcomes)
    tracebacks = sum(o.problem == "traceback" for o in outcomes)
    runaway = sum((o.problem or "").startswith("runaway") for o in outcomes)
    lost = sum((o.problem or "").startswith("data lost") for o in outcomes)
    wrong = sum(o.problem is not None for o in outcomes) - tracebacks - runaway - lost
    print(f"[{label}] cases {len(outcomes)}: refused cleanly {refused}, accepted rightly "
          f"{accepted}, tracebacks {tracebacks}, wrong answers {wrong}, runaway {runaway}, "
          f"data lost {lost}", flush=True)
    return outcomes


def main() -> int:
    global AS_LIMIT
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", metavar="DIR", help="build the cases in DIR and keep it")
    ap.add_argument("--only", metavar="TEXT", help="run only the cases whose name holds TEXT")
    a = ap.parse_args()
    scratch = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="fault_suite."))
    scratch.mkdir(parents=True, exist_ok=True)
    try:
        r = cli("run", "short_nominal", "--out", scratch / "base")
        if r.returncode:
            print(r.stderr.decode(), file=sys.stderr)
            return 1
        table = pq.read_table(scratch / "base" / "short_nominal" / "run.parquet",
                              columns=["t", "q", "v"]).to_pydict()
        base = {k: np.array(v) for k, v in table.items()}
        cases = [c for c in build_cases(base, scratch) if not a.only or a.only in c.name]
        quarter = psutil.virtual_memory().total // 4
        ok = True
        for label, limit in (("plain", None), (f"ulimit -v {quarter // 1024}", quarter)):
            AS_LIMIT = limit
            outcomes = run_pass(label, cases, scratch / ("plain" if limit is None else "as"))
            ok = ok and all(o.problem is None for o in outcomes)
        return 0 if ok else 1
    finally:
        AS_LIMIT = None
        if not a.keep:
            shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
