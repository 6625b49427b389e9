"""The robot the code sees is the robot in the file: Pinocchio's model of a robot file against
MuJoCo's own compile of the same file (eq. 1).

MuJoCo defines what an MJCF means and compiles URDF through its own importer, so it is an
independent second reading of every robot file. :func:`crosscheck_robot_file` compares the
two at the neutral configuration and at :data:`N_RANDOM` seeded random ones (random bus
position within ±:data:`BUS_RANGE` m, a uniform unit quaternion, each arm joint uniform within
its limits):

- the world placement (position and rotation) of every body both keep (matched by name), of
  every joint (its anchor and world axis) and of every MJCF site, the camera frame first;
- each moving rigid body's mass, CoM and rotational inertia about that CoM, in world axes.
  Pinocchio merges the bodies fixed to a joint into that joint's inertia and MuJoCo keeps
  them, so MuJoCo's bodies are summed by the body they are welded to (``body_weldid``, the
  owner of their dofs) and compared with Pinocchio's joint inertia;
- the total mass and the whole-body CoM;
- each body's twist for a random velocity, and the joint-space inertia matrix M (eq. 1,
  Pinocchio's CRBA against ``mj_fullM``).

Conventions. MuJoCo's free joint has qpos = [p; quat (w, x, y, z)] and qvel = [ṗ in world;
ω in body], Pinocchio's free flyer q = [p; quat (x, y, z, w)] and v = [v_b; ω_b] both in the
body frame (eq. 1). So v_mj = T v_pin with T = blkdiag(R_tb, I₃, I₆) (the arm's dofs permuted
by name), and the kinetic energy ½ v_mjᵀ M_mj v_mj = ½ v_pinᵀ M_pin v_pin gives
M_pin = Tᵀ M_mj T. The convention is verified, not assumed: every body's twist, mapped through
T, must agree before M is compared.

Tolerances: round-off, not engineering. Both parsers read the same decimal numbers and
compose the same products of rigid transforms; they differ only in the order and kind of
floating-point operations (euler and rpy angles to rotations, MuJoCo's quaternions and
diagonalised inertias against Pinocchio's matrices, MuJoCo's CoM-centred spatial algebra
against Pinocchio's local frames). A quantity therefore passes when

    max |x_pin − x_mj| ≤ ULPS · ε · scale,     ULPS = 256, ε = 2.2e-16 (float64),

with ``scale`` the largest magnitude of that kind of quantity in the comparison (normwise, as
floating-point error bounds are): the largest position (m) among the compared frames, 1 for
rotation entries and unit axes, the total mass (kg), the largest inertia entry (kg·m²), the
largest twist entry times (1 + the largest position) (a twist is moved between points by
lever arms of that size), the largest entry of M. Chains of a dozen rotations and products
cost tens of ulp at most; on the shipped robots the largest difference is 19 ulp of its scale
(docs/architecture.md §2), so 256 leaves a margin above ten, while a modelling difference (a
misplaced frame or a mis-read inertia, 1e-9 relative and more) is orders of magnitude above.

The verdict is cached by the SHA-256 of the file's content, the camera frame's name, the pin
and mujoco versions and this module's own source (a changed check checks again), in one small
JSON file per key (:func:`cache_dir`), written atomically: a warm run reads it and imports
neither MuJoCo nor anything else. Only a pass is cached; a disagreement is a
:class:`~pipeline.errors.SpecError` of one line naming the file, the frame or body, both values
and the likely cause, every time.
"""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.errors import OutputError, SpecError
from pipeline.paths import PACKAGE_DIR, source_checkout, user_cache_dir
from pipeline.shapes import Q

ULPS = 256
EPS = float(np.finfo(float).eps)
N_RANDOM = 3
SEED = 2534
BUS_RANGE = 5.0  # m
URDF_SUFFIXES = (".urdf",)
ISSUE_2534 = ("Pinocchio's MJCF parser up to 4.1.0 misplaces it (pinocchio issue 2534); "
              "declare it on the jointed body")


