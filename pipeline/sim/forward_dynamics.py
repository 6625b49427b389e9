"""The robot's forward dynamics, compiled: Featherstone's articulated-body algorithm on the
free-floating tree (eq. 29), for the sampled-data plant's RK4 substeps.

Pinocchio's ``aba`` costs a Python call per RK4 stage (32 a step at 8 substeps, most of the
sampled plant's 1.9 ms a step); this is the same algorithm in a Numba kernel, on the model's
own numbers, so the plant's whole step runs without Python (:mod:`pipeline.sim.plant`).
Spatial vectors are Pinocchio's, [linear; angular], in each joint's frame; the tree is a free
joint (the bus) and revolute joints of one axis each, as :func:`load_robot_model` leaves it
(locked joints folded in), gravity off.

With ^iX_λ the motion transform from the parent λ(i) to body i, S_i the joint's motion
subspace, c_i = v_i × S_i q̇_i and p_i = v_i ×* (Y_i v_i):

    v_i = ^iX_λ v_λ + S_i q̇_i                                  (pass 1, root to leaves)
    U_i = I^A_i S_i,  D_i = S_iᵀ U_i,  u_i = τ_i − S_iᵀ p^A_i    (pass 2, leaves to root)
    I^A_λ += ^iX_λᵀ (I^A_i − U_i D_i⁻¹ U_iᵀ) ^iX_λ
    p^A_λ += ^iX_λᵀ (p^A_i + I^a_i c_i + U_i D_i⁻¹ u_i)
    a'_i = ^iX_λ a_λ + c_i,  q̈_i = D_i⁻¹ (u_i − U_iᵀ a'_i),  a_i = a'_i + S_i q̈_i   (pass 3)

(Featherstone, Rigid Body Dynamics Algorithms, 2008, table 7.1). Checked against Pinocchio's
``aba`` (tests/test_forward_dynamics.py): the two are independent implementations.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from pipeline.errors import SpecError
from pipeline.sim.jit import jit
from pipeline.sim.linalg import solve

_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0),
         "JointModelRZ": (0.0, 0.0, 1.0)}


class RigidTree(NamedTuple):
    """The model's numbers the kernel reads, joint by joint (index 0: the universe)."""

    parent: np.ndarray  # (nj,) int64
    axis: np.ndarray  # (nj, 3): a revolute joint's axis in its frame (the free joint: 0)
    placement_R: np.ndarray  # (nj, 3, 3): the joint frame's rotation in its parent's
    placement_p: np.ndarray  # (nj, 3): its origin in its parent's frame
    inertia: np.ndarray  # (nj, 6, 6): the body's spatial inertia in the joint frame
    q_index: np.ndarray  # (nj,) int64: the joint's first coordinate in q
    v_index: np.ndarray  # (nj,) int64: its first velocity in v


def spatial_inertia(mass: float, com: np.ndarray, I_c: np.ndarray) -> np.ndarray:
    """Y = [[m 1, −m ĉ], [m ĉ, I_c − m ĉ ĉ]] (linear rows first): the momentum [m(v + ω × c);
    I_c ω + c × m(v + ω × c)] of a body moving at [v; ω] (eq. 29)."""
    c = np.asarray(com, dtype=float)
    C = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    Y = np.zeros((6, 6))
    Y[:3, :3] = mass * np.eye(3)
    Y[:3, 3:] = -mass * C
    Y[3:, :3] = mass * C
    Y[3:, 3:] = np.asarray(I_c, dtype=float) - mass * C @ C
    return Y


def rigid_tree(model: pin.Model) -> RigidTree:
    """The kernel's bundle of a loaded model (a free joint, then revolute joints)."""
    nj = model.njoints
    kinds = [j.shortname() for j in model.joints]
    if nj < 2 or kinds[1] != "JointModelFreeFlyer":
        raise SpecError("the compiled dynamics need a free joint at the root")
    axis = np.zeros((nj, 3))
    for j in range(2, nj):
        if kinds[j] in _AXES:
            axis[j] = _AXES[kinds[j]]
        elif kinds[j] == "JointModelRevoluteUnaligned":
            axis[j] = model.joints[j].extract().axis
        else:
            raise SpecError(f"joint {model.names[j]!r}: a {kinds[j]}; the compiled dynamics "
                            "take revolute joints of one axis")
    return RigidTree(
        parent=np.array(model.parents, dtype=np.int64),
        axis=axis,
        placement_R=np.array([model.jointPlacements[j].rotation for j in range(nj)]),
        placement_p=np.array([model.jointPlacements[j].translation for j in range(nj)]),
        inertia=np.array([spatial_inertia(model.inertias[j].mass, model.inertias[j].lever,
                                          model.inertias[j].inertia) for j in range(nj)]),
        q_index=np.array([model.joints[j].idx_q if j else 0 for j in range(nj)], dtype=np.int64),
        v_index=np.array([model.joints[j].idx_v if j else 0 for j in range(nj)],
                         dtype=np.int64))


