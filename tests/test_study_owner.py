"""Two different study files of one name never share outputs (issue 49 item 4): the second is
refused in one line before anything runs, the first's verdict and kept records untouched;
``--force`` replaces them; the same file edited keeps its folders (its results superseded by
their key)."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import run_cli, run_cli_in_process

from pipeline.errors import SpecError
from pipeline.montecarlo.owner import claim_folders, owner
from pipeline.montecarlo.verdict import read_verdict

# Two samples of 0.1 s of the seed robot's sampled plant (29 steps each).
TINY = """\
description: {what}
mission: omega_ripple_sampled_delay_dt0035
set: {{mission.duration: 0.1}}
seed: {seed}
samples: 2
ripple_max: 1.0e-4
dispersions:
  controller.gains.bus.D: {{dist: uniform, rel: {spread}}}
"""


def _file(folder: Path, seed: int = 7, spread: float = 0.1, what: str = "first") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "seed.yaml"
    path.write_text(TINY.format(what=what, seed=seed, spread=spread))
    return path


def _montecarlo(path: Path, tmp_path: Path, *extra: str):
    return run_cli("montecarlo", path, "--workers", "1", "--logs", tmp_path / "logs",
                   "--out", tmp_path / "out", *extra)


def test_claim_folders_refuses_another_owner_and_writes_nothing(tmp_path):
    a, b = _file(tmp_path / "a"), _file(tmp_path / "b", what="second")
    logs, out = tmp_path / "logs" / "seed", tmp_path / "out" / "seed"
    claim_folders("montecarlo", "seed", a, [logs, out])
    assert owner(logs) == owner(out) == str(a.resolve())
    (logs / "seed_0.json").write_text("{}")  # a kept record of a's
    (tmp_path / "out" / "other").mkdir()
    with pytest.raises(SpecError, match="holds the results of another montecarlo file of "
                                        "that name") as refused:
        claim_folders("montecarlo", "seed", b, [tmp_path / "out" / "other", logs])
    assert str(a.resolve()) in str(refused.value) and "--force" in str(refused.value)
    assert owner(tmp_path / "out" / "other") is None  # nothing written before the check
    assert (logs / "seed_0.json").is_file()
    claim_folders("montecarlo", "seed", a, [logs, out])  # its own: no refusal
    claim_folders("montecarlo", "seed", b, [logs, out], force=True)
    # --force gives the folders to b and removes nothing: b's results replace a's as they
    # are written, a's other records stay (keyed by their content, never read for b)
    assert owner(logs) == str(b.resolve()) and (logs / "seed_0.json").is_file()


def test_a_folder_whose_owner_file_is_gone_is_taken_over(tmp_path, capsys):
    """A checkout moved or renamed: the recorded owner is no longer there, and `make all`
    cannot pass --force; the folder is taken over and that is said."""
    a = _file(tmp_path / "a")
    logs = tmp_path / "logs" / "seed"
    claim_folders("montecarlo", "seed", a, [logs])
    moved = tmp_path / "moved"
    (tmp_path / "a").rename(moved)
    claim_folders("montecarlo", "seed", moved / "seed.yaml", [logs])
    assert owner(logs) == str((moved / "seed.yaml").resolve())
    assert "(no longer there)" in capsys.readouterr().err


@pytest.mark.slow
def test_a_second_file_of_one_name_is_refused_and_force_replaces_the_first(tmp_path):
    first = _file(tmp_path / "a")
    r = _montecarlo(first, tmp_path)
    assert r.returncode == 0, r.stderr
    verdict = tmp_path / "out" / "seed" / "verdict.json"
    before = verdict.read_bytes()
    records = sorted((tmp_path / "logs" / "seed").glob("*.json"))
    assert records

    second = _file(tmp_path / "b", spread=0.3, what="second")
    r = _montecarlo(second, tmp_path)
    assert r.returncode == 2, r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert str(first.resolve()) in line and "--force" in line, line
    assert verdict.read_bytes() == before  # nothing of the first's lost
    assert sorted((tmp_path / "logs" / "seed").glob("*.json")) == records

    r = _montecarlo(second, tmp_path, "--force")
    assert r.returncode == 0, r.stderr
    assert read_verdict(verdict).file == str(second.resolve())

    # The same file edited: its own folders, run again without --force.
    _file(tmp_path / "b", seed=8, spread=0.3, what="second, edited")
    r = _montecarlo(second, tmp_path)
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_a_power_study_of_a_name_in_use_is_refused(tmp_path):
    from pipeline.paths import SHIPPED_SPECS

    shipped = (SHIPPED_SPECS / "montecarlo" / "detector_power.yaml").read_text()
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "a" / "power.yaml").write_text(shipped)
    (tmp_path / "b" / "power.yaml").write_text(shipped)
    out = tmp_path / "out" / "power"
    claim_folders("power", "power", tmp_path / "a" / "power.yaml", [out])
    r = run_cli("power", tmp_path / "b" / "power.yaml", "--samples", "1", "--workers", "1",
                "--logs", tmp_path / "logs", "--out", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    assert "holds the results of another power file" in r.stderr


def test_a_records_path_that_is_a_folder_is_refused_before_any_flight(tmp_path):
    path = _file(tmp_path / "a")
    (tmp_path / "logs" / "seed" / "seed__00000.json").mkdir(parents=True)
    r = run_cli_in_process("montecarlo", path, "--workers", "1", "--logs", tmp_path / "logs",
                           "--out", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    assert "seed__00000.json: not a file" in r.stderr and len(r.stderr.splitlines()) == 1
    assert not (tmp_path / "out").exists()
