"""Verdicts on the loop as flown (issue 32): the map of the loop that ran (eq. 34), each damping
mode's margins (eq. 35) against python-control, what rings in the data (eq. 36) and the modes
judged one by one, including a log whose wrong mode rings.

Known answers come from elsewhere: python-control's stability margins and closed-loop poles
for eq. 35, the simulator's own step for eq. 34 (the cross-check's finite differences, here on
a real log's analysis), synthetic series for eq. 36, and a log that another controller flew
for the judgement.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.analysis import margins as mg
from pipeline.analysis.ringing import MIN_STEPS, ring
from pipeline.analysis.stages import analyze_log
from pipeline.errors import SpecError
from pipeline.importer.mapping import load_mapping
from pipeline.importer.run import import_log
from pipeline.logs import verify_log
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides
from pipeline.store.door import ArtefactStore

control = pytest.importorskip("control")

REQ = mg.Requirement(6.0, 30.0, 1.0)
ROLL = "camera roll ω_e,z (about the boresight)"
YAW = "bus yaw ω_b,z"

# The seed robot's two fast modes (robot card, eq. 21): μ_bus = 2/0.015625, μ_roll = 1/0.023413.
MU = {"bus yaw": 128.0, "camera roll": 42.71}


def _loop(g: float, d: int, dt: float):
    """python-control's L(z) = g z^−d/(z − 1) at sample time dt."""
    return control.tf([g], np.r_[1.0, -1.0, np.zeros(d)], dt)


def _closed_loop_radius(plant, k: float = 1.0) -> float:
    return float(np.max(np.abs(control.poles(control.feedback(k * plant, 1)))))


@pytest.mark.parametrize("mode", sorted(MU))
@pytest.mark.parametrize("dt", [0.03, 0.01])
@pytest.mark.parametrize("delay", [0, 1])
@pytest.mark.parametrize("integrator", ["explicit", "imex"])
def test_margins_against_python_control(mode, dt, delay, integrator):
    """Gain and phase margins as python-control's stability_margins gives them (where its
    phase crossover lies inside the band: with no delay it is at the Nyquist frequency, which
    it does not report; there the closed loop at g·GM, python-control's poles, is on the unit
    circle); the delay margin: python-control's closed-loop poles of the loop with that much
    more delay (eq. 35's held command, as a transfer function) are on the unit circle, inside
    at 0.99 of it and outside at 1.01."""
    g = mg.loop_gain(dt * MU[mode], integrator)
    m = mg.margins(g, delay, dt, REQ)
    L = _loop(g, delay, dt)
    with warnings.catch_warnings():  # it evaluates L at z = 1, the integrator's pole
        warnings.simplefilter("ignore", RuntimeWarning)
        gm, pm, _, wpc, wgc, _ = control.stability_margins(L)
    gm_factor = 10 ** (m.gain_margin_db / 20)
    assert _closed_loop_radius(L, gm_factor) == pytest.approx(1.0, abs=1e-9)
    if delay:
        assert 20 * math.log10(gm) == pytest.approx(m.gain_margin_db, abs=1e-9)
        assert wpc * dt == pytest.approx(m.phase_crossover, rel=1e-9)
    if m.phase_margin_deg is None:
        assert g > 2
        return
    assert pm == pytest.approx(m.phase_margin_deg, abs=1e-7)
    assert wgc * dt == pytest.approx(m.gain_crossover, rel=1e-9)
    if m.delay_margin_s == 0.0:  # unstable as flown
        assert _closed_loop_radius(L) > 1.0
        return
    assert not m.delay_margin_beyond

    def radius_at(extra_s: float) -> float:
        total = delay + extra_s / dt
        n, frac = math.floor(total), total - math.floor(total)
        held = control.tf(g * np.array([1 - frac, frac]), np.r_[1.0, -1.0, np.zeros(n + 1)],
                          dt)
        return _closed_loop_radius(held)

    assert radius_at(0.99 * m.delay_margin_s) < 1.0 < radius_at(1.01 * m.delay_margin_s)


