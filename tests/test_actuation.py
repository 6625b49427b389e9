"""The actuator outputs in the log (eq. 29) and the harm statistics on them (eqs. 30–32).

The commanded force is checked against Pinocchio's RNEA at the acceleration rebuilt from the
logged velocities with Γ̇ by finite differences; what the plant received against the plant's
rules (delay, torque limit); the harm statistics against synthetic signals of known answer
and against the closed form of a held torque.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from pipeline.analysis.harm import channel_harm, harm, period2_amplitude
from pipeline.sim.mission import Mission
from pipeline.spec import load_spec, with_overrides


def _steps(spec, n: int):
    """n consecutive (row, next state) of a mission from its start."""
    m = Mission(spec)
    s, out = m.initial_state(), []
    for _ in range(n):
        nxt, row = m.step(s)
        out.append((row, nxt))
        s = nxt
    return m, out


@pytest.mark.parametrize("name", ["nominal", "servicer_nominal"])
def test_the_commanded_force_is_the_rnea_of_the_commanded_velocity_change(name):
    """u_cmd = M a + C v with a = Γ⁻¹(ν̇ − Γ̇ v): against pin.rnea at a rebuilt with Γ from
    the logged q and Γ̇ v by central differences of Γ along v (h = 1e-6; measured 7.7e-9
    relative on the seed robot at step 40)."""
    spec = load_spec(name)
    m, steps = _steps(spec, 41)
    row, nxt = steps[-1]
    model = m.robot.model
    q, v = row["q"], row["v"]
    nu, nu_next = np.r_[row["v_c"], row["v_breve"]], np.r_[nxt.v_c, nxt.v_breve]

    def gamma(qq):
        return m.robot.gamma_matrices(qq[None])[0]

    h = 1e-6
    gamma_dot_v = (gamma(pin.integrate(model, q, v * h))
                   - gamma(pin.integrate(model, q, -v * h))) @ v / (2 * h)
    a = np.linalg.solve(gamma(q), (nu_next - nu) / spec.mission.dt - gamma_dot_v)
    ref = pin.rnea(model, model.createData(), q, v, a)
    assert np.max(np.abs(row["u_cmd"] - ref)) <= 1e-6 * np.max(np.abs(ref))
    # The update of eq. 15 applies the command as it is and turns the bus at a constant rate.
    assert np.array_equal(row["u_applied"], row["u_cmd"])
    assert row["attitude_excursion_deg"] == 0.0


def test_the_seed_robots_ripple_torque_is_the_acceleration_limit_through_the_bus_inertia():
    """In the nominal limit cycle ω_b,z moves by dt·a_max each step, so the bus torque about z_b
    alternates by ±I_zz,bus·a_max = 0.015625 × 10.005 = 0.1563 N·m about the slow feedback's
    (measured over steps 100–667: period-2 amplitude 0.15632, median |τ_z| 0.15629; during the
    growth, step 40: 0.1385)."""
    spec = with_overrides(load_spec("nominal"), {"mission.duration": 20.0})
    res = Mission(spec).run()
    tz = res.columns["u_applied"][100:, 5]
    i_zz = 0.015625
    a_max = spec.controller.limits.omega_b_acc
    assert np.all(tz[:-1] * tz[1:] < 0)  # it reverses on every step of the cycle
    assert period2_amplitude(tz) == pytest.approx(i_zz * a_max, rel=1e-3)


def test_the_sampled_plant_receives_the_delayed_and_limited_command():
    """delay_steps = 1: the plant receives the previous instant's command (before the first,
    C v: the force that holds v_0); bus_torque_max bounds ‖τ_b‖ and scales it alone."""
    spec = with_overrides(load_spec("omega_ripple_sampled"),
                          {"mission.duration": 0.3, "mission.plant.delay_steps": 1})
    m, steps = _steps(spec, 8)
    rows = [r for r, _ in steps]
    model = m.robot.model
    hold0 = pin.rnea(model, model.createData(), rows[0]["q"], rows[0]["v"], np.zeros(model.nv))
    assert np.allclose(rows[0]["u_applied"], hold0, rtol=0, atol=1e-12)
    for k in range(1, len(rows)):
        assert np.array_equal(rows[k]["u_applied"], rows[k - 1]["u_cmd"])

    bound = 0.05
    spec = with_overrides(load_spec("omega_ripple_sampled"),
                          {"mission.duration": 0.3, "mission.plant.bus_torque_max": bound})
    _, steps = _steps(spec, 8)
    bound_hit = 0
    for row, _ in steps:
        cmd, got = row["u_cmd"], row["u_applied"]
        n = np.linalg.norm(cmd[3:6])
        assert np.linalg.norm(got[3:6]) <= bound * (1 + 1e-12)
        assert np.array_equal(np.r_[got[:3], got[6:]], np.r_[cmd[:3], cmd[6:]])
        if n > bound:
            bound_hit += 1
            assert np.allclose(got[3:6], cmd[3:6] * bound / n, rtol=1e-14, atol=0)
    assert bound_hit > 0  # the test saw the limit bind


def test_the_sampled_plants_excursion_is_the_held_torques_ramp():
    """Under the held torque the bus's rate ramps over the step, and the attitude leaves the
    geodesic between the instants by |Δω| dt/8 (eq. 29) on the bus-yaw mode: measured against
    the logged ω_b,z of the sampled run's cycle."""
    spec = with_overrides(load_spec("omega_ripple_sampled"), {"mission.duration": 2.0})
    res = Mission(spec).run()
    c, dt = res.columns, spec.mission.dt
    wz = c["v"][:, 5]
    predicted = np.degrees(np.abs(np.diff(wz)) * dt / 8)[40:]
    measured = c["attitude_excursion_deg"][40:-1]
    assert np.allclose(measured, predicted, rtol=1e-3)


