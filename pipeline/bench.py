"""``python -m pipeline bench``: simulator and analysis cost against the Pinocchio floor (what
Pinocchio takes for the rigid-body terms one step needs; the step computes them itself, in
compiled code, :mod:`pipeline.sim.rigid_body_terms`).

See docs/architecture.md §7.

Every figure is measured in this process on the same configurations (those of a nominal run),
repeated, and reported as median with min and max. Each repeat times the floor, the simulator
and the analysis back to back, and the ratios are the median of the per-repeat ratios, so a
drift of the host's speed between repeats does not enter them:

- ``floor_us``: the Pinocchio calls that would give one step's terms (CRBA, Coriolis matrix,
  joint Jacobians and their time variation with the camera frame's Jacobian and its
  variation, centroidal map and its time variation);
- ``sim_step_us``: one whole controller step of the nominal mission (both loops, guidance,
  coverage, filling the log's columns), from ``Mission.run``;
- ``sampled_step_us``: the same mission's step on the sampled-data plant with one step of
  delay (eq. 29: RK4 on the compiled articulated-body algorithm), its ratio to the
  simulator's step (``sampled_ratio``) and to MuJoCo's RK4 with the same substeps on the same
  robot file, ``mj_step`` in a Python loop, measured in the same repeats
  (``mujoco_rk4_step_us``, ``sampled_mujoco_ratio``, target ≤ 2); ``sampled_jitter_step_us``:
  the same with the command arriving within the step and jittered (eq. 41: a quarter to three
  quarters of a step after the one step of delay), the hold split in two;
- ``montecarlo``: the wall time of an 852-sample Monte Carlo of that 60 s mission on two
  workers (``specs/montecarlo/bench_sampled_delay.yaml``; 40 samples in quick mode), its
  records in a fresh folder, against what its flights cost by the sampled step above
  (``wall_over_flights``, target ≤ 1.25: the overhead outside the flights at most a quarter);
  ``montecarlo_throughput``: samples per second, start-up and per-sample overhead in process,
  on a 2-worker LocalCluster and on the local SLURM (:mod:`pipeline.sweep.throughput`);
- ``analysis_step_us``: the per-step analysis of a log (Γ rebuilt from q, per-direction SVD,
  lag-1), streamed by row group as ``analyze`` does it;
- growth of mission wall time with length (10³, 10⁴, 10⁵ steps) and its fitted exponent;
- peak memory (max RSS of a fresh process) of ``analyze`` on a 10⁵- and a 10⁶-step log;
- the step's linear algebra, the project's kernels against BLAS and LAPACK in compiled code
  (:mod:`pipeline.bench_linalg`);
- sweep throughput (``sweep.<setting>.*``): points per second, start-up and the per-point
  overhead of Dask, in process, on a 2-worker LocalCluster and on the local SLURM
  (``pipeline.sweep.throughput``; the SLURM setting is recorded as skipped, with the reason,
  when no SLURM answers).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.analysis import signals
from pipeline.analysis.stages import Window, rebuild_and_project
from pipeline.artefact_paths import log_path
from pipeline.atomic_files import atomic_write_text
from pipeline.bench_linalg import linalg_costs, linalg_markdown
from pipeline.bench_linalg import summary as _stats
from pipeline.logs import SEAL_KEY, TableDigest, file_metadata
from pipeline.sim.mission import Mission
from pipeline.sim.robot import LOCAL, GiordanoRobot
from pipeline.sim.run import run_spec
from pipeline.spec import Spec, load_spec, spec_hash_of, with_overrides
from pipeline.store.door import ArtefactStore
from pipeline.sweep.throughput import MC_SAMPLES, montecarlo_throughput, sweep_throughput


def floor_once(robot: GiordanoRobot, q: np.ndarray, v: np.ndarray) -> float:
    """Per-step cost (µs) of the Pinocchio calls of one step, over the given states."""
    model, data, fid = robot.model, robot.data, robot.frame_id
    t0 = time.perf_counter()
    for qk, vk in zip(q, v, strict=True):
        pin.computeJointJacobiansTimeVariation(model, data, qk, vk)
        pin.updateFramePlacement(model, data, fid)
        pin.getFrameJacobian(model, data, fid, LOCAL)
        pin.getFrameJacobianTimeVariation(model, data, fid, LOCAL)
        pin.crba(model, data, qk)
        pin.computeCoriolisMatrix(model, data, qk, vk)
        pin.computeCentroidalMapTimeVariation(model, data, qk, vk)
    return (time.perf_counter() - t0) / len(q) * 1e6


def sim_once(spec: Spec) -> float:
    """Per-step cost (µs) of ``Mission.run`` (construction excluded)."""
    mission = Mission(spec)
    t0 = time.perf_counter()
    mission.run()
    return (time.perf_counter() - t0) / spec.n_steps * 1e6


def mujoco_rk4_once(model, data, steps: int, substeps: int) -> float:
    """Per-control-step cost (µs) of MuJoCo's RK4 on the same robot file: ``substeps`` calls
    of ``mj_step`` per control step (its timestep dt/substeps), a generalized force held over
    the step, from a Python loop, as a user would fly it."""
    import mujoco

    mujoco.mj_resetData(model, data)
    data.qvel[:] = 0.1
    data.qfrc_applied[:] = 0.01
    t0 = time.perf_counter()
    for _ in range(steps):
        for _ in range(substeps):
            mujoco.mj_step(model, data)
    return (time.perf_counter() - t0) / steps * 1e6


def mujoco_model_rk4(spec: Spec):
    """The spec's robot file compiled by MuJoCo for RK4 at the sampled plant's substep,
    gravity zero (orbit), and its data."""
    import mujoco

    from pipeline.sim.robot_crosscheck import mujoco_model

    model = mujoco_model(spec.robot_path)
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    model.opt.timestep = spec.mission.dt / spec.mission.plant.substeps
    model.opt.gravity[:] = 0.0
    return model, mujoco.MjData(model)


def analysis_once(robot: GiordanoRobot, path: Path) -> float:
    """Per-step cost (µs) of stages 1–3 on a log: Γ rebuild, per-direction SVD, lag-1."""
    log = ArtefactStore().open_log(path)  # verified before the clock starts
    n = log.rows
    t0 = time.perf_counter()
    _, y, _, _ = rebuild_and_project(robot, log, Window(n // 2, n, "bench"))
    signals.lag1_autocorrelation(y)
    signals.step_rms(y)
    return (time.perf_counter() - t0) / n * 1e6


def step_costs(spec: Spec, log: Path, repeats: int) -> dict:
    """Floor, simulator and analysis per step, measured back to back in each repeat.

    On a shared host the speed drifts between repeats; a ratio taken within one repeat
    compares like with like, so the ratios are the median of the per-repeat ratios.
    """
    cols = ArtefactStore().open_log(log).columns(["q", "v"])
    q, v = cols["q"], cols["v"]
    robot = GiordanoRobot(spec)
    analysis_once(robot, log)  # warm-up: compiles the analysis kernels if the cache is cold
    sampled_spec = with_overrides(spec, {"mission.plant.model": "sampled",
                                         "mission.plant.delay_steps": 1}, name="bench_sampled")
    jitter_spec = with_overrides(sampled_spec, {"mission.plant.timing": {
        "delay_fraction": 0.25, "jitter": 0.5, "seed": 1}}, name="bench_sampled_jitter")
    mj_model, mj_data = mujoco_model_rk4(sampled_spec)
    substeps = sampled_spec.mission.plant.substeps
    floor, sim, ana, sampled, jittered, mj = [], [], [], [], [], []
    for _ in range(repeats):
        floor.append(floor_once(robot, q, v))
        sim.append(sim_once(spec))
        sampled.append(sim_once(sampled_spec))
        mj.append(mujoco_rk4_once(mj_model, mj_data, spec.n_steps, substeps))
        jittered.append(sim_once(jitter_spec))
        ana.append(analysis_once(robot, log))
    f = np.asarray(floor)
    return {"floor_us": _stats(floor), "sim_step_us": _stats(sim), "analysis_step_us": _stats(ana),
            "sampled_step_us": _stats(sampled), "sampled_jitter_step_us": _stats(jittered),
            "mujoco_rk4_step_us": _stats(mj), "substeps": substeps,
            "sim_ratio": _stats(list(np.asarray(sim) / f)),
            "sampled_ratio": _stats(list(np.asarray(sampled) / np.asarray(sim))),
            "sampled_mujoco_ratio": _stats(list(np.asarray(sampled) / np.asarray(mj))),
            "analysis_ratio": _stats(list(np.asarray(ana) / f))}


def montecarlo_wall(samples: int, folder: Path) -> dict:
    """Wall time (s) of ``python -m pipeline montecarlo bench_sampled_delay`` with
    ``samples`` samples on two workers, from an empty record folder (start-up included)."""
    cmd = [sys.executable, "-m", "pipeline", "montecarlo", "bench_sampled_delay",
           "--samples", str(samples), "--workers", "2", "--logs", str(folder / "logs"),
           "--out", str(folder / "out")]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        return {"samples": samples, "skipped": (r.stderr.strip().splitlines() or ["?"])[-1]}
    verdict = json.loads((folder / "out" / "bench_sampled_delay" / "verdict.json").read_text())
    return {"samples": samples, "wall_s": wall, "driver_s": verdict["wall_s"],
            "per_sample_s": wall / samples, "skipped": ""}


def flights_share(m: dict, sampled_step_us: float, steps: int = 2000, workers: int = 2
                  ) -> dict:
    """What the Monte Carlo's samples cost in flight alone, by the bench's own sampled step
    (samples × steps × that step ÷ workers), the wall time's ratio to it (target ≤ 1.25) and
    the share of the wall time spent outside the flights (start-up, spawn, verdicts,
    records)."""
    if m.get("skipped"):
        return {}
    flights = m["samples"] * steps * sampled_step_us * 1e-6 / workers
    return {"flights_s": flights, "wall_over_flights": m["wall_s"] / flights,
            "overhead_share": 1.0 - flights / m["wall_s"]}


def growth(spec: Spec, lengths: list[int], repeats: int) -> dict:
    """Median wall time of missions of the given step counts and the fitted exponent of
    t ∝ Nᵖ (least squares in log–log)."""
    walls, spread = [], []
    for n in lengths:
        s = with_overrides(spec, {"mission.duration": n * spec.mission.dt})
        times = []
        for _ in range(repeats):
            mission = Mission(s)
            t0 = time.perf_counter()
            mission.run()
            times.append(time.perf_counter() - t0)
        walls.append(float(np.median(times)))
        spread.append(_stats(times))
    p = float(np.polyfit(np.log(lengths), np.log(walls), 1)[0])
    return {"steps": lengths, "wall_s": walls, "wall_stats": spread, "exponent": p}


def tiled_log(src: Path, dst: Path, factor: int) -> Path:
    """A log of ``factor`` times the rows of ``src``: its rows repeated, with ``step`` and ``t``
    numbered on and the metadata of a mission ``factor`` times as long, so the analysis window
    is the second half of the long log.

    The analysis' cost per step does not depend on the trajectory, so a long log for the
    memory measurement need not be simulated.
    """
    pf = pq.ParquetFile(src)
    n = pf.metadata.num_rows
    md = {k.encode(): v.encode() for k, v in file_metadata(src).items() if k != SEAL_KEY}
    spec = json.loads(md[b"pipeline.spec"])
    dt = spec["mission"]["dt"]
    # The metadata says what the file is, so the log passes verify_log: a mission `factor`
    # times as long (its spec re-hashed), with every row counted.
    spec["mission"]["duration"] = spec["mission"]["duration"] * factor
    md.update({b"pipeline.spec": json.dumps(spec, sort_keys=True).encode(),
               b"pipeline.spec_hash": spec_hash_of(spec).encode(),
               b"pipeline.rows": str(n * factor).encode()})
    dst.parent.mkdir(parents=True, exist_ok=True)
    digest = TableDigest(pf.schema_arrow.names)  # its own seal: its columns are new
    with pq.ParquetWriter(dst, pf.schema_arrow.with_metadata(md), compression="zstd") as w:
        for i in range(factor):
            for rg in range(pf.num_row_groups):
                t = pf.read_row_group(rg)
                step = t.column("step").to_numpy() + i * n
                t = t.set_column(t.schema.get_field_index("step"), "step", pa.array(step))
                t = t.set_column(t.schema.get_field_index("t"), "t", pa.array(step * dt))
                w.write_table(t)
                digest.update(t)
        w.add_key_value_metadata({SEAL_KEY: digest.hexdigest()})
    return dst


_PEAK = ("import resource, sys; from pipeline.cli import main; rc = main(sys.argv[1:]); "
         "print('MAXRSS_KB', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); "
         "sys.exit(rc)")


def peak_memory_mb(log: Path, out: Path) -> float:
    """Max RSS (MB) of a fresh process running ``analyze`` on ``log``."""
    r = subprocess.run([sys.executable, "-c", _PEAK, "analyze", str(log), "--out", str(out)],
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        raise RuntimeError(f"analyze of {log} failed: {r.stderr.strip()}")
    kb = next(int(line.split()[1]) for line in r.stdout.splitlines()
              if line.startswith("MAXRSS_KB"))
    return kb / 1024


def machine() -> dict:
    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import numba

    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "pinocchio": pin.__version__, "numba": numba.__version__,
            "platform": platform.platform()}


def run_bench(out_dir: Path, quick: bool = False) -> dict:
    spec = load_spec("nominal")
    repeats = 3 if quick else 7
    repeats_growth = 1 if quick else 3
    base_steps = 1000 if quick else spec.n_steps
    base = with_overrides(spec, {"mission.duration": base_steps * spec.mission.dt})
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _progress("warm-up and reference run")
        log = run_spec(base, tmp / "logs").path
        _progress(f"floor, simulator and analysis steps, {repeats} repeats")
        costs = step_costs(base, log, repeats)
        lengths = [1000, 3000, 10000] if quick else [1000, 10000, 100000]
        _progress(f"growth over {lengths} steps, {repeats_growth} repeats each")
        grow = growth(spec, lengths, repeats_growth)
        _progress("peak memory")
        n_mem = 10000 if quick else 100000
        long = run_spec(with_overrides(spec, {"mission.duration": n_mem * spec.mission.dt},
                                       name="bench_long"), tmp / "logs").path
        big = tiled_log(long, log_path(tmp / "big", "bench_long"), 10)
        memory = {f"{n_mem}": peak_memory_mb(long, tmp / "a1"),
                  f"{10 * n_mem}": peak_memory_mb(big, tmp / "a2")}
        n_mc = 40 if quick else 852
        _progress(f"a Monte Carlo of {n_mc} samples of the 60 s sampled mission, 2 workers")
        montecarlo = montecarlo_wall(n_mc, tmp / "montecarlo")
    _progress(f"the step's linear algebra against BLAS and LAPACK, {repeats} repeats")
    linalg = linalg_costs(repeats)
    sweeps = {k: v.as_dict() for k, v in sweep_throughput(progress=_progress).items()}
    mc_throughput = {k: v.as_dict() for k, v in
                     montecarlo_throughput(progress=_progress).items()}
    result = {
        "floor_us": costs["floor_us"],
        "sim_step_us": costs["sim_step_us"],
        "sim_ratio": costs["sim_ratio"]["median"],
        "sim_ratio_stats": costs["sim_ratio"],
        "sampled_step_us": costs["sampled_step_us"],
        "sampled_jitter_step_us": costs["sampled_jitter_step_us"],
        "sampled_ratio": costs["sampled_ratio"]["median"],
        "sampled_ratio_stats": costs["sampled_ratio"],
        "mujoco_rk4_step_us": costs["mujoco_rk4_step_us"],
        "substeps": costs["substeps"],
        "sampled_mujoco_ratio": costs["sampled_mujoco_ratio"]["median"],
        "sampled_mujoco_ratio_stats": costs["sampled_mujoco_ratio"],
        "montecarlo": montecarlo | flights_share(montecarlo, costs["sampled_step_us"]["median"]),
        "montecarlo_throughput": mc_throughput,
        "analysis_step_us": costs["analysis_step_us"],
        "analysis_ratio": costs["analysis_ratio"]["median"],
        "analysis_ratio_stats": costs["analysis_ratio"],
        "growth": grow,
        "peak_memory_mb": memory,
        "linalg": linalg,
        "steps_per_s": 1e6 / costs["sim_step_us"]["median"],
        "sweep": sweeps,
        "quick": quick,
        "machine": machine(),
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "bench.json", json.dumps(result, indent=1) + "\n")
    atomic_write_text(out_dir / "bench.md", bench_markdown(result))
    return result


def _progress(msg: str) -> None:
    print(f"bench: {msg}", file=sys.stderr, flush=True)


def bench_markdown(r: dict) -> str:
    def row(name, s):
        return f"| {name} | {s['median']:.1f} | {s['min']:.1f} | {s['max']:.1f} |"

    g = r["growth"]
    mem = "\n".join(f"| {n} | {mb:.0f} |" for n, mb in r["peak_memory_mb"].items())
    grow = "\n".join(f"| {n} | {w['median']:.2f} | {w['min']:.2f} | {w['max']:.2f} |"
                     for n, w in zip(g["steps"], g["wall_stats"], strict=True))
    sr, ar, pr = r["sim_ratio_stats"], r["analysis_ratio_stats"], r["sampled_ratio_stats"]
    mr = r["sampled_mujoco_ratio_stats"]
    m = r["machine"]
    return f"""# Benchmark