def test_the_seeds_margins_in_numbers():
    """The issue's figures: the bus yaw at dt 0.03 s fails by −5.67 dB; at 0.01 s it passes
    the phase (50.2°) but not the gain (3.88 dB) or the delay margin (7.81 ms, dt/g exactly);
    one step of delay makes it unstable (roots of modulus √1.28 = 1.131); imex with one step
    of delay at 0.03 s keeps it stable with 2.0 dB."""
    def m(dt, d, integ="explicit", mode="bus yaw"):
        return mg.margins(mg.loop_gain(dt * MU[mode], integ), d, dt, REQ)

    assert m(0.03, 0).gain_margin_db == pytest.approx(20 * math.log10(2 / 3.84))
    dt010 = m(0.01, 0)
    assert dt010.gain_margin_db == pytest.approx(3.876, abs=1e-3) and not dt010.meets_gain
    assert dt010.phase_margin_deg == pytest.approx(50.21, abs=1e-2) and dt010.meets_phase
    assert dt010.delay_margin_s == pytest.approx(0.01 / 1.28, rel=1e-6)
    assert abs(mg.dominant_root(1.28, 1)) == pytest.approx(math.sqrt(1.28), rel=1e-12)
    late = m(0.03, 1, "imex")
    assert late.gain_margin_db == pytest.approx(20 * math.log10(1 / (3.84 / 4.84)), rel=1e-9)
    assert not late.meets and abs(mg.dominant_root(3.84 / 4.84, 1)) < 1


# -- eq. 36: what rings --------------------------------------------------------------------

def test_ring_reads_a_held_six_step_cycle_and_refuses_to_judge_short_or_still_series():
    k = np.arange(1000, dtype=float)
    # The relay cycle of one step of delay: 0.5, −0.5, −1.5, −0.5, 0.5, 1.5 (× dt·a_max).
    cycle = np.resize([0.5, -0.5, -1.5, -0.5, 0.5, 1.5], k.size) * 0.3
    r = ring(cycle + 0.01 * np.sin(2 * np.pi * k / 900), "x", "rad/s")
    assert r.rings and r.period_steps == pytest.approx(6.0, rel=1e-3)
    assert r.peak_to_peak == pytest.approx(0.9, rel=1e-3)
    short = ring(cycle[:MIN_STEPS - 1], "x", "rad/s")
    assert short.rings is None and short.period_steps is None
    still = ring(np.full(1000, 0.2), "x", "rad/s")
    assert still.rings is None


def test_a_reduced_plant_is_refused_a_field_only_the_sampled_plant_reads():
    for field, value in (("delay_steps", 1), ("bus_torque_max", 5.0), ("substeps", 4)):
        with pytest.raises(SpecError, match=f"{field} is read only by the sampled plant"):
            with_overrides(load_spec("short_nominal"), {f"mission.plant.{field}": value})


# -- eq. 34 on real logs, and the judgement ---------------------------------------------

@pytest.fixture(scope="module")
def delayed(tmp_path_factory):
    """The short delayed runs at dt 0.03 and 0.01 s, analysed."""
    out = tmp_path_factory.mktemp("delayed")
    recs = {}
    for name in ("short_omega_ripple_sampled_delay", "short_omega_ripple_sampled_delay_dt010"):
        o = run_spec(load_spec(name), out)
        recs[name] = analyze_log(verify_log(o.path))
    return recs


def test_a_delayed_run_reads_the_delayed_map_and_names_what_rings(delayed):
    """At dt 0.01 s the undelayed loop is stable, the delayed one is not: the record's
    spectral radius is the delayed map's (near √1.28 = 1.131, the stiffness adding a little),
    never the undelayed 0.996; at 0.03 s the camera roll rings beside the bus yaw, both
    predicted, over the relay's six steps."""
    th = delayed["short_omega_ripple_sampled_delay_dt010"].theory
    assert th.plant == "sampled" and th.delay_steps == 1
    assert th.spectral_radius == pytest.approx(1.135, abs=0.01)
    assert th.spectral_radius > 1 and th.regime.startswith("unstable: oscillation")
    assert len(th.maps.explicit.eigenvalues.real) == 27
    rec = delayed["short_omega_ripple_sampled_delay"]
    modes = {j.mode: j for j in rec.prediction.modes}
    assert modes[YAW].predicted_rings and modes[YAW].measured.rings
    assert modes[ROLL].predicted_rings and modes[ROLL].measured.rings
    assert modes[ROLL].driven_by is None
    for name in (YAW, ROLL):
        assert modes[name].measured.period_steps == pytest.approx(6.0, rel=0.01)
    assert modes[YAW].held_by.limit == "omega_b_acc"
    assert rec.prediction.agrees


