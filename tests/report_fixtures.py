"""Short runs, analyses and rendered reports shared by the report, claims and browser tests.

Built once per test process (``functools.cache``) in a temporary folder removed at exit: three
4-second missions (nominal, dt010, imex), their analyses as ``make analyses`` makes them, and
``render_all`` over them.
"""

from __future__ import annotations

import atexit
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

from conftest import run_cli as _run_cli

from pipeline.analysis.record import write_analysis
from pipeline.analysis.schema import AnalysisRecord
from pipeline.analysis.stages import analyze_log, compare
from pipeline.logs import verify_log
from pipeline.reports.render import render_all
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec

SHORT = {"t_nominal": "short_nominal", "t_dt010": "short_omega_ripple_dt010",
         "t_imex": "short_omega_ripple_imex"}
DURATION = 12.0  # s: 400 steps at dt 0.03, a 200-step analysis window (the least eq. 36 judges)


@dataclass(frozen=True)
class Built:
    root: Path
    specs: Path  # the test specs (t_*.yaml)
    logs: Path
    reports: Path  # analyses and rendered reports

    def spec_file(self, name: str) -> Path:
        return self.specs / f"{name}.yaml"


def write_spec(folder: Path, name: str, parent: str, **extra: str) -> Path:
    lines = [f"extends: {parent}", f"mission: {{duration: {DURATION}}}"]
    lines += [f"{k}: {v}" for k, v in extra.items()]
    path = folder / f"{name}.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def analyse_pair(log: Path, against: Path | None, out: Path) -> AnalysisRecord:
    record = analyze_log(verify_log(log))
    if against is not None:
        other = verify_log(against)
        record = replace(record, comparison=compare(record, analyze_log(other),
                                                    verify_log(log).meta.spec,
                                                    other.meta.spec))
    write_analysis(record, out)
    return record


@cache
def built() -> Built:
    root = Path(tempfile.mkdtemp(prefix="breve-reports-"))
    atexit.register(shutil.rmtree, root, True)
    b = Built(root, root / "specs", root / "logs", root / "reports")
    b.specs.mkdir()
    logs = {}
    for name, parent in SHORT.items():
        spec = load_spec(write_spec(b.specs, name, parent))
        logs[name] = run_spec(spec, b.logs).path
    analyse_pair(logs["t_nominal"], logs["t_dt010"], b.reports)
    analyse_pair(logs["t_imex"], logs["t_dt010"], b.reports)
    analyse_pair(logs["t_dt010"], None, b.reports)
    render_all(b.reports)
    return b


def run_cli(*args: str | Path) -> subprocess.CompletedProcess:
    """conftest's run_cli with a report's time (figures and the cross-check)."""
    return _run_cli(*args, timeout=600)