Machine: {m['cpu']}, {m['cores']} cores; Python {m['python']}, NumPy {m['numpy']},
Pinocchio {m['pinocchio']}, Numba {m['numba']}.{' Quick mode (shorter runs).' if r['quick'] else ''}

| per step (µs) | median | min | max |
|---|---|---|---|
{row('floor: Pinocchio calls of one step', r['floor_us'])}
{row('simulator: whole controller step', r['sim_step_us'])}
{row('sampled-data plant, one step of delay: whole step', r['sampled_step_us'])}
{row('sampled plant, 1.25–1.75 steps of delay (eq. 41)', r['sampled_jitter_step_us'])}
{row('analysis: Γ rebuild, per-direction SVD, lag-1', r['analysis_step_us'])}
{row(f"MuJoCo's RK4, {r['substeps']} mj_step per control step, same robot file",
     r['mujoco_rk4_step_us'])}

Each repeat measures the floor, the simulator and the analysis back to back; a ratio is the
median over repeats of that repeat's step / floor (min–max in brackets).

- sim_ratio = {r['sim_ratio']:.2f} [{sr['min']:.2f}–{sr['max']:.2f}] (target ≤ 5)
- sampled_ratio = {r['sampled_ratio']:.2f} [{pr['min']:.2f}–{pr['max']:.2f}] (the sampled step
  over the simulator's)
- sampled_mujoco_ratio = {r['sampled_mujoco_ratio']:.2f} [{mr['min']:.2f}–{mr['max']:.2f}] (the
  sampled step, controller included, over MuJoCo's RK4 alone with the same substeps; target
  ≤ 2)
- analysis_ratio = {r['analysis_ratio']:.2f} [{ar['min']:.2f}–{ar['max']:.2f}] (target ≤ 2)
- {r['steps_per_s']:.0f} simulator steps per second.

## Monte Carlo

{montecarlo_markdown(r["montecarlo"])}

## Growth with mission length (fitted exponent {g['exponent']:.3f})

Median wall time of {g['wall_stats'][0]['repeats']} run(s) per length.

| steps | wall (s) | min | max |
|---|---|---|---|
{grow}

## Peak memory of `analyze` (max RSS of a fresh process)

The longer log repeats the shorter one's rows ten times (the analysis cost does not depend on
the trajectory); it is read by row groups.

