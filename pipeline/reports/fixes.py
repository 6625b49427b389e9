"""The fix tables (issue 32): per robot and loop as flown (plant and delay), every analysed run,
what flew (step, integrator, damping gains), whether every mode meets the spec's requirement
(eq. 35), what rings in the data (eq. 36) and the cost; a run is called a fix only where every
mode meets the requirement on the loop it declares, the data ring in no mode, the theory and
data agree mode by mode and the arm stayed above the damped inverse's floor over the window
(where the theory holds). Every cell is read from the runs' analysis records.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.analysis.confidence import samples_needed, samples_to_show
from pipeline.analysis.joint_ranges import range_mark, range_words
from pipeline.analysis.schema import CompleteRecord
from pipeline.montecarlo.plan import Target
from pipeline.montecarlo.verdict import MonteCarloVerdict, loop_key
from pipeline.reports.figures import RunData

FIX = "fix"
# A loop that meets the requirement on a trajectory off the arm's joint ranges (eq. 42): its
# verdict starts so, and the decision box reads it by this prefix.
OFF_RANGE = "meets the requirement, but "


@dataclass(frozen=True)
class FixRow:
    run: str
    dt: float
    integrator: str
    gains: str  # the damping gains D of the bus and camera-orientation blocks
    fastest: str  # the fastest mode's symbol
    fastest_mu: float  # its rate μ (1/s), the mode's bandwidth
    fastest_zeta: float | None  # its damping ratio under the block stiffness
    meets: bool  # every mode meets the requirement, on this loop
    least: str  # the mode of least gain margin
    gain_margin_db: float
    phase_margin_deg: float | None
    delay_margin_ms: float
    rings: str  # the modes that ring of their own in the data ("" none)
    agrees: bool | None  # None: undetermined (eq. 36)
    pointing_err_deg_max: float
    boresight_err_deg_max: float
    steps_per_s: float
    below_floor: int  # window steps with σ_min(J⊕) below the damped inverse's floor
    window_steps: int
    verdict: str


@dataclass(frozen=True)
class FixTable:
    robot: str
    loop: str
    requirement: str
    rows: list[FixRow]

    @property
    def fixes(self) -> list[FixRow]:
        return [r for r in self.rows if r.verdict == FIX]


def agreement_words(p) -> str:
    """How theory and data compare mode by mode for a ``Prediction`` (eq. 36), in words."""
    if p.agrees is None:
        return f"cannot be compared mode by mode: {p.undetermined_why}"
    return "agree mode by mode" if p.agrees else "DISAGREE mode by mode"


def _verdict(meets: bool, rings: list[str], agrees: bool | None, least: str, gm: float,
             below_floor: int, window_steps: int, left_range: str = "",
             undetermined_why: str | None = None) -> str:
    # The theory (eqs. 21, 34, 35) is the loop's linearisation above the damped inverse's
    # floor; a run that spends window steps below it flew another loop there, so neither its
    # margins nor its agreement speak for those steps: no verdict, least of all "fix".
    if below_floor:
        return (f"not judged: below the damped inverse's floor on {below_floor} of "
                f"{window_steps} window steps, where the theory does not hold")
    if agrees is None:
        return f"undetermined: {undetermined_why}"
    if not agrees:
        return "theory and data disagree"
    if rings:
        return f"unstable: {', '.join(rings)} ring"
    if not meets:
        return f"stable and quiet, misses the requirement ({least}: {gm:.3g} dB)"
    # A loop that meets the requirement on a trajectory the arm cannot fly (eq. 42) is no fix
    # for the arm: it would be flown another way.
    if left_range:
        return f"{OFF_RANGE}{left_range}"
    return FIX


def fix_row(r: RunData) -> FixRow:
    rec: CompleteRecord = r.record
    th, p = rec.theory, rec.prediction
    least = min(th.modes, key=lambda m: m.margins.gain_margin_db)
    rings = [j.symbol for j in p.modes if j.measured.rings and not j.driven_by]
    meets = all(m.margins.meets for m in th.modes)
    gains = r.spec.get("controller", {}).get("gains", {})
    fast = th.modes[0]
    below = int(th.window_steps_below_floor)
    steps = int(rec.window.stop_step - rec.window.start_step)
    return FixRow(
        run=r.name, dt=rec.dt, integrator=rec.integrator,
        gains=f"bus {gains.get('bus', {}).get('D', '?')}, "
              f"cam_ori {gains.get('cam_ori', {}).get('D', '?')}",
        fastest=fast.symbol, fastest_mu=fast.mu, fastest_zeta=fast.damping_ratio,
        meets=meets, least=least.symbol, gain_margin_db=least.margins.gain_margin_db,
        phase_margin_deg=least.margins.phase_margin_deg,
        delay_margin_ms=1e3 * least.margins.delay_margin_s, rings=", ".join(rings),
        agrees=p.agrees, pointing_err_deg_max=rec.metrics.pointing_err_deg_max,
        boresight_err_deg_max=rec.metrics.boresight_err_deg_max, steps_per_s=1.0 / rec.dt,
        below_floor=below, window_steps=steps,
        verdict=_verdict(meets, rings, p.agrees, least.symbol, least.margins.gain_margin_db,
                         below, steps, range_words(rec.joint_ranges), p.undetermined_why))


def _loop_words(plant: str, delay: int) -> str:
    if plant == "reduced":
        return "the simulator's update (eq. 22)"
    late = f", {delay} step of delay" if delay else ", no delay"
    return f"sampled-data plant, command held over the step{late} (eq. 34)"


def fix_tables(runs: list[RunData]) -> list[FixTable]:
    """One table per robot file and loop as flown, the runs by cost (steps per second)."""
    groups: dict[tuple, list[RunData]] = {}
    for r in runs:
        if not isinstance(r.record, CompleteRecord):
            continue
        th = r.record.theory
        robot = str(r.spec.get("robot", {}).get("file", "?"))
        groups.setdefault((robot, th.plant != "reduced", th.delay_steps, th.plant), []).append(r)
    tables = []
    for (robot, _, delay, plant), members in sorted(groups.items()):
        req = members[0].record.theory.requirement
        rows = sorted((fix_row(r) for r in members), key=lambda x: (x.steps_per_s, x.run))
        tables.append(FixTable(
            robot=robot, loop=_loop_words(plant, delay),
            requirement=(f"GM ≥ {req.gain_margin_db:g} dB, PM ≥ {req.phase_margin_deg:g}°, "
                         f"DM ≥ {req.delay_margin_steps:g} step"), rows=rows))
    return tables


@dataclass(frozen=True)
class Decision:
    """What the index opens with, per robot (issue 32): the verdict on its loop of record,
    the severity in mission units, the recommended fix with its margin and cost."""

    robot: str
    verdict: str
    severity: str | None
    fix: str | None


def _loop_of_record(tables: list[FixTable], runs: dict[str, RunData]) -> FixTable:
    """The loop a flight computer flies, of those the robot's runs cover: the sampled-data
    plant with the most delay, else the sampled plant, else the simulator's update."""
    def rank(t: FixTable) -> tuple:
        th = runs[t.rows[0].run].record.theory
        return (th.plant == "sampled", th.delay_steps)

    return max(tables, key=rank)


