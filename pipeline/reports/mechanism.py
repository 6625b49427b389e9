"""The mechanism report of one analysed run pair: verdict, loop, derivation, evidence, causal
test, fix. Every number comes from the pair's analysis.json (the damping mode's shape is the
generalised eigenvector of the D̆ and M̆ stored there); the wording follows the numbers.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from pipeline.analysis.joint_ranges import excursion_words, range_mark
from pipeline.analysis.schema import (
    AnalysisRecord,
    CompleteRecord,
    Theory,
    same_duration,
    same_mission,
    value_at,
)
from pipeline.claims.seed_note import (
    NOTE_FILE,
    column_regimes,
    differences,
    fmt,
    load_note,
    note_table,
)
from pipeline.reports.figures import RunData, against_log
from pipeline.reports.fixes import severity
from pipeline.reports.templating import num
from pipeline.sim.stability import damping_modes

V_BREVE_LABELS = ("ω_b,x", "ω_b,y", "ω_b,z", "ν_e,x (linear)", "ν_e,y (linear)",
                  "ν_e,z (linear)", "ω_e,x", "ω_e,y", "ω_e,z (camera roll about the boresight)")
LAG1_SMOOTH = 0.9  # the threshold of claim C2


@dataclass(frozen=True)
class Verdict:
    kind: str  # "ripple", "fix", "stable" or "inconclusive"
    headline: str


def damping_mode(theory: Theory) -> dict:
    """The fastest damping mode w (D̆ w = μ_max M̆ w, :func:`damping_modes`) and its largest
    component's share of the unit vector w."""
    fastest = damping_modes(np.array(theory.M_breve), np.array(theory.D_breve))[0]
    w = fastest.vector / np.linalg.norm(fastest.vector)
    shares = w**2
    i = int(np.argmax(shares))
    return {"mu_max": fastest.mu, "component": V_BREVE_LABELS[i], "index": i,
            "share": float(shares[i]),
            "shares": [{"label": V_BREVE_LABELS[k], "share": float(shares[k])}
                       for k in np.argsort(-shares)[:3]]}


def ringing_words(run: CompleteRecord) -> str:
    """The modes that ring of their own in the data (eq. 36), with period, size and limit."""
    parts = []
    for j in run.prediction.modes:
        r = j.measured
        if not r.rings or j.driven_by:
            continue
        held = f", held by {j.held_by.limit}" if j.held_by and j.held_by.explains else ""
        parts.append(f"the {j.mode} mode over {r.period_steps:.3g} steps "
                     f"({r.peak_to_peak:.3g} {r.unit} peak to peak, {r.trend}{held})")
    return "; ".join(parts) or "no mode"


def recommended(th: Theory) -> str:
    """The cheapest change that meets the requirement on this run's loop (eq. 35; fewest
    steps per second, then the larger gain margin), in words, or why none is named."""
    ok = sorted((f for f in th.requirement_fixes if f.meets and f.change != "as flown"),
                key=lambda f: (f.steps_per_s, -f.gain_margin_db))
    if th.requirement_fixes and th.requirement_fixes[0].meets:
        return "none needed: every mode meets the requirement as flown"
    if not ok:
        return "no single change of the step, the integrator or the damping gains meets it"
    f = ok[0]
    pm = "" if f.phase_margin_deg is None else f", {f.phase_margin_deg:.3g}°"
    return (f"{f.change} (least margins {f.gain_margin_db:.3g} dB{pm}, "
            f"{1e3 * f.delay_margin_s:.3g} ms, {f.worst_mode}; {f.steps_per_s:.4g} steps per "
            f"second)")


def verdict(run: CompleteRecord, other: CompleteRecord) -> Verdict:
    """The headline, from the modes of the loop as flown judged one by one (eqs. 35, 36),
    marked where either run left a joint range (eq. 42)."""
    v = _verdict(run, other)
    mark = (range_mark(run.spec_name, run.joint_ranges)
            + range_mark(other.spec_name, other.joint_ranges))
    return Verdict(v.kind, v.headline + mark) if mark else v