@dataclass(frozen=True)
class CrossCheck:
    """A passed cross-parse: what was compared and the largest differences found (SI units),
    each with the tolerance it was held to."""

    file: str
    sha256: str
    pin: str
    mujoco: str
    camera_frame: str
    bodies: list[str]  # compared by placement and twist
    joints: list[str]  # compared by anchor and axis, and as rigid bodies (inertia)
    sites: list[str]  # MJCF sites compared by placement
    configurations: int
    max_diff: dict[str, float]
    tol: dict[str, float]
    notes: list[str] = field(default_factory=list)  # e.g. a missing mesh the check did not need


def cache_dir() -> Path:
    """Where verdicts are cached: beside the compiled kernels in a source checkout, in the
    per-user cache folder of an installed package (:func:`pipeline.paths.user_cache_dir`)."""
    if source_checkout():
        return PACKAGE_DIR / "sim" / "__pycache__" / "robot-crosscheck"
    return user_cache_dir() / "robot-crosscheck"


@functools.lru_cache(maxsize=1)
def _code_identity() -> tuple[bytes, bytes, bytes]:
    """(pin's version, mujoco's, this module's source), read once per process: reading an
    installed package's version parses its metadata file, about 9 ms, and every mission and
    Monte Carlo sample loads its robot."""
    return (pin.__version__.encode(), metadata.version("mujoco").encode(),
            Path(__file__).read_bytes())


def cache_key(path: Path, camera_frame: str, package_dirs: tuple[Path, ...] = ()) -> str:
    """SHA-256 over the file's bytes, the camera frame, the package folders, the pin and
    mujoco versions and this module's source."""
    h = hashlib.sha256()
    dirs = "\0".join(str(Path(d).resolve()) for d in package_dirs)
    for part in (path.read_bytes(), camera_frame.encode(), dirs.encode(), *_code_identity()):
        h.update(hashlib.sha256(part).digest())
    return h.hexdigest()


def crosscheck_robot_file(path: Path | str, model: pin.Model, camera_frame: str,
                          package_dirs: tuple[Path, ...] = ()) -> CrossCheck:
    """Check ``model`` (Pinocchio's parse of ``path``) against MuJoCo's, once per file content.
    ``package_dirs``: where ``package://`` mesh URIs are looked for (robot.package_dirs).

    Raises :class:`~pipeline.errors.SpecError` on a disagreement beyond round-off.
    """
    path = Path(path)
    key = cache_key(path, camera_frame, package_dirs)
    stored = cache_dir() / f"{key}.json"
    try:
        return CrossCheck(**json.loads(stored.read_text()))
    except (OSError, ValueError, TypeError):
        pass
    result = compare_parsers(path, model, camera_frame, package_dirs)
    try:
        from pipeline.atomic_files import atomic_write_text

        atomic_write_text(stored, json.dumps(asdict(result), indent=1) + "\n")
    except OutputError:
        pass  # a read-only cache costs a check per process, nothing else
    return result


# -- MuJoCo's reading of the file -----------------------------------------------------------

def mujoco_model(path: Path, package_dirs: tuple[Path, ...] = ()):
    """MuJoCo's compile of ``path``: an MJCF as it is; a URDF through MuJoCo's importer with its
    fixed links kept as bodies (``fusestatic`` off, as Pinocchio keeps them as frames) and a
    free joint added to the root link (the bus), as the loader adds Pinocchio's free flyer.
    Meshes are resolved as :func:`mujoco_spec` says."""
    return mujoco_spec(path, package_dirs)[0].compile()


