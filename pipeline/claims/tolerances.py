"""The per-column tolerances of the pinned baselines across platforms, and their measurement.

A baseline re-run on the platform it was pinned on must match its pin bitwise; on another
platform (another CPU target, BLAS kernel, libm or thread count: :mod:`pipeline.platform`) a
last-bit difference in one operation is allowed, and the unstable nominal loop amplifies it
until a saturation binds. How far each column may then move is not chosen but measured,
by :func:`measure` (``python -m pipeline.claims.baselines tolerances``, ``make tolerances``),
and committed as ``logs/baselines/tolerances.json`` (docs/reproducibility.md):

1. every baseline is run once as the reference, in this process;
2. the ensemble of last-bit perturbations that stand for another platform, each run again:
   - ``coretype:NAME``: the whole run under ``OPENBLAS_CORETYPE=NAME``, in a subprocess, for
     each OpenBLAS kernel this CPU runs that differs from the default one (the candidates of
     ``CORETYPES``; none with AVX-512, which a CPU without it cannot run; a candidate whose
     process dies is left out, and said);
   - ``ulp:q[i]`` and ``ulp:v[i]``: one entry of the initial configuration q0 or velocity v0
     moved by one ulp (``np.nextafter`` towards +inf), for every entry; ``ulp:all-``: every
     entry of both moved by one ulp towards −inf. This stands for a last-bit difference
     anywhere (libm, Pinocchio's Eigen build, a BLAS kernel) and measures how much each
     mission amplifies it, whatever calls BLAS;
   - ``ulp:steps-S``: at the end of every step, each entry of q and v moved by one ulp up,
     down or not at all (seeded, S = 0…3). Another platform rounds differently at every
     step, not once: a stable mission damps a difference at the start away (the ``ulp:q``
     members move dt010 by 1e-15 where a BLAS kernel moves it by 1e-11) but not one
     injected at each step;
3. per column, the largest |member − reference| over the ensemble, times ``SAFETY_FACTOR``,
   and never below ``FLOOR_ULPS`` ulp of the column's largest magnitude (a column that no
   member moved still may move by rounding on a platform that rounds one more operation
   differently); integer columns (``step``) get 0, and flags (``sat_*``) 0, or 1 (any flip)
   when a member flipped one.

Why a factor of 10: the ensemble samples a few dozen single-ulp perturbations of one
platform, while another platform differs in many operations at every step (all of a libm
function's results, every BLAS product), so its effective perturbation can be several ulp
and its pattern another; before a saturation binds the loop is linear in the perturbation,
so one order of magnitude above the largest difference measured covers a perturbation ten
times the size of any sampled one. A real regression (a gain, a sign, a swapped column)
moves the columns by 1e-4 to 1, orders of magnitude above (tests/test_baselines_contract.py).
"""

from __future__ import annotations

import datetime
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from pipeline.atomic_files import atomic_write_text
from pipeline.errors import SpecError
from pipeline.platform import fingerprint
from pipeline.provenance.keys import SIM_LIBRARIES, library_versions, sim_version
from pipeline.sim.mission import LoopState, Mission
from pipeline.sim.mission_loop import DIVERGED, FLOWN, NOT_FINITE
from pipeline.spec import Spec, load_spec

SCHEMA = "breve-tolerances/1"
SAFETY_FACTOR = 10.0
FLOOR_ULPS = 4
# OpenBLAS kernels for x86-64 without AVX-512 (OPENBLAS_CORETYPE); the ones this CPU runs and
# that differ from the default are the ensemble's ``coretype:`` members.
CORETYPES = ("Prescott", "Nehalem", "Sandybridge", "Haswell", "Zen", "Core2", "Atom",
             "Barcelona", "Bulldozer")
REASON = ("The pinned baselines re-run bitwise on the platform they were pinned on. On another "
          "platform (another CPU target of the compiled kernels, BLAS kernel, libm or thread "
          "count) an operation may round its last bit differently, and the nominal mission's "
          "loop is unstable by design (dt·μ_max = 3.84 > 2): it amplifies such a difference "
          "step after step until the acceleration saturation binds, so its columns move by up "
          "to these amounts; the stable missions damp it and move by rounding only.")


class NudgedMission(Mission):
    """A mission whose initial state has some entries of q0 and v0 moved by one ulp, and, with
    a ``seed``, its q and v moved by one ulp (up, down or not, at random) after every step:
    the hooks of the measurement, by overriding :meth:`Mission.initial_state` and
    ``Mission._fly`` (one step per call of the compiled loop here; the simulator itself is
    untouched)."""

    def __init__(self, spec: Spec, nudges: list[tuple[str, int, float]],
                 seed: int | None = None):
        super().__init__(spec)
        self.nudges = nudges  # (field "q" or "v", index, direction ±inf)
        self.rng = None if seed is None else np.random.default_rng(seed)
        self.steps_nudged = 0

    def initial_state(self) -> LoopState:
        s = super().initial_state()
        for name, i, towards in self.nudges:
            x = getattr(s, name)
            x[i] = np.nextafter(x[i], towards)
        return s

    def _fly(self, start, stop, state, rows, ctrl, coverage, clip):
        if self.rng is None:
            return super()._fly(start, stop, state, rows, ctrl, coverage, clip)
        for i in range(start, stop):
            status, last, why = super()._fly(i, i + 1, state, rows, ctrl, coverage, clip)
            if status == NOT_FINITE:  # no row: the run ends before it
                return status, last, why
            for sl in (self.layout.state["q"], self.layout.state["v"]):
                way = self.rng.integers(-1, 2, sl.stop - sl.start)  # −1, 0 or +1 ulp
                x = state[sl]
                state[sl] = np.where(way == 0, x, np.nextafter(x, way * np.inf))
            self.steps_nudged += 1
            if status == DIVERGED:  # its row is logged, the last
                return status, last, why
        return FLOWN, stop, ""


