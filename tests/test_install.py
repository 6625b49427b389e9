"""The installed tool: ``pip install .`` (not editable) into a fresh venv, then used from another
folder with the user's own specs, robot file and claims (architecture §8).

The venv reads its dependencies from this environment (through ``site.addsitedir``, so their
own ``.pth`` files apply) and installs only the package, from the checkout. The kernels run
as plain Python (``NUMBA_DISABLE_JIT=1``): compiling them afresh for an installed copy takes
minutes, and what is tested here is where things are found, not the compiler.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from pipeline.paths import PROJECT_ROOT, SHIPPED_SPECS

pytestmark = pytest.mark.install

MISSION = """\
# the user's own mission: the shipped nominal, the user's robot file, 1 s
extends: nominal
robot: {file: robots/my_ur3.xml}
mission: {duration: 1.0}
"""
FINE = "extends: mission\nmission: {dt: 0.01}\n"
CLAIMS = """\
logs: logs
runs:
  mine: {spec: my_specs/mission.yaml, against: fine}
  fine: {spec: my_specs/mission_fine.yaml}
claims:
  - id: U1
    statement: The user's mission at dt 0.03 s steps faster than at 0.01 s.
    expect: hold
    checks:
      - {metric: "mine:spec.mission.dt", op: gt, threshold: {metric: "fine:spec.mission.dt"}}
"""


def _sh(argv: list, cwd: Path, env: dict | None = None, timeout: float = 600):
    return subprocess.run([str(a) for a in argv], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("installed")
    venv = root / "venv"
    r = _sh([sys.executable, "-m", "venv", venv], root)
    assert r.returncode == 0, r.stderr
    vpy = venv / "bin" / "python"
    vsite = Path(_sh([vpy, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     root).stdout.strip())
    deps = sysconfig.get_paths()["purelib"]
    (vsite / "breve-deps.pth").write_text(f"import site; site.addsitedir({deps!r})\n")
    r = _sh([vpy, "-m", "pip", "install", "--quiet", "--no-deps", PROJECT_ROOT], root)
    assert r.returncode == 0, r.stderr[-2000:]
    work = root / "work"
    (work / "my_specs" / "robots").mkdir(parents=True)
    (work / "my_specs" / "robots" / "my_ur3.xml").write_bytes(
        (SHIPPED_SPECS / "robots" / "seed_ur3_box.xml").read_bytes())
    (work / "my_specs" / "mission.yaml").write_text(MISSION)
    (work / "my_specs" / "mission_fine.yaml").write_text(FINE)
    (work / "my_claims.yaml").write_text(CLAIMS)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR")}
    env |= {"PATH": f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}",
            "XDG_CACHE_HOME": str(root / "cache"), "NUMBA_DISABLE_JIT": "1"}
    return {"vpy": vpy, "vsite": vsite, "work": work, "env": env, "root": root}


def _tool(inst: dict, *args: str):
    return _sh(["breve-pipeline", *args], inst["work"], inst["env"])


def test_the_package_is_the_installed_copy_and_caches_per_user(installed):
    code = ("import pipeline, pipeline.sim.jit as j; print(pipeline.__file__); "
            "print(j.kernel_cache_dir())")
    r = _sh([installed["vpy"], "-c", code], installed["work"], installed["env"])
    assert r.returncode == 0, r.stderr
    package, cache = r.stdout.split()
    assert Path(package).is_relative_to(installed["vsite"])
    assert Path(cache).is_relative_to(installed["root"] / "cache" / "breve-pipeline")
    assert (Path(package).parent / "specs" / "nominal.yaml").is_file()  # shipped specs


def test_the_installed_tool_runs_the_users_specs_from_their_folder(installed):
    work = installed["work"]
    r = _tool(installed, "--version")
    assert r.returncode == 0 and r.stdout.startswith("breve-pipeline "), r.stderr
    r = _tool(installed, "run", "my_specs/mission.yaml", "my_specs/mission_fine.yaml")
    assert r.returncode == 0, r.stderr
    log = work / "logs" / "mission" / "run.parquet"
    md = pq.read_metadata(log).metadata
    assert md[b"pipeline.robot_file"].decode() == "my_specs/robots/my_ur3.xml"
    r = _tool(installed, "run", "my_specs/mission.yaml")
    assert r.returncode == 0 and "up to date" in r.stdout, (r.stdout, r.stderr)
    r = _tool(installed, "analyze", "logs/mission/run.parquet", "--against",
              "logs/mission_fine/run.parquet", "--out", "reports")
    assert r.returncode == 0, r.stderr
    r = _tool(installed, "analyze", "logs/mission_fine/run.parquet", "--out", "reports")
    assert r.returncode == 0, r.stderr
    r = _tool(installed, "claims", "--claims", "my_claims.yaml", "--out", "reports")
    assert r.returncode == 0, (r.stdout, r.stderr)
    claims = json.loads((work / "reports" / "claims.json").read_text())
    assert [c["status"] for c in claims["claims"]] == ["PASS"]
    r = _tool(installed, "report", "--out", "reports")
    assert r.returncode == 0, r.stderr
    assert (work / "reports" / "index.html").is_file()
    assert (work / "reports" / "mission" / "mechanism.html").is_file()
    r = _tool(installed, "report", "--out", "reports")
    assert r.returncode == 0 and "up to date" in r.stdout, r.stdout
    r = _tool(installed, "validate", "nominal")  # the shipped specs, by name
    assert r.returncode == 0, r.stderr