def mujoco_spec(path: Path, package_dirs: tuple[Path, ...] = ()) -> tuple[object, list[str]]:
    """MuJoCo's reading of ``path`` before it compiles, and what was left out of it: a mesh
    file that is missing (or a ``package://`` URI that none of ``package_dirs`` holds) is not
    needed for what the cross-parse compares (placements, masses, inertias) where its body's
    inertia is explicit: its geoms are dropped, said in the returned notes. A body whose
    inertia would come from its geoms (no explicit inertial) with a mesh missing is refused
    naming the body: its mass is the mesh's."""
    import mujoco

    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        first = (str(exc).strip().splitlines() or ["?"])[0]
        raise SpecError(f"{path}: MuJoCo cannot read it ({first[:300]})") from None
    if path.suffix.lower() in URDF_SUFFIXES:
        spec.compiler.fusestatic = False
        spec.compiler.discardvisual = True
        roots = list(spec.worldbody.bodies)
        if len(roots) != 1:
            raise SpecError(f"{path}: MuJoCo's URDF importer finds {len(roots)} root links, "
                            f"not one")
        roots[0].add_freejoint(name="root_joint")
    notes = _drop_missing_meshes(spec, path, package_dirs)
    return spec, notes


def _mesh_file(spec, mesh, path: Path, package_dirs: tuple[Path, ...]) -> Path | None:
    """Where a mesh's file is, or None when it is not there."""
    name = mesh.file
    if name.startswith("package://"):
        rest = name.removeprefix("package://")
        package, _, inside = rest.partition("/")
        for d in package_dirs:
            for cand in (d / package / inside, d / rest, d / inside):
                if cand.is_file():
                    mesh.file = str(cand.resolve())
                    return cand
        return None
    base = Path(spec.modelfiledir or path.parent) / (spec.meshdir or "")
    cand = Path(name) if Path(name).is_absolute() else base / name
    return cand if cand.is_file() else None


# The mesh formats MuJoCo decodes without a plugin; a ROS description's Collada (.dae) is not
# one of them.
MUJOCO_MESH_SUFFIXES = (".stl", ".obj", ".msh")


def _unusable(spec, mesh, path: Path, package_dirs: tuple[Path, ...]) -> str | None:
    """Why MuJoCo cannot use a mesh (missing, or a format it does not decode), or None."""
    found = _mesh_file(spec, mesh, path, package_dirs)
    if found is None:
        return "missing"
    if found.suffix.lower() not in MUJOCO_MESH_SUFFIXES:
        return f"in a format MuJoCo does not read ({found.suffix})"
    return None


def _drop_missing_meshes(spec, path: Path, package_dirs: tuple[Path, ...]) -> list[str]:
    import mujoco

    notes = []
    from_geoms = spec.compiler.inertiafromgeom != mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    for mesh in list(spec.meshes):
        why = _unusable(spec, mesh, path, package_dirs)
        if why is None:
            continue
        users = [g for g in spec.geoms if g.meshname == mesh.name]
        for g in users:
            body = g.parent
            forced = spec.compiler.inertiafromgeom == \
                mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
            if from_geoms and (forced or not body.explicitinertial):
                raise SpecError(f"{path}: body {body.name!r}: its inertia comes from its "
                                f"geoms, and its mesh {mesh.file!r} is {why} (give the body "
                                f"an explicit inertial, or the mesh"
                                + (", robot.package_dirs for package:// URIs"
                                   if mesh.file.startswith("package://") else "") + ")")
        owners = sorted({g.parent.name for g in users})
        for g in users:
            spec.delete(g)
        spec.delete(mesh)
        notes.append(f"mesh {mesh.file} {why}, not needed: "
                     + (f"the inertia of {', '.join(owners)} is explicit" if owners else
                        "no geom uses it"))
    return notes


@dataclass
class _Pair:
    """Both models, their data, and what matches between them (Pinocchio id, MuJoCo id)."""

    path: Path
    model: pin.Model
    data: pin.Data
    mj: object
    d: object
    bodies: dict[str, tuple[int, int]]  # BODY frame, body
    joints: dict[str, tuple[int, int]]  # joint, joint (the free flyer: the free joint)
    sites: dict[str, tuple[int, int]]  # OP_FRAME, site
    camera: tuple[str, str]  # ("site" | "body", its name)
    notes: list[str]  # what MuJoCo's reading left out (missing meshes not needed)


