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


def grasp_preview(rgb: np.ndarray, grasps, K: np.ndarray, gripper, per_object: int = 3
                  ) -> np.ndarray:
    """The best ``per_object`` grasps of each object drawn over the RGB image as open jaws
    (fingers, finger bases and a stem towards the palm), green for high scores, red for low."""
    from sr3d_cli.geometry.camera import project

    out = np.ascontiguousarray(rgb.copy())
    g = grasps.sorted()
    for i in range(len(g) - 1, -1, -1):  # worst first, so the best are drawn on top
        k = int(g.object_ids[i])
        rank = sum(1 for j in range(i) if int(g.object_ids[j]) == k)
        if rank >= per_object:
            continue
        w, d, L = g.widths[i], g.depths[i], gripper.finger_length
        local = np.array([[d, -w / 2, 0], [d - L, -w / 2, 0], [d - L, w / 2, 0], [d, w / 2, 0],
                          [d - L, 0, 0], [d - L - gripper.palm_depth / 2, 0, 0]])
        pts = local @ g.R[i].T + g.t[i]
        if (pts[:, 2] <= 0).any():
            continue
        uv = np.round(project(pts, K)).astype(np.int32)
        s = float(np.clip(g.scores[i], 0, 1))
        colour = (int(255 * (1 - s)), int(255 * s), 0)
        thick = 2 if rank == 0 else 1
        cv2.polylines(out, [uv[:4].reshape(-1, 1, 2)], False, colour, thick, cv2.LINE_AA)
        cv2.line(out, tuple(map(int, uv[4])), tuple(map(int, uv[5])), colour, thick, cv2.LINE_AA)
    return out


INSTANCE_COLOURS = ((255, 64, 64), (64, 200, 64), (64, 128, 255), (255, 200, 0),
                    (255, 64, 255), (0, 220, 220), (255, 140, 0), (160, 90, 255))


def instances_preview(rgb: np.ndarray, ids: np.ndarray, objects: list[dict]) -> np.ndarray:
    """RGB ``(H, W, 3) uint8`` with each instance tinted and outlined in its own colour and
    labelled ``#id score`` at its box's top-left corner; a line at the top says how many
    instances there are and what the score is (the segmenter's confidence, 0-1)."""
    out = rgb.astype(np.float32)
    scale = max(rgb.shape[1] / 640, 0.5)
    for n, obj in enumerate(objects):
        colour = np.array(INSTANCE_COLOURS[n % len(INSTANCE_COLOURS)], np.float32)
        mask = ids == obj["id"]
        out[mask] = 0.6 * out[mask] + 0.4 * colour
    out = out.astype(np.uint8)
    for n, obj in enumerate(objects):
        colour = INSTANCE_COLOURS[n % len(INSTANCE_COLOURS)]
        mask = (ids == obj["id"]).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(out, contours, -1, colour, max(1, int(2 * scale)))
        x0, y0 = obj["bbox"][:2]
        _label(out, f"#{obj['id']} {obj.get('score', 0):.2f}", (x0, max(y0 - 4, 12)), colour,
               scale)
    _label(out, f"{len(objects)} instance(s); #id score = segmenter confidence (0-1)",
           (6, int(18 * scale)), (255, 255, 255), scale)
    return out


def _label(image: np.ndarray, text: str, org: tuple[int, int], colour, scale: float) -> None:
    """Text with a dark outline, readable on any background."""
    font, size = cv2.FONT_HERSHEY_SIMPLEX, 0.5 * scale
    cv2.putText(image, text, org, font, size, (0, 0, 0), max(2, int(3 * scale)), cv2.LINE_AA)
    cv2.putText(image, text, org, font, size, colour, max(1, int(scale)), cv2.LINE_AA)
