"""Pose error of placed objects against their true poses: rotation (the axis only for a surface
of revolution), translation, scale and ADD-S.

Both poses follow the data contract (DESIGN.md): a mesh point ``p`` lands at ``R @ (scale * p) +
t`` in the camera frame, with the object frame's origin at the centre of the base and its z axis
up the object (the symmetry axis of a surface of revolution). The predicted mesh may be another
mesh than the true one (a reconstruction): translation compares the base centres, scale the
placed heights (z extents), and ADD-S the placed surfaces; with the true mesh as the prediction
they are the usual pose errors.

:func:`pose_error` is the metric on arrays and meshes; :func:`evaluate_frame_poses` reads a
frame's true objects (``gt/objects``) and placed ones (``poses/``), matches them by their masks
and scores each pair.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path

import numpy as np
import trimesh

from sr3d_cli.geometry.transforms import place_points

METRICS = ("rotation_deg", "axis_deg", "translation_mm", "scale_pct", "add_s_mm")
TRUE_POINTS = 1000  # true-surface points averaged by ADD-S: 0.1 mm spread of the mean
PRED_POINTS = 20000  # placed-surface points searched: about 1 mm apart on a 10 cm glass,
# so a point on the surface itself lies about 0.3 mm from the nearest
MATCH_IOU = 0.5  # a placed object is a true object's when their masks overlap this well
SEED_TRUE, SEED_PRED = 0, 1  # surface samples: the same scores on every run
UNITS = {"rotation_deg": "degrees", "axis_deg": "degrees", "translation_mm": "mm",
         "scale_pct": "percent", "add_s_mm": "mm"}
METHOD = (f"true objects (gt/objects) matched to placed ones (poses/) by mask IoU >= "
          f"{MATCH_IOU:g}; rotation: angle between the rotations, between the z axes only where "
          "the true mesh is a surface of revolution; axis: angle between the z axes (what a "
          "surface of revolution can get right); translation: between the base centres "
          "(object origins); scale: placed height against the true height; ADD-S: mean "
          "distance from the true surface to the nearest point of the placed one")


def rotation_error_deg(R: np.ndarray, R_true: np.ndarray, symmetric: bool) -> float:
    """Angle in degrees between two rotations ``(3, 3)``; with ``symmetric``, between their
    z axes only (a turn about the symmetry axis of a surface of revolution is no error)."""
    R, R_true = np.asarray(R, dtype=np.float64), np.asarray(R_true, dtype=np.float64)
    if symmetric:
        c = R[:, 2] @ R_true[:, 2]
    else:
        c = (np.trace(R.T @ R_true) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def height(mesh: trimesh.Trimesh) -> float:
    """The mesh's extent along its z axis (object-frame units)."""
    z = np.asarray(mesh.vertices)[:, 2]
    return float(z.max() - z.min())


def is_revolution(mesh: trimesh.Trimesh) -> bool:
    """Whether the mesh maps onto itself turned about its z axis, judged with its largest
    extent as the unit (a mesh in metres and one of unit height are judged alike)."""
    from sr3d_cli.align.view_matching import is_axisymmetric

    unit = mesh.copy()
    unit.vertices = np.asarray(mesh.vertices) / max(float(np.max(mesh.extents)), 1e-12)
    return is_axisymmetric(unit)


def add_s(points_true: np.ndarray, points_pred: np.ndarray) -> float:
    """Mean distance from each true point ``(N, 3)`` to the nearest predicted point ``(M, 3)``
    (ADD-S), in the points' units."""
    from scipy.spatial import cKDTree

    return float(cKDTree(points_pred).query(points_true)[0].mean())


def pose_error(T_pred: np.ndarray, scale_pred: float, mesh_pred: trimesh.Trimesh,
               T_true: np.ndarray, scale_true: float, mesh_true: trimesh.Trimesh,
               symmetric: bool | None = None) -> dict:
    """Error of one placed object against the truth.

    Parameters
    ----------
    T_pred, T_true : (4, 4) float
        ``T_cam_obj`` of the prediction and of the truth (metres).
    scale_pred, scale_true : float
        Metres per object-frame unit of each mesh.
    mesh_pred, mesh_true : trimesh.Trimesh
        Object-frame meshes (origin at the base centre, z up the object).
    symmetric : bool, optional
        Whether the true object is a surface of revolution (default: judged from
        ``mesh_true`` by :func:`is_revolution`).

    Returns
    -------
    dict
        ``rotation_deg`` (:func:`rotation_error_deg`), ``axis_deg`` (between the z axes,
        whatever the symmetry), ``translation_mm`` (between the base centres), ``scale_pct`` (100 |placed height / true height - 1|), ``add_s_mm`` (ADD-S of
        the placed surfaces, :func:`add_s`), ``symmetric``.
    """
    T_pred, T_true = np.asarray(T_pred, dtype=np.float64), np.asarray(T_true, dtype=np.float64)
    if symmetric is None:
        symmetric = is_revolution(mesh_true)
    truth, _ = trimesh.sample.sample_surface(mesh_true, TRUE_POINTS, seed=SEED_TRUE)
    pred, _ = trimesh.sample.sample_surface(mesh_pred, PRED_POINTS, seed=SEED_PRED)
    size_true = scale_true * height(mesh_true)
    return {"rotation_deg": rotation_error_deg(T_pred[:3, :3], T_true[:3, :3], symmetric),
            "axis_deg": rotation_error_deg(T_pred[:3, :3], T_true[:3, :3], symmetric=True),
            "translation_mm": 1000 * float(np.linalg.norm(T_pred[:3, 3] - T_true[:3, 3])),
            "scale_pct": 100 * abs(scale_pred * height(mesh_pred) / size_true - 1)
            if size_true > 0 else math.nan,
            "add_s_mm": 1000 * add_s(place_points(truth, T_true, scale_true),
                                     np.vstack([place_points(pred, T_pred, scale_pred),
                                                place_points(mesh_pred.vertices, T_pred,
                                                             scale_pred)])),
            "symmetric": bool(symmetric)}