@pytest.fixture(scope="module")
def roll_rings(tmp_path_factory):
    """A log another controller flew: the seed robot at dt 0.03 s with a soft bus gain (the bus
    yaw stable, dt·μ 0.96) and a stiff camera-orientation gain (the roll unstable, dt·μ 2.56),
    cut to t, q and v and imported."""
    out = tmp_path_factory.mktemp("roll_rings")
    spec = with_overrides(load_spec("short_nominal"), {
        "mission.duration": 15.0, "controller.gains.bus.D": 0.5,
        "controller.gains.cam_ori.D": 2.0}, name="roll_rings")
    o = run_spec(spec, out / "logs")
    log = verify_log(o.path)
    own = analyze_log(log)
    cols = log.columns(["t", "q", "v"])
    src = out / "roll_rings.parquet"
    pq.write_table(pa.table({"t": cols["t"], "q": list(cols["q"]), "v": list(cols["v"])}), src)
    done = import_log(src, load_mapping(None, {"robot": "short_nominal"}), "roll_rings",
                      out / "logs")
    return own, done.path, out, spec


def test_the_wrong_mode_ringing_reads_disagree(roll_rings):
    """Declared with the nominal controller (the bus yaw predicted to ring, the roll stable),
    the log where the roll rings and the bus yaw does not reads DISAGREE, on both modes; its
    own analysis agrees. (The old yes/no judgement said "period-2 predicted, measured:
    agree": the roll's period-2 made the dominant lag-1 negative.)"""
    own, path, out, _ = roll_rings
    assert own.prediction.agrees
    store = ArtefactStore(path.parents[2], out / "rep")
    rec = store.analysis(store.open_log(path), quiet=True,
                         controller=with_overrides(load_spec("short_nominal"),
                                                   {"mission.duration": 15.0})).record
    assert rec.dominant.lag1 < 0  # what the old rule judged on
    modes = {j.mode: j for j in rec.prediction.modes}
    assert modes[YAW].predicted_rings and modes[YAW].measured.rings is False
    assert not modes[ROLL].predicted_rings and modes[ROLL].measured.rings
    assert modes[YAW].agrees is False and modes[ROLL].agrees is False
    assert rec.prediction.agrees is False


def test_nothing_is_called_a_fix_that_misses_the_requirement(delayed, tmp_path):
    """The fix table's verdicts: the delayed run rings (unstable); the implicit damping with
    one step of delay, stable and quiet in every mode, misses the requirement (its bus yaw's
    gain margin is 2.0 dB) and is not called a fix; the smaller step that meets it is."""
    from pipeline.reports.figures import RunData
    from pipeline.reports.fixes import FIX, decisions, fix_tables

    runs = []
    for name in ("omega_ripple_sampled_delay_imex", "omega_ripple_sampled_delay_dt0035"):
        o = run_spec(with_overrides(load_spec(name), {"mission.duration": 12.0}, name=name),
                     tmp_path)
        log = verify_log(o.path)
        runs.append(RunData(name, analyze_log(log), log, log.meta.spec, name))
    log = verify_log(delayed["short_omega_ripple_sampled_delay"].log)
    runs.append(RunData("delayed", delayed["short_omega_ripple_sampled_delay"], log,
                        log.meta.spec, "delayed"))
    (table,) = fix_tables(runs)
    verdict = {r.run: r.verdict for r in table.rows}
    assert verdict["delayed"].startswith("unstable")
    assert verdict["omega_ripple_sampled_delay_imex"].startswith(
        "stable and quiet, misses the requirement")
    assert verdict["omega_ripple_sampled_delay_dt0035"] == FIX
    (d,) = decisions(runs)
    assert "omega_ripple_sampled_delay_dt0035" in d.fix and "not a fix" in d.fix
    assert d.verdict.startswith("robots/seed_ur3_box.xml: on sampled-data plant")
