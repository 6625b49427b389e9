"""Checks of the loop equations (eqs. 12–18): each RHS term against its formula, both
integrators against their closed forms, the saturations, the guidance and the coverage.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from pipeline.verify.checks_base import (
    Outcome,
    check,
    fmt,
    maxdiff,
    random_state,
    rng,
    robot,
)
from pipeline.verify.checks_base import spec as check_spec

# The acceleration and rate bounds of the three v̆ blocks, too large to bind.
_NO_BOUNDS = (np.full(3, 1e9), np.full(3, 1e9))


def _spd(g: np.random.Generator, n: int = 9) -> np.ndarray:
    A = g.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


def _loop_inputs(salt: int) -> dict:
    """A real state's reduced terms and random loop quantities (x̃, J_x, v̆_des, …)."""
    q, v = random_state(salt)
    T = robot().terms(q, v)
    g = rng(100 + salt)
    return {"C": np.array(T.reduced_coriolis), "M": np.array(T.reduced_inertia),
            "G": np.array(T.gamma),
            "C_c": np.array(T.com_coupling), "Gi": np.array(T.gamma_inv), "q": q,
            "D": np.diag(g.uniform(0.5, 8, 9)), "K": np.diag(g.uniform(0.5, 4, 9)),
            "J_x": g.standard_normal((9, 9)), "x": g.standard_normal(9),
            "vb": g.standard_normal(9), "vd": g.standard_normal(9),
            "vdd": g.standard_normal(9), "G_vc": g.standard_normal((9, 3)),
            "xc": g.standard_normal(3)}