def severity(rec: CompleteRecord, spec: dict) -> str:
    """What the ripple harms in mission units (eqs. 30–32): torque reversals, attitude
    jitter, the camera roll's smear."""
    h, c = rec.harm, rec.camera_roll
    limit = float(spec.get("mission", {}).get("plant", {}).get("bus_torque_max", 0.0) or 0.0)
    against = (f"against its {limit:g} N·m limit" if limit > 0 else
               "no bus torque limit declared (mission.plant.bus_torque_max)")
    smear = ("" if c.smear_px is None else
             f"; camera roll smear {c.smear_px:.3g} px at the image corner "
             f"({c.resolution_px} px, {c.fov_deg:g}° field of view)")
    # The short-period peak to peak (eq. 30b) sees a cycle of any period the ring detector
    # judges; the period-2 figures, amplitudes, a delayed loop's longer cycle only in part.
    bt, at = h.bus_torque, h.attitude
    torque_pp = ("" if bt.short_period_peak_to_peak is None else
                 f"; over the short periods {bt.short_period_peak_to_peak:.3g} N·m peak to peak "
                 f"about {bt.short_period_channel}")
    attitude_pp = ("" if at.short_period_peak_to_peak_deg is None else
                   f"; over the short periods {at.short_period_peak_to_peak_deg:.3g}° peak to "
                   f"peak")
    return (f"the bus torque reverses {bt.reversals_per_s:.3g} times a second about "
            f"{bt.channel} at a period-2 amplitude of {bt.period2_amplitude:.3g} N·m"
            f"{torque_pp} ({against}); the bus attitude's period-2 jitter (amplitude) "
            f"{at.jitter_deg:.3g}°{attitude_pp}{smear}")


