"""The command line explains itself: help on every option, the stages listed, ``--version``,
``validate``, ``make help``; and the files an open tool ships (LICENSE, CITATION.cff)."""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import tomllib

import pytest
import yaml
from report_fixtures import write_spec

from pipeline.budget import ROW_FLOATS
from pipeline.cli import build_parser, main
from pipeline.errors import SpecError
from pipeline.paths import PROJECT_ROOT
from pipeline.spec import load_spec


def _stages() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _documented(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]


def test_every_argument_has_help_with_an_example_and_every_option_its_default():
    stages = _stages()
    assert set(stages) >= {"validate", "run", "analyze", "report", "claims", "sweep", "bench"}
    missing = []
    for name, parser in stages.items():
        for a in _documented(parser):
            what = f"{name} {a.option_strings[0] if a.option_strings else a.dest}"
            text = a.help or ""
            if "e.g." not in text:
                missing.append(f"{what}: no example")
            if a.option_strings and "default" not in text:
                missing.append(f"{what}: no default")
    assert not missing, missing


def test_the_help_check_can_fail():
    """An option added without help is caught by the rule above."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="x")
    bad = [a for a in _documented(parser) if "e.g." not in (a.help or "")]
    assert [a.dest for a in bad] == ["out"]


def test_top_level_help_lists_each_stage_on_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "``" not in out, "raw reStructuredText markup in the help"
    for name, parser in _stages().items():
        line = next((ln for ln in out.splitlines() if ln.split()[:1] == [name]), None)
        assert line is not None, f"stage {name} not listed"
        assert len(line.split()) > 3, f"stage {name} has no one-line summary: {line!r}"
        assert parser.epilog and f"python -m pipeline {name}" in parser.epilog


def test_version_is_the_release_of_pyproject_and_citation(capsys):
    release = tomllib.loads((PROJECT_ROOT / "pyproject.toml").read_text())["project"]["version"]
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"breve-pipeline {release}"
    cff = yaml.safe_load((PROJECT_ROOT / "CITATION.cff").read_text())
    assert str(cff["version"]) == release


def test_citation_cites_the_tool_the_paper_and_pinocchio():
    cff = yaml.safe_load((PROJECT_ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert cff["license"] == "BSD-3-Clause"
    refs = {r["title"]: r for r in cff["references"]}
    paper = next(r for t, r in refs.items() if t.startswith("Coordinated Control"))
    assert [a["family-names"] for a in paper["authors"]] == ["Giordano", "Ott", "Albu-Schäffer"]
    assert paper["year"] == 2019 and paper["journal"] == "IEEE Robotics and Automation Letters"
    assert any("Pinocchio" in t for t in refs)
    assert "BSD 3-Clause License" in (PROJECT_ROOT / "LICENSE").read_text()


def test_validate_prints_the_cost_and_runs_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    spec_file = write_spec(tmp_path, "v_nominal", "short_nominal")
    spec = load_spec(spec_file)
    assert main(["validate", str(spec_file)]) == 0
    out = capsys.readouterr().out
    steps = re.search(r"steps:\s+([\d,]+)", out)
    assert steps and int(steps.group(1).replace(",", "")) == spec.n_steps
    mib = re.search(r"at most ([\d.]+) KiB before compression", out)
    assert mib and float(mib.group(1)) == pytest.approx(spec.n_steps * ROW_FLOATS * 8 / 1024,
                                                        rel=1e-2)
    assert "dt·μ_bus = 3.84" in out  # the seed robot: 0.03 s × 2/0.015625 s⁻¹
    assert list(tmp_path.iterdir()) == [spec_file], "validate wrote something"


def test_validate_refuses_a_bad_spec_with_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("extends: nominal\nmission: {dt: -0.03}\n")
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "mission.dt" in err


def test_validate_refuses_a_mission_over_the_budget(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("BREVE_TIME_BUDGET_H", "0.001")  # 3.6 s
    spec_file = tmp_path / "long.yaml"
    spec_file.write_text("extends: nominal\nmission: {duration: 3600.0}\n")
    assert main(["validate", str(spec_file)]) == 2
    err = capsys.readouterr().err
    assert "mission.duration" in err and "time budget" in err


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_help_lists_every_target_with_a_line():
    makefile = (PROJECT_ROOT / "Makefile").read_text()
    phony = [t for line in re.findall(r"^\.PHONY:(.*)$", makefile, re.M) for t in line.split()]
    r = subprocess.run(["make", "-s", "--no-print-directory", "help"], cwd=PROJECT_ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    listed = {m.group(1): m.group(2) for m in re.finditer(r"^\s+make (\S+)\s+(.+)$", r.stdout,
                                                          re.M)}
    assert set(phony) <= set(listed), f"targets without a help line: {set(phony) - set(listed)}"


@pytest.mark.parametrize("claims_end, code, reported", [
    ("pass", 0, True),
    ("claim_fails", 1, True),  # a failed claim: the reports are still rendered, then exit 1
    ("run_fails", 1, True),  # a mission failed: the same, with its one-line error
    ("bad_register", 2, False),  # bad input: one line, nothing else runs
])
def test_all_runs_compile_claims_and_report_in_order_and_ends_with_the_claims_code(
        monkeypatch, capsys, tmp_path, claims_end, code, reported):
    from pipeline import cli, compile
    from pipeline.errors import RunFailed, SpecError

    calls = []
    check = object()  # the claims' CrossCheck, handed to the report
    outcome = argparse.Namespace(cross_check=check)

    def claims(name, out, force=False):
        calls.append(("claims", name, out))
        if claims_end == "run_fails":
            raise RunFailed("mission nominal: diverged")
        if claims_end == "bad_register":
            raise SpecError("claims.yaml: claims[0].id: missing")
        return (1 if claims_end == "claim_fails" else 0), outcome

    monkeypatch.setattr(compile, "compile_kernels",
                        lambda n, when_idle=None: calls.append(("compile", n)))
    monkeypatch.setattr(cli, "_claims", claims)
    monkeypatch.setattr(cli, "_report", lambda out, force=False, cross_check=None:
                        calls.append(("report", out, cross_check)) or 0)
    assert main(["all", "--out", str(tmp_path), "--claims", "claims_ci"]) == code
    expected = [("compile", 2), ("claims", "claims_ci", tmp_path)]
    if reported:
        expected.append(("report", tmp_path, None if claims_end == "run_fails" else check))
    assert calls == expected
    err = capsys.readouterr().err
    assert err.count("error:") == (claims_end in ("run_fails", "bad_register"))


def test_all_keeps_the_claims_code_when_the_report_then_fails_too(monkeypatch, capsys, tmp_path):
    """A failed claim (1) and then a report that cannot render (its own error, 2): both are
    said, and the exit code is the claims', the news."""
    from pipeline import cli, compile
    from pipeline.errors import LogError

    def report(out, force=False, cross_check=None):
        raise LogError(f"{out}: nothing to report")

    monkeypatch.setattr(compile, "compile_kernels", lambda n, when_idle=None: None)
    monkeypatch.setattr(cli, "_claims", lambda name, out, force=False: (1, None))
    monkeypatch.setattr(cli, "_report", report)
    assert main(["all", "--out", str(tmp_path)]) == 1
    assert "nothing to report" in capsys.readouterr().err
    monkeypatch.setattr(cli, "_claims", lambda name, out, force=False: (0, None))
    assert main(["all", "--out", str(tmp_path)]) == 2  # claims passed: the report's own code


