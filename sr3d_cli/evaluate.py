"""Depth metrics over transparent-object pixels, as ClearGrasp (Sajjan et al., ICRA 2020) and
TransCG (Fang et al., RA-L 2022) report them, under one of three protocols (:data:`PROTOCOLS`).

Counted pixels: inside the object mask and where the ground truth is valid (finite, > 0).
Holes in the prediction (0 / NaN) either count with full error, the prediction taken as 0 as
ClearGrasp does (``holes="full"``), or are left out (``holes="ignore"``); ``coverage`` is the
share of counted pixels where the prediction is valid, so both readings can be reconstructed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sr3d_cli.errors import InputError
from sr3d_cli.geometry.silhouette import mask_iou
from sr3d_cli.io.images import read_rgb

METRICS = ("rmse", "rel", "mae", "delta_1.05", "delta_1.10", "delta_1.25")
DELTAS = {"delta_1.05": 1.05, "delta_1.10": 1.10, "delta_1.25": 1.25}
HOLES_NOTE = {
    "full": "holes in the prediction count with full error (prediction taken as 0, as ClearGrasp)",
    "ignore": "only pixels where the prediction is valid are counted",
}


def depth_metrics(pred_m: np.ndarray, gt_m: np.ndarray, mask: np.ndarray, *,
                  holes: str = "full") -> dict[str, float]:
    """Error of a depth prediction against ground truth over a mask.

    Parameters
    ----------
    pred_m, gt_m : (H, W) float ndarray
        Predicted and true depth in metres; 0 or non-finite means no value.
    mask : (H, W) bool or int ndarray
        Pixels to evaluate (non-zero), e.g. the transparent objects.
    holes : {"full", "ignore"}
        How pixels without a prediction are treated (see module doc).

    Returns
    -------
    dict
        ``rmse``, ``mae`` (metres), ``rel`` (mean |e| / gt), ``delta_1.05`` ... (percent of
        pixels with max(pred/gt, gt/pred) below the threshold), ``pixels`` (counted),
        ``coverage`` (share of mask-and-valid-gt pixels with a prediction). Metrics are NaN when
        no pixel is counted.
    """
    if holes not in HOLES_NOTE:
        raise ValueError(f"holes must be 'full' or 'ignore', got {holes!r}")
    pred = np.asarray(pred_m, dtype=np.float64)
    gt = np.asarray(gt_m, dtype=np.float64)
    if pred.shape != gt.shape or np.shape(mask) != gt.shape:
        raise ValueError(f"shapes differ: pred {pred.shape}, gt {gt.shape}, mask {np.shape(mask)}")
    base = (np.asarray(mask) != 0) & np.isfinite(gt) & (gt > 0)
    pred_valid = np.isfinite(pred) & (pred > 0)
    n_base = int(base.sum())
    coverage = float((base & pred_valid).sum() / n_base) if n_base else math.nan
    sel = base & pred_valid if holes == "ignore" else base
    p = np.where(pred_valid, pred, 0.0)[sel]
    g = gt[sel]
    out: dict[str, float] = {"pixels": int(sel.sum()), "coverage": coverage}
    if g.size == 0:
        out.update({k: math.nan for k in METRICS + ("rel_median",)})
        return out
    err = p - g
    out["rmse"] = float(np.sqrt(np.mean(err ** 2)))
    out["mae"] = float(np.mean(np.abs(err)))
    out["rel"] = float(np.mean(np.abs(err) / g))
    out["rel_median"] = float(np.median(np.abs(err) / g))
    with np.errstate(divide="ignore"):
        ratio = np.maximum(np.where(p > 0, p / g, np.inf), np.where(p > 0, g / p, np.inf))
    for name, thr in DELTAS.items():
        out[name] = float(100.0 * np.mean(ratio < thr))
    return out


def mean_metrics(rows: list[dict[str, float]]) -> dict[str, float]:
    """Average of per-frame metrics over the frames that counted any pixel (``frames``: how many)."""
    used = [r for r in rows if r.get("pixels", 0) > 0]
    out: dict[str, float] = {"frames": len(used)}
    for key in METRICS + ("rel_median", "coverage"):
        values = [r[key] for r in used if key in r and not math.isnan(r[key])]
        out[key] = float(np.mean(values)) if values else math.nan
    out["pixels"] = int(sum(r["pixels"] for r in used))
    return out

@dataclass(frozen=True)
class Protocol:
    """How a published table counts: resolution, depth range, pixel sets, hole handling.

    resolution : (width, height) every image is resized to (nearest neighbour) before
        counting, or None for the frames' own size.
    depth_range : (near, far) metres; readings outside it, in the prediction and the ground
        truth, are set to 0 before counting (None: no range).
    pixel_sets : "object" (mask and valid ground truth) and/or "all" (valid ground truth).
    """

    name: str
    resolution: tuple[int, int] | None
    depth_range: tuple[float, float] | None
    pixel_sets: tuple[str, ...]
    holes: str | None  # None: the configured holes mode
    note: str

    def describe(self, holes: str) -> dict:
        return {"name": self.name,
                "resolution": ("native" if self.resolution is None
                               else f"{self.resolution[0]}x{self.resolution[1]} (nearest)"),
                "depth_range_m": list(self.depth_range) if self.depth_range else None,
                "pixel_sets": {s: PIXEL_SETS[s] for s in self.pixel_sets},
                "holes": HOLES_NOTE[self.holes or holes], "note": self.note}


PIXEL_SETS = {"object": "inside the object mask where the ground truth is valid",
              "all": "every pixel where the ground truth is valid"}
PROTOCOLS = {
    "native": Protocol("native", None, None, ("object",), None,
                       "per-frame metrics at the frames' size, averaged over frames"),
    # Fang et al., TransCG (RA-L 2022), utils/metrics.py: per-image sums over the pixel set,
    # divided per image, averaged over images; depth outside 0.3-1.5 m is 0 in both images
    "transcg": Protocol("transcg", None, (0.3, 1.5), ("object", "all"), "full",
                        "TransCG: per-image means over object pixels and over all pixels, "
                        "depth 0.3-1.5 m, averaged over images (usually at 320x240)"),
    # Sajjan et al., ClearGrasp (ICRA 2020), eval_depth_completion.py: metrics at the
    # depth2depth output size 256x144, over mask and valid ground truth, averaged over images
    "cleargrasp": Protocol("cleargrasp", (256, 144), None, ("object",), "full",
                           "ClearGrasp: metrics at 256x144 over object pixels, averaged over "
                           "images; rel_median: median relative error"),
}


def parse_resolution(text: str) -> tuple[int, int] | None:
    """``"320x240"`` -> (320, 240); ``"native"`` or ``""`` -> None; ValueError otherwise."""
    if text in ("", "native"):
        return None
    w, sep, h = text.lower().partition("x")
    if not sep or not w.isdigit() or not h.isdigit() or int(w) < 1 or int(h) < 1:
        raise ValueError(f"resolution must be WIDTHxHEIGHT (e.g. 320x240) or native, "
                         f"got {text!r}")
    return int(w), int(h)


def protocol_metrics(pred_m: np.ndarray, gt_m: np.ndarray, mask: np.ndarray,
                     protocol: Protocol, *, holes: str = "full",
                     resolution: tuple[int, int] | None = None) -> dict[str, dict[str, float]]:
    """Metrics of one frame under ``protocol``: ``{pixel set: depth_metrics(...)}``.

    pred_m, gt_m : (H, W) float metres (0 / non-finite = no value); mask : (H, W), non-zero =
    object. ``resolution`` (width, height) overrides the protocol's.
    """
    import cv2

    size = resolution or protocol.resolution
    pred = np.nan_to_num(np.asarray(pred_m, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    gt = np.nan_to_num(np.asarray(gt_m, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    obj = (np.asarray(mask) != 0).astype(np.uint8)
    if size is not None and size != (gt.shape[1], gt.shape[0]):
        pred, gt, obj = (cv2.resize(a, size, interpolation=cv2.INTER_NEAREST)
                         for a in (pred, gt, obj))
    if protocol.depth_range is not None:
        near, far = protocol.depth_range
        pred = np.where((pred >= near) & (pred <= far), pred, 0.0)
        gt = np.where((gt >= near) & (gt <= far), gt, 0.0)
    sets = {"object": obj, "all": np.ones_like(obj)}
    mode = protocol.holes or holes
    return {name: depth_metrics(pred, gt, sets[name], holes=mode)
            for name in protocol.pixel_sets}


def error_map_image(pred_m: np.ndarray, gt_m: np.ndarray, mask: np.ndarray, *,
                    max_error: float = 0.05) -> np.ndarray:
    """Colour picture of |pred - gt| inside the mask: ``(H, W, 3) uint8`` RGB.

    Error 0 is dark blue and ``max_error`` (metres) or more is red (OpenCV's JET scale); pixels
    outside the mask or without ground truth are dark grey, holes in the prediction magenta.
    """
    import cv2

    pred = np.asarray(pred_m, dtype=np.float64)
    gt = np.asarray(gt_m, dtype=np.float64)
    base = (np.asarray(mask) != 0) & np.isfinite(gt) & (gt > 0)
    hole = base & ~(np.isfinite(pred) & (pred > 0))
    err = np.abs(np.nan_to_num(pred) - np.nan_to_num(gt))
    level = np.clip(err / max_error, 0, 1) * 255
    colour = cv2.applyColorMap(level.astype(np.uint8), cv2.COLORMAP_JET)[..., ::-1]
    image = np.full(gt.shape + (3,), 40, dtype=np.uint8)
    image[base] = colour[base]
    image[hole] = (255, 0, 255)
    return image


# ------------------------------------------------------------------------------------------------
# per-frame evaluation of a scene (reads files through a SceneSource)

def evaluation_mask(source, frame_id: str, shape: tuple[int, int], which: str
                    ) -> tuple[np.ndarray, str]:
    """Object mask to evaluate over and where it came from.

    ``which``: ``gt`` (gt/masks or the adapter's mask), ``pred`` (masks/ written by segment), or
    ``auto`` (gt, else pred).
    """
    if which in ("auto", "gt"):
        path = source.gt_mask_path(frame_id)
        if path is not None:
            return source.load_mask(path, shape), str(path)
    if which in ("auto", "pred"):
        path = source.stage_file("masks", frame_id, (".png",))
        if path is not None:
            return source.load_mask(path, shape), str(path)
    raise InputError(source.frame_key(frame_id),
                     f"no object mask to evaluate over (mask source: {which}; looked for "
                     "gt/masks/ and masks/)")


def _colour_shape(source, frame_id: str) -> tuple[int, int] | None:
    """(H, W) of the frame's colour image, where it is there and readable (the size every
    file of the frame must have); else None (the ground truth then sets it)."""
    try:
        return read_rgb(source.rgb_path(frame_id)).shape[:2]
    except InputError:
        return None


def evaluate_frame(source, frame_id: str, preds: list[str], *, holes: str = "full",
                   mask_source: str = "auto", protocol: Protocol | None = None,
                   resolution: tuple[int, int] | None = None) -> dict:
    """Metrics of each prediction folder for one frame.

    Returns ``{"mask": path, "preds": {name: metrics}, "arrays": {...}}``; ``arrays`` holds
    gt, mask and the predictions (metres) for plotting. Under a protocol with several pixel
    sets, the first set keeps the prediction's name and the others are ``"<pred>:<set>"``.
    """
    protocol = protocol or PROTOCOLS["native"]
    gt_path = source.gt_depth_path(frame_id)
    if gt_path is None:
        raise InputError(source.frame_key(frame_id), "no ground-truth depth (gt/depth/)")
    gt = source.read_depth_checked(gt_path, _colour_shape(source, frame_id))
    mask, mask_from = evaluation_mask(source, frame_id, gt.shape, mask_source)
    result = {"mask": mask_from, "preds": {}, "arrays": {"gt": gt, "mask": mask}}
    for pred in preds:
        path = source.prediction_path(pred, frame_id)
        if path is None:
            raise InputError(source.frame_key(frame_id),
                             f"no prediction '{pred}' (looked in {source.out / pred})")
        depth = source.read_depth_checked(path, gt.shape)
        per_set = protocol_metrics(depth, gt, mask, protocol, holes=holes,
                                   resolution=resolution)
        for i, (name, metrics) in enumerate(per_set.items()):
            result["preds"][pred if i == 0 else f"{pred}:{name}"] = metrics
        result["arrays"][pred] = depth
    return result


def result_names(preds: list[str], protocol: Protocol) -> list[str]:
    """The row names :func:`evaluate_frame` gives its results, in order."""
    return [p if i == 0 else f"{p}:{name}" for p in preds
            for i, name in enumerate(protocol.pixel_sets)]


def instance_ious(pred_ids: np.ndarray, gt_ids: np.ndarray) -> dict[int, float]:
    """Best IoU of each ground-truth instance against any predicted instance.

    pred_ids, gt_ids : (H, W) int, 0 = background. Returns {gt id: IoU in [0, 1]}.
    """
    out = {}
    preds = [p for p in np.unique(pred_ids) if p > 0]
    for g in np.unique(gt_ids):
        if g <= 0:
            continue
        gm = gt_ids == g
        out[int(g)] = float(max((mask_iou(gm, pred_ids == p) for p in preds), default=0.0))
    return out


def chamfer_distance(mesh_a, mesh_b, samples: int = 4000, seed: int = 0) -> float:
    """Symmetric Chamfer distance: the mean of the two mean nearest-neighbour distances between
    ``samples`` surface points of each mesh (units of the meshes)."""
    import trimesh
    from scipy.spatial import cKDTree

    pa, _ = trimesh.sample.sample_surface(mesh_a, samples, seed=seed)
    pb, _ = trimesh.sample.sample_surface(mesh_b, samples, seed=seed + 1)
    return 0.5 * float(cKDTree(pb).query(pa)[0].mean() + cKDTree(pa).query(pb)[0].mean())
