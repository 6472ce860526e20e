"""Pinhole camera in OpenCV's convention: x right, y down, z forward; depth is Z, not ray length."""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np


@dataclass(frozen=True)
class Camera:
    """Intrinsics of one camera (one scene folder).

    K : (3, 3) float64 pixel intrinsics, pixel centres at integer coordinates.
    width, height : image size in pixels the intrinsics belong to (0 = not known yet).
    depth_scale : metres per unit of integer depth files.
    """

    K: np.ndarray
    width: int
    height: int
    depth_scale: float = 0.001
    source: str = field(default="", compare=False)

    def __post_init__(self):
        K = np.asarray(self.K, dtype=np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"K must be 3x3, got {K.shape}")
        if not np.isfinite(K).all():
            raise ValueError("K must hold finite numbers")
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError("focal lengths must be positive")
        if not (np.allclose(K[2], [0.0, 0.0, 1.0]) and K[1, 0] == 0):
            # a pinhole's K is [[fx, s, cx], [0, fy, cy], [0, 0, 1]]; a K written column by
            # column (transposed) has (cx, cy, 1) as its last row
            raise ValueError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] row by row, "
                             f"got last row {K[2].tolist()}" + (
                                 " (transposed? give K's rows, not its columns)"
                                 if np.allclose(K[:, 2], [0.0, 0.0, 1.0]) else ""))
        if self.width < 0 or self.height < 0:
            raise ValueError("image size must not be negative")
        if not (self.depth_scale > 0 and np.isfinite(self.depth_scale)):
            raise ValueError("depth_scale must be positive")
        object.__setattr__(self, "K", K)

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    def scaled(self, width: int, height: int) -> "Camera":
        """Intrinsics for the same camera with images resized to ``width`` x ``height``."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, :] *= sx
        K[1, :] *= sy
        # pixel centres sit at integer coordinates: c' = (c + 0.5) * s - 0.5
        K[0, 2] = (self.K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * sy - 0.5
        return Camera(K, width, height, self.depth_scale, self.source)

    def to_json(self) -> dict:
        return {"K": self.K.tolist(), "width": self.width, "height": self.height,
                "depth_scale": self.depth_scale}


def on_image_border(mask: np.ndarray) -> bool:
    """Whether a mask ``(H, W) bool`` reaches the image's border."""
    return bool(mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())


def mask_window(mask: np.ndarray, margin: int) -> tuple[slice, slice] | None:
    """Rows and columns of the box of ``mask``'s (H, W) bool set pixels widened by ``margin``
    px, clipped to the image (None when none is set). cv2 scans a uint8 view of the image
    without listing its pixels."""
    x, y, w, h = cv2.boundingRect(np.ascontiguousarray(mask, dtype=bool).view(np.uint8))
    if w == 0:
        return None
    return (slice(max(y - margin, 0), min(y + h + margin, mask.shape[0])),
            slice(max(x - margin, 0), min(x + w + margin, mask.shape[1])))


def convex_hull(mask: np.ndarray) -> np.ndarray:
    """``(H, W) bool``: the convex hull of the set pixels of ``mask`` ``(H, W)`` bool (all
    False where none is set), filled by cv2. The hull of each row's two end pixels is the hull
    of them all: a frame-sized table patch gives 2 H points, not every pixel."""
    out = np.zeros(mask.shape, np.uint8)
    box = mask_window(mask, 0)
    if box is None:
        return out > 0
    sub = np.asarray(mask[box], dtype=bool)
    rows = np.flatnonzero(sub.any(axis=1))
    left = sub[rows].argmax(axis=1)
    right = sub.shape[1] - 1 - sub[rows, ::-1].argmax(axis=1)
    pts = np.column_stack([np.concatenate([left, right]) + box[1].start,
                           np.tile(rows, 2) + box[0].start]).astype(np.int32)
    cv2.fillConvexPoly(out, cv2.convexHull(pts), 1)
    return out > 0


def window_K(K: np.ndarray, x0: int, y0: int) -> np.ndarray:
    """Intrinsics ``(3, 3)`` of the image window whose top-left pixel is ``(x0, y0)``."""
    out = np.array(K, dtype=np.float64)
    out[0, 2] -= x0
    out[1, 2] -= y0
    return out


def project(points_cam: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame points ``(n, 3)`` metres to pixels ``(n, 2)`` (u right, v down)."""
    points_cam = np.asarray(points_cam, dtype=np.float64)
    z = points_cam[:, 2:3]
    uv = (points_cam[:, :2] / z) * np.array([K[0, 0], K[1, 1]]) + np.array([K[0, 2], K[1, 2]])
    return uv


def unproject(uv: np.ndarray, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixels ``(n, 2)`` with depths ``(n,)`` metres to camera-frame points ``(n, 3)``."""
    uv = np.asarray(uv, dtype=np.float64)
    z = np.asarray(depth_m, dtype=np.float64)
    x = (uv[:, 0] - K[0, 2]) / K[0, 0] * z
    y = (uv[:, 1] - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=1)


def depth_to_points(depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Depth image ``(H, W)`` to a point image ``(H, W, 3)`` in the camera frame (0 where empty)."""
    h, w = depth_m.shape
    v, u = np.mgrid[0:h, 0:w]
    z = depth_m.astype(np.float64)
    x = (u - K[0, 2]) / K[0, 0] * z
    y = (v - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=-1)


def pixel_rays(shape: tuple[int, int], K: np.ndarray) -> np.ndarray:
    """Ray directions ``(H, W, 3)`` with z = 1 through every pixel centre."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w]
    return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((h, w))], axis=-1)


def depth_normals(points: np.ndarray, step: int = 2, max_jump: float = 0.02,
                  stride: int = 1) -> np.ndarray:
    """Unit surface normals of a point image (from :func:`depth_to_points`), facing the camera;
    0 where a neighbour ``step`` pixels away is empty or further than ``max_jump`` metres in
    depth (an occluding edge). Returned for every ``stride``-th pixel of each row and column:
    ``(ceil(H / stride), ceil(W / stride), 3)``."""
    h, w = points.shape[:2]
    pad = np.pad(points, ((step, step), (step, step), (0, 0)))

    def at(dy, dx):  # the point image shifted by (dy, dx), at the strided pixels
        return pad[step + dy:step + dy + h:stride, step + dx:step + dx + w:stride]

    centre, right, left, down, up = at(0, 0), at(0, step), at(0, -step), at(step, 0), at(-step, 0)
    z = centre[..., 2]
    n = np.cross(right - left, down - up)
    ok = z > 0
    for nb in (right, left, down, up):
        ok &= (nb[..., 2] > 0) & (np.abs(nb[..., 2] - z) <= max_jump)
    norm = np.linalg.norm(n, axis=-1)
    ok &= norm > 0
    n = np.where(ok[..., None], n / np.where(norm > 0, norm, 1)[..., None], 0.0)
    flip = np.einsum("hwk,hwk->hw", n, centre) > 0  # must face the camera (against the ray)
    n[flip] *= -1
    return n
