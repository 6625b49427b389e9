"""Procedural target spacecraft and camera coverage (eq. 18).

The target is a box bus with two solar-panel wings along its y-axis, centred at the t-frame
origin, sampled as surface points with outward normals (panels have two faces). No meshes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
    areas = np.array([np.linalg.norm(np.cross(u, v)) for _, u, v, _ in faces])
    counts = np.floor(cfg.n_points * areas / areas.sum()).astype(int)
    counts[: cfg.n_points - counts.sum()] += 1
    rng = np.random.default_rng(cfg.seed)
    pts, nrm = zip(*(_face_samples(rng, k, *f) for k, f in zip(counts, faces, strict=True)),
                   strict=True)
    return TargetGeometry(np.vstack(pts), np.vstack(nrm).copy())


def visible(target: TargetGeometry, p_e: np.ndarray, R_te: np.ndarray, cam: Camera) -> np.ndarray:
    """Points seen by the camera: in the field of view, within [d_min, d_max] along the
    boresight, and with incidence (normal vs line of sight) below ``max_angle``. Occlusion
    is not modelled. Vectorised over points.
    """
    rel = target.points - p_e
    p_cam = rel @ R_te  # rows: R_et (p − p_e)
    depth = p_cam[:, 2]
    lateral = np.hypot(p_cam[:, 0], p_cam[:, 1])
    in_fov = lateral <= depth * np.tan(np.deg2rad(cam.fov_deg) / 2)
    in_range = (depth >= cam.d_min) & (depth <= cam.d_max)
    dist = np.linalg.norm(rel, axis=1)
    cos_inc = -np.einsum("ij,ij->i", target.normals, rel) / np.maximum(dist, 1e-12)
    facing = cos_inc >= np.cos(np.deg2rad(cam.max_angle_deg))
    return in_fov & in_range & facing