def match_instances(pred_ids: np.ndarray, true_ids: np.ndarray,
                    min_iou: float = MATCH_IOU) -> dict[int, tuple[int, float]]:
    """One-to-one matches of true instances to predicted ones, best IoU first.

    pred_ids, true_ids : (H, W) int, 0 = background. Returns ``{true id: (predicted id,
    IoU)}`` for the pairs with IoU >= ``min_iou``.
    """
    pred = np.asarray(pred_ids).astype(np.int64).ravel()
    true = np.asarray(true_ids).astype(np.int64).ravel()
    both = (pred > 0) & (true > 0)
    pairs, overlap = np.unique(np.stack([true[both], pred[both]]), axis=1, return_counts=True)
    area_pred = dict(zip(*np.unique(pred[pred > 0], return_counts=True)))
    area_true = dict(zip(*np.unique(true[true > 0], return_counts=True)))
    scored = sorted(((n / (area_true[t] + area_pred[p] - n), int(t), int(p))
                     for (t, p), n in zip(pairs.T, overlap)), reverse=True)
    out: dict[int, tuple[int, float]] = {}
    taken = set()
    for iou, t, p in scored:
        if iou >= min_iou and t not in out and p not in taken:
            out[t] = (p, float(iou))
            taken.add(p)
    return out


def pose_masks_path(source, frame_id: str, poses: dict) -> Path | None:
    """The instance masks the placed objects' ids refer to: the file whose fingerprint the
    poses' ``made_from`` record holds (masks/ or gt/masks), else masks/, else gt/masks."""
    from sr3d_cli.io.provenance import RECORD_KEY, fingerprint
    from sr3d_cli.stages import masks_path

    candidates = [p for p in (masks_path(source, frame_id, "segment"),
                              source.gt_mask_path(frame_id)) if p is not None]
    recorded = ((poses.get(RECORD_KEY) or {}).get("inputs") or {}).get("masks")
    for path in candidates:
        if recorded is not None and fingerprint(path) == recorded:
            return path
    return candidates[0] if candidates else None


def evaluate_frame_poses(source, frame_id: str) -> dict | None:
    """Pose error of every true object of a frame, None where the frame has no true poses
    (gt/objects), no placed objects (poses/), or no masks to match them by (gt/masks and the
    placed objects' masks).

    Returns ``{"masks": path, "objects": [...]}``: one row per true object with its ``id`` and
    ``label``, and either the matched placed object (``pred_id``, mask ``iou``) and the
    :func:`pose_error` numbers, or ``pred_id`` None (no placed object matches it).
    """
    from sr3d_cli.stages import check_placement, find_mesh, load_mesh, load_pose_document

    truth = source.load_gt_objects(frame_id)
    if not truth or not truth.get("objects") or \
            source.stage_file("poses", frame_id, (".json",)) is None:
        return None
    poses = load_pose_document(source, frame_id)
    shape = source.load_frame(frame_id).depth_m.shape
    masks = pose_masks_path(source, frame_id, poses)
    true_path = source.gt_mask_path(frame_id)
    if masks is None or true_path is None:
        return None
    matches = match_instances(source.load_mask(masks, shape), source.load_mask(true_path, shape))
    placed = {int(o["id"]): o for o in poses.get("objects", [])}
    rows = []
    for obj in truth["objects"]:
        check_placement(obj, source.gt_objects_path(frame_id))
        k = int(obj["id"])
        row = {"id": k, "label": obj.get("label", ""), "pred_id": None}
        pred_id, iou = matches.get(k, (None, 0.0))
        if pred_id in placed:
            p = placed[pred_id]
            row.update(pred_id=pred_id, iou=round(iou, 4), **pose_error(
                p["T_cam_obj"], float(p["scale"]), load_mesh(find_mesh(source, frame_id, pred_id)),
                obj["T_cam_obj"], float(obj["scale"]), load_mesh(source.root / obj["mesh"])))
        rows.append(row)
    return {"masks": str(masks), "objects": rows}


def summarise(rows: list[dict]) -> dict:
    """Totals over pose rows of :func:`evaluate_frame_poses`: ``objects`` (true), ``matched``,
    and the median and mean of each of :data:`METRICS` over the matched ones."""
    matched = [r for r in rows if r.get("pred_id") is not None]
    out: dict = {"objects": len(rows), "matched": len(matched)}
    for key in METRICS:
        values = [r[key] for r in matched if not math.isnan(r[key])]
        out[f"median_{key}"] = float(statistics.median(values)) if values else math.nan
        out[f"mean_{key}"] = float(statistics.fmean(values)) if values else math.nan
    return out
