"""Instance masks of transparent objects: training-free default, SAM through ONNX, imported.

:func:`segment_frame` returns an :class:`Instances` (id image + per-object records) for one
frame; the command writes ``masks/<id>.png`` and ``masks/<id>.json``.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sr3d_cli.config import PlaneConfig, SegmentConfig
from sr3d_cli.errors import InputError
from sr3d_cli.geometry.plane import Plane, fit_support_plane
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


def support_plane(depth_m: np.ndarray, K: np.ndarray, cfg: PlaneConfig,
                  exclude: np.ndarray | None = None) -> Plane:
    """The table, fitted once per frame by every stage with the same settings."""
    return fit_support_plane(depth_m, K, threshold=cfg.threshold, iterations=cfg.iterations,
                             min_share=cfg.min_share, exclude=exclude)


def read_boxes(path: Path, frame_id: str) -> list[list[float]]:
    """Boxes for a frame from a JSON file ``{frame_id: [[x0, y0, x1, y1], ...]}`` or a folder
    of ``<frame_id>.json`` files holding such a list (or ``{"boxes": [...]}``)."""
    file = path / f"{frame_id}.json" if path.is_dir() else path
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(file, f"cannot read boxes JSON ({exc})") from None
    if isinstance(data, dict):
        data = data.get("boxes", data.get(frame_id, []))
    boxes = np.asarray(data, dtype=np.float64) if data else np.zeros((0, 4))
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise InputError(file, f"boxes for frame {frame_id} must be a list of [x0, y0, x1, y1]")
    return boxes.tolist()


def import_masks(folder: Path, frame_id: str, shape: tuple[int, int], label: str,
                 min_area: int) -> Instances:
    """Masks made elsewhere: ``folder/<frame_id>.png`` with instance ids, or binary (split into
    8-connected components)."""
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
    values = [int(v) for v in np.unique(ids) if v > 0]
    return from_masks([ids == v for v in values], [1.0] * len(values), shape, label, min_area)


class Segmenter:
    """One per batch: loads models once, then :meth:`__call__` per frame."""

    def __init__(self, cfg: SegmentConfig, plane_cfg: PlaneConfig):
        self.cfg, self.plane_cfg = cfg, plane_cfg
        self.sam = None
        if cfg.backend == "sam-onnx":
            from sr3d_cli.segment.sam import SamOnnx

            self.sam = SamOnnx(cfg.sam_encoder, cfg.sam_decoder)

    def default(self, rgb, depth_m, K) -> tuple[list[np.ndarray], list[float]]:
        from sr3d_cli.segment.training_free import segment_training_free

        c = self.cfg
        plane = support_plane(depth_m, K, self.plane_cfg)
        found = segment_training_free(rgb, depth_m, K, plane, rough_factor=c.rough_factor,
                                      min_area=c.min_area, close_radius=c.close_radius,
                                      grabcut_iterations=c.grabcut_iterations,
                                      max_object_share=c.max_object_share)
        return [f.mask for f in found], [f.score for f in found]

    def __call__(self, frame_id: str, rgb: np.ndarray, depth_m: np.ndarray,
                 K: np.ndarray) -> Instances:
        c = self.cfg
        shape = depth_m.shape
        label = c.prompt or "transparent object"
        if c.backend == "import":
            if not c.import_dir:
                raise InputError("segment.import_dir", "the import backend needs a folder of masks")
            return import_masks(Path(c.import_dir), frame_id, shape, label, c.min_area)
        if c.backend == "training-free":
            masks, scores = self.default(rgb, depth_m, K)
            return from_masks(masks, scores, shape, label, c.min_area)
        # sam-onnx: boxes from the user, else from the training-free backend
        if c.boxes:
            boxes = read_boxes(Path(c.boxes), frame_id)
        else:
            masks, _ = self.default(rgb, depth_m, K)
            boxes = [bbox(m) for m in masks]
        embedding, scale = self.sam.embed(rgb)
        masks, scores = [], []
        for box in boxes:
            mask, score = self.sam.segment_box(embedding, scale, np.asarray(box), shape)
            masks.append(mask)
            scores.append(score)
        return from_masks(masks, scores, shape, label, c.min_area)
