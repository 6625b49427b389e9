"""The claims' studies: the Monte Carlos and the detector-power studies a register names, the N
each needs, and whether a current result of that N exists (docs/montecarlo.md, "In the
claims: the decision and the studies").

`make all` (the decision) does not fly the studies: it reads a current result where one exists
and defers the claims that need one otherwise. `make studies` flies them at their files' full
N; `make claims-ci` flies them at the small N its register declares, which exercises the
machinery but cannot show the target, so its claims are deferred too. A result is current when
its ``key`` (:func:`study_key`: the file, its mission specs and robot files, the N asked and
the samples' code) is this code's for that file; a result of fewer samples than the file's N
defers the claims that read it, naming the N that ran and the most confidence that N can show
(eq. 38d).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

from pipeline.analysis.confidence import confidence_reachable
from pipeline.errors import LogError
from pipeline.paths import display_path

Kind = Literal["montecarlo", "power"]
# Where a study's records are kept (under the register's logs) and its result is written
# (under the report folder), by kind.
FOLDERS: dict[str, str] = {"montecarlo": "montecarlo", "power": "power"}


def declared(kind: Kind, path: Path) -> tuple[int, float | None]:
    """What the study's file declares, read once: its N (a Monte Carlo's ``samples``, else the
    success-run count of its target, eq. 38b; a power study's runs per mission and level) and
    a Monte Carlo's target pass probability (None for a power study)."""
    if kind == "montecarlo":
        from pipeline.montecarlo.plan import file_samples, read_montecarlo

        config = read_montecarlo(path)
        return file_samples(config), config.target.p
    from pipeline.montecarlo.power import read_power_file

    return read_power_file(path).samples, None


def study_key(kind: Kind, path: Path, samples: int) -> str:
    """What a study's result is made from: its file's content, its missions' specs and robot
    files, the N flown and the samples' code (:func:`pipeline.provenance.keys.sample_version`).
    A result carries it; a result whose key is not this one is not current."""
    if kind == "montecarlo":
        from pipeline.montecarlo.plan import result_key
    else:
        from pipeline.montecarlo.power import result_key
    return result_key(path, samples)


@dataclass(frozen=True)
class StudyResult:
    """A study the claims read: its result (None: no current one), the N that ran and the N
    its file declares, and the files the claims' key holds."""

    kind: Kind
    name: str  # the file's stem: the result's folder
    file: Path
    full: int
    ran: int
    result: dict | None
    provenance: dict
    files: tuple[Path, ...]
    target_p: float | None  # a Monte Carlo's target pass probability

    @property
    def deferred(self) -> bool:
        return self.result is None or self.ran < self.full

    def deferral(self) -> str:
        """Why a claim that reads this study is deferred: what ran and what it can show."""
        what = "samples" if self.kind == "montecarlo" else "runs per mission and level"
        ran = (f"{self.ran} of the {self.full} {what} ran" if self.result is not None else
               f"no current result (the file's {self.full} {what} have not flown with this "
               "code)")
        reach = ""
        if self.kind == "montecarlo" and self.target_p is not None:
            reach = (f"; {self.ran} samples can show p {self.target_p:g} at no more than "
                     f"{100 * confidence_reachable(self.target_p, self.ran):.3g} % confidence "
                     f"(eq. 38d), {self.full} at "
                     f"{100 * confidence_reachable(self.target_p, self.full):.3g} %")
        return f"{self.kind} {self.name}: {ran}{reach}"


def result_files(kind: Kind, name: str, out: Path) -> tuple[Path, Path]:
    """The study's table and its result (the result written last) under report folder
    ``out``."""
    from pipeline.montecarlo import power
    from pipeline.montecarlo.verdict import TABLE_NAME, VERDICT_NAME

    folder = Path(out) / FOLDERS[kind] / name
    if kind == "montecarlo":
        return folder / TABLE_NAME, folder / VERDICT_NAME
    return folder / power.TABLE_NAME, folder / power.RESULT_NAME


def read_result(kind: Kind, path: Path) -> tuple[dict, str, int]:
    """A study's result as a mapping, its key and the N it flew (LogError if it is damaged)."""
    if kind == "montecarlo":
        from pipeline.montecarlo.verdict import read_verdict

        v = read_verdict(path)
        return asdict(v), v.key, v.samples
    from pipeline.montecarlo.power import read_power

    r = read_power(path)
    return asdict(r), r.key, r.samples


def study_result(kind: Kind, file: Path, samples: int | None, out: Path) -> StudyResult:
    """The current result of the study ``file`` flown at ``samples`` (None: the file's N)
    under report folder ``out``, or a result of None when there is none (absent, made from
    other inputs or code, or damaged: a damaged one is said on stderr, never read)."""
    import sys

    full, target = declared(kind, file)
    asked = samples or full
    name = Path(file).stem
    table, result_path = result_files(kind, name, out)
    prov = {"source": kind, "version": "—", "file": display_path(result_path)}
    none = StudyResult(kind, name, Path(file), full, 0, None, prov, (), target)
    if not result_path.is_file() or not table.is_file():
        return none
    try:
        data, key, ran = read_result(kind, result_path)
    except LogError as exc:
        print(f"claims: {exc}: not read; `make studies` makes it again", file=sys.stderr)
        return none
    if key != study_key(kind, file, asked) or ran != asked:
        return none
    from pipeline.provenance.keys import sample_version

    prov = {**prov, "version": f"samples {sample_version()}"}
    return StudyResult(kind, name, Path(file), full, ran, data, prov, (table, result_path),
                       target)


def current_key(kind: Kind, name: str, samples: int, file: str = "") -> str | None:
    """The key a result of ``samples`` made from the file ``file`` (else the shipped file
    ``name``) as it is now, by this code, carries; None where neither is there or valid (its
    inputs cannot be checked)."""
    from pipeline.errors import SpecError
    from pipeline.montecarlo.plan import resolve_montecarlo

    try:
        path = Path(file) if file and Path(file).is_file() else resolve_montecarlo(name)
        return study_key(kind, path, samples)
    except SpecError:  # gone, or no longer a valid file
        return None


def is_current(kind: Kind, name: str, key: str, samples: int, file: str = "") -> bool:
    """Whether a result found in a report folder (``<kind>/<name>/``) was made from the file
    it names (``file``, else the shipped file of that name) as it is now, by this code (False
    where neither is there: its inputs cannot be checked)."""
    return bool(key) and key == current_key(kind, name, samples, file)