def _verdict(run: CompleteRecord, other: CompleteRecord) -> Verdict:
    th, p = run.theory, run.prediction
    unstable = [m for m in th.modes if m.rings]
    if p.theory_consistent is False:
        return Verdict("inconclusive", "The damping modes' loops and the map of the loop as "
                       f"flown disagree on its stability (spectral radius "
                       f"{th.spectral_radius:.4g}; eq. 34 keeps the stiffness the modes drop): "
                       "the modes cannot say which must ring.")
    if p.agrees is None:
        return Verdict("inconclusive", f"Undetermined: {p.undetermined_why}.")
    if not p.agrees:
        wrong = [j.mode for j in p.modes if j.agrees is False]
        return Verdict("inconclusive", "Theory and data disagree mode by mode"
                       + (f" ({', '.join(wrong)})" if wrong else
                          " (the modes' loops against the map of eq. 34)") + ".")
    if unstable:
        causal = other.prediction
        test = ("; the causal run cannot judge it: " + str(causal.undetermined_why) + "."
                if causal.agrees is None else
                "; the causal test removes it." if (
                    causal.agrees and not any(m.rings for m in other.theory.modes)) else
                "; the causal test does not remove it.")
        return Verdict("ripple", f"Unstable as flown ({th.update_order}, dt = {run.dt:g} s, "
                       f"{run.integrator}): {ringing_words(run)}; theory and data agree mode "
                       f"by mode" + test)
    if run.integrator == "imex":
        return Verdict("fix", "The implicit damping (imex) keeps every mode stable at the same "
                       "step and gains; theory and data agree mode by mode.")
    return Verdict("stable", "Every mode stable as flown and quiet in the data.")


def versions(rec: AnalysisRecord) -> str:
    """The Python and numerical-library versions a record's log was made with, in one line."""
    v = getattr(rec, "versions", None) or {}
    return ", ".join(f"{k} {v[k]}" for k in sorted(v)) or "not recorded"


def robot_card(rec: AnalysisRecord) -> dict:
    """The record's robot card with the bus inertia's diagonal, as the templates show it."""
    card = asdict(rec.robot)
    card["bus_inertia_diag"] = np.diag(np.array(card["bus_inertia"])).tolist()
    return card


# The harm table of section 7 (eqs. 30–32): label, unit, the record's value, and the field
# naming the channel it was measured on (or None).
HARM_ROWS = (
    ("max z_b pointing error", "deg", ("metrics", "pointing_err_deg_max"), None),
    ("final coverage", "", ("metrics", "coverage_final"), None),
    ("bus torque, RMS of ‖τ_b‖", "N·m", ("harm", "bus_torque", "rms"), None),
    ("bus torque, period-2 amplitude", "N·m", ("harm", "bus_torque", "period2_amplitude"),
     ("harm", "bus_torque", "channel")),
    ("bus torque, short-period peak to peak (eq. 30b)", "N·m",
     ("harm", "bus_torque", "short_period_peak_to_peak"),
     ("harm", "bus_torque", "short_period_channel")),
    ("bus torque, reversal share", "", ("harm", "bus_torque", "reversal_share"),
     ("harm", "bus_torque", "channel")),
    ("bus torque, reversals per second", "1/s", ("harm", "bus_torque", "reversals_per_s"),
     ("harm", "bus_torque", "channel")),
    ("joint torque, period-2 amplitude", "N·m", ("harm", "joint_torque", "period2_amplitude"),
     ("harm", "joint_torque", "channel")),
    ("joint torque, reversal share", "", ("harm", "joint_torque", "reversal_share"),
     ("harm", "joint_torque", "channel")),
    ("joint rate, period-2 amplitude", "rad/s", ("harm", "joint_rate", "period2_amplitude"),
     ("harm", "joint_rate", "channel")),
    ("joint rate, reversal share", "", ("harm", "joint_rate", "reversal_share"),
     ("harm", "joint_rate", "channel")),
    ("bus attitude jitter", "deg", ("harm", "attitude", "jitter_deg"), None),
    ("… at the control instants", "deg", ("harm", "attitude", "at_instants_deg"), None),
    ("… between them", "deg", ("harm", "attitude", "between_instants_deg"), None),
    ("bus attitude, short-period peak to peak (eq. 30b: at the instants, plus twice the "
     "largest excursion between them)", "deg",
     ("harm", "attitude", "short_period_peak_to_peak_deg"), None),
)


def harm_table(rec: CompleteRecord, other: CompleteRecord) -> list[dict]:
    """Section 7's rows for the pair: each quantity of ``HARM_ROWS``, formatted, with the
    channel it was measured on."""
    def cell(r: CompleteRecord, path, channel) -> str:
        value = num(value_at(r, path))
        where = value_at(r, channel) if channel else None
        return f"{value} ({where})" if where is not None else value

    return [{"quantity": f"{label} ({unit})" if unit else label,
             "a": cell(rec, path, channel), "b": cell(other, path, channel)}
            for label, unit, path, channel in HARM_ROWS]


