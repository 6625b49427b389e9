"""The rigid-body terms of one state, compiled: what the controller takes from Pinocchio
(eqs. 2–11), computed inside the step kernel.

At (q, v) the controller needs the bus and camera placements, the camera Jacobian J_e and
its time variation J̇_e (LOCAL frame), the mass matrix M, the Coriolis matrix C and the
centroidal map A_g with its time variation Ȧ_g. Through Pinocchio these are five Python
calls a step (the bench's floor), and a mission loop in compiled code cannot make them. This
module computes the same quantities by the same algorithms on the model's own numbers
(:class:`~pipeline.sim.forward_dynamics.RigidTree`), in world-frame spatial algebra,
[linear; angular], as Pinocchio does:

- forward kinematics: ᵒM_i = ᵒM_λ ^λM_i, v_i = ^iX_λ v_λ + S_i q̇_i, the world columns
  J_i = ᵒX_i S_i and their variation J̇_i = ᵒv_i × J_i (``computeJointJacobiansTimeVariation``);
- M = Jᵀ Y J by composite inertias, leaves to root (CRBA);
- C by Pinocchio's factorisation (``computeCoriolisMatrix``, Ṁ = C + Cᵀ): with B_i =
  ½ (ᵒv_i ×* Y_i − Y_i ᵒv_i ×) − ½ (Y_i ᵒv_i)×̄ summed over the subtree, the rows of joint i
  are J_iᵀ (Y_i J̇_j + B_i J_j) for j in its subtree and (Y_i J_i)ᵀ J̇_j + J_iᵀ B_i J_j for j
  among its ancestors;
- A_g = Y J about the world origin, its angular rows moved to the CoM, and Ȧ_g = Y J̇ + Ẏ J
  with Ẏ_i = ᵒv_i ×* Y_i − Y_i ᵒv_i × (``computeCentroidalMapTimeVariation``);
- the camera frame's LOCAL Jacobian ᵒX_e⁻¹ J and its variation ᵒX_e⁻¹ J̇ − v_e × ᵒX_e⁻¹ J
  (``getFrameJacobianTimeVariation``).

The spatial quantities are taken with world axes about the bus origin, not the target's (t):
about a far origin the inertias' m ĉ ĉ and the velocities' p × ω would cancel digits (a robot
1 km out would lose twelve of them in M), about the bus only the arm's size enters. M, C, the
camera's LOCAL Jacobians and the centroidal maps about the CoM do not depend on that choice;
p_b and p_e are handed back in t.

Independent of Pinocchio's code, checked against it to round-off (tests/test_rigid_body_terms.py);
the two differ in their last bits (another order of the same sums).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from pipeline.errors import SpecError
from pipeline.sim.forward_dynamics import (
    RigidTree,
    axis_rotation,
    motion_cross,
    motion_inverse,
    quat_rotation,
    rigid_tree,
)
from pipeline.sim.jit import jit
from pipeline.sim.task_transform import DynamicsInputs


class CameraMount(NamedTuple):
    """Where the camera frame sits: its parent joint and its placement in that joint's frame."""

    joint: int
    placement_R: np.ndarray  # 3×3
    placement_p: np.ndarray  # (3,)


class RobotTerms(NamedTuple):
    """The kernel's bundle of one model: the tree
    (:func:`~pipeline.sim.forward_dynamics.rigid_tree`), each body's mass, CoM and rotational
    inertia about its CoM (joint frame), the last velocity of each joint's subtree, and the
    camera's mount."""

    tree: RigidTree
    mass: np.ndarray  # (nj,)
    com: np.ndarray  # (nj, 3)
    inertia_c: np.ndarray  # (nj, 3, 3)
    subtree_end: np.ndarray  # (nj,) int64: one past the subtree's last velocity
    camera: CameraMount


