"""Instance masks of transparent objects: training-free default, SAM through ONNX, imported.

:func:`segment_frame` returns an :class:`Instances` (id image + per-object records) for one
frame; the command writes ``masks/<id>.png`` and ``masks/<id>.json``.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from sr3d_cli.config import PlaneConfig, SegmentConfig
from sr3d_cli.errors import InputError, NoTable
from sr3d_cli.geometry.camera import Camera
from sr3d_cli.geometry.plane import support_plane
from sr3d_cli.io import images

log = logging.getLogger("sr3d")


@dataclass
class Instances:
    """ids : (H, W) int32, 0 = background, k = object k; objects : one dict per id with
    ``id``, ``label``, ``score``, ``bbox`` [x0, y0, x1, y1] (inclusive pixels)."""

    ids: np.ndarray
    objects: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_json(self, backend: str) -> dict:
        return {"backend": backend, "objects": self.objects, "notes": self.notes}


def bbox(mask: np.ndarray) -> list[int]:
    ys, xs = np.nonzero(mask)
    return [int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max())]


def from_masks(masks: list[np.ndarray], scores: list[float], shape: tuple[int, int],
               label: str, min_area: int) -> Instances:
    """Number non-empty masks 1..n (earlier masks win overlaps); drop ones below ``min_area``."""
    ids = np.zeros(shape, np.int32)
    out = Instances(ids)
    for mask, score in zip(masks, scores):
        mask = mask & (ids == 0)
        if mask.sum() < min_area:
            out.notes.append(f"dropped a region of {int(mask.sum())} px (< min_area {min_area})")
            continue
        k = len(out.objects) + 1
        ids[mask] = k
        out.objects.append({"id": k, "label": label, "score": round(float(score), 4),
                            "bbox": bbox(mask)})
    return out


WORK_WIDTH = 640  # pixels: a frame is segmented reduced by the whole factor floor(W / 640) (1280
# px: half size), as the segmenter's pixel constants (closing radius, GrabCut margins) are set for
# VGA-sized frames


def to_working_size(rgb: np.ndarray, depth_m: np.ndarray, K: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame reduced by the whole factor ``W // WORK_WIDTH`` (none below 1280 px across).

    rgb : (H, W, 3) uint8; depth_m : (H, W) metres (0 = none); K : (3, 3).
    Returns (rgb, depth_m, K) at (H/f, W/f): colour averaged, depth the nearest reading (a hole
    stays a hole), K for the smaller image (pixel centres at integer coordinates).
    """
    h, w = depth_m.shape
    factor = w // WORK_WIDTH
    if factor <= 1:
        return rgb, depth_m, K
    size = (w // factor, h // factor)
    small_rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
    small_depth = depth_m[factor // 2::factor, factor // 2::factor][:size[1], :size[0]]
    small_K = Camera(K, w, h).scaled(w // factor, h // factor).K
    return small_rgb, np.ascontiguousarray(small_depth), small_K


def to_full_size(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A working-size mask ``(h, w) bool`` brought back to the frame's ``shape`` (smoothly
    interpolated, then cut at one half, so the outline does not come back as steps)."""
    if mask.shape == tuple(shape):
        return mask
    big = cv2.resize(mask.astype(np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)
    return big >= 0.5


def read_prompts(path: Path, frame_id: str, kind: str = "boxes") -> list[list[float]]:
    """Prompts for a frame from a JSON file ``{frame_id: [...], ...}`` or a folder of
    ``<frame_id>.json`` files holding such a list (or ``{"boxes": [...]}``, ``{"points":
    [...]}``).

    kind : ``boxes`` (each ``[x0, y0, x1, y1]``) or ``points`` (each ``[x, y]``), pixels.
    A frame the file does not name has no prompts.
    """
    width = {"boxes": 4, "points": 2}[kind]
    file = path / f"{frame_id}.json" if path.is_dir() else path
    if path.is_dir() and not file.is_file():
        return []
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(file, f"cannot read {kind} JSON ({exc})") from None
    if isinstance(data, dict):
        data = data.get(kind, data.get(frame_id, []))
    try:
        prompts = np.asarray(data, dtype=np.float64) if data else np.zeros((0, width))
    except (TypeError, ValueError):
        prompts = np.zeros((0, 0))
    layout = "[x0, y0, x1, y1]" if kind == "boxes" else "[x, y]"
    if prompts.ndim != 2 or prompts.shape[1] != width or not np.isfinite(prompts).all():
        raise InputError(file, f"{kind} for frame {frame_id} must be a list of {layout} numbers")
    return prompts.tolist()


def imported_ids(folder: Path, frame_id: str, shape: tuple[int, int]) -> np.ndarray:
    """Masks made elsewhere: ``folder/<frame_id>.png`` with instance ids, or binary (split into
    8-connected components); ``(H, W)`` int ids, 0 = background."""
    path = None
    for suffix in (".png", ".tif", ".tiff", ".bmp"):
        if (folder / f"{frame_id}{suffix}").is_file():
            path = folder / f"{frame_id}{suffix}"
            break
    if path is None:
        raise InputError(folder / f"{frame_id}.png", "no imported mask for this frame")
    ids = images.read_mask(path, split_binary=True)
    if ids.shape != shape:
        raise InputError(path, f"mask is {ids.shape[1]}x{ids.shape[0]} but the frame is "
                               f"{shape[1]}x{shape[0]}")
    return ids


def import_masks(folder: Path, frame_id: str, shape: tuple[int, int], label: str,
                 min_area: int) -> Instances:
    """The instances of :func:`imported_ids`, each with confidence 1, numbered 1..n."""
    ids = imported_ids(folder, frame_id, shape)
    values = [int(v) for v in np.unique(ids) if v > 0]
    return from_masks([ids == v for v in values], [1.0] * len(values), shape, label, min_area)


class Segmenter:
    """One per batch: builds the configured backend (:data:`sr3d_cli.backends.SEGMENT`), which
    loads its models once, then :meth:`__call__` per frame."""

    def __init__(self, cfg: SegmentConfig, plane_cfg: PlaneConfig):
        from sr3d_cli.backends import SEGMENT

        self.cfg, self.plane_cfg = cfg, plane_cfg
        self.backend = SEGMENT.create(cfg.backend, cfg, plane_cfg)

    def __call__(self, frame_id: str, rgb: np.ndarray, depth_m: np.ndarray,
                 K: np.ndarray) -> Instances:
        c = self.cfg
        shape = depth_m.shape
        label = c.prompt or "transparent object"
        masks, scores = self.backend(frame_id, rgb, depth_m, K)
        kept = [(m, s) for m, s in zip(masks, scores) if s >= c.min_score]
        out = from_masks([m for m, _ in kept], [s for _, s in kept], shape, label, c.min_area)
        dropped = len(masks) - len(kept)
        if dropped:
            out.notes.append(f"dropped {dropped} instance(s) scored below segment.min_score "
                             f"{c.min_score:g}")
        return out


# Backends: built with (segment config, plane config); called per frame with (frame id, rgb
# (H, W, 3) uint8, depth (H, W) metres, K (3, 3)), they return the frame's masks ((H, W) bool
# each) and their confidences.

class TrainingFree:
    """``training-free``: where the depth fails and the colour looks like glass, no weights."""

    def __init__(self, cfg: SegmentConfig, plane_cfg: PlaneConfig):
        self.cfg, self.plane_cfg = cfg, plane_cfg

    def __call__(self, frame_id: str, rgb, depth_m, K) -> tuple[list[np.ndarray], list[float]]:
        from sr3d_cli.segment.training_free import segment_training_free

        c = self.cfg
        shape = depth_m.shape
        rgb_w, depth_w, K_w = to_working_size(rgb, depth_m, K)
        try:
            plane = support_plane(depth_w, K_w, self.plane_cfg)
        except ValueError as exc:  # it finds glass by where the table's readings fail
            raise NoTable(f"{exc}; the training-free segmenter needs the table in view "
                          "(give masks: segment --import-dir, or SAM prompts)") from None
        found = segment_training_free(rgb_w, depth_w, K_w, plane, rough_factor=c.rough_factor,
                                      min_area=c.min_area, close_radius=c.close_radius,
                                      grabcut_iterations=c.grabcut_iterations,
                                      max_object_share=c.max_object_share,
                                      stereo_baseline=c.stereo_baseline,
                                      min_score=c.min_score)
        return [to_full_size(f.mask, shape) for f in found], [f.score for f in found]


class Imported:
    """``import``: masks made elsewhere (:func:`imported_ids`), each with confidence 1."""

    def __init__(self, cfg: SegmentConfig, plane_cfg: PlaneConfig):
        self.cfg = cfg

    def __call__(self, frame_id: str, rgb, depth_m, K) -> tuple[list[np.ndarray], list[float]]:
        if not self.cfg.import_dir:
            raise InputError("segment.import_dir", "the import backend needs a folder of masks")
        ids = imported_ids(Path(self.cfg.import_dir), frame_id, depth_m.shape)
        masks = [ids == v for v in np.unique(ids) if v > 0]
        return masks, [1.0] * len(masks)


class SamPrompted:
    """``sam-onnx``: SAM through onnxruntime, prompted by the user's points or boxes, else by
    the boxes of the training-free backend's instances."""

    def __init__(self, cfg: SegmentConfig, plane_cfg: PlaneConfig):
        from sr3d_cli.segment.sam import SamOnnx

        self.cfg = cfg
        self.sam = SamOnnx(cfg.sam_encoder, cfg.sam_decoder)
        self.default = TrainingFree(cfg, plane_cfg)

    def __call__(self, frame_id: str, rgb: np.ndarray, depth_m: np.ndarray, K: np.ndarray
                 ) -> tuple[list[np.ndarray], list[float]]:
        """SAM's masks and predicted IoUs, one per prompt: the user's points, else the user's
        boxes, else the boxes of the training-free backend's instances scored at least
        ``segment.min_score`` (the ones it would keep)."""
        c = self.cfg
        shape = depth_m.shape
        embedding, scale = self.sam.embed(rgb)
        if c.points:
            points = read_prompts(Path(c.points), frame_id, "points")
            found = [self.sam.segment_point(embedding, scale, np.asarray(p), shape)
                     for p in points]
        else:
            if c.boxes:
                boxes = read_prompts(Path(c.boxes), frame_id, "boxes")
            else:
                masks, scores = self.default(frame_id, rgb, depth_m, K)
                boxes = [bbox(m) for m, s in zip(masks, scores) if s >= c.min_score]
            found = [self.sam.segment_box(embedding, scale, np.asarray(b), shape) for b in boxes]
        return [m for m, _ in found], [s for _, s in found]
