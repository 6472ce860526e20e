"""Pictures and point clouds for people: previews of repaired depth, error maps and grasps, each
with a colour bar in its units and a legend of the other colours; coloured PLY points.

Every picture is ``(H, W, 3) uint8`` RGB: the image itself on top, its key (a strip of the same
width) below it, so the image pixels keep their coordinates.
"""

from __future__ import annotations

import cv2
import numpy as np
import trimesh

from sr3d_cli.geometry.camera import depth_to_points

OBJECT_OUTLINE = (255, 0, 255)
HOLE = (255, 0, 255)
NOT_SCORED = (40, 40, 40)
KEY_BACKGROUND = (255, 255, 255)
TEXT = (0, 0, 0)


def depth_colours(level: np.ndarray) -> np.ndarray:
    """TURBO colours of ``level`` in [0, 1] (0 = near, red; 1 = far, blue): ``(..., 3) uint8``."""
    x = np.clip(np.asarray(level, dtype=np.float64), 0, 1)
    flat = (255 * (1 - x)).astype(np.uint8).reshape(-1, 1)
    return cv2.applyColorMap(flat, cv2.COLORMAP_TURBO)[:, 0, ::-1].reshape(x.shape + (3,))


def error_colours(level: np.ndarray) -> np.ndarray:
    """JET colours of ``level`` in [0, 1] (0 = dark blue, 1 = red): ``(..., 3) uint8``."""
    x = np.clip(np.asarray(level, dtype=np.float64), 0, 1)
    flat = (255 * x).astype(np.uint8).reshape(-1, 1)
    return cv2.applyColorMap(flat, cv2.COLORMAP_JET)[:, 0, ::-1].reshape(x.shape + (3,))


def score_colours(score: np.ndarray) -> np.ndarray:
    """Grasp score in [0, 1] to red (0) ... green (1): ``(..., 3) uint8``."""
    s = np.clip(np.asarray(score, dtype=np.float64), 0, 1)[..., None]
    return np.concatenate([255 * (1 - s), 255 * s, 0 * s], -1).astype(np.uint8)


