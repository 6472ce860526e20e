"""Check a native scene folder against the data contract (DESIGN.md, "Scene folder").

:func:`check_frame` returns a list of problems (empty = conforms) rather than raising, so one
run reports everything. Ground-truth poses are checked by rendering each ground-truth mesh at
its ``T_cam_obj`` and ``scale`` and comparing with the ground-truth mask.
"""

from __future__ import annotations

import numpy as np
import trimesh

from sr3d_cli.errors import Sr3dError
from sr3d_cli.geometry.silhouette import mask_iou
from sr3d_cli.geometry.transforms import is_rigid, place_points
from sr3d_cli.io import images
from sr3d_cli.io.scene import SceneSource
from sr3d_cli.render import RenderMesh, Renderer


def check_frame(source: SceneSource, frame_id: str, renderer: Renderer | None = None,
                min_iou: float = 0.9) -> tuple[list[str], dict[int, float]]:
    """Problems of one frame and the pose-vs-mask IoU of each ground-truth object."""
    problems: list[str] = []
    ious: dict[int, float] = {}
    key = source.frame_key(frame_id)
    try:
        frame = source.load_frame(frame_id)
    except Sr3dError as exc:
        return [str(exc)], ious
    shape = frame.rgb.shape[:2]
    raw = images.decode_image(source.depth_path(frame_id))
    if raw.dtype != np.uint16:
        problems.append(f"{key}: depth PNG is {raw.dtype}, expected uint16")
    try:
        gt = source.load_gt_depth(frame_id, shape)
        mask = source.load_mask(source.gt_mask_path(frame_id), shape)
        objects = source.load_gt_objects(frame_id)
    except Sr3dError as exc:
        return problems + [str(exc)], ious
    if gt is None or mask is None or objects is None:
        return problems + [f"{key}: ground truth incomplete (gt/depth, gt/masks, gt/objects)"], ious
    listed = {int(o["id"]) for o in objects.get("objects", [])}
    present = set(np.unique(mask[mask > 0]).tolist())
    if not present <= listed:
        problems.append(f"{key}: mask ids {sorted(present - listed)} not in gt/objects")
    if np.any((mask > 0) & (gt <= 0)):
        problems.append(f"{key}: ground-truth depth missing inside object masks")
    meshes = []
    for obj in objects.get("objects", []):
        T = np.asarray(obj["T_cam_obj"], dtype=np.float64)
        if not is_rigid(T):
            problems.append(f"{key}: object {obj['id']}: T_cam_obj is not a rigid 4x4")
            continue
        if not obj.get("scale", 0) > 0:
            problems.append(f"{key}: object {obj['id']}: scale must be > 0")
            continue
        path = source.root / obj["mesh"]
        try:
            mesh = trimesh.load(path, force="mesh", process=False)
        except Exception as exc:
            problems.append(f"{path}: cannot load mesh ({exc})")
            continue
        if not mesh.is_watertight:
            problems.append(f"{path}: mesh is not watertight")
        verts = place_points(mesh.vertices, T, float(obj["scale"]))
        meshes.append(RenderMesh(verts, mesh.faces, int(obj["id"])))
    if renderer is not None and meshes:
        out = renderer.render(meshes, frame.camera, normals=False)
        # only where the object is really in front (occluders are not listed in gt/objects)
        visible = (out.depth > 0) & (out.depth <= np.where(gt > 0, gt, np.inf) + 0.005)
        for m in meshes:
            ious[m.id] = mask_iou(mask == m.id, (out.ids == m.id) & visible, empty=1.0)
            if ious[m.id] < min_iou:
                problems.append(f"{key}: object {m.id}: pose projects onto its mask with IoU "
                                f"{ious[m.id]:.3f} < {min_iou}")
    return problems, ious

