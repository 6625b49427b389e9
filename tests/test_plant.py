"""The sampled-data plant (pipeline/sim/plant.py, eq. 29): its integrator against conservation
laws and its own convergence, and the sampled-data mission against the simulator's update
where the two must agree (a fine step) and where the physics says they ring alike.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.analysis.signals import lag1_autocorrelation
from pipeline.sim.forward_dynamics import rigid_tree
from pipeline.sim.mission import Mission
from pipeline.sim.plant import integrate_held
from pipeline.sim.robot import GiordanoRobot
from pipeline.spec import load_spec, with_overrides


@pytest.fixture(scope="module")
def seed():
    robot = GiordanoRobot(load_spec("nominal"))
    rng = np.random.default_rng(29)
    q = pin.neutral(robot.model)
    q[3:7] = pin.Quaternion(pin.SE3.Random().rotation).coeffs()
    q[7:] = robot.spec.robot.q_bar + rng.uniform(-0.3, 0.3, 6)
    v = rng.uniform(-0.3, 0.3, robot.model.nv)
    return robot.model, robot.model.createData(), q, v


def _held(model, q, v, tau, dt, substeps):
    """The plant's step (the compiled one), without the excursion."""
    q1, v1, _ = integrate_held(rigid_tree(model), q, v, tau, dt, substeps)
    return q1, v1


def _momentum(model, data, q, v) -> np.ndarray:
    """The spatial momentum about the world origin, world axes: conserved without a force."""
    pin.computeCentroidalMomentum(model, data, q, v)
    h = data.hg.copy()  # about the CoM
    c = data.com[0]
    return np.r_[h.linear, h.angular + np.cross(c, h.linear)]


def test_without_a_command_momentum_and_energy_are_conserved(seed):
    """τ = 0 on the free-floating robot: its spatial momentum about a fixed point and its
    kinetic energy are invariants of the exact flow; RK4 keeps them to its truncation error
    (measured: below 1e-11 relative over 0.3 s at 1.5 ms substeps)."""
    model, data, q, v = seed
    h0, e0 = _momentum(model, data, q, v), pin.computeKineticEnergy(model, data, q, v)
    for _ in range(10):
        q, v = _held(model, q, v, np.zeros(model.nv), 0.03, 20)
    h1, e1 = _momentum(model, data, q, v), pin.computeKineticEnergy(model, data, q, v)
    assert np.max(np.abs(h1 - h0)) <= 1e-10 * np.max(np.abs(h0))
    assert abs(e1 - e0) <= 1e-10 * e0


def test_the_integrator_converges_at_fourth_order(seed):
    """Halving the substep divides the error against a 320-substep reference by about 16."""
    model, _data, q, v = seed
    tau = np.random.default_rng(5).uniform(-0.5, 0.5, model.nv)

    def end(n: int) -> np.ndarray:
        qn, vn = _held(model, q, v, tau, 0.03, n)
        return np.r_[pin.difference(model, q, qn), vn]

    ref = end(320)
    errors = [np.max(np.abs(end(n) - ref)) for n in (5, 10, 20)]
    ratios = [errors[i] / errors[i + 1] for i in range(2)]
    assert all(12 < r < 20 for r in ratios), (errors, ratios)


