"""Pictures and point clouds for people: previews of repaired depth, coloured PLY points."""

from __future__ import annotations

import cv2
import numpy as np
import trimesh

from sr3d_cli.geometry.camera import depth_to_points


def colour_depth(depth_m: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Depth to an RGB ``(H, W, 3) uint8`` image on a fixed scale [lo, hi] m; no reading = black."""
    x = np.clip((depth_m - lo) / max(hi - lo, 1e-6), 0, 1)
    rgb = cv2.applyColorMap((255 * (1 - x)).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
    return np.where((depth_m > 0)[..., None], rgb, 0).astype(np.uint8)


def preview_image(rgb: np.ndarray, raw_m: np.ndarray, repaired_m: np.ndarray,
                  ids: np.ndarray) -> np.ndarray:
    """RGB with object outlines | raw depth | repaired depth, both depths on one colour scale."""
    both = np.concatenate([raw_m[raw_m > 0], repaired_m[repaired_m > 0]])
    lo, hi = (np.percentile(both, [1, 99]) if both.size else (0.0, 1.0))
    outlined = rgb.copy()
    edges = cv2.morphologyEx((ids > 0).astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3)))
    outlined[edges > 0] = (255, 0, 255)
    return np.hstack([outlined, colour_depth(raw_m, lo, hi), colour_depth(repaired_m, lo, hi)])


def point_cloud_ply(depth_m: np.ndarray, rgb: np.ndarray, K: np.ndarray) -> bytes:
    """Binary PLY of the valid depth pixels, coloured from ``rgb`` (camera frame, metres)."""
    valid = depth_m > 0
    pts = depth_to_points(depth_m, K)[valid]
    colours = np.column_stack([rgb[valid], np.full(int(valid.sum()), 255, np.uint8)])
    return trimesh.PointCloud(pts, colors=colours).export(file_type="ply", encoding="binary")