def test_a_reader_that_goes_away_ends_the_command_without_a_traceback():
    """`python -m pipeline … | head`: the pipe closes under the command; it stops quietly."""
    import sys

    p = subprocess.Popen([sys.executable, "-m", "pipeline", "validate", "nominal"],
                         cwd=PROJECT_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    p.stdout.close()  # before the child writes what it found
    err = p.stderr.read()
    assert p.wait() == 1
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_warnings_never_make_an_error_more_than_its_line(monkeypatch, capsys):
    """A RuntimeWarning raised on the way to a refusal is a symptom of the bad input: stderr is
    the error's one line; after a success each warning is one line (issue 36, item 8)."""
    import warnings

    import pipeline.cli as cli

    def refusing(a):
        warnings.warn("overflow encountered in multiply\n  x = a * b", RuntimeWarning,
                      stacklevel=1)
        raise SpecError("bad.csv: field q: not numbers")

    def passing(a):
        warnings.warn("overflow encountered in multiply\n  x = a * b", RuntimeWarning,
                      stacklevel=1)
        return 0

    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as outside the tests (pytest makes them errors)
        monkeypatch.setattr(cli, "_cmd_validate", refusing)
        assert cli.main(["validate", "nominal"]) == 2
        assert capsys.readouterr().err == "error: bad.csv: field q: not numbers\n"
        monkeypatch.setattr(cli, "_cmd_validate", passing)
        assert cli.main(["validate", "nominal"]) == 0
        err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("warning: RuntimeWarning: overflow encountered "
                                               "in multiply x = a * b (test_cli.py:")
