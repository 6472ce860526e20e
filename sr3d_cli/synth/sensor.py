"""Raw depth as an active stereo / ToF camera reports it on a scene with glass.

Glass pixels fail in three ways, mixed per object: holes (no reading) in clusters, more at
grazing angles and near silhouettes; see-through readings of the surface behind; and some true
front-surface returns with extra noise. Opaque surfaces get depth-dependent noise, dropouts at
depth discontinuities, and sometimes the invalid band on the left that stereo cameras have.
"""

from __future__ import annotations

import cv2
import numpy as np

from sr3d_cli.geometry.camera import pixel_rays
from sr3d_cli.synth.appearance import smooth_noise


def _rank(values: np.ndarray) -> np.ndarray:
    """Values mapped to their quantile in [0, 1]."""
    order = np.argsort(values, kind="stable")
    ranks = np.empty(len(values))
    ranks[order] = np.linspace(0, 1, len(values))
    return ranks


def simulate_depth(gt_m: np.ndarray, behind_m: np.ndarray, ids: np.ndarray, normals: np.ndarray,
                   K: np.ndarray, glass_ids: list[int], rng: np.random.Generator, *,
                   hole_fraction: tuple[float, float], see_through_fraction: tuple[float, float],
                   noise_opaque: float, noise_glass: float, max_range: float) -> np.ndarray:
    """Sensor depth ``(H, W) float32`` metres (0 = no reading).

    gt_m : true depth with every object opaque; behind_m : depth of the scene without the glass;
    ids, normals : the full render (glass objects have ids in ``glass_ids``).
    """
    h, w = gt_m.shape
    out = gt_m + rng.normal(0, 1, gt_m.shape) * noise_opaque * gt_m ** 2
    # dropouts at depth edges
    grad = np.hypot(*np.gradient(gt_m))
    edge = (grad > 0.02 * np.maximum(gt_m, 0.1)) & (rng.uniform(size=gt_m.shape) < 0.5)
    out[edge] = 0
    rays = pixel_rays((h, w), K)
    view = -rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    cos = np.abs((normals * view).sum(-1))
    for obj_id in glass_ids:
        sel = ids == obj_id
        n = int(sel.sum())
        if n == 0:
            continue
        inside = cv2.distanceTransform(sel.astype(np.uint8), cv2.DIST_L2, 3)[sel]
        cluster = smooth_noise(rng, (h, w), rng.uniform(5, 14))[sel]
        score = _rank(cluster) + 0.8 * (1 - cos[sel]) + 0.6 * np.exp(-inside / 3.0)
        holes = _rank(score) > 1 - rng.uniform(*hole_fraction)
        through_score = _rank(smooth_noise(rng, (h, w), rng.uniform(6, 16))[sel])
        through = ~holes & (through_score > 1 - rng.uniform(*see_through_fraction))
        front = ~holes & ~through
        vals = np.empty(n, np.float32)
        vals[holes] = 0
        vals[through] = behind_m[sel][through] * (1 + rng.normal(0, 0.003, int(through.sum())))
        vals[front] = gt_m[sel][front] + rng.normal(0, noise_glass, int(front.sum()))
        out[sel] = vals
    if rng.uniform() < 0.5:  # stereo cameras' invalid band on the left edge
        out[:, : int(rng.integers(6, 40))] = 0
    out[(gt_m <= 0) | (out > max_range) | (out < 0)] = 0
    return out.astype(np.float32)