def robot_terms(model: pin.Model, frame_id: int) -> RobotTerms:
    """The bundle of a loaded model (a free joint, then revolute joints) and its camera frame."""
    tree = rigid_tree(model)
    frame = model.frames[frame_id]
    nj = model.njoints
    end = np.zeros(nj, dtype=np.int64)
    count = np.zeros(nj, dtype=np.int64)  # the velocities of each joint's subtree
    for j in range(nj - 1, 0, -1):  # a joint's subtree ends where its last descendant's does
        joint, parent = model.joints[j], model.parents[j]
        end[j] = max(end[j], joint.idx_v + joint.nv)
        count[j] += joint.nv
        if parent > 0:
            end[parent] = max(end[parent], end[j])
            count[parent] += count[j]
    # The kernel takes a subtree's velocities as one range from the joint's own: joints
    # numbered depth first, as Pinocchio's parsers number them. A model built otherwise is
    # refused, not given a wrong M and C.
    for j in range(1, nj):
        if end[j] - model.joints[j].idx_v != count[j]:
            raise SpecError(f"joint {model.names[j]!r}: the joints are not numbered depth "
                            "first; the compiled rigid-body terms need a subtree's velocities "
                            "in one range")
    return RobotTerms(
        tree=tree,
        mass=np.array([model.inertias[j].mass for j in range(nj)]),
        com=np.array([model.inertias[j].lever for j in range(nj)]),
        inertia_c=np.array([model.inertias[j].inertia for j in range(nj)]),
        subtree_end=end,
        camera=CameraMount(int(frame.parentJoint),
                           np.ascontiguousarray(frame.placement.rotation),
                           np.ascontiguousarray(frame.placement.translation)))


@jit
def _act_motion(R, p, m, out):
    """out = ᵒX m for the placement (R, p): [R v + p × R ω; R ω]."""
    w0 = R[0, 0] * m[3] + R[0, 1] * m[4] + R[0, 2] * m[5]
    w1 = R[1, 0] * m[3] + R[1, 1] * m[4] + R[1, 2] * m[5]
    w2 = R[2, 0] * m[3] + R[2, 1] * m[4] + R[2, 2] * m[5]
    l0 = R[0, 0] * m[0] + R[0, 1] * m[1] + R[0, 2] * m[2]
    l1 = R[1, 0] * m[0] + R[1, 1] * m[1] + R[1, 2] * m[2]
    l2 = R[2, 0] * m[0] + R[2, 1] * m[1] + R[2, 2] * m[2]
    out[0] = l0 + p[1] * w2 - p[2] * w1
    out[1] = l1 + p[2] * w0 - p[0] * w2
    out[2] = l2 + p[0] * w1 - p[1] * w0
    out[3], out[4], out[5] = w0, w1, w2


@jit
def _world_inertia(R, p, m, c, Ic, out):
    """out = ᵒY: the spatial inertia of a body of mass m, CoM c and rotational inertia I_c
    (its joint frame, placed at (R, p)) about the world origin with world axes:
    [[m 1, −m ĉ], [m ĉ, R I_c Rᵀ − m ĉ ĉ]], c = R c + p."""
    x = R[0, 0] * c[0] + R[0, 1] * c[1] + R[0, 2] * c[2] + p[0]
    y = R[1, 0] * c[0] + R[1, 1] * c[1] + R[1, 2] * c[2] + p[1]
    z = R[2, 0] * c[0] + R[2, 1] * c[1] + R[2, 2] * c[2] + p[2]
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += R[i, k] * (Ic[k, 0] * R[j, 0] + Ic[k, 1] * R[j, 1] + Ic[k, 2] * R[j, 2])
            out[3 + i, 3 + j] = s
        for j in range(3):
            out[i, j] = m if i == j else 0.0
    # ĉ ĉ = c cᵀ − |c|² 1, so −m ĉ ĉ = m (|c|² 1 − c cᵀ)
    cc = x * x + y * y + z * z
    cw = (x, y, z)
    for i in range(3):
        for j in range(3):
            out[3 + i, 3 + j] += m * ((cc if i == j else 0.0) - cw[i] * cw[j])
    out[0, 3], out[0, 4], out[0, 5] = 0.0, m * z, -m * y
    out[1, 3], out[1, 4], out[1, 5] = -m * z, 0.0, m * x
    out[2, 3], out[2, 4], out[2, 5] = m * y, -m * x, 0.0
    for i in range(3):
        for j in range(3):
            out[3 + i, j] = out[j, 3 + i]


