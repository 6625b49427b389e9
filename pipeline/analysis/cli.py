"""``python -m pipeline analyze``: analysis.json and the per-direction table of one log."""

from __future__ import annotations

from pathlib import Path

from pipeline.analysis.record import write_analysis
from pipeline.analysis.stages import analyze_log, compare
from pipeline.errors import LogError, SpecError
from pipeline.logs import LogMeta, read_meta


def _num(x: float | None) -> str:
    return "none" if x is None else f"{x:.4g}"


def _robot(meta: LogMeta) -> tuple:
    """What makes two logs the same robot: the robot file's content, the camera frame the task
    is defined on, and the bus-inertia knob (it changes the model, architecture §2)."""
    r = meta.spec.get("robot", {})
    return meta.robot_hash, r.get("camera_frame"), r.get("bus_inertia_scale", 1.0)


def check_same_robot(log: Path, against: Path) -> None:
    """SpecError (exit 2) when ``against`` is a run of another robot: its lag-1 or ‖Δv‖ says
    nothing about this robot's step, so the comparison would mean nothing."""
    a, b = read_meta(log), read_meta(against)
    if _robot(a) != _robot(b):
        ra, rb = a.spec.get("robot", {}), b.spec.get("robot", {})
        raise SpecError(
            f"--against {against}: a run of another robot ({b.robot_file}, bus inertia × "
            f"{rb.get('bus_inertia_scale', 1.0):g}, camera frame {rb.get('camera_frame')!r}, "
            f"file hash {b.robot_hash[:12]}) than {log} ({a.robot_file}, × "
            f"{ra.get('bus_inertia_scale', 1.0):g}, {ra.get('camera_frame')!r}, "
            f"{a.robot_hash[:12]}); compare runs of one robot")


def _seconds(record: dict) -> tuple[float, float, float]:
    """(duration, window start, window end) in seconds."""
    dt, w = record["dt"], record["window"]
    return record["n_steps"] * dt, w["start_step"] * dt, w["stop_step"] * dt


def basis_lines(a: dict, b: dict) -> list[str]:
    """What a comparison compares, in seconds: the robot, dt, integrator, duration and
    windows; the durations and windows when they differ, named as such (a lag-1 of a shorter
    window is a noisier estimate, a different window sees another part of the orbit)."""
    da, sa, ea = _seconds(a)
    db, sb, eb = _seconds(b)
    robot = a.get("robot", {})
    lines = [f"  compares {a['spec_name']} with {b['spec_name']}: same robot "
             f"(I_zz,bus {robot.get('I_zz_bus', float('nan')):.4g} kg·m²), "
             f"dt {a['dt']:g} s vs {b['dt']:g} s, integrator {a['integrator']} vs "
             f"{b['integrator']}, duration {da:.4g} s vs {db:.4g} s, window "
             f"{sa:.4g}–{ea:.4g} s vs {sb:.4g}–{eb:.4g} s"]
    if a["dt"] == b["dt"] and a["integrator"] == b["integrator"]:
        lines.append(f"  note: same dt ({a['dt']:g} s) and integrator: the comparison tests "
                     f"neither the step nor the integrator")
    # Equal to within a step of the coarser run: a window that starts at step n//2 of each
    # run starts at times one step apart at most, which is no difference of substance.
    step = max(a["dt"], b["dt"])
    if abs(da - db) > step:
        lines.append(f"  note: different durations ({da:.4g} s vs {db:.4g} s)")
    if abs(sa - sb) > step or abs(ea - eb) > step:
        lines.append(f"  note: different windows ({sa:.4g}–{ea:.4g} s vs {sb:.4g}–{eb:.4g} s)")
    return lines


def analyze_command(log: Path, against: Path | None, out: Path,
                    window_start: float | None = None) -> int:
    if against is not None:  # refused before the work: another robot's run compares nothing
        check_same_robot(log, against)
    record = analyze_log(log, window_start)
    if record.get("status") == "diverged":
        if against is not None:
            raise LogError(f"{log}: a diverged log is not compared (--against): only its "
                           f"divergence stage runs")
        path = write_analysis(record, out)
        g = record["divergence"]
        print(f"{record['spec_name']}: {record['note']}; ω_b grows by {g['growth_factor']:+.4g} "
              f"per step over steps {g['fit_steps'][0]}–{g['fit_steps'][1]}, Φ predicts "
              f"{g['predicted']:+.4g} (simulator's order; {g['predicted_note_order']:+.4g} "
              f"under the note's) -> {path}")
        return 0
    basis: list[str] = []
    if against is not None:
        other = analyze_log(against, window_start)
        record["comparison"] = compare(record, other)
        basis = basis_lines(record, other)
    path = write_analysis(record, out)
    th, dom = record["theory"], record["dominant"]
    print(f"{record['spec_name']}: dominant lag-1 {dom['lag1']:+.3f} (σ {dom['sigma']:.3g}), "
          f"dt·μ_max {th['dt_mu_max']:.3g}, dt*_damping {th['dt_star_damping']:.4g} s, "
          f"dt*_map {_num(th['dt_star_map'])} s, dominant eigenvalue "
          f"{th['eig_dominant']['real']:+.3f}{th['eig_dominant']['imag']:+.3f}j, "
          f"|cos| {record['alignment']['abs_cos']:.3f}, median ‖Δv‖ "
          f"{record['velocity_jump']['median']:.3g} (m/s, rad/s mixed), provenance "
          f"{record['provenance']['max_abs_s_min_G']:.1e} -> {path}")
    if "comparison" in record:
        c = record["comparison"]
        print(f"  vs {c['against']}: lag-1 flip {c['lag1_flip']}, ‖Δv‖ ratio "
              f"{c['amplitude_ratio']:.3g}, coverage difference {c['coverage_diff_pp']:.2f} pp")
        for line in basis:
            print(line)
    return 0
