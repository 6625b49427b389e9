"""``python -m pipeline analyze``: analysis.json and the per-direction table of one log."""

from __future__ import annotations

from pathlib import Path

from pipeline.analysis.record import write_analysis
from pipeline.analysis.stages import analyze_log, compare
from pipeline.errors import LogError


def _num(x: float | None) -> str:
    return "none" if x is None else f"{x:.4g}"


def analyze_command(log: Path, against: Path | None, out: Path,
                    window_start: float | None = None) -> int:
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
    if against is not None:
        record["comparison"] = compare(record, analyze_log(against, window_start))
    path = write_analysis(record, out)
    th, dom = record["theory"], record["dominant"]
    print(f"{record['spec_name']}: dominant lag-1 {dom['lag1']:+.3f} (σ {dom['sigma']:.3g}), "
          f"dt·μ_max {th['dt_mu_max']:.3g}, dt*_damping {th['dt_star_damping']:.4g} s, "
          f"dt*_map {_num(th['dt_star_map'])} s, dominant eigenvalue "
          f"{th['eig_dominant']['real']:+.3f}{th['eig_dominant']['imag']:+.3f}j, "
          f"|cos| {record['alignment']['abs_cos']:.3f}, median ‖Δv‖ "
          f"{record['velocity_jump']['median']:.3g}, provenance "
          f"{record['provenance']['max_abs_s_min_G']:.1e} -> {path}")
    if "comparison" in record:
        c = record["comparison"]
        print(f"  vs {c['against']}: lag-1 flip {c['lag1_flip']}, ‖Δv‖ ratio "
              f"{c['amplitude_ratio']:.3g}, coverage difference {c['coverage_diff_pp']:.2f} pp")
    return 0