def _rows(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x by explicit sums over rows (independent of the @ operator)."""
    return np.array([sum(A[i, j] * x[j] for j in range(A.shape[1])) for i in range(A.shape[0])])


_TERM_TEXT = "terms of a random state (seed {s}); random D̆, K̆, J_x, x̃, v̆, v̆_des"


@check("13a", "Coriolis term −C̆ v̆", "pipeline.sim.breve_controller.coriolis_term")
def _coriolis() -> Outcome:
    from pipeline.sim import breve_controller as bc

    d = _loop_inputs(1)
    return Outcome(_TERM_TEXT.format(s=1),
                   maxdiff(bc.coriolis_term(d["C"], d["vb"]), -_rows(d["C"], d["vb"])), 1e-12)


@check("13b", "damping term −D̆ (v̆ − v̆_des)", "pipeline.sim.breve_controller.damping_term")
def _damping() -> Outcome:
    from pipeline.sim import breve_controller as bc

    d = _loop_inputs(2)
    ref = -_rows(d["D"], d["vb"] - d["vd"])
    return Outcome(_TERM_TEXT.format(s=2), maxdiff(bc.damping_term(d["D"], d["vb"], d["vd"]), ref),
                   1e-12)


@check("13c", "stiffness term −J_xᵀ K̆ x̃", "pipeline.sim.breve_controller.stiffness_term")
def _stiffness() -> Outcome:
    from pipeline.sim import breve_controller as bc

    d = _loop_inputs(3)
    ref = -_rows(d["J_x"].T, _rows(d["K"], d["x"]))
    return Outcome(_TERM_TEXT.format(s=3),
                   maxdiff(bc.stiffness_term(d["J_x"], d["K"], d["x"]), ref), 1e-12)


@check("13d", "CoM coupling −(C_c + D̆ G_vc) ẋ̃_c", "pipeline.sim.breve_controller.com_coupling_term")
def _com_coupling() -> Outcome:
    from pipeline.sim import breve_controller as bc

    d = _loop_inputs(4)
    ref = -_rows(d["C_c"], d["xc"]) - _rows(d["D"], _rows(d["G_vc"], d["xc"]))
    # C_c as a view of a wider matrix, as the step kernel passes Ĉ[3:, :3]: one compiled
    # specialisation of the term
    C_c = np.hstack([d["C_c"], np.zeros((9, 9))])[:, :3]
    got = bc.com_coupling_term(C_c, d["D"], d["G_vc"], d["xc"])
    return Outcome(_TERM_TEXT.format(s=4), maxdiff(got, ref), 1e-12)


@check("13e", "posture term vs rows 3: of Γ⁻ᵀ τ, τ = [0; 0; −k (q_a − q̄)] (numpy's Γ⁻ᵀ)",
       "pipeline.sim.breve_controller.posture_term")
def _posture() -> Outcome:
    from pipeline.sim import breve_controller as bc

    d = _loop_inputs(5)
    k, q_bar = 0.7, np.asarray(robot().q_bar)
    tau = np.r_[np.zeros(6), -k * (d["q"][7:] - q_bar)]
    ref = np.linalg.solve(d["G"].T, tau)[3:]  # Γ⁻ᵀ τ without the closed-form inverse
    got = bc.posture_term(d["Gi"], k, d["q"][7:], q_bar)
    return Outcome(_TERM_TEXT.format(s=5) + f", k_post = {k}", maxdiff(got, ref), 1e-12)


@check("13f", "feed-forward M̆ v̆̇_des + C̆ v̆_des", "pipeline.sim.breve_controller.feedforward_term")
def _feedforward() -> Outcome:
    from pipeline.sim import breve_controller as bc

    d = _loop_inputs(6)
    ref = _rows(d["M"], d["vdd"]) + _rows(d["C"], d["vd"])
    got = bc.feedforward_term(d["M"], d["vdd"], d["C"], d["vd"])
    return Outcome(_TERM_TEXT.format(s=6), maxdiff(got, ref), 1e-12)


@check("13", "block gains K̆, D̆ = blockdiag(s k_b I₃, k_p I₃, k_o I₃), s = γ only when derated",
       "pipeline.sim.base_controller.block_gains")
def _block_gains() -> Outcome:
    from pipeline.sim.base_controller import block_gains
    from pipeline.spec import with_overrides

    diffs = []
    for derate in (False, True):
        c = with_overrides(check_spec(), {"controller.base.derate.gain": derate}).controller
        g, gam = c.gains, 0.4
        s = gam if derate else 1.0
        K, D = block_gains(c, gam)
        K_ref = sla.block_diag(s * g.bus.K * np.eye(3), g.cam_pos.K * np.eye(3),
                               g.cam_ori.K * np.eye(3))
        D_ref = sla.block_diag(s * g.bus.D * np.eye(3), g.cam_pos.D * np.eye(3),
                               g.cam_ori.D * np.eye(3))
        diffs += [maxdiff(K, K_ref), maxdiff(D, D_ref)]
    return Outcome("spec gains, γ = 0.4, derate.gain false and true", max(diffs), 0.0)


@check("12", "CoM step vs the PD + bounded integral + feed-forward law with both saturations",
       "pipeline.sim.com_controller.com_update")
def _com_update() -> Outcome:
    from pipeline.sim.com_controller import com_update

    c, g, dt = check_spec().controller, rng(12), 0.03
    diffs = []
    for scale in (1e-3, 10.0):  # saturations inactive, then active
        x, xd, vc, a_ff, integ = (scale * g.standard_normal(3) for _ in range(5))
        v_c, integral, _, _ = com_update(
            x_c=x, xd_c=xd, v_c=vc, a_ff=a_ff, integral=integ, K=c.com.K, D=c.com.D,
            Ki=c.com.Ki, i_max=c.com.i_max, acc_bound=c.limits.v_c_acc,
            rate_bound=c.limits.v_c_rate, dt=dt)
        i_ref = np.minimum(np.maximum(integ + dt * x, -c.com.i_max), c.com.i_max)
        acc = -c.com.K * x - c.com.D * xd - c.com.Ki * i_ref + a_ff
        acc = acc * min(1.0, c.limits.v_c_acc / np.sqrt(acc @ acc))
        v_new = vc + dt * acc
        v_new = v_new * min(1.0, c.limits.v_c_rate / np.sqrt(v_new @ v_new))
        diffs += [maxdiff(v_c, v_new), maxdiff(integral, i_ref)]
    return Outcome("random errors at scales 1e-3 and 10 (limits inactive, active), dt 0.03",
                   max(diffs), 1e-14)


@check("14", "attitude error 2ε of quat(R_desᵀR) vs an axis-angle construction; "
       "d(2ε)/dt = E ω by finite differences", "pipeline.sim.rotations.attitude_error")
def _attitude_error() -> Outcome:
    import pinocchio as pin

    from pipeline.sim.rotations import attitude_error

    g, diffs = rng(14), []
    for _ in range(5):
        axis = g.standard_normal(3)
        axis /= np.linalg.norm(axis)
        angle = g.uniform(0.1, 2.5)
        R_des = pin.exp3(g.standard_normal(3))
        R = R_des @ pin.exp3(angle * axis)
        x, E = attitude_error(R, R_des)
        diffs.append(maxdiff(x, 2 * np.sin(angle / 2) * axis))
        w, h = g.standard_normal(3), 1e-6
        xp, _ = attitude_error(R @ pin.exp3(h * w), R_des)
        xm, _ = attitude_error(R @ pin.exp3(-h * w), R_des)
        diffs.append(maxdiff((xp - xm) / (2 * h), E @ w))
    return Outcome("5 random error rotations (angle 0.1–2.5 rad) and body rates; h = 1e-6",
                   max(diffs), 1e-6)


@check("15a", "explicit step vs v̆ + dt M̆⁻¹RHS (limits off) and the scalar closed form "
       "v⁺ − v_des = (1 − dt d/m)(v − v_des)", "pipeline.sim.breve_controller.explicit_update")
def _explicit() -> Outcome:
    from pipeline.sim.breve_controller import explicit_update

    g, dt = rng(15), 0.03
    M, rhs, v = _spd(g), g.standard_normal(9), g.standard_normal(9)
    d1 = maxdiff(explicit_update(M, rhs, v, dt, *_NO_BOUNDS)[0], v + dt * sla.inv(M) @ rhs)
    m, dd, vdes = 2.0, 150.0, g.standard_normal(9)
    v1, _, _ = explicit_update(m * np.eye(9), -dd * (v - vdes), v, dt, *_NO_BOUNDS)
    d2 = maxdiff(v1 - vdes, (1 - dt * dd / m) * (v - vdes))
    return Outcome("random SPD M̆ and RHS; scalar mode m = 2, d = 150 (dt·d/m = 2.25), dt 0.03",
                   max(d1, d2), 1e-12, f"matrix {fmt(d1)}, scalar {fmt(d2)}")


@check("15b", "imex step vs (M̆ + dt D̆)⁻¹(M̆v̆ + dt(RHS + D̆v̆)) and the scalar closed form "
       "v⁺ − v_des = (v − v_des)/(1 + dt d/m)", "pipeline.sim.breve_controller.imex_update")
def _imex() -> Outcome:
    from pipeline.sim.breve_controller import imex_update

    g, dt = rng(16), 0.03
    M, D = _spd(g), np.diag(g.uniform(1, 10, 9))
    rhs, v = g.standard_normal(9), g.standard_normal(9)
    ref = sla.inv(M + dt * D) @ (M @ v + dt * (rhs + D @ v))
    d1 = maxdiff(imex_update(M, D, rhs, v, dt, *_NO_BOUNDS)[0], ref)
    m, dd, vdes = 2.0, 150.0, g.standard_normal(9)
    v1, _, _ = imex_update(m * np.eye(9), dd * np.eye(9), -dd * (v - vdes), v, dt,
                           *_NO_BOUNDS)
    d2 = maxdiff(v1 - vdes, (v - vdes) / (1 + dt * dd / m))
    return Outcome("random SPD M̆, diagonal D̆, RHS; scalar mode m = 2, d = 150, dt 0.03",
                   max(d1, d2), 1e-12, f"matrix {fmt(d1)}, scalar {fmt(d2)}")


@check("16", "sat(x, b) = x·min(1, b/‖x‖) per block, and its flags",
       "pipeline.sim.limits.saturate")
def _saturate() -> Outcome:
    from pipeline.sim.limits import breve_bounds, saturate, saturate_blocks

    g, lim, diffs = rng(17), check_spec().controller.limits, []
    for scale in (0.01, 1.0, 100.0):
        x = scale * g.standard_normal(9)
        for kind in ("acc", "rate"):
            # a writable copy, as the step kernel's bounds: one compiled specialisation
            out, hit = saturate_blocks(x, breve_bounds(lim, kind).copy())
            for j, name in enumerate(("omega_b", "nu_e_lin", "nu_e_ang")):
                b, blk = getattr(lim, f"{name}_{kind}"), x[3 * j:3 * j + 3]
                n = float(np.linalg.norm(blk))
                diffs.append(maxdiff(out[3 * j:3 * j + 3], blk * min(1.0, b / n)))
                if hit[j] != (n > b):
                    raise AssertionError(f"flag sat_{name}_{kind} wrong at scale {scale}")
        y = scale * g.standard_normal(3)
        diffs.append(maxdiff(saturate(y, 0.2)[0], y * min(1.0, 0.2 / np.linalg.norm(y))))
    return Outcome("random 9-vectors at scales 0.01, 1, 100 with the spec's limits", max(diffs),
                   1e-15)


@check("17", "orbit reference p_c, ṗ_c, p̈_c vs r[cos φ, sin φ, 0] and its derivatives; "
       "ω_b,des vs a finite difference of R_b,des", "pipeline.sim.base_guidance")
def _guidance() -> Outcome:
    import pinocchio as pin

    from pipeline.sim.base_guidance import BaseGuidance

    gcfg = check_spec().guidance
    gd = BaseGuidance(gcfg, np.array([0.3, 0.1, 0.8]), np.array([1.0, 0.0, 0.0]))
    Om, r, diffs = 2 * np.pi / gcfg.orbit_period, gcfg.orbit_radius, []
    for tau in (0.0, 13.7, 250.0):
        ref = gd.reference(tau)
        phi = np.deg2rad(gcfg.orbit_phase_deg) + Om * tau
        c, s = np.cos(phi), np.sin(phi)
        diffs += [maxdiff(ref.p_c, r * np.array([c, s, 0])),
                  maxdiff(ref.v_c, r * Om * np.array([-s, c, 0])),
                  maxdiff(ref.a_c, -r * Om**2 * np.array([c, s, 0]))]
        h = 1e-3
        Rp, Rm = gd.reference(tau + h).R_b, gd.reference(tau - h).R_b
        w = ref.R_b @ pin.log3(Rm.T @ Rp) / (2 * h)  # t frame
        diffs.append(maxdiff(ref.w_b, w))
    return Outcome(f"τ = 0, 13.7, 250 s; spec {check_spec().name} guidance; h = 1e-3 for ω_b,des",
                   max(diffs), 1e-7)


@check("18", "visible points (field of view, depth range, facing) vs a per-point loop",
       "pipeline.sim.target")
def _coverage() -> Outcome:
    import pinocchio as pin

    from pipeline.sim.target import build_target, visible

    sp = check_spec()
    tgt, cam, g = build_target(sp.target), sp.camera, rng(18)
    mism, total = 0, 0
    for _ in range(4):
        p_e = g.uniform(-6, 6, 3)
        R = pin.exp3(g.standard_normal(3))
        got = visible(tgt, p_e, R, cam)
        for j, (p, n) in enumerate(zip(tgt.points, tgt.normals, strict=True)):
            x, y, d = R.T @ (p - p_e)
            dist = float(np.linalg.norm(p - p_e))
            seen = (np.hypot(x, y) <= d * np.tan(np.radians(cam.fov_deg / 2))
                    and cam.d_min <= d <= cam.d_max
                    and -(n @ (p - p_e)) / dist >= np.cos(np.radians(cam.max_angle_deg)))
            mism += int(bool(seen) != bool(got[j]))
            total += 1
    return Outcome(f"{total} point tests: 4 random camera poses × {len(tgt.points)} target points",
                   float(mism), 0.0, "number of points classified differently")


@check("29", "the commanded force u = M a + C v, a = Γ⁻¹(ν̇ − Γ̇ v), vs Pinocchio's RNEA at "
       "a = Γ⁻¹(ν̇ − Γ̇_fd v), Γ̇ v by central differences of Γ along v (h = 1e-6)",
       "pipeline.sim.plant.commanded_force")
def _commanded_force() -> Outcome:
    import pinocchio as pin

    from pipeline.sim.plant import commanded_force

    r = robot()
    q, v = random_state(291)
    g = rng(291)
    nu, nu_next, dt = g.standard_normal(12), g.standard_normal(12), 0.03
    T = r.terms(q, v)
    got = commanded_force(np.ascontiguousarray(T.M), np.ascontiguousarray(T.C),
                          np.ascontiguousarray(T.gamma_inv), np.ascontiguousarray(T.gamma_dot),
                          v, nu, nu_next, dt)
    h = 1e-6
    gamma_dot_v = (r.gamma_matrices(pin.integrate(r.model, q, v * h)[None])[0]
                   - r.gamma_matrices(pin.integrate(r.model, q, -v * h)[None])[0]) @ v / (2 * h)
    a = np.linalg.solve(T.gamma, (nu_next - nu) / dt - gamma_dot_v)
    ref = pin.rnea(r.model, r.model.createData(), q, v, a)
    return Outcome("one random robot state, random ν and ν⁺, dt = 0.03 s",
                   maxdiff(got, ref) / float(np.max(np.abs(ref))), 1e-9,
                   "relative to max |u|; central differences of step h err by O(h²)")


@check("29", "the bus attitude's excursion from the geodesic between two instants under a "
       "held torque about a principal axis vs the closed form |ω⁺ − ω| dt/8, and 0 at a "
       "constant rate", "pipeline.sim.plant.attitude_excursion")
def _attitude_excursion() -> Outcome:
    import pinocchio as pin

    from pipeline.sim.forward_dynamics import rigid_tree
    from pipeline.sim.plant import integrate_held

    body = pin.Model()
    jid = body.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "free")
    body.appendBodyToJoint(jid, pin.Inertia(5.0, np.zeros(3), np.diag([0.008, 0.02, 0.015625])),
                           pin.SE3.Identity())
    body.gravity.setZero()
    tree, dt = rigid_tree(body), 0.03
    q0 = pin.neutral(body)
    diffs = []
    for w, torque in ((0.15, -0.15625), (0.3, 0.0)):
        v0 = np.array([0, 0, 0, 0, 0, w])
        _, v1, excursion = integrate_held(tree, q0, v0, np.r_[np.zeros(5), torque], dt, 8)
        diffs.append(abs(excursion - abs(v1[5] - w) * dt / 8))
    return Outcome("a 5 kg body about z: ω from 0.15 rad/s under −0.156 N·m, and at 0.3 rad/s "
                   "under none, 8 substeps", max(diffs), 1e-12, "rad")


@check("29", "the compiled articulated-body algorithm's v̇ vs Pinocchio's aba at random states "
       "and forces of the seed robot, the servicer and the 7-joint Panda",
       "pipeline.sim.forward_dynamics.forward_dynamics", "pipeline.sim.forward_dynamics.rigid_tree")
def _forward_dynamics() -> Outcome:
    import pinocchio as pin

    from pipeline.sim.forward_dynamics import forward_dynamics, rigid_tree
    from pipeline.sim.robot_file import load_spec_robot
    from pipeline.spec import load_spec

    g = rng(2929)
    worst = 0.0
    for name in ("nominal", "servicer_nominal", "panda_nominal"):
        model = load_spec_robot(load_spec(name))
        data, tree = model.createData(), rigid_tree(model)
        for _ in range(5):
            q = pin.neutral(model)
            q[:3] = g.standard_normal(3)
            quat = g.standard_normal(4)
            q[3:7] = quat / np.linalg.norm(quat)
            q[7:] = g.uniform(-np.pi, np.pi, model.nq - 7)
            v, tau = g.standard_normal(model.nv), g.standard_normal(model.nv)
            ref = pin.aba(model, data, q, v, tau)
            worst = max(worst, maxdiff(forward_dynamics(tree, q, v, tau), ref)
                        / float(np.max(np.abs(ref))))
    return Outcome("5 random states and forces of each of 3 robots (6 and 7 joints)", worst,
                   1e-12, "relative to max |v̇|")


# This module's checks, in the order the cross-check shows them: an explicit list, read by
# :func:`pipeline.verify.suite.all_checks` (no registration by import).
@check("29", "the held command on one rigid body spinning about a principal axis vs the "
       "closed form ω⁺ = (1 − dt·D/I) ω (exact under zero-order hold), and τ = M a + C v "
       "vs Pinocchio's CRBA and Coriolis matrix at a robot state",
       "pipeline.sim.plant.integrate_held", "pipeline.sim.plant.held_command")
def _held_command() -> Outcome:
    import pinocchio as pin

    from pipeline.sim.forward_dynamics import rigid_tree
    from pipeline.sim.plant import held_command, integrate_held

    body = pin.Model()
    inertia = np.diag([0.008, 0.02, 0.015625])
    jid = body.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "free")
    body.appendBodyToJoint(jid, pin.Inertia(5.0, np.zeros(3), inertia), pin.SE3.Identity())
    body.gravity.setZero()
    tree = rigid_tree(body)
    q, v, dt, D = pin.neutral(body), np.array([0, 0, 0, 0, 0, 0.15]), 0.03, 2.0
    tau = np.r_[np.zeros(5), -D * v[5]]
    diffs = []
    for _ in range(3):
        q, v_next, _ = integrate_held(tree, q, v, tau, dt, 20)
        diffs.append(abs(v_next[5] - (1 - dt * D / inertia[2, 2]) * v[5]) / abs(v[5]))
        v = v_next
        tau = np.r_[np.zeros(5), -D * v[5]]
    model = robot().model
    rdata = model.createData()
    qr, vr = random_state(29)
    a = rng(29).standard_normal(model.nv)
    M = pin.crba(model, rdata, qr)
    M = np.triu(M) + np.triu(M, 1).T
    C = pin.computeCoriolisMatrix(model, rdata, qr, vr)
    ref = M @ a + C @ vr
    diffs.append(maxdiff(held_command(model, rdata, qr, vr, a), ref) / np.max(np.abs(ref)))
    return Outcome("3 held steps of a 5 kg body (dt·D/I = 3.84), and one robot state",
                   max(diffs), 1e-12)


CHECKS = (
    _coriolis,
    _damping,
    _stiffness,
    _com_coupling,
    _posture,
    _feedforward,
    _block_gains,
    _com_update,
    _attitude_error,
    _explicit,
    _imex,
    _saturate,
    _guidance,
    _coverage,
    _held_command,
    _forward_dynamics,
    _commanded_force,
    _attitude_excursion,
)