def note_records(rec: CompleteRecord, other: CompleteRecord, others: list[RunData]
                 ) -> dict[str, CompleteRecord]:
    """The seed note's table's records (its columns: today's nominal and dt010, then the
    note's regime, issue 50) when this pair is the note's own (its runs), else {}."""
    note = load_note(NOTE_FILE)
    if (rec.spec_name, other.spec_name) != (note.runs["nominal"], note.runs["dt010"]):
        return {}
    by_spec = {o.record.spec_name: o.record for o in others
               if isinstance(o.record, CompleteRecord)}
    regime = {col: by_spec[spec] for col, spec in note.regime_runs.items() if spec in by_spec}
    return {"nominal": rec, "dt010": other, **regime}


def note_rows(records: dict[str, CompleteRecord], claims: dict | None = None) -> list:
    """The seed note's table beside ``records`` (note_records), judged by the register's
    ``claims`` (claims.json) when given."""
    if not records:
        return []
    return note_table(load_note(NOTE_FILE), records, claims["claims"] if claims else None)


# The rows of the orbit's quantities, in the evidence table (stage 7's) and the harm table.
ORBIT_ROWS = ("max pointing error (deg)", "final coverage", "max z_b pointing error (deg)")


def _orbit_marked(rows: list[dict], same: bool) -> list[dict]:
    """The rows, the orbit's quantities marked where the pair flew different missions."""
    return [{**r, "quantity": f"{r['quantity']} (another mission: not compared)"}
            if not same and r["quantity"] in ORBIT_ROWS else r for r in rows]


def mechanism_context(run: RunData, others: list[RunData], claims: dict | None = None) -> dict:
    """Everything the mechanism templates show, for ``run`` and its comparison; ``claims``
    (claims.json) judges the seed note's table."""
    rec = run.record
    comp = rec.comparison
    other = comp.other
    th = rec.theory
    names = (rec.spec_name, other.spec_name)
    differs = comp.mission_differs
    same = same_mission(rec, other, differs)
    rows = _orbit_marked([{"quantity": r["quantity"], "a": r[names[0]], "b": r[names[1]]}
                          for r in comp.table], same)
    flipped = sum(d.lag1 is not None and d.lag1 > LAG1_SMOOTH for d in other.directions)
    limits = sorted(((k, v) for k, v in rec.metrics.limit_share.items() if v > 0),
                    key=lambda kv: -kv[1])
    note_recs = note_records(rec, other, others)
    table = note_rows(note_recs, claims)
    # The implicit-damping runs of this robot on this loop (plant and delay) at this step.
    def loop(r: RunData) -> tuple:
        th_r = r.record.theory
        return (r.spec.get("robot", {}).get("file"), th_r.plant, th_r.delay_steps)

    fixes = [o for o in others if isinstance(o.record, CompleteRecord)
             and o.record.integrator == "imex" and o.record.dt == rec.dt
             and o.name != run.name and loop(o) == loop(run)]
    return {
        "run": run, "rec": rec, "other": other, "comp": comp, "th": th, "names": names,
        "rows": rows, "verdict": verdict(rec, other), "mode": damping_mode(th),
        "other_mode": damping_mode(other.theory), "limits": limits,
        "flipped": flipped, "n_directions": len(other.directions),
        "same_mission": same, "differs": differs, "same_length": same_duration(rec, other),
        "seconds": (rec.n_steps * rec.dt, other.n_steps * other.dt),
        "fix_runs": fixes, "diag_D": np.diag(np.array(th.D_breve)).tolist(),
        "lag1_smooth": LAG1_SMOOTH, "ringing": ringing_words(rec),
        "card": robot_card(rec), "robot_file": str(run.spec.get("robot", {}).get("file", "?")),
        "modes": th.modes, "prediction": rec.prediction, "requirement": th.requirement,
        "severity": severity(rec, run.spec), "recommended": recommended(th),
        "ranges": [(r.spec_name, excursion_words(r.joint_ranges)) for r in (rec, other)],
        "plant_words": th.update_order,
        "note_rows": table,
        "note_regimes": column_regimes(note_recs), "note_differences": differences(table),
        "fmt": fmt, "versions": versions,
        "harm_rows": _orbit_marked(harm_table(rec, other), same),
        # The pair's start-up and spectrum figures are drawn when both logs are there.
        "startup": against_log(run) is not None,
    }