@jit
def _inertia_variation(Y, v, X, out):
    """out = Ẏ = v ×* Y − Y v× = −(v×)ᵀ Y − Y v×: the rate of a world inertia Y moving at v
    (X: scratch for v×, [[ω̂, v̂], [0, ω̂]])."""
    X[:] = 0.0
    for o in (0, 3):
        X[o + 0, o + 1], X[o + 0, o + 2] = -v[5], v[4]
        X[o + 1, o + 0], X[o + 1, o + 2] = v[5], -v[3]
        X[o + 2, o + 0], X[o + 2, o + 1] = -v[4], v[3]
    X[0, 4], X[0, 5] = -v[2], v[1]
    X[1, 3], X[1, 5] = v[2], -v[0]
    X[2, 3], X[2, 4] = -v[1], v[0]
    for a in range(6):
        for b in range(6):
            s = 0.0
            for k in range(6):
                s -= X[k, a] * Y[k, b] + Y[a, k] * X[k, b]
            out[a, b] = s


@jit
def _add_force_cross_matrix(f, B, scale):
    """B −= (scale f)×̄, the matrix of v ↦ v ×* (scale f): blocks (lin, ang) and (ang, lin)
    −f̂_lin, (ang, ang) −f̂_ang (Pinocchio's ``addForceCrossMatrix``)."""
    for o_r, o_c, o_f in ((0, 3, 0), (3, 0, 0), (3, 3, 3)):
        a0, a1, a2 = scale * f[o_f], scale * f[o_f + 1], scale * f[o_f + 2]
        B[o_r + 0, o_c + 1] += a2
        B[o_r + 0, o_c + 2] -= a1
        B[o_r + 1, o_c + 0] -= a2
        B[o_r + 1, o_c + 2] += a0
        B[o_r + 2, o_c + 0] += a1
        B[o_r + 2, o_c + 1] -= a0


@jit
def _joint_placement(tree, j, q, Rl, pl):
    """(Rl, pl) = ^λM_j: joint j's frame in its parent's at q (placement · joint motion)."""
    iq = tree.q_index[j]
    Rp, pp = tree.placement_R[j], tree.placement_p[j]
    if j == 1:  # the free joint: q = [p; x, y, z, w]
        RJ = quat_rotation(q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6])
        for a in range(3):
            pl[a] = pp[a] + Rp[a, 0] * q[iq] + Rp[a, 1] * q[iq + 1] + Rp[a, 2] * q[iq + 2]
    else:
        RJ = axis_rotation(tree.axis[j], q[iq])
        for a in range(3):
            pl[a] = pp[a]
    for a in range(3):
        for b in range(3):
            Rl[a, b] = Rp[a, 0] * RJ[0, b] + Rp[a, 1] * RJ[1, b] + Rp[a, 2] * RJ[2, b]


@jit
def dynamics_terms(bundle, q, v):
    """Pinocchio's outputs at (q, v) that eqs. 2–11 take (module docstring), as
    ``DynamicsInputs``, from the model ``bundle`` (``RobotTerms``). Ȧ_g's angular rows are
    the time variation's whole: Pinocchio 4.1's ``computeCentroidalMapTimeVariation`` leaves out
    their A_g,lin × v_com term (its ``vcom`` is not computed there); no step reads them."""
    return _terms(bundle, q, v)


@jit
def placement_terms(bundle, q):
    """(R_tb, p_b, R_te, p_e, J_e, M) at q: what eqs. 2–6 take (Γ alone), by the same
    operations as :func:`dynamics_terms`, so the same bits, without the rates."""
    d = _terms(bundle, q, np.empty(0))
    return d.R_tb, d.p_b, d.R_te, d.p_e, d.J_e, d.M