def ulp_members(spec: Spec) -> dict[str, list[tuple[str, int, float]]]:
    """The ``ulp:`` members of the ensemble for a spec's robot: name → its nudges."""
    m = Mission(spec)
    nq, nv = m.robot.model.nq, m.robot.model.nv
    members = {f"ulp:q[{i}]": [("q", i, np.inf)] for i in range(nq)}
    members |= {f"ulp:v[{i}]": [("v", i, np.inf)] for i in range(nv)}
    members["ulp:all-"] = ([("q", i, -np.inf) for i in range(nq)]
                           + [("v", i, -np.inf) for i in range(nv)])
    return members


STEP_SEEDS = (0, 1, 2, 3)


def run_columns(spec: Spec, nudges: list[tuple[str, int, float]] | None = None,
                seed: int | None = None) -> dict[str, np.ndarray]:
    """The log's columns of a run of ``spec``, its initial state nudged, and its every step
    if ``seed`` is given."""
    mission = NudgedMission(spec, nudges or [], seed)
    result = mission.run()
    if seed is not None and mission.steps_nudged != result.rows:
        raise RuntimeError(f"the per-step hook ran {mission.steps_nudged} times in "
                           f"{result.rows} steps: Mission._fly no longer flies the steps")
    return result.columns


def column_tolerance(name: str, reference: np.ndarray, ensemble_max: float) -> dict:
    """The tolerance of one column from its ensemble's largest difference (module doc)."""
    if reference.dtype.kind in "iub":  # a count is exact; a flag flips (1) or does not (0)
        tol = 0.0 if ensemble_max == 0.0 else 1.0
        return {"tolerance": tol, "ensemble_max": ensemble_max, "floor": 0.0}
    magnitude = float(np.max(np.abs(reference.astype(float)), initial=0.0))
    floor = FLOOR_ULPS * float(np.spacing(magnitude))
    tol = max(SAFETY_FACTOR * ensemble_max, floor)
    return {"tolerance": tol, "ensemble_max": ensemble_max, "floor": floor}