| steps | MB |
|---|---|
{mem}

## The step's linear algebra against BLAS and LAPACK

Per call, inside compiled code, on the step's sizes, the two alternating within each repeat
(`pipeline/bench_linalg.py`); own / library is the median of the per-repeat ratios [min–max].
The own kernels give the same bits on every processor; LAPACK's do not.

{linalg_markdown(r["linalg"]) if "linalg" in r else "(not measured)"}

## Sweep throughput (32 points: 8 dt × 4 bus D, 20-s nominal missions)

Overhead per point = steady-state wall time per point × workers − the median per-point
simulation and analysis time; its ratio to that time should be below 1. Start-up (cluster,
job submission, workers up with their imports) is apart.

{sweep_markdown(r["sweep"])}

## Monte Carlo throughput (the first {MC_SAMPLES} samples of the bench's Monte Carlo)

The same figures per sample (a sample's task: its flight, its verdict, its kept record). A
study of N samples on W workers takes about start-up + N × (task + overhead) / W.

{sweep_markdown(r["montecarlo_throughput"]).replace("points/s", "samples/s")
 .replace("overhead/point", "overhead/sample")}
"""


def montecarlo_markdown(m: dict) -> str:
    if m.get("skipped"):
        return f"{m['samples']} samples of the 60 s sampled mission: skipped ({m['skipped']})."
    return (f"{m['samples']} samples of the 60 s sampled mission with one step of delay "
            f"(`specs/montecarlo/bench_sampled_delay.yaml`) on two workers: {m['wall_s']:.1f} s "
            f"wall from the command's start, {m['per_sample_s']:.3f} s per sample; the "
            f"driver's own count from its cluster's start {m['driver_s']:.1f} s. Its flights "
            f"alone, by the sampled step above (samples × 2,000 steps × that step ÷ 2 "
            f"workers): {m['flights_s']:.1f} s; wall / flights = {m['wall_over_flights']:.3f} "
            f"(target ≤ 1.25), {100 * m['overhead_share']:.0f} % of the wall time outside "
            f"the flights.")


def sweep_markdown(sweeps: dict) -> str:
    rows = ["| setting | workers | points/s | start-up (s) | task (s) | overhead/point (s) "
            "| overhead ratio | against the mean task |", "|---|---|---|---|---|---|---|---|"]
    for name, s in sweeps.items():
        if s["skipped"]:
            rows.append(f"| {name} | {s['workers']} | skipped: {s['skipped']} | | | | | |")
        else:
            rows.append(f"| {name} | {s['workers']} | {s['points_per_s']:.2f} | "
                        f"{s['startup_s']:.1f} | {s['task_s']:.2f} | {s['overhead_s']:.3f} | "
                        f"{s['overhead_ratio']:.3f} | {s['overhead_ratio_mean']:.3f} |")
    return "\n".join(rows)


def bench_command(args) -> int:
    r = run_bench(Path(args.out), quick=args.quick)
    print(f"floor {r['floor_us']['median']:.1f} µs, sim {r['sim_step_us']['median']:.1f} µs "
          f"(ratio {r['sim_ratio']:.2f}), sampled {r['sampled_step_us']['median']:.1f} µs "
          f"({r['sampled_ratio']:.2f} × sim), analysis {r['analysis_step_us']['median']:.1f} µs "
          f"(ratio {r['analysis_ratio']:.2f}), growth exponent {r['growth']['exponent']:.3f}, "
          f"peak memory {r['peak_memory_mb']} MB -> {Path(args.out) / 'bench.json'}")
    return 0