@jit
def _terms(bundle, q, v):
    """:func:`dynamics_terms`; with v empty, the rates (J̇_e, C, Ȧ_g) are zeros (a flag
    argument would compile once per literal value)."""
    tree, cam = bundle.tree, bundle.camera
    nj = tree.parent.size
    rates = v.size > 0
    nv = bundle.subtree_end[1]
    if not rates:
        v = np.zeros(nv)
    R = np.zeros((nj, 3, 3))
    p = np.zeros((nj, 3))
    R[0, 0, 0] = R[0, 1, 1] = R[0, 2, 2] = 1.0
    vel = np.zeros((nj, 6))  # each joint's velocity in its own frame
    ov = np.zeros((nj, 6))  # the same in the world frame
    Jt = np.zeros((nv, 6))  # the world columns J_d, one per row
    dJt = np.zeros((nv, 6))
    Y = np.empty((nj, 6, 6))  # world inertias, composite after the backward pass
    dY = np.zeros((nj, 6, 6))
    B = np.zeros((nj, 6, 6))
    Rl = np.empty((3, 3))
    pl = np.empty(3)
    origin = np.empty(3)  # the bus origin in t
    X = np.empty((6, 6))
    h = np.empty(6)
    e = np.zeros(6)
    for j in range(1, nj):
        par, iv = tree.parent[j], tree.v_index[j]
        _joint_placement(tree, j, q, Rl, pl)
        Rpar, ppar = R[par], p[par]
        for a in range(3):
            for b in range(3):
                R[j, a, b] = Rpar[a, 0] * Rl[0, b] + Rpar[a, 1] * Rl[1, b] + Rpar[a, 2] * Rl[2, b]
            p[j, a] = ppar[a] + Rpar[a, 0] * pl[0] + Rpar[a, 1] * pl[1] + Rpar[a, 2] * pl[2]
        if j == 1:  # the frame's origin moves to the bus (module docstring)
            origin[:] = p[1]
            p[1, :] = 0.0
        # the joint's world columns J = ᵒX_j S_j and their variation ᵒv_j × J
        for d in range(6 if j == 1 else 1):
            e[:] = 0.0
            if j == 1:
                e[d] = 1.0
            else:
                e[3:] = tree.axis[j]
            _act_motion(R[j], p[j], e, Jt[iv + d])
        _world_inertia(R[j], p[j], bundle.mass[j], bundle.com[j], bundle.inertia_c[j], Y[j])
        if not rates:
            continue
        motion_inverse(Rl, pl, vel[par], vel[j])
        if j == 1:
            for a in range(6):
                vel[j, a] += v[iv + a]
        else:
            for a in range(3):
                vel[j, 3 + a] += tree.axis[j, a] * v[iv]
        _act_motion(R[j], p[j], vel[j], ov[j])
        for d in range(iv, iv + (6 if j == 1 else 1)):
            motion_cross(ov[j], Jt[d], dJt[d])
        _inertia_variation(Y[j], ov[j], X, dY[j])
        # Pinocchio's B_j = Y.variation(½ ᵒv) − (½ Y ᵒv)×̄ (the variation is linear in v)
        for a in range(6):
            s = 0.0
            for b in range(6):
                s += Y[j, a, b] * ov[j, b]
                B[j, a, b] = 0.5 * dY[j, a, b]
            h[a] = s
        _add_force_cross_matrix(h, B[j], 0.5)
    # Backward pass: composites, M, C, A_g and Ȧ_g (about the world origin).
    M = np.zeros((nv, nv))
    C = np.zeros((nv, nv))
    Agt = np.zeros((nv, 6))
    dAgt = np.zeros((nv, 6))
    dFt = np.zeros((nv, 6))
    BJ = np.empty(6)
    for j in range(nj - 1, 0, -1):
        iv, end = tree.v_index[j], bundle.subtree_end[j]
        ndof = 6 if j == 1 else 1
        Yj, Bj, dYj = Y[j], B[j], dY[j]
        for d in range(iv, iv + ndof):
            for a in range(6):
                s_a = 0.0
                s_f = 0.0
                s_b = 0.0
                s_d = 0.0
                for b in range(6):
                    s_a += Yj[a, b] * Jt[d, b]
                    if rates:
                        s_f += Yj[a, b] * dJt[d, b]
                        s_b += Bj[a, b] * Jt[d, b]
                        s_d += dYj[a, b] * Jt[d, b]
                Agt[d, a] = s_a
                dFt[d, a] = s_f + s_b
                dAgt[d, a] = s_d + s_f
        for r in range(iv, iv + ndof):
            # against the subtree's columns: M = J_jᵀ Y J, C = J_jᵀ (Y dJ + B J)
            for c in range(iv, end):
                sm = 0.0
                sc = 0.0
                for a in range(6):
                    sm += Jt[r, a] * Agt[c, a]
                    if rates:
                        sc += Jt[r, a] * dFt[c, a]
                M[r, c] = sm
                M[c, r] = sm
                C[r, c] = sc
            # against the ancestors' columns: M = (Y J_j)ᵀ J, C = (Y J_j)ᵀ dJ + J_jᵀ B J
            if rates:
                for a in range(6):
                    s = 0.0
                    for b in range(6):
                        s += Jt[r, b] * Bj[b, a]
                    BJ[a] = s
            anc = tree.parent[j]
            while anc > 0:
                a_iv = tree.v_index[anc]
                for c in range(a_iv, a_iv + (6 if anc == 1 else 1)):
                    sm = 0.0
                    sc = 0.0
                    for a in range(6):
                        sm += Agt[r, a] * Jt[c, a]
                        if rates:
                            sc += Agt[r, a] * dJt[c, a] + BJ[a] * Jt[c, a]
                    M[r, c] = sm
                    M[c, r] = sm
                    C[r, c] = sc
                anc = tree.parent[anc]
        par = tree.parent[j]
        if par > 0:
            Y[par] += Yj
            if rates:
                B[par] += Bj
                dY[par] += dYj
    # The whole robot's CoM and its velocity, then A_g's and Ȧ_g's angular rows about it.
    mass = Y[1, 0, 0]
    com = np.array([Y[1, 5, 1], Y[1, 3, 2], Y[1, 4, 0]]) / mass  # Y[3:, :3] = m ĉ
    vcom = np.zeros(3)
    for d in range(nv):
        for a in range(3):
            vcom[a] += Agt[d, a] * v[d]
    vcom /= mass
    Ag = np.empty((6, nv))
    dAg = np.empty((6, nv))
    for d in range(nv):
        l0, l1, l2 = Agt[d, 0], Agt[d, 1], Agt[d, 2]
        m0, m1, m2 = dAgt[d, 0], dAgt[d, 1], dAgt[d, 2]
        Ag[0, d], Ag[1, d], Ag[2, d] = l0, l1, l2
        dAg[0, d], dAg[1, d], dAg[2, d] = m0, m1, m2
        Ag[3, d] = Agt[d, 3] + l1 * com[2] - l2 * com[1]
        Ag[4, d] = Agt[d, 4] + l2 * com[0] - l0 * com[2]
        Ag[5, d] = Agt[d, 5] + l0 * com[1] - l1 * com[0]
        dAg[3, d] = dAgt[d, 3] + m1 * com[2] - m2 * com[1] + l1 * vcom[2] - l2 * vcom[1]
        dAg[4, d] = dAgt[d, 4] + m2 * com[0] - m0 * com[2] + l2 * vcom[0] - l0 * vcom[2]
        dAg[5, d] = dAgt[d, 5] + m0 * com[1] - m1 * com[0] + l0 * vcom[1] - l1 * vcom[0]
    # The camera frame: its placement, LOCAL Jacobian and its variation.
    jc = cam.joint
    Rc, pc, Rf, pf = R[jc], p[jc], cam.placement_R, cam.placement_p
    R_te = np.empty((3, 3))
    p_e = np.empty(3)
    p_rel = np.empty(3)  # the camera from the bus origin, t axes
    for a in range(3):
        for b in range(3):
            R_te[a, b] = Rc[a, 0] * Rf[0, b] + Rc[a, 1] * Rf[1, b] + Rc[a, 2] * Rf[2, b]
        p_rel[a] = pc[a] + Rc[a, 0] * pf[0] + Rc[a, 1] * pf[1] + Rc[a, 2] * pf[2]
        p_e[a] = origin[a] + p_rel[a]
    v_frame = np.empty(6)
    motion_inverse(Rf, pf, vel[jc], v_frame)
    J_e = np.zeros((6, nv))
    dJ_e = np.zeros((6, nv))
    jl = np.empty(6)
    djl = np.empty(6)
    anc = jc
    while anc > 0:
        a_iv = tree.v_index[anc]
        for d in range(a_iv, a_iv + (6 if anc == 1 else 1)):
            motion_inverse(R_te, p_rel, Jt[d], jl)
            motion_inverse(R_te, p_rel, dJt[d], djl)
            motion_cross(v_frame, jl, h)
            for a in range(6):
                J_e[a, d] = jl[a]
                dJ_e[a, d] = djl[a] - h[a]
        anc = tree.parent[anc]
    return DynamicsInputs(R_tb=R[1].copy(), p_b=origin, R_te=R_te, p_e=p_e, J_e=J_e,
                          dJ_e=dJ_e, M=M, C=C, Ag=Ag, dAg=dAg)
