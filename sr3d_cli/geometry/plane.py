"""The supporting plane (table): RANSAC fit on valid depth, ray intersection, heights above it.

A plane is ``n . p + d = 0`` in the camera frame (metres) with the unit normal ``n`` pointing
towards the camera side (``d > 0``), so ``height(p) = n . p + d`` is positive above the table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sr3d_cli.geometry.camera import pixel_rays, project, unproject

if TYPE_CHECKING:
    from sr3d_cli.config import PlaneConfig

FACING = 0.9  # |cos| between a plane's normal and the optical axis above which the camera looks
# straight down onto it (a wrist camera over a table): its tilt in the image is no evidence


@dataclass(frozen=True)
class Plane:
    """normal : (3,) unit vector towards the camera; offset : d in ``n . p + d = 0`` (metres)."""

    normal: np.ndarray
    offset: float
    inlier_share: float = 1.0

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed distance ``(...)`` of points ``(..., 3)`` above the plane, metres."""
        return np.asarray(points, dtype=np.float64) @ self.normal + self.offset

    def intersect(self, rays: np.ndarray) -> np.ndarray:
        """Points ``(..., 3)`` where rays from the camera centre ``(..., 3)`` meet the plane
        (NaN where a ray is parallel to it or meets it behind the camera)."""
        rays = np.asarray(rays, dtype=np.float64)
        denom = rays @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -self.offset / denom
        s = np.where((np.abs(denom) > 1e-9) & (s > 0), s, np.nan)
        return rays * s[..., None]

    def intersect_pixels(self, uv: np.ndarray, K: np.ndarray) -> np.ndarray:
        """Points ``(n, 3)`` on the plane seen at pixels ``(n, 2)``."""
        uv = np.asarray(uv, dtype=np.float64)
        rays = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1],
                         np.ones(len(uv))], axis=1)
        return self.intersect(rays)

    def down_at(self, uv: np.ndarray, K: np.ndarray) -> np.ndarray:
        """Unit image direction (2,) of 'down the table normal' at pixel ``uv`` (2,): image +y
        where the pixel does not see the plane or the normal points along its ray."""
        p = self.intersect_pixels(np.atleast_2d(uv), K)[0]
        if not np.all(np.isfinite(p)):
            return np.array([0.0, 1.0])
        a, b = project(np.stack([p, p + 0.05 * self.normal]), K)
        d = a - b
        return d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else np.array([0.0, 1.0])

    def depth_image(self, shape: tuple[int, int], K: np.ndarray) -> np.ndarray:
        """Depth ``(H, W)`` float64 metres of the plane at every pixel (0 where not seen)."""
        z = self.intersect(pixel_rays(shape, K))[..., 2]
        return np.nan_to_num(z, nan=0.0)

    def project_direction(self, v: np.ndarray) -> np.ndarray:
        """Component of ``v`` parallel to the plane."""
        v = np.asarray(v, dtype=np.float64)
        return v - (v @ self.normal) * self.normal

    def to_json(self) -> dict:
        return {"normal": self.normal.tolist(), "offset": float(self.offset),
                "inlier_share": float(self.inlier_share)}

    @classmethod
    def from_json(cls, doc: dict) -> "Plane":
        return cls(np.asarray(doc["normal"], dtype=np.float64), float(doc["offset"]),
                   float(doc.get("inlier_share", 1.0)))


def _orient(normal: np.ndarray, offset: float) -> tuple[np.ndarray, float]:
    norm = np.linalg.norm(normal)
    normal, offset = normal / norm, offset / norm
    if offset < 0:  # camera centre (origin) must be on the positive side
        normal, offset = -normal, -offset
    return normal, float(offset)


def seen_from_above(plane: Plane) -> bool:
    """Whether ``plane`` can be the table under the objects: the camera looks down onto it, so
    its normal (towards the camera) points up in the image (negative y in the camera frame), or
    the camera faces it squarely (:data:`FACING`). A wall beside or behind the table, seen
    from a camera tilted down at the table, has a normal across the image or down it (a
    ClearGrasp frame whose table the sensor fails on: the room's wall on the left holds more
    readings)."""
    n = plane.normal
    return bool(n[1] < 0.0 or abs(n[2]) >= FACING)