def colour_depth(depth_m: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Depth to an RGB ``(H, W, 3) uint8`` image on a fixed scale [lo, hi] m; no reading = black."""
    rgb = depth_colours((depth_m - lo) / max(hi - lo, 1e-6))
    return np.where((depth_m > 0)[..., None], rgb, 0).astype(np.uint8)


# ---- keys ----------------------------------------------------------------------------------------

def _font(width: int) -> tuple[float, int, int]:
    """Font scale, thickness and line height for a key ``width`` pixels wide."""
    scale = float(np.clip(width / 1500, 0.3, 1.3))
    thick = 1 if scale < 0.6 else 2
    (_, h), base = cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
    return scale, thick, h + base + 4


def _text(image: np.ndarray, text: str, x: int, y: int, scale: float, thick: int) -> int:
    """Draw ``text`` with its baseline at y; returns the x after it."""
    cv2.putText(image, text, (int(x), int(y)), cv2.FONT_HERSHEY_SIMPLEX, scale, TEXT, thick,
                cv2.LINE_AA)
    return int(x) + cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0]


def colour_bar(width: int, colours, lo: float, hi: float, unit: str, title: str,
               ticks: int = 5, fmt: str = "{:.2f}") -> np.ndarray:
    """A key strip: ``title`` above a horizontal bar of ``colours`` (a function of [0, 1]) from
    ``lo`` (left) to ``hi`` (right) with ``ticks`` labelled values in ``unit``.

    Returns ``(h, width, 3) uint8``; the bar spans columns ``[m, width - m)`` with
    ``m = bar_margin(width)``.
    """
    scale, thick, line = _font(width)
    m = bar_margin(width)
    bar_h = max(8, line)
    strip = np.full((3 * line + bar_h, width, 3), KEY_BACKGROUND, np.uint8)
    _text(strip, title, m, line - 4, scale, thick)
    x = np.linspace(0, 1, max(width - 2 * m, 2))
    strip[line + 2:line + 2 + bar_h, m:width - m] = colours(x)[None]
    for k in range(ticks):
        f = k / max(ticks - 1, 1)
        u = int(round(m + f * (width - 2 * m - 1)))
        strip[line + 2 + bar_h:line + 6 + bar_h, u] = TEXT
        label = fmt.format(lo + f * (hi - lo)) + (f" {unit}" if k == ticks - 1 else "")
        w = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0]
        _text(strip, label, np.clip(u - w // 2, 0, width - w), 2 * line + bar_h + 2, scale, thick)
    return strip


def bar_margin(width: int) -> int:
    return max(4, width // 40)


def legend(width: int, items: list[tuple[tuple[int, int, int], str]]) -> np.ndarray:
    """A key strip of coloured squares with their meaning, wrapped to ``width``:
    ``(h, width, 3) uint8``."""
    scale, thick, line = _font(width)
    m = bar_margin(width)
    rows: list[list[tuple]] = [[]]
    x = m
    for colour, text in items:
        w = line + 4 + cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0] + 2 * m
        if rows[-1] and x + w > width:
            rows.append([])
            x = m
        rows[-1].append((x, colour, text))
        x += w
    strip = np.full((len(rows) * line + 6, width, 3), KEY_BACKGROUND, np.uint8)
    for r, row in enumerate(rows):
        y = r * line + 3
        for x0, colour, text in row:
            if colour is not None:
                cv2.rectangle(strip, (x0, y + 2), (x0 + line - 6, y + line - 4), colour, -1)
                cv2.rectangle(strip, (x0, y + 2), (x0 + line - 6, y + line - 4), TEXT, 1)
            _text(strip, text, x0 + line, y + line - 6, scale, thick)
    return strip


def with_key(image: np.ndarray, *strips: np.ndarray) -> np.ndarray:
    """``image`` with key strips stacked below it (each as wide as the image)."""
    return np.vstack([image, *strips])


# ---- pictures --------------------------------------------------------------------------------

def preview_image(rgb: np.ndarray, raw_m: np.ndarray, repaired_m: np.ndarray,
                  ids: np.ndarray) -> np.ndarray:
    """RGB with object outlines | raw depth | repaired depth, both depths on one colour scale
    (the 1st-99th percentile of their readings), with a colour bar in metres and a legend.

    rgb : (H, W, 3) uint8; raw_m, repaired_m : (H, W) float metres, 0 = no reading;
    ids : (H, W) int object ids, 0 = none. Returns ``(H + key, 3 W, 3) uint8``.
    """
    both = np.concatenate([raw_m[raw_m > 0], repaired_m[repaired_m > 0]])
    lo, hi = (np.percentile(both, [1, 99]) if both.size else (0.0, 1.0))
    outlined = rgb.copy()
    edges = cv2.morphologyEx((ids > 0).astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3)))
    outlined[edges > 0] = OBJECT_OUTLINE
    image = np.hstack([outlined, colour_depth(raw_m, lo, hi), colour_depth(repaired_m, lo, hi)])
    width = image.shape[1]
    return with_key(image,
                    colour_bar(width, lambda x: depth_colours(x), lo, hi, "m",
                               "left: colour image | middle: raw depth | right: repaired depth "
                               "(depth in metres, red = near)", fmt="{:.3f}"),
                    legend(width, [(OBJECT_OUTLINE, "object outline"),
                                   ((0, 0, 0), "no depth reading")]))


def error_map_figure(image: np.ndarray, max_error: float) -> np.ndarray:
    """An error map from :func:`sr3d_cli.evaluate.error_map_image` with its key: a colour bar
    of |prediction - ground truth| from 0 to ``max_error`` (shown in cm) and what magenta and
    grey mean."""
    width = image.shape[1]
    return with_key(image,
                    colour_bar(width, error_colours, 0.0, 100 * max_error, "cm",
                               f"|prediction - ground truth| (at or above {100 * max_error:g} cm:"
                               " red)", fmt="{:g}"),
                    legend(width, [(HOLE, "hole in the prediction"),
                                   (NOT_SCORED, "not scored (outside mask or no ground truth)")]))


def point_cloud_ply(depth_m: np.ndarray, rgb: np.ndarray, K: np.ndarray) -> bytes:
    """Binary PLY of the valid depth pixels, coloured from ``rgb`` (camera frame, metres)."""
    valid = depth_m > 0
    pts = depth_to_points(depth_m, K)[valid]
    colours = np.column_stack([rgb[valid], np.full(int(valid.sum()), 255, np.uint8)])
    return trimesh.PointCloud(pts, colors=colours).export(file_type="ply", encoding="binary")


def gripper_points(grasps, i: int, gripper) -> np.ndarray:
    """The drawn gripper of grasp ``i``: ``(6, 3)`` float camera-frame points, metres: finger
    tip, finger base, finger base, finger tip (a polyline: the two fingers open to the grasp
    width and the bar joining their bases), then the stem from the bar towards the palm."""
    w, d, L = grasps.widths[i], grasps.depths[i], gripper.finger_length
    local = np.array([[d, -w / 2, 0], [d - L, -w / 2, 0], [d - L, w / 2, 0], [d, w / 2, 0],
                      [d - L, 0, 0], [d - L - gripper.palm_depth / 2, 0, 0]])
    return local @ grasps.R[i].T + grasps.t[i]


def best_per_object(grasps, per_object: int) -> list[int]:
    """Indices into ``grasps`` (sorted best first) of the ``per_object`` best of each object."""
    seen: dict[int, int] = {}
    keep = []
    for i, k in enumerate(int(x) for x in grasps.object_ids):
        if seen.get(k, 0) < per_object:
            keep.append(i)
        seen[k] = seen.get(k, 0) + 1
    return keep


def grasp_preview(rgb: np.ndarray, grasps, K: np.ndarray, gripper, per_object: int = 3
                  ) -> np.ndarray:
    """The best ``per_object`` grasps of each object drawn over the RGB image as the gripper
    seen from the camera (:func:`gripper_points`), coloured by score (colour bar below: red 0
    ... green 1), the best grasp of each object thicker. Returns ``(H + key, W, 3) uint8``."""
    from sr3d_cli.geometry.camera import project

    out = np.ascontiguousarray(rgb.copy())
    g = grasps.sorted()
    keep = best_per_object(g, per_object)
    firsts = {int(g.object_ids[i]): i for i in reversed(keep)}
    for i in reversed(keep):  # worst first, so the best are drawn on top
        pts = gripper_points(g, i, gripper)
        if (pts[:, 2] <= 0).any():
            continue
        uv = np.round(project(pts, K)).astype(np.int32)
        colour = tuple(int(c) for c in score_colours(float(g.scores[i])))
        thick = 2 if firsts[int(g.object_ids[i])] == i else 1
        cv2.polylines(out, [uv[:4].reshape(-1, 1, 2)], False, colour, thick, cv2.LINE_AA)
        cv2.line(out, tuple(map(int, uv[4])), tuple(map(int, uv[5])), colour, thick, cv2.LINE_AA)
    width = out.shape[1]
    return with_key(out,
                    colour_bar(width, score_colours, 0.0, 1.0, "", "grasp score (fingers, "
                               "finger bases and stem to the palm; thick: best of each object)",
                               ticks=3, fmt="{:.1f}"),
                    legend(width, [(None, f"the {per_object} best grasps of each object")]))


INSTANCE_COLOURS = ((255, 64, 64), (64, 200, 64), (64, 128, 255), (255, 200, 0),
                    (255, 64, 255), (0, 220, 220), (255, 140, 0), (160, 90, 255))


def instances_preview(rgb: np.ndarray, ids: np.ndarray, objects: list[dict]) -> np.ndarray:
    """RGB ``(H, W, 3) uint8`` with each instance tinted and outlined in its own colour and
    labelled ``#id score`` at its box's top-left corner, and a legend below: each instance's
    colour, id and score (the segmenter's confidence, 0-1)."""
    out = rgb.astype(np.float32)
    scale = max(rgb.shape[1] / 640, 0.5)
    colours = [INSTANCE_COLOURS[n % len(INSTANCE_COLOURS)] for n in range(len(objects))]
    for obj, colour in zip(objects, colours):
        mask = ids == obj["id"]
        out[mask] = 0.6 * out[mask] + 0.4 * np.array(colour, np.float32)
    out = out.astype(np.uint8)
    for obj, colour in zip(objects, colours):
        mask = (ids == obj["id"]).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(out, contours, -1, colour, max(1, int(2 * scale)))
        x0, y0 = obj["bbox"][:2]
        _label(out, f"#{obj['id']} {obj.get('score', 0):.2f}", (x0, max(y0 - 4, 12)), colour,
               scale)
    items = [(colour, f"#{obj['id']} score {obj.get('score', 0):.2f}")
             for obj, colour in zip(objects, colours)]
    items.append((None, f"{len(objects)} instance(s); score = segmenter confidence (0-1)"))
    return with_key(out, legend(out.shape[1], items))


def _label(image: np.ndarray, text: str, org: tuple[int, int], colour, scale: float) -> None:
    """Text with a dark outline, readable on any background."""
    font, size = cv2.FONT_HERSHEY_SIMPLEX, 0.5 * scale
    cv2.putText(image, text, org, font, size, (0, 0, 0), max(2, int(3 * scale)), cv2.LINE_AA)
    cv2.putText(image, text, org, font, size, colour, max(1, int(scale)), cv2.LINE_AA)