def test_channel_harm_reads_a_known_ripple():
    """An alternating ±0.156 on z over a slow sine on x: z is the channel, its amplitude 0.156,
    every step reverses (33.3 per second at dt 0.03); the slow sine alone reverses twice."""
    k = np.arange(600)
    x = np.c_[0.3 * np.sin(2 * np.pi * k / 600 + 0.1), np.zeros(600), 0.156 * (-1.0) ** k]
    got = channel_harm(x, 0.03, ("x_b", "y_b", "z_b"))
    assert got.channel == "z_b"
    assert got.period2_amplitude == pytest.approx(0.156, rel=1e-12)
    assert got.reversal_share == 1.0 and got.reversals_per_s == pytest.approx(1 / 0.03)
    slow = channel_harm(x[:, :1], 0.03, ("x_b",))
    assert slow.reversal_share == pytest.approx(2 / 599)


def test_attitude_jitter_adds_the_instants_and_the_excursion():
    """The simulator's zigzag (at the instants, amplitude A) and the held torque's arcs (between
    them, ε) both read as jitter: A + ε when both are present."""
    n, A, eps = 300, 0.00225, 0.06
    k = np.arange(n)
    quat = Rotation.from_rotvec(np.c_[np.zeros(n), np.zeros(n),
                                      0.001 * k + A * (-1.0) ** k]).as_quat()
    q = np.c_[np.zeros((n, 3)), quat, np.zeros((n, 6))]
    zeros = np.zeros((n, 12))
    zig = harm(zeros, zeros, q, np.zeros(n), 0.03).attitude
    assert zig.at_instants_deg == pytest.approx(np.degrees(A), rel=1e-9)
    assert zig.between_instants_deg == 0.0 and zig.jitter_deg == zig.at_instants_deg
    both = harm(zeros, zeros, q, np.full(n, eps), 0.03).attitude
    assert both.jitter_deg == pytest.approx(np.degrees(A) + eps, rel=1e-9)