def _bus_yaw(spec, **over):
    res = Mission(with_overrides(spec, over)).run()
    vb = res.columns["v_breve"]
    return res, vb[len(vb) // 2:, 2]


def test_the_sampled_plant_and_the_simulators_update_converge_to_one_loop():
    """Both are first-order approximations of the same continuous closed loop: over 0.5 s of
    the nominal mission their joint angles differ by an amount that halves with dt (measured:
    6.3e-3, 3.2e-3, 1.6e-3 rad at dt = 4, 2, 1 ms). Without the −Γ̇v term of the commanded
    acceleration (eq. 29) the gap stays at 0.11 rad whatever dt."""
    gaps = []
    for dt in (0.004, 0.002):
        spec = with_overrides(load_spec("nominal"), {"mission.dt": dt, "mission.duration": 0.5})
        reduced = Mission(spec).run().columns["q"]
        sampled = Mission(with_overrides(spec, {"mission.plant.model": "sampled"})).run()
        gaps.append(np.max(np.abs(sampled.columns["q"][:, 7:] - reduced[:, 7:])))
    assert 1.7 < gaps[0] / gaps[1] < 2.3 and gaps[1] < 0.01, gaps


@pytest.mark.slow
def test_the_ripple_is_a_property_of_the_sampled_data_loop():
    """The plant's own dynamics under a held command at dt = 0.03 s (dt·μ_bus = 3.84) ring in
    the bus yaw as the simulator's update does; at dt = 0.01 s (1.28) they are smooth; with one
    step of delay, dt = 0.01 s is past the halved bound (dt·μ > 1) and the bus yaw oscillates
    at ten times the smooth run's amplitude, not at period 2 (complex roots, eq. 29)."""
    spec = with_overrides(load_spec("nominal"), {"mission.duration": 12.0})
    res, ring = _bus_yaw(spec, **{"mission.plant.model": "sampled"})
    assert res.status == "complete" and lag1_autocorrelation(ring[:, None])[0] < -0.9
    smooth_spec = with_overrides(spec, {"mission.dt": 0.01})
    res, smooth = _bus_yaw(smooth_spec, **{"mission.plant.model": "sampled"})
    assert res.status == "complete" and lag1_autocorrelation(smooth[:, None])[0] > 0.9
    res, late = _bus_yaw(smooth_spec, **{"mission.plant.model": "sampled",
                                         "mission.plant.delay_steps": 1})
    assert res.status == "complete"
    assert np.sqrt(np.mean(late**2)) > 10 * np.sqrt(np.mean(smooth**2))
    assert lag1_autocorrelation(late[:, None])[0] > -0.5  # not a period-2


def test_the_configuration_rate_is_pinocchios_integrate_differentiated(seed):
    """q̇ against a central difference of pin.integrate(q, ±ε v): the same group, another
    route (Pinocchio's exponential map)."""
    from pipeline.sim.plant import configuration_rate

    model, _, q, v = seed
    eps = 1e-6
    fd = (pin.integrate(model, q, eps * v) - pin.integrate(model, q, -eps * v)) / (2 * eps)
    assert np.max(np.abs(configuration_rate(q, v) - fd)) <= 1e-9


def test_the_bus_torque_limit_bounds_the_norm_and_keeps_the_direction():
    from pipeline.sim.plant import limit_bus_torque

    tau = np.r_[1.0, -2.0, 3.0, 3.0, -4.0, 12.0, np.arange(6.0)]  # bus torque norm 13
    out, hit = limit_bus_torque(tau, 6.5)
    assert hit and np.linalg.norm(out[3:6]) == pytest.approx(6.5, rel=1e-15)
    assert np.allclose(out[3:6] / 6.5, tau[3:6] / 13.0, rtol=0, atol=1e-15)
    assert np.array_equal(out[[0, 1, 2, *range(6, 12)]], tau[[0, 1, 2, *range(6, 12)]])
    for bound in (0.0, 13.0, 20.0):  # no bound, or not exceeded: unchanged
        out, hit = limit_bus_torque(tau, bound)
        assert not hit and np.array_equal(out, tau)


@pytest.mark.parametrize("dt_mu", [0.1, 0.5, 1.28, 3.84])
def test_the_delayed_modes_root_against_its_closed_form_and_a_simulation(dt_mu):
    """z² − z + dt·μ = 0 (eqs. 24, 35 with d = 1): real below ¼, else modulus √(dt·μ) at angle
    arccos(1/(2√(dt·μ))); and the recursion e⁺ = e − dt·μ·e⁻ grows by that modulus per step."""
    from pipeline.sim.margins import dominant_root, period_steps

    z = dominant_root(dt_mu, 1)
    if dt_mu < 0.25:
        assert z.imag == 0.0 and period_steps(z) is None
        assert abs(z) == pytest.approx((1 + np.sqrt(1 - 4 * dt_mu)) / 2)
    else:
        assert abs(z) == pytest.approx(np.sqrt(dt_mu), rel=1e-12)
        angle = np.arccos(1 / (2 * np.sqrt(dt_mu)))
        assert period_steps(z) == pytest.approx(2 * np.pi / angle, rel=1e-12)
    e = [1.0, 1.0]
    for _ in range(400):
        e.append(e[-1] - dt_mu * e[-2])
    env = max(abs(x) for x in e[-20:]) / max(abs(x) for x in e[-120:-100])
    assert env ** (1 / 100) == pytest.approx(abs(z), rel=2e-2)
    assert (abs(z) < 1) == (dt_mu < 1)
