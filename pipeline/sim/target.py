"""Procedural target spacecraft and camera coverage (eq. 18).

The target is a box bus with two solar-panel wings along its y-axis, centred at the t-frame
origin, sampled as surface points with outward normals (panels have two faces). No meshes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pipeline.sim.jit import jit
from pipeline.spec import Camera, Target


@dataclass(frozen=True)
class TargetGeometry:
    points: np.ndarray  # N×3, t frame
    normals: np.ndarray  # N×3, unit


def _face_samples(rng, n, centre, u, v, normal):
    a = rng.uniform(-0.5, 0.5, size=(n, 2))
    pts = centre + a[:, :1] * u + a[:, 1:] * v
    return pts, np.broadcast_to(normal, pts.shape)


def build_target(cfg: Target) -> TargetGeometry:
    """Sample the target's surface: points spread over faces in proportion to their area."""
    sx, sy, sz = cfg.bus_size
    ex, ey, ez = np.eye(3)
    faces = []  # (centre, u, v, normal)
    for sgn in (1.0, -1.0):
        faces.append((sgn * ex * sx / 2, ey * sy, ez * sz, sgn * ex))
        faces.append((sgn * ey * sy / 2, ex * sx, ez * sz, sgn * ey))
        faces.append((sgn * ez * sz / 2, ex * sx, ey * sy, sgn * ez))
    for side in (1.0, -1.0):  # wings, both faces (normals ±x)
        centre = side * ey * (sy / 2 + cfg.panel_span / 2)
        for sgn in (1.0, -1.0):
            faces.append((centre, ey * cfg.panel_span, ez * cfg.panel_width, sgn * ex))
    # Exactly rounded sums (math.fsum), not NumPy's: its dot products go to BLAS and its
    # reductions to SIMD code, both chosen for the processor, and a last-bit difference here
    # could move a point from one face to the next.
    areas = np.array([math.sqrt(math.fsum(np.cross(u, v) ** 2)) for _, u, v, _ in faces])
    counts = np.floor(cfg.n_points * areas / math.fsum(areas)).astype(int)
    counts[: cfg.n_points - counts.sum()] += 1
    rng = np.random.default_rng(cfg.seed)
    pts, nrm = zip(*(_face_samples(rng, k, *f) for k, f in zip(counts, faces, strict=True)),
                   strict=True)
    return TargetGeometry(np.ascontiguousarray(np.vstack(pts)),
                          np.ascontiguousarray(np.vstack(nrm)))


def visible(target: TargetGeometry, p_e: np.ndarray, R_te: np.ndarray, cam: Camera) -> np.ndarray:
    """Points seen by the camera (eq. 18): in the field of view, within [d_min, d_max] along
    the boresight, and with incidence (normal vs line of sight) below ``max_angle``.
    Occlusion is not modelled.
    """
    return visible_mask(target.points, target.normals, np.ascontiguousarray(p_e),
                        np.ascontiguousarray(R_te), *camera_limits(cam))


def camera_limits(cam: Camera) -> tuple[float, float, float, float]:
    """(tan(fov/2), d_min, d_max, cos(max_angle)): the camera's bounds as the kernels take them."""
    return (math.tan(math.radians(cam.fov_deg) / 2), cam.d_min, cam.d_max,
            math.cos(math.radians(cam.max_angle_deg)))


class CoverageCounter(NamedTuple):
    """The target points seen so far by a camera and their count (eq. 18), with the camera's
    bounds: the step kernel's coverage bundle, updated in place (:func:`mark_visible`)."""

    points: np.ndarray  # N×3, t frame
    normals: np.ndarray  # N×3, unit
    tan_half_fov: float
    d_min: float
    d_max: float
    cos_max: float
    seen: np.ndarray  # N booleans
    count: np.ndarray  # how many are seen; one integer in an array, updated in place

    @classmethod
    def start(cls, target: TargetGeometry, cam: Camera) -> CoverageCounter:
        """Nothing seen yet."""
        return cls(target.points, target.normals, *camera_limits(cam),
                   seen=np.zeros(len(target.points), dtype=bool),
                   count=np.zeros(1, dtype=np.int64))


@jit
def mark_visible(points, normals, p_e, R_te, tan_half_fov, d_min, d_max, cos_max, seen):
    """Mark the points the camera sees in ``seen`` (eq. 18); how many were not seen before.

    Point i, with r = p_i − p_e and (x, y, z) = R_teᵀ r, is seen iff d_min <= z <= d_max,
    √(x² + y²) <= z tan(fov/2) and −n_i·r >= ‖r‖ cos(max_angle). Points already seen are
    skipped, and the cheapest test comes first: most points are behind the camera or out of
    range.
    """
    new = 0
    for i in range(points.shape[0]):
        if seen[i]:
            continue
        r0 = points[i, 0] - p_e[0]
        r1 = points[i, 1] - p_e[1]
        r2 = points[i, 2] - p_e[2]
        z = R_te[0, 2] * r0 + R_te[1, 2] * r1 + R_te[2, 2] * r2
        if not d_min <= z <= d_max:
            continue
        x = R_te[0, 0] * r0 + R_te[1, 0] * r1 + R_te[2, 0] * r2
        y = R_te[0, 1] * r0 + R_te[1, 1] * r1 + R_te[2, 1] * r2
        if not np.sqrt(x * x + y * y) <= z * tan_half_fov:
            continue
        facing = -(normals[i, 0] * r0 + normals[i, 1] * r1 + normals[i, 2] * r2)
        if facing >= np.sqrt(r0 * r0 + r1 * r1 + r2 * r2) * cos_max:
            seen[i] = True
            new += 1
    return new


@jit
def visible_mask(points, normals, p_e, R_te, tan_half_fov, d_min, d_max, cos_max):
    """Which points the camera sees (eq. 18; the test of :func:`mark_visible`)."""
    seen = np.zeros(points.shape[0], dtype=np.bool_)
    mark_visible(points, normals, p_e, R_te, tan_half_fov, d_min, d_max, cos_max, seen)
    return seen
