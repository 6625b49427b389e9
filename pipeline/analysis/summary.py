"""What ``python -m pipeline analyze`` says of an analysis record: its headline numbers and,
for a comparison, what it compares."""

from __future__ import annotations

from pathlib import Path

from pipeline.analysis.joint_ranges import excursion_words
from pipeline.analysis.schema import AnalysisRecord, CompleteRecord, ImportedRecord, same_duration
from pipeline.analysis.verdict import ModeLoop, Prediction, measured_words


def _num(x: float | None) -> str:
    return "none" if x is None else f"{x:.4g}"


def _seconds(record: CompleteRecord) -> tuple[float, float, float]:
    """(duration, window start, window end) in seconds."""
    dt, w = record.dt, record.window
    return record.n_steps * dt, w.start_step * dt, w.stop_step * dt


def basis_lines(a: CompleteRecord, b: CompleteRecord) -> list[str]:
    """What a comparison compares, in seconds: the robot, dt, integrator, duration and
    windows; the durations and windows when they differ, named as such (a lag-1 of a shorter
    window is a noisier estimate, a different window sees another part of the orbit)."""
    da, sa, ea = _seconds(a)
    db, sb, eb = _seconds(b)
    lines = [f"  compares {a.spec_name} with {b.spec_name}: same robot "
             f"(I_zz,bus {a.robot.I_zz_bus:.4g} kg·m²), "
             f"dt {a.dt:g} s vs {b.dt:g} s, integrator {a.integrator} vs "
             f"{b.integrator}, duration {da:.4g} s vs {db:.4g} s, window "
             f"{sa:.4g}–{ea:.4g} s vs {sb:.4g}–{eb:.4g} s"]
    if a.dt == b.dt and a.integrator == b.integrator:
        lines.append(f"  note: same dt ({a.dt:g} s) and integrator: the comparison tests "
                     f"neither the step nor the integrator")
    # Equal to within a step of the coarser run: a window that starts at step n//2 of each
    # run starts at times one step apart at most, which is no difference of substance.
    step = max(a.dt, b.dt)
    if not same_duration(a, b):
        lines.append(f"  note: different durations ({da:.4g} s vs {db:.4g} s)")
    if abs(sa - sb) > step or abs(ea - eb) > step:
        lines.append(f"  note: different windows ({sa:.4g}–{ea:.4g} s vs {sb:.4g}–{eb:.4g} s)")
    differs = a.comparison.mission_differs if a.comparison is not None else []
    if differs:
        lines.append(f"  note: the specs also differ in {', '.join(differs)}")
    return lines


def summary_lines(record: AnalysisRecord, path: Path) -> list[str]:
    """What ``analyze`` prints of a record written to ``path``: the headline numbers, and for
    a comparison what it compares (:func:`basis_lines`)."""
    if isinstance(record, ImportedRecord):
        return [*imported_lines(record, path),
                f"  joint ranges: {excursion_words(record.joint_ranges)}"]
    if not isinstance(record, CompleteRecord):
        g = record.divergence
        return [f"{record.spec_name}: {record.note}; ω_b grows by "
                f"{g.growth_factor:+.4g} per step over steps {g.fit_steps[0]}–"
                f"{g.fit_steps[1]}, Φ predicts {g.predicted:+.4g} (simulator's order; "
                f"{g.predicted_note_order:+.4g} under the note's) -> {path}",
                f"  joint ranges: {excursion_words(record.joint_ranges)}"]
    th, dom = record.theory, record.dominant
    lines = [f"{record.spec_name}: dominant lag-1 {_lag(dom.lag1)} (σ {dom.sigma:.3g}), "
             f"dt·μ_max {th.dt_mu_max:.3g}, dt*_damping {th.dt_star_damping:.4g} s, "
             f"dt*_map {_num(th.dt_star_map)} s, dominant eigenvalue "
             f"{th.eig_dominant.real:+.3f}{th.eig_dominant.imag:+.3f}j, "
             f"|cos| {record.alignment.abs_cos:.3f}, median ‖Δv‖ "
             f"{record.velocity_jump.median:.3g} (m/s, rad/s mixed), provenance "
             f"{record.provenance.max_abs_s_min_G:.1e} -> {path}"]
    lines.append(f"  joint ranges: {excursion_words(record.joint_ranges)}")
    lines += mode_lines(th.modes, record.prediction, th.plant, th.delay_steps)
    if th.latency is not None:  # the command arriving within the step (eq. 41)
        lat = th.latency
        lines.append(f"  latency: {th.update_order}; margins and map at "
                     f"{lat.judged_delay_steps:.3g} steps (ρ {th.spectral_radius:.6g}; at the "
                     f"earliest arrival {lat.earliest_radius:.6g}); {lat.verdict}")
    if record.comparison is not None:
        c = record.comparison
        coverage = ("not compared (another mission)" if c.coverage_diff_pp is None
                    else f"{c.coverage_diff_pp:.2f} pp")
        lines.append(f"  vs {c.against}: lag-1 flip {c.lag1_flip}, ‖Δv‖ ratio "
                     f"{c.amplitude_ratio:.3g}, coverage difference {coverage}")
        lines += basis_lines(record, c.other)
    return lines