def _probe(coretype: str) -> tuple[str, str]:
    """The kernels OpenBLAS runs under ``OPENBLAS_CORETYPE=coretype`` here, or why none."""
    code = ("import numpy as np, scipy.linalg as sl\n"
            "from threadpoolctl import threadpool_info\n"
            "a = np.arange(1.0, 401.0).reshape(20, 20) % 7; m = a @ a.T + 20 * np.eye(20)\n"
            "sl.cho_factor(m); np.linalg.solve(m, a)\n"
            "print(','.join(sorted(i['architecture'] for i in threadpool_info()"
            " if i['user_api'] == 'blas')))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, env=dict(os.environ, OPENBLAS_CORETYPE=coretype))
    if r.returncode != 0:
        return "", f"exit {r.returncode}"
    return r.stdout.strip(), ""


def _coretype_runs(names: list[str], tmp: Path, say: Callable[[str], None]
                   ) -> dict[str, Path]:
    """Each distinct non-default OpenBLAS kernel: the folder of its run of every baseline."""
    default = ",".join(sorted(b.architecture for b in fingerprint().blas))
    seen, runs = {default}, {}
    for core in CORETYPES:
        kernels, why = _probe(core)
        if why or kernels in seen:
            say(f"coretype {core}: " + (f"does not run here ({why})" if why else
                                        f"kernels {kernels} already in the ensemble"))
            continue
        seen.add(kernels)
        out = tmp / core
        r = subprocess.run([sys.executable, "-m", "pipeline.claims.tolerances", "run",
                            str(out), *names], capture_output=True, text=True, timeout=1800,
                           env=dict(os.environ, OPENBLAS_CORETYPE=core))
        if r.returncode != 0:
            say(f"coretype {core}: the run failed (exit {r.returncode}), left out")
            continue
        say(f"coretype {core}: kernels {kernels}")
        runs[f"coretype:{core}"] = out
    return runs


def _max_diffs(ref: dict[str, np.ndarray], other: dict[str, np.ndarray], member: str
               ) -> dict[str, float]:
    if set(ref) != set(other) or any(ref[c].shape != other[c].shape for c in ref):
        raise SpecError(f"ensemble member {member} changed the log's columns or length: "
                        "a perturbation of one ulp should not")
    return {c: float(np.max(np.abs(ref[c].astype(float) - other[c].astype(float)),
                            initial=0.0)) for c in ref}


def measure(names: list[str], say: Callable[[str], None] = print) -> dict:
    """Measure every baseline's per-column tolerances (module doc); the file's content."""
    here = fingerprint()
    result: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="tolerances-") as tmp:
        cores = _coretype_runs(names, Path(tmp), say)
        for name in names:
            spec = load_spec(name)
            ref = run_columns(spec)
            per_member: dict[str, dict[str, float]] = {}
            for member, folder in cores.items():
                other = dict(np.load(folder / f"{name}.npz"))
                per_member[member] = _max_diffs(ref, other, member)
            for member, nudges in ulp_members(spec).items():
                per_member[member] = _max_diffs(ref, run_columns(spec, nudges), member)
            for seed in STEP_SEEDS:
                member = f"ulp:steps-{seed}"
                per_member[member] = _max_diffs(ref, run_columns(spec, seed=seed), member)
            columns = {}
            for c in ref:
                worst = max(per_member, key=lambda m, c=c: per_member[m][c])
                entry = column_tolerance(c, ref[c], per_member[worst][c])
                entry["worst_member"] = worst if per_member[worst][c] > 0 else ""
                for kind in ("coretype", "ulp"):
                    entry[f"{kind}_max"] = max((d[c] for m, d in per_member.items()
                                                if m.startswith(kind)), default=0.0)
                columns[c] = entry
            result[name] = {"spec_hash": spec.spec_hash, "columns": columns}
            top = max(columns, key=lambda c: columns[c]["ensemble_max"])
            say(f"{name}: {len(per_member)} members, largest difference "
                f"{columns[top]['ensemble_max']:.3e} ({top}, {columns[top]['worst_member']})")
        members = ([*cores, *ulp_members(load_spec(names[0])),
                    *(f"ulp:steps-{seed}" for seed in STEP_SEEDS)] if names else [])
    return {
        "schema": SCHEMA,
        "about": ("Per-column tolerances of the pinned baselines (logs/baselines/*/run.parquet) "
                  "when re-run on another platform than the one they were pinned on; on the "
                  "same platform the comparison is bitwise. Measured, not chosen: see "
                  "pipeline/claims/tolerances.py and docs/reproducibility.md."),
        "reason": REASON,
        "method": {
            "command": "python -m pipeline.claims.baselines tolerances (make tolerances)",
            "ensemble": members,
            "safety_factor": SAFETY_FACTOR,
            "floor_ulps": FLOOR_ULPS,
            "rule": ("tolerance = max(safety_factor × the largest |member − reference| over "
                     "the ensemble, floor_ulps × ulp(the column's largest |value|)); 0 for "
                     "integer columns; for flags 0, or 1 (any flip) when a member flipped one"),
            "why_safety_factor": ("the ensemble samples single-ulp perturbations on one "
                                  "machine; another platform differs in many operations at "
                                  "every step. Before a saturation binds the loop is linear in "
                                  "the perturbation: a factor of 10 covers one ten times the "
                                  "size of any sampled, and a real regression moves the "
                                  "columns orders of magnitude more"),
        },
        "measured": {
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "platform": here.to_dict(), "platform_key": here.key(),
            "platform_summary": here.summary(), "sim_version": sim_version(),
            "versions": library_versions(SIM_LIBRARIES),
        },
        "baselines": result,
    }


def write_tolerances(content: dict, path: Path) -> None:
    atomic_write_text(Path(path), json.dumps(content, indent=1, allow_nan=False) + "\n")


def load_tolerances(path: Path) -> dict | None:
    """The tolerances file (its ``baselines`` mapping: name → column → tolerance), or None
    when there is none. A file that is not one is a SpecError naming it."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
        if data.get("schema") != SCHEMA:
            raise ValueError(f"schema {data.get('schema')!r}, not {SCHEMA}")
        table = {name: {c: float(e["tolerance"]) for c, e in b["columns"].items()}
                 for name, b in data["baselines"].items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise SpecError(f"{path}: not a tolerances file ({exc})") from None
    if any(not np.isfinite(t) or t < 0 for b in table.values() for t in b.values()):
        raise SpecError(f"{path}: a tolerance is negative or not finite")
    return {"table": table, "sim_version": data.get("measured", {}).get("sim_version"),
            "spec_hashes": {n: b.get("spec_hash") for n, b in data["baselines"].items()}}


def _run_main(out: Path, names: list[str]) -> int:
    """The subprocess of a ``coretype:`` member: every baseline's columns into OUT."""
    out.mkdir(parents=True, exist_ok=True)
    for name in names:
        np.savez(out / f"{name}.npz", **run_columns(load_spec(name)))
    return 0


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "run":
        sys.exit(_run_main(Path(sys.argv[2]), sys.argv[3:]))
    print("usage: python -m pipeline.claims.baselines tolerances", file=sys.stderr)
    sys.exit(2)