def _change(a: RunData, b: RunData) -> str:
    """What run ``b`` changes from run ``a``: step, integrator, damping gains."""
    ra, rb = a.record, b.record
    parts = []
    if ra.dt != rb.dt:
        parts.append(f"dt {ra.dt:g} → {rb.dt:g} s")
    if ra.integrator != rb.integrator:
        parts.append(f"{rb.integrator} integrator")
    ga = a.spec.get("controller", {}).get("gains", {})
    gb = b.spec.get("controller", {}).get("gains", {})
    cuts = [f"{k}.D {ga[k]['D']:g} → {gb[k]['D']:g}" for k in ("bus", "cam_pos", "cam_ori")
            if k in ga and k in gb and ga[k].get("D") != gb[k].get("D")]
    if cuts:
        fa, fb = ra.theory.modes[0], rb.theory.modes[0]
        zeta = (f", ζ {fa.damping_ratio:.3g} → {fb.damping_ratio:.3g}"
                if fa.damping_ratio is not None and fb.damping_ratio is not None else "")
        parts.append(f"damping {', '.join(cuts)} (fastest mode's μ {fa.mu:.3g} → "
                     f"{fb.mu:.3g} 1/s{zeta})")
    return "; ".join(parts) or "the same loop"


def across_dispersions(spec: dict, studies: list[MonteCarloVerdict]) -> tuple[bool, str]:
    """(shown, words): what the current Monte Carlos of a run's loop (``loop_key``) show of
    it across the dispersions (eq. 38). Shown only by a study whose verdict shows its target;
    otherwise what the best study shows and what it lacks (the samples that would show the
    target with no more failing, or the gain margin its worst sample misses), or that none
    flies this loop and how many samples, none failing, would show the default target."""
    key = loop_key(spec) if spec else ""
    # A study that does not show it speaks first: two studies of one nominal loop may disperse
    # it differently (a whole step of delay, a latency within the step), and the loop must
    # hold under each.
    mine = sorted((v for v in studies if key and v.nominal_loop == key),
                  key=lambda v: (v.shown is not True, v.failures, v.samples), reverse=True)
    if not mine:
        t = Target()
        return False, (f"no current Monte Carlo flies this loop across the dispersions: "
                       f"{samples_needed(t.p, t.confidence)} samples, none failing, would "
                       f"show p ≥ {t.p:g} at {100 * t.confidence:g} % confidence (eq. 38b)")
    v = mine[0]
    if v.shown is True:
        return True, ("shown across the dispersions by "
                      + "; by ".join(f"{x.name}: {x.statement}" for x in mine))
    if v.shown is None:
        return False, f"{v.name}, a Monte Carlo of this loop, has no verdict: {v.statement}"
    more = samples_to_show(v.failures, v.target_p, v.confidence)
    lack = (f"{more - v.samples} more samples, none of them failing, would show it"
            if v.failures == 0 else
            f"it would take {more} samples with no more than {v.failures} failing")
    worst = v.worst[0] if v.worst and not v.worst[0].passes else None
    short = v.requirement.gain_margin_db - worst.gain_margin_db if worst else 0.0
    if worst is not None and short > 0:
        lack += (f", or {short:.3g} dB more gain margin on its worst sample ({worst.index}: "
                 f"{worst.gain_margin_db:.3g} dB against {v.requirement.gain_margin_db:g} dB)")
    shown_by = [x.name for x in mine if x.shown is True]
    return False, (f"across the dispersions {v.name} does not show it: {v.statement}; {lack}"
                   + (f" (shown by {', '.join(shown_by)}, under other dispersions)"
                      if shown_by else ""))