def test_a_six_step_cycle_is_seen_whole_by_the_short_period_peak_to_peak():
    """A delayed loop's relay cycle over six steps, in the torque and in the bus attitude about
    a tilted axis on a slow turn: its period-2 amplitude reads a fraction of it, the
    short-period peak to peak (eq. 30b) reads √3 A, the peak to peak of A sin(2πk/6)."""
    n, A, T = 600, 0.004, 0.156
    k = np.arange(n)
    wave = np.sin(2 * np.pi * k / 6)
    axis = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    quat = Rotation.from_rotvec(np.outer(0.0005 * k + A * wave, axis)).as_quat()
    q = np.c_[np.zeros((n, 3)), quat, np.zeros((n, 6))]
    u = np.zeros((n, 12))
    u[:, 5] = T * wave + 0.01  # τ_b about z_b, on a bias
    u[:, 3] = 0.04 * (-1.0) ** k  # a small period-2 ripple about x_b
    h = harm(u, np.zeros((n, 12)), q, np.zeros(n), 0.03)
    # The period-2 figures pick x_b and read a fraction of the z_b cycle; eq. 30b finds it.
    assert h.bus_torque.channel == "x_b"
    assert h.bus_torque.short_period_channel == "z_b"
    assert h.bus_torque.short_period_peak_to_peak == pytest.approx(np.sqrt(3) * T, rel=1e-3)
    assert period2_amplitude(u[:, 5]) < 0.2 * T
    # The largest bus axis: the tilted axis' largest component carries that share of it.
    assert h.attitude.short_period_peak_to_peak_deg == pytest.approx(
        np.degrees(np.sqrt(3) * A * axis.max()), rel=1e-3)
    assert h.attitude.at_instants_deg < 0.2 * np.degrees(A)
    # A held torque's cycle between the instants (excursion ε, the instants still): 2ε.
    still = np.c_[np.zeros((n, 3)), Rotation.identity(n).as_quat(), np.zeros((n, 6))]
    arcs = harm(u, np.zeros((n, 12)), still, np.full(n, 0.05), 0.03).attitude
    assert arcs.short_period_peak_to_peak_deg == pytest.approx(0.1, abs=1e-12)
    # Too short a window for the band's filter: no figure rather than a wrong one.
    short = harm(u[:100], np.zeros((100, 12)), q[:100], np.zeros(100), 0.03)
    assert short.bus_torque.short_period_peak_to_peak is None
    assert short.bus_torque.short_period_channel is None
    assert short.attitude.short_period_peak_to_peak_deg is None


@pytest.mark.parametrize(("name", "mode"), [
    ("short_nominal", "bus yaw ω_b,z"),
    ("short_servicer_nominal", "camera roll ω_e,z (about the boresight)")])
def test_the_fastest_mode_is_named_along_the_whole_log(tmp_path, name, mode):
    """The analysis names the fastest damping mode at steps over the whole log (eq. 21): the
    seed robot's bus yaw, the servicer's camera roll, on every sampled step, with the largest
    dt·μ_max equal to the guard's logged maximum at those steps."""
    from pipeline.analysis.stages import fastest_modes_along
    from pipeline.logs import read_columns, verify_log
    from pipeline.sim.robot import GiordanoRobot
    from pipeline.sim.run import run_spec

    spec = with_overrides(load_spec(name), {"mission.duration": 3.0})
    path = run_spec(spec, tmp_path).path
    got = fastest_modes_along(GiordanoRobot(spec), spec, verify_log(path), samples=12)
    assert got.share == {mode: 1.0} and got.samples == 12
    logged = read_columns(path, ["dt_mu_max"])["dt_mu_max"]
    assert got.dt_mu_max == pytest.approx(logged[got.step_of_max], rel=1e-9)


@pytest.mark.parametrize(("name", "rel"), [("nominal", 1e-6), ("servicer_nominal", 1e-12)])
def test_the_camera_rolls_closed_form_is_the_reduced_inertias_mode(name, rel):
    """μ_roll = D_o/I_roll from the robot card (the last joint's body about its axis, eq. 21)
    against the camera-roll eigenpair of M̆⁻¹D̆ at the start (Γ⁻ᵀMΓ⁻¹ from CRBA): equal to
    1e-15 on the servicer (CoM and camera on the axis), 4e-7 on the seed robot (its payload's
    CoM 1.5e-5 m off it)."""
    from pipeline.sim.base_controller import block_gains
    from pipeline.sim.robot import GiordanoRobot
    from pipeline.sim.stability import damping_modes

    spec = load_spec(name)
    robot = GiordanoRobot(spec)
    q = robot.start_configuration()
    card = robot.card(q)
    _, D = block_gains(spec.controller, 1.0)
    modes = damping_modes(robot.terms(q, np.zeros(robot.model.nv)).reduced_inertia, D)
    roll = next(m for m in modes if m.axis == 8)
    assert card.mu_roll == pytest.approx(roll.mu, rel=rel)
    assert card.roll_boresight_cos == pytest.approx(1.0, abs=1e-6)