def plane_from_points(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane through points ``(n >= 3, 3)``: (normal, offset), oriented."""
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    normal = vt[-1]
    return _orient(normal, -float(normal @ centre))


def fit_plane_ransac(points: np.ndarray, *, threshold: float, iterations: int,
                     rng: np.random.Generator) -> tuple[Plane, np.ndarray]:
    """Largest plane among ``points (n, 3)``: RANSAC then least squares on the inliers.

    threshold : inlier distance in metres. Returns the plane and the inlier mask ``(n,) bool``.
    Raises ValueError with fewer than 3 points or no plane holding 3 points.
    """
    points = np.asarray(points, dtype=np.float64)
    n = len(points)
    if n < 3:
        raise ValueError("fewer than 3 valid depth points: no support plane")
    best_count, best = -1, None
    idx = rng.integers(0, n, size=(iterations, 3))
    a, b, c = points[idx[:, 0]], points[idx[:, 1]], points[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    good = lengths > 1e-12
    normals, a = normals[good] / lengths[good, None], a[good]
    offsets = -(normals * a).sum(1)
    # score the hypotheses on a subsample, then recount the best exactly
    sub = points[rng.choice(n, size=min(n, 4000), replace=False)]
    counts = (np.abs(sub @ normals.T + offsets) < threshold).sum(0)
    if counts.size == 0:
        raise ValueError("depth points are degenerate (collinear): no support plane")
    order = np.argsort(-counts)[:5]
    for k in order:
        inliers = np.abs(points @ normals[k] + offsets[k]) < threshold
        if inliers.sum() > best_count:
            best_count, best = int(inliers.sum()), inliers
    for _ in range(2):  # refine: least squares on inliers, recount
        normal, offset = plane_from_points(points[best])
        best = np.abs(points @ normal + offset) < threshold
    return Plane(normal, offset, float(best.mean())), best


def fit_support_plane(depth_m: np.ndarray, K: np.ndarray, *, threshold: float = 0.006,
                      iterations: int = 300, min_share: float = 0.15, max_points: int = 30000,
                      exclude: np.ndarray | None = None, seed: int = 0) -> Plane:
    """Fit the table under the objects from valid raw depth.

    depth_m : (H, W) metres, 0 = no reading; exclude : (H, W) bool pixels not to use (e.g.
    object masks). The inlier threshold grows with depth (stereo noise ~ z^2). The largest
    plane is the table unless it is not :func:`seen_from_above` and the largest plane among
    the other readings is, holding ``min_share`` of them all too (a wall larger in the image
    than the table).
    Raises ValueError when no plane covers ``min_share`` of the valid pixels.
    """
    valid = depth_m > 0
    if exclude is not None:
        valid &= ~exclude
    # the points of the valid pixels in row order (as depth_to_points(...)[valid]), of the
    # sampled ones only: a 1280x720 frame's every point costs 50 ms
    v, u = np.nonzero(valid)
    rng = np.random.default_rng(seed)
    if len(v) > max_points:
        pick = rng.choice(len(v), size=max_points, replace=False)
        v, u = v[pick], u[pick]
    pts = unproject(np.column_stack([u, v]), depth_m[v, u], K)
    median_z = float(np.median(pts[:, 2])) if len(pts) else 1.0
    threshold = threshold * max(1.0, median_z ** 2)
    plane, inliers = fit_plane_ransac(pts, threshold=threshold, iterations=iterations, rng=rng)
    if inliers.mean() < min_share:
        raise ValueError(f"no support plane: the best plane holds {100 * inliers.mean():.0f}% "
                         f"of the valid depth (need {100 * min_share:.0f}%)")
    if not seen_from_above(plane) and (~inliers).sum() >= max(3.0, min_share * len(pts)):
        other, held = fit_plane_ransac(pts[~inliers], threshold=threshold,
                                       iterations=iterations, rng=rng)
        share = float(held.sum()) / len(pts)
        if seen_from_above(other) and share >= min_share:
            return Plane(other.normal, other.offset, share)
    return plane


def support_plane(depth_m: np.ndarray, K: np.ndarray, cfg: "PlaneConfig",
                  exclude: np.ndarray | None = None) -> Plane:
    """The table with the ``plane`` config's settings (the one place they are passed on).

    depth_m : (H, W) metres, 0 = no reading; K : (3, 3); exclude : (H, W) bool pixels left out.
    Raises ValueError when there is none (:func:`fit_support_plane`)."""
    return fit_support_plane(depth_m, K, threshold=cfg.threshold, iterations=cfg.iterations,
                             min_share=cfg.min_share, exclude=exclude)