def _pair(path: Path, model: pin.Model, camera_frame: str,
          package_dirs: tuple[Path, ...] = ()) -> _Pair:
    import mujoco

    spec, notes = mujoco_spec(path, package_dirs)
    try:
        mj = spec.compile()
    except ValueError as exc:  # MuJoCo's compile error
        reason = " ".join(str(exc).split()) or "?"
        raise SpecError(f"{path}: MuJoCo cannot compile it ({reason[:600]}); "
                        "the cross-parse needs it") from None

    def mj_id(kind, name: str) -> int:
        return mujoco.mj_name2id(mj, kind, name)

    frames = [(f.name, f.type, i) for i, f in enumerate(model.frames)]
    bodies = {n: (i, b) for n, t, i in frames if t == pin.FrameType.BODY
              and (b := mj_id(mujoco.mjtObj.mjOBJ_BODY, n)) > 0}
    sites = {n: (i, s) for n, t, i in frames if t == pin.FrameType.OP_FRAME
             and (s := mj_id(mujoco.mjtObj.mjOBJ_SITE, n)) >= 0}
    free = [j for j in range(mj.njnt) if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    joints = {}
    for i in range(1, model.njoints):
        name = model.names[i]
        j = free[0] if i == 1 and len(free) == 1 else mj_id(mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0 or (i > 1 and mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE):
            raise SpecError(f"{path}: Pinocchio's joint {name!r} has no MuJoCo counterpart; "
                            "the two parsers build different trees")
        joints[name] = (i, j)
    if len(joints) != mj.njnt:
        raise SpecError(f"{path}: MuJoCo finds {mj.njnt} joints, Pinocchio {len(joints)}")
    if camera_frame in sites:
        camera = ("site", camera_frame)
    elif camera_frame in bodies:
        camera = ("body", camera_frame)
    else:
        raise SpecError(f"{path}: MuJoCo finds no site or body {camera_frame!r} "
                        "(robot.camera_frame)")
    return _Pair(path, model, model.createData(), mj, mujoco.MjData(mj), bodies, joints, sites,
                 camera, notes)


def _set_mujoco(p: _Pair, q: np.ndarray) -> np.ndarray:
    """MuJoCo's state at Pinocchio's q (forward kinematics and CRBA done); returns T (v_mj =
    T v_pin) at that configuration."""
    import mujoco

    model, mj, d = p.model, p.mj, p.d
    pin.forwardKinematics(model, p.data, q)
    T = np.zeros((mj.nv, model.nv))
    for i, j in p.joints.values():
        jm, qa, va = model.joints[i], mj.jnt_qposadr[j], mj.jnt_dofadr[j]
        if i == 1:  # MuJoCo's free-joint qpos is the body's world pose
            M = p.data.oMi[1]
            xyzw = pin.SE3ToXYZQUAT(M)[3:]
            d.qpos[qa:qa + 3] = M.translation
            d.qpos[qa + 3:qa + 7] = xyzw[[3, 0, 1, 2]]
            T[va:va + 3, jm.idx_v:jm.idx_v + 3] = M.rotation
            T[va + 3:va + 6, jm.idx_v + 3:jm.idx_v + 6] = np.eye(3)
        elif jm.nq == 1:
            d.qpos[qa] = q[jm.idx_q]
            T[va, jm.idx_v] = 1.0
        else:  # an unbounded revolute joint: (cos, sin)
            d.qpos[qa] = np.arctan2(q[jm.idx_q + 1], q[jm.idx_q])
            T[va, jm.idx_v] = 1.0
    d.qvel[:] = 0.0
    mujoco.mj_forward(mj, d)
    return T


def configurations(model: pin.Model, n_random: int = N_RANDOM, seed: int = SEED
                   ) -> list[tuple[str, np.ndarray]]:
    """The neutral configuration and ``n_random`` seeded random ones (labelled)."""
    rng = np.random.default_rng(seed)
    out = [("the neutral configuration", pin.neutral(model))]
    for k in range(n_random):
        q = pin.neutral(model)
        q[0:3] = rng.uniform(-BUS_RANGE, BUS_RANGE, 3)
        quat = rng.standard_normal(4)
        q[Q.quat_tb] = quat / np.linalg.norm(quat)
        for i in range(2, model.njoints):
            jm = model.joints[i]
            if jm.nq == 1:
                lo, hi = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
                lo, hi = (lo, hi) if np.isfinite(lo) and np.isfinite(hi) else (-np.pi, np.pi)
                q[jm.idx_q] = rng.uniform(lo, hi)
            else:
                a = rng.uniform(-np.pi, np.pi)
                q[jm.idx_q:jm.idx_q + 2] = np.cos(a), np.sin(a)
        out.append((f"random configuration {k + 1} (seed {seed})", q))
    return out


# -- The comparison -------------------------------------------------------------------------

def _fmt(x: np.ndarray | float) -> str:
    a = np.atleast_1d(np.asarray(x, dtype=float)).ravel()
    return f"{a[0]:.6g}" if a.size == 1 else "(" + ", ".join(f"{v:.4f}" for v in a) + ")"


class _Diffs:
    """The largest difference of each kind over the configurations, and its tolerance."""

    def __init__(self, path: Path):
        self.path, self.max_diff, self.tol = path, {}, {}

    def check(self, kind: str, what: str, a, b, scale: float, where: str, unit: str,
              cause: str, shown: tuple | None = None) -> None:
        """Hold max |a − b| to ULPS·ε·scale; record it, or raise naming ``what``."""
        diff = float(np.max(np.abs(np.asarray(a) - np.asarray(b)), initial=0.0))
        tol = ULPS * EPS * max(scale, np.finfo(float).tiny)
        self.max_diff[kind] = max(self.max_diff.get(kind, 0.0), diff)
        self.tol[kind] = max(self.tol.get(kind, 0.0), tol)
        if not diff <= tol:
            sa, sb = shown if shown is not None else (a, b)
            raise SpecError(
                f"{self.path}: Pinocchio and MuJoCo disagree on {what} at {where}: Pinocchio "
                f"{_fmt(sa)}{unit}, MuJoCo {_fmt(sb)}{unit} (max difference {diff:.3g} > "
                f"round-off tolerance {tol:.3g}); likely cause: {cause}")


def _site_cause(p: _Pair, site: int) -> str:
    body = int(p.mj.site_bodyid[site])
    if p.mj.body_jntnum[body] == 0:
        name = p.mj.body(body).name
        return f"a site of a body without a joint ({name!r}): {ISSUE_2534}"
    return "the parsers place the site differently (its pos, quat or euler attribute)"


TREE_CAUSE = ("the parsers compose the kinematic tree differently (a pos, quat, euler or "
              "axisangle attribute, the compiler's angle unit, or a URDF origin rpy)")
INERTIA_CAUSE = ("the parsers read the inertial data differently (an inertial frame, a "
                 "fullinertia order, a compiler inertia option, or a body merged elsewhere)")


def mujoco_slide() -> int:
    """MuJoCo's code of a slide (prismatic) joint."""
    import mujoco

    return int(mujoco.mjtJoint.mjJNT_SLIDE)


def _placements(p: _Pair, c: _Diffs, where: str) -> None:
    """World placements: the bodies from the root down (the first to disagree points at the
    cause), then the sites (the camera frame first), then the joints (anchor, world axis).
    A site is blamed only once its body agrees."""
    model, data, d = p.model, p.data, p.d
    pin.updateFramePlacements(model, data)
    pin.computeJointJacobians(model, data)
    camera = f"{p.camera[0]} {p.camera[1]!r}"
    items = [(f"body {n!r}", fid, d.xpos[b], d.xmat[b], TREE_CAUSE)
             for n, (fid, b) in sorted(p.bodies.items(), key=lambda it: it[1][1])]
    items += sorted([(f"site {n!r}", fid, d.site_xpos[s], d.site_xmat[s], _site_cause(p, s))
                     for n, (fid, s) in p.sites.items()], key=lambda it: it[0] != camera)
    scale = max([1.0] + [np.max(np.abs(it[2])) for it in items])
    for what, fid, x_mj, R_mj, cause in items:
        oMf = data.oMf[fid]
        label = what + (" (the camera frame)" if what == camera else "")
        c.check("position", f"the position of {label}", oMf.translation, x_mj, scale, where,
                " m", cause)
        R_mj = np.reshape(R_mj, (3, 3))
        c.check("rotation", f"the rotation of {label}", oMf.rotation, R_mj, 1.0, where,
                " (quaternion x, y, z, w)",
                cause, shown=(pin.Quaternion(oMf.rotation).coeffs(),
                              pin.Quaternion(R_mj).coeffs()))
    for n, (i, j) in p.joints.items():
        if i == 1:
            continue
        axis, r = d.xaxis[j], data.oMi[i].translation - d.xanchor[j]
        if p.mj.jnt_type[j] == mujoco_slide():
            # A slide joint's axis is its twist's linear part; it has no line of its own.
            c.check("axis", f"the world axis of joint {n!r}", data.J[:3, model.joints[i].idx_v],
                    axis, 1.0, where, "", TREE_CAUSE)
            continue
        c.check("axis", f"the world axis of joint {n!r}", data.J[3:, model.joints[i].idx_v],
                axis, 1.0, where, "", TREE_CAUSE)
        # Any point of the axis line is the same joint: the anchors' offset across the axis.
        c.check("position", f"the axis line of joint {n!r} (anchors)", r - axis * (axis @ r),
                0.0, scale, where, " m", TREE_CAUSE,
                shown=(data.oMi[i].translation, d.xanchor[j]))


def _mujoco_rigid_body(p: _Pair, body: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, world CoM and world inertia about it of MuJoCo's bodies welded to ``body``."""
    mj, d = p.mj, p.d
    group = [b for b in range(1, mj.nbody) if mj.body_weldid[b] == body]
    m = float(sum(mj.body_mass[b] for b in group))
    com = (sum(mj.body_mass[b] * d.xipos[b] for b in group) / m if m > 0
           else np.array(d.xpos[body]))
    inertia = np.zeros((3, 3))
    for b in group:  # each body's principal inertia, rotated to world, moved to the CoM
        R, r = d.ximat[b].reshape(3, 3), d.xipos[b] - com
        inertia += (R @ np.diag(mj.body_inertia[b]) @ R.T
                    + mj.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r)))
    return m, com, inertia


def _inertias(p: _Pair, c: _Diffs, q: np.ndarray, where: str) -> None:
    """Each moving rigid body, the total mass m and the whole-body CoM p_c (eq. 1)."""
    model, data, mj, d = p.model, p.data, p.mj, p.d
    total = float(sum(model.inertias[i].mass for i in range(model.njoints)))
    total_mj = float(mj.body_mass[1:].sum())
    c.check("mass", "the total mass", total, total_mj, total, where, " kg",
            "a body one parser keeps and the other drops, or one fixed to the world")
    bodies = [(n, data.oMi[i].act(model.inertias[i]), _mujoco_rigid_body(p, mj.jnt_bodyid[j]))
              for n, (i, j) in p.joints.items()]
    pos_scale = max(1.0, *(np.max(np.abs(b[1].lever)) for b in bodies))
    I_scale = max(np.max(np.abs(b[1].inertia)) for b in bodies)
    for n, Y, (m_mj, com_mj, I_mj) in bodies:
        what = f"the rigid body of joint {n!r}"
        c.check("mass", f"the mass of {what}", Y.mass, m_mj, total, where, " kg", INERTIA_CAUSE)
        c.check("com", f"the world CoM of {what}", Y.lever, com_mj, pos_scale, where, " m",
                INERTIA_CAUSE)
        c.check("inertia", f"the world inertia about its CoM of {what}", Y.inertia, I_mj,
                I_scale, where, " kg m^2", INERTIA_CAUSE,
                shown=(np.diag(Y.inertia), np.diag(I_mj)))
    c.check("com", "the whole-body CoM", pin.centerOfMass(model, data, q), d.subtree_com[0],
            pos_scale, where, " m", INERTIA_CAUSE)


def _twists(p: _Pair, c: _Diffs, q: np.ndarray, T: np.ndarray, where: str,
            rng: np.random.Generator) -> None:
    """Verify the velocity convention v_mj = T v_pin: every body's and site's LOCAL twist
    [v; ω] (eq. 1) for one random v_pin (MuJoCo returns [ω; v])."""
    import mujoco

    model, data, mj, d = p.model, p.data, p.mj, p.d
    v = rng.standard_normal(model.nv)
    pin.forwardKinematics(model, data, q, v)
    d.qvel[:] = T @ v
    mujoco.mj_forward(mj, d)
    objs = [(f"body {n!r}", fid, mujoco.mjtObj.mjOBJ_XBODY, b) for n, (fid, b) in p.bodies.items()]
    objs += [(f"site {n!r}", fid, mujoco.mjtObj.mjOBJ_SITE, s) for n, (fid, s) in p.sites.items()]
    pairs = []
    for what, fid, kind, k in objs:
        res = np.zeros(6)
        mujoco.mj_objectVelocity(mj, d, kind, k, res, 1)
        pairs.append((what, pin.getFrameVelocity(model, data, fid, pin.LOCAL).vector,
                      np.concatenate([res[3:], res[:3]])))
    lever = max(1.0, float(np.max(np.abs(d.xpos))))
    scale = lever * max(float(np.max(np.abs(np.array([a for _, a, _ in pairs])))), 1e-300)
    for what, a, b in pairs:
        c.check("twist", f"the LOCAL twist [v; w] of {what} for v_mj = T v_pin", a, b, scale,
                where, "", "the free joint's velocity convention (MuJoCo: world linear, body "
                "angular; Pinocchio: both in the body frame) or a joint's axis or sign")
    d.qvel[:] = 0.0


def _mass_matrix(p: _Pair, c: _Diffs, q: np.ndarray, T: np.ndarray, where: str) -> None:
    """M_pin (CRBA, eq. 1) against Tᵀ M_mj T (``mj_fullM``)."""
    import mujoco

    M = pin.crba(p.model, p.data, q)
    M = np.triu(M) + np.triu(M, 1).T
    M_mj = np.zeros((p.mj.nv, p.mj.nv))
    mujoco.mj_fullM(p.mj, p.d, M_mj)
    M_mj = T.T @ M_mj @ T
    k = np.unravel_index(np.argmax(np.abs(M - M_mj)), M.shape)
    c.check("mass_matrix", f"the joint-space inertia matrix M (largest at [{k[0]}, {k[1]}])",
            M, M_mj, float(np.max(np.abs(M))), where, "",
            "a joint axis, an armature or the free joint's velocity convention",
            shown=(M[k], M_mj[k]))


def compare_parsers(path: Path, model: pin.Model, camera_frame: str,
                    package_dirs: tuple[Path, ...] = ()) -> CrossCheck:
    """Compare Pinocchio's ``model`` of ``path`` with MuJoCo's compile of it (no cache)."""
    p = _pair(path, model, camera_frame, package_dirs)
    c = _Diffs(path)
    rng = np.random.default_rng(SEED + 1)
    confs = configurations(model)
    for where, q in confs:
        T = _set_mujoco(p, q)
        _placements(p, c, where)
        _inertias(p, c, q, where)
        _twists(p, c, q, T, where, rng)
        _mass_matrix(p, c, q, T, where)
    return CrossCheck(
        file=str(path), sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
        pin=pin.__version__, mujoco=metadata.version("mujoco"), camera_frame=camera_frame,
        bodies=sorted(p.bodies), joints=list(p.joints), sites=sorted(p.sites),
        configurations=len(confs), max_diff=c.max_diff, tol=c.tol, notes=p.notes)