@jit
def _cross3(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@jit
def quat_rotation(x: float, y: float, z: float, w: float) -> np.ndarray:
    """The rotation matrix of the unit quaternion (x, y, z; w)."""
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[0, 1] = 2.0 * (x * y - z * w)
    R[0, 2] = 2.0 * (x * z + y * w)
    R[1, 0] = 2.0 * (x * y + z * w)
    R[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[1, 2] = 2.0 * (y * z - x * w)
    R[2, 0] = 2.0 * (x * z - y * w)
    R[2, 1] = 2.0 * (y * z + x * w)
    R[2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


@jit
def axis_rotation(k: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: the rotation of ``angle`` about the unit axis k."""
    s, c = math.sin(angle), math.cos(angle)
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = (1.0 - c) * k[i] * k[j]
    R[0, 0] += c
    R[1, 1] += c
    R[2, 2] += c
    R[0, 1] -= s * k[2]
    R[0, 2] += s * k[1]
    R[1, 0] += s * k[2]
    R[1, 2] -= s * k[0]
    R[2, 0] -= s * k[1]
    R[2, 1] += s * k[0]
    return R


@jit
def motion_inverse(R: np.ndarray, p: np.ndarray, m: np.ndarray, out: np.ndarray) -> None:
    """out = ^iX_λ m: a parent-frame motion [v; ω] in the child frame of (R, p)
    (ω_c = Rᵀ ω, v_c = Rᵀ (v − p × ω))."""
    w0, w1, w2 = m[3], m[4], m[5]
    c0, c1, c2 = _cross3(p[0], p[1], p[2], w0, w1, w2)
    l0, l1, l2 = m[0] - c0, m[1] - c1, m[2] - c2
    for i in range(3):
        out[i] = R[0, i] * l0 + R[1, i] * l1 + R[2, i] * l2
        out[3 + i] = R[0, i] * w0 + R[1, i] * w1 + R[2, i] * w2


@jit
def _force_to_parent(R: np.ndarray, p: np.ndarray, f: np.ndarray, out: np.ndarray) -> None:
    """out += ^iX_λᵀ f: a child-frame force [f; n] in the parent frame (f_p = R f,
    n_p = R n + p × R f)."""
    f0 = R[0, 0] * f[0] + R[0, 1] * f[1] + R[0, 2] * f[2]
    f1 = R[1, 0] * f[0] + R[1, 1] * f[1] + R[1, 2] * f[2]
    f2 = R[2, 0] * f[0] + R[2, 1] * f[1] + R[2, 2] * f[2]
    n0 = R[0, 0] * f[3] + R[0, 1] * f[4] + R[0, 2] * f[5]
    n1 = R[1, 0] * f[3] + R[1, 1] * f[4] + R[1, 2] * f[5]
    n2 = R[2, 0] * f[3] + R[2, 1] * f[4] + R[2, 2] * f[5]
    c0, c1, c2 = _cross3(p[0], p[1], p[2], f0, f1, f2)
    out[0] += f0
    out[1] += f1
    out[2] += f2
    out[3] += n0 + c0
    out[4] += n1 + c1
    out[5] += n2 + c2


@jit
def motion_cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = a × b of motions [v; ω]: [ω_a × v_b + v_a × ω_b; ω_a × ω_b]."""
    x0, x1, x2 = _cross3(a[3], a[4], a[5], b[0], b[1], b[2])
    y0, y1, y2 = _cross3(a[0], a[1], a[2], b[3], b[4], b[5])
    z0, z1, z2 = _cross3(a[3], a[4], a[5], b[3], b[4], b[5])
    out[0], out[1], out[2] = x0 + y0, x1 + y1, x2 + y2
    out[3], out[4], out[5] = z0, z1, z2


@jit
def _force_cross(a: np.ndarray, f: np.ndarray, out: np.ndarray) -> None:
    """out = a ×* f of a motion [v; ω] and a force [f; n]: [ω × f; ω × n + v × f]."""
    x0, x1, x2 = _cross3(a[3], a[4], a[5], f[0], f[1], f[2])
    y0, y1, y2 = _cross3(a[3], a[4], a[5], f[3], f[4], f[5])
    z0, z1, z2 = _cross3(a[0], a[1], a[2], f[0], f[1], f[2])
    out[0], out[1], out[2] = x0, x1, x2
    out[3], out[4], out[5] = y0 + z0, y1 + z1, y2 + z2


@jit
def _inertia_to_parent(R: np.ndarray, p: np.ndarray, Ia: np.ndarray, out: np.ndarray) -> None:
    """out += ^iX_λᵀ Ia ^iX_λ, column by column: ^iX_λ of each unit parent motion, Ia times
    it, the force carried to the parent."""
    e = np.zeros(6)
    m = np.empty(6)
    f = np.empty(6)
    col = np.empty(6)
    for k in range(6):
        e[:] = 0.0
        e[k] = 1.0
        motion_inverse(R, p, e, m)
        for i in range(6):
            s = 0.0
            for j in range(6):
                s += Ia[i, j] * m[j]
            f[i] = s
        col[:] = 0.0
        _force_to_parent(R, p, f, col)
        for i in range(6):
            out[i, k] += col[i]


@jit
def forward_dynamics(tree: RigidTree, q: np.ndarray, v: np.ndarray, tau: np.ndarray
                     ) -> np.ndarray:
    """v̇ = M(q)⁻¹ (τ − C(q, v) v), gravity off (eq. 29), by the articulated-body algorithm
    (module docstring)."""
    nj = tree.parent.size
    R = np.empty((nj, 3, 3))
    p = np.empty((nj, 3))
    vel = np.zeros((nj, 6))
    c = np.zeros((nj, 6))
    IA = tree.inertia.copy()
    pA = np.zeros((nj, 6))
    U = np.zeros((nj, 6))
    D = np.zeros(nj)
    u = np.zeros(nj)
    vJ = np.zeros(6)
    tmp = np.empty(6)
    # Pass 1: each joint's placement in its parent, velocity, bias acceleration and force.
    for j in range(1, nj):
        par, iq, iv = tree.parent[j], tree.q_index[j], tree.v_index[j]
        Rp, pp = tree.placement_R[j], tree.placement_p[j]
        if j == 1:  # the free joint: q = [p; x, y, z, w], v its frame's [v; ω]
            RJ = quat_rotation(q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6])
            for a in range(3):
                p[j, a] = pp[a] + Rp[a, 0] * q[iq] + Rp[a, 1] * q[iq + 1] + Rp[a, 2] * q[iq + 2]
            for a in range(6):
                vJ[a] = v[iv + a]
        else:
            RJ = axis_rotation(tree.axis[j], q[iq])
            p[j] = pp
            vJ[:3] = 0.0
            for a in range(3):
                vJ[3 + a] = tree.axis[j, a] * v[iv]
        for a in range(3):
            for b in range(3):
                R[j, a, b] = Rp[a, 0] * RJ[0, b] + Rp[a, 1] * RJ[1, b] + Rp[a, 2] * RJ[2, b]
        motion_inverse(R[j], p[j], vel[par], vel[j])
        for a in range(6):
            vel[j, a] += vJ[a]
        motion_cross(vel[j], vJ, c[j])
        for a in range(6):
            s = 0.0
            for b in range(6):
                s += IA[j, a, b] * vel[j, b]
            tmp[a] = s
        _force_cross(vel[j], tmp, pA[j])
    # Pass 2: the articulated inertias and bias forces, leaves to root.
    Ia = np.empty((6, 6))
    pa = np.empty(6)
    for j in range(nj - 1, 1, -1):
        par, iv, k = tree.parent[j], tree.v_index[j], tree.axis[j]
        for a in range(6):
            U[j, a] = IA[j, a, 3] * k[0] + IA[j, a, 4] * k[1] + IA[j, a, 5] * k[2]
        D[j] = k[0] * U[j, 3] + k[1] * U[j, 4] + k[2] * U[j, 5]
        u[j] = tau[iv] - (k[0] * pA[j, 3] + k[1] * pA[j, 4] + k[2] * pA[j, 5])
        for a in range(6):
            for b in range(6):
                Ia[a, b] = IA[j, a, b] - U[j, a] * U[j, b] / D[j]
        for a in range(6):
            s = pA[j, a] + U[j, a] * u[j] / D[j]
            for b in range(6):
                s += Ia[a, b] * c[j, b]
            pa[a] = s
        _inertia_to_parent(R[j], p[j], Ia, IA[par])
        _force_to_parent(R[j], p[j], pa, pA[par])
    # Pass 3: accelerations, root to leaves; the free joint solves its 6×6 system.
    acc = np.zeros((nj, 6))
    out = np.empty(v.size)
    rhs = np.empty(6)
    for a in range(6):
        s = tau[a] - pA[1, a]
        for b in range(6):
            s -= IA[1, a, b] * c[1, b]
        rhs[a] = s
    qdd = solve(IA[1], rhs)
    for a in range(6):
        acc[1, a] = c[1, a] + qdd[a]
        out[tree.v_index[1] + a] = qdd[a]
    for j in range(2, nj):
        par, iv, k = tree.parent[j], tree.v_index[j], tree.axis[j]
        motion_inverse(R[j], p[j], acc[par], acc[j])
        s = u[j]
        for a in range(6):
            acc[j, a] += c[j, a]
            s -= U[j, a] * acc[j, a]
        qdd_j = s / D[j]
        out[iv] = qdd_j
        for a in range(3):
            acc[j, 3 + a] += k[a] * qdd_j
    return out