def imported_lines(record: ImportedRecord, path: Path) -> list[str]:
    """An imported log's headline numbers, its origin, and which stages ran and why."""
    o, dom = record.origin, record.dominant
    lines = [f"{record.spec_name} (imported {o.format} {o.source}, sha256 "
             f"{o.source_sha256[:12]}): dominant lag-1 {_lag(dom.lag1)} (σ {dom.sigma:.3g}), "
             f"bus rate lag-1 {_lag(record.bus_rate.lag1)}, median ‖Δv‖ "
             f"{record.velocity_jump.median:.3g} (m/s, rad/s mixed), provenance "
             + (f"{record.provenance.max_abs_s_min_G:.1e}" if record.provenance is not None
                else "not applicable (σ rebuilt from q on import)")
             + f", σ_min(Γ) ≥ "
             f"{record.conditioning.s_min_G_min:.3g} -> {path}"]
    if record.damping is not None:
        d, p = record.damping, record.prediction
        lines.append(f"  controller {d.controller} (declared): dt·μ_max {d.dt_mu_max:.3g} "
                     f"({d.fastest_mode.name}), dt*_damping {d.dt_star_damping:.4g} s")
        lines += mode_lines(d.modes, p, d.plant, d.delay_steps)
    lines += [f"  not run: {s.stage}: {s.why.removeprefix('not run: ')}"
              for s in record.stages if not s.ran]
    return lines


def _lag(r: float | None) -> str:
    return "undetermined (no motion)" if r is None else f"{r:+.3f}"


def _margins(m: ModeLoop) -> str:
    g = m.margins
    pm = "none" if g.phase_margin_deg is None else f"{g.phase_margin_deg:.3g}°"
    dm = f"{'≥ ' if g.delay_margin_beyond else ''}{g.delay_margin_s * 1e3:.3g} ms"
    return (f"GM {g.gain_margin_db:+.3g} dB, PM {pm}, DM {dm}: "
            f"{'meets' if g.meets else 'FAILS'} the requirement")


def mode_lines(modes: list[ModeLoop], prediction: Prediction, plant: str, delay: int
               ) -> list[str]:
    """The modes judged one by one (eqs. 35, 36): each mode that rings in the theory or in the
    data, or fails the margins, on a line; the others counted."""
    late = f", {delay} step of delay" if delay else ""
    verdict = ("agree" if prediction.agrees else "DISAGREE" if prediction.agrees is False
               else f"undetermined on {prediction.undetermined} of {len(prediction.modes)} "
                    f"modes")
    lines = [f"  modes of the loop as flown ({plant} plant{late}): theory and data {verdict}"]
    if prediction.agrees is None and prediction.undetermined_why:
        lines.append(f"    undetermined: {prediction.undetermined_why}")
    quiet, driven = 0, {}
    for m, j in zip(modes, prediction.modes, strict=True):
        if not (m.rings or j.measured.rings or not m.margins.meets):
            quiet += 1
            continue
        if j.driven_by is not None and m.margins.meets:
            driven.setdefault(j.driven_by, []).append(m.symbol)
            continue
        data = measured_words(j)
        period = "" if m.period_steps is None else f", period {m.period_steps:.3g} steps"
        word = "undetermined" if j.agrees is None else "agree" if j.agrees else "DISAGREE"
        lines.append(f"    {m.name}: dt·μ {m.dt_mu:.3g}, root |z| {m.modulus:.3g}{period} "
                     f"({m.regime}); data: {data}; {word}; {_margins(m)}")
    for driver, symbols in driven.items():
        lines.append(f"    {len(symbols)} stable modes ({', '.join(symbols)}) ring at the "
                     f"{driver} mode's period with less modal energy: driven by it; margins met")
    if quiet:
        lines.append(f"    {quiet} other modes: stable, quiet in the data, margins met")
    return lines