def decisions(runs: list[RunData], studies: list[MonteCarloVerdict] = ()) -> list[Decision]:
    """Per robot, on its loop of record: the cheapest run that rings, what harms, and the
    cheapest flown fix (fewest steps per second, then the larger gain margin). The fix is
    named "Fix" only where a current Monte Carlo of its loop (``studies``: the current
    verdicts) shows the target across the dispersions; otherwise it is a candidate, with what
    it shows and what it lacks (:func:`across_dispersions`)."""
    by_name = {r.name: r for r in runs}
    out = []
    tables = fix_tables(runs)
    for robot in dict.fromkeys(t.robot for t in tables):
        t = _loop_of_record([x for x in tables if x.robot == robot], by_name)
        bad = next((r for r in t.rows if r.rings), None)
        if bad is None:
            # A run the data cannot judge (too short a window, a still robot) rings nowhere
            # that anyone saw: say so, not "no run rings".
            unjudged = [r for r in t.rows if r.agrees is None]
            out.append(Decision(robot, f"{robot}: on {t.loop}, no run rings in any mode"
                                + ("".join(f"; {r.run} is {r.verdict}" for r in unjudged)
                                   if unjudged else "") + ".", None, None))
            continue
        rec = by_name[bad.run].record
        ringing = [(m, j) for m, j in zip(rec.theory.modes, rec.prediction.modes, strict=True)
                   if j.measured.rings and not j.driven_by]
        # A limit is named only for the cycle it holds (HeldBy.explains), as the modes' table.
        held = {j.held_by.limit for _, j in ringing if j.held_by and j.held_by.explains}
        verdict = (f"{robot}: on {t.loop}, {bad.run} (dt {bad.dt:g} s, {bad.integrator}) is "
                   f"unstable: " + ", ".join(f"{m.symbol} (|z| {m.modulus:.3g})"
                                             for m, _ in ringing)
                   + f" ring over {ringing[0][1].measured.period_steps:.3g} steps"
                   + (f", held by {', '.join(sorted(held))}" if held else "")
                   + f"; theory and data {agreement_words(rec.prediction)}."
                   + range_mark(bad.run, rec.joint_ranges))
        fixes = sorted(t.fixes, key=lambda r: (r.steps_per_s, -r.gain_margin_db))
        if fixes:
            # The cheapest a study shows, else the cheapest, a candidate.
            judged = [(f, *across_dispersions(by_name[f.run].spec, list(studies)))
                      for f in fixes]
            f, shown, study = next((j for j in judged if j[1]), judged[0])
            not_fix = [r for r in t.rows if r.verdict != FIX and not r.rings]
            fix = (("Fix: " if shown else "Candidate fix, not the fix until a study shows it: ")
                   + f"{f.run}, {_change(by_name[bad.run], by_name[f.run])}: every mode "
                   f"meets {t.requirement} on its nominal flight (least {f.least}: "
                   f"{f.gain_margin_db:.3g} dB, "
                   + (f"{f.phase_margin_deg:.3g}°, " if f.phase_margin_deg is not None else "")
                   + f"{f.delay_margin_ms:.3g} ms), flown clean, at {f.steps_per_s:.4g} steps "
                   f"per second ({f.steps_per_s / bad.steps_per_s:.3g}× {bad.run}'s)"
                   + f"; {study}"
                   + "".join(f"; not a fix: {r.run}, {r.verdict}" for r in not_fix) + "."
                   + range_mark(f.run, by_name[f.run].record.joint_ranges))
        else:
            off = [r.run for r in t.rows if r.verdict.startswith(OFF_RANGE)]
            fix = (f"No flown run of this loop meets {t.requirement}"
                   + (f" on a trajectory the arm can fly ({', '.join(off)} meet it off the "
                      f"joint ranges)" if off else "") + ": see the fix table.")
        out.append(Decision(robot, verdict, "Severity: " + severity(
            rec, by_name[bad.run].spec) + ".", fix))
    return out
