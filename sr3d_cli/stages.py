"""Per-frame stage runs on scene folders: read a stage's inputs, call the core, write outputs.

The commands in :mod:`sr3d_cli.cli` loop over frames and report; this module knows which file
each stage reads and writes (DESIGN.md, "Scene folder"). Object-level problems do not fail the
frame: they are returned as messages and recorded in the stage's JSON.
"""

from __future__ import annotations

import json
import logging

import numpy as np
import trimesh

from sr3d_cli.errors import InputError
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.io.atomic import write_bytes, write_json, write_png
from sr3d_cli.io.scene import Frame, SceneSource

log = logging.getLogger("sr3d")


def write_instances(source: SceneSource, frame_id: str, instances, backend: str) -> None:
    ids = instances.ids
    dtype = np.uint8 if ids.max(initial=0) <= 255 else np.uint16
    write_png(source.output_path("masks", frame_id), ids.astype(dtype))
    write_json(source.output_path("masks", frame_id, ".json"), instances.to_json(backend))


def load_instances(source: SceneSource, frame_id: str, shape: tuple[int, int],
                   which: str = "segment") -> tuple[np.ndarray, dict[int, dict]]:
    """Instance ids ``(H, W) int32`` and per-id records, from ``masks/`` or the ground truth."""
    if which == "gt":
        path = source.gt_mask_path(frame_id)
        if path is None:
            raise InputError(source.root / "gt" / "masks", f"no ground-truth mask for {frame_id}")
        ids = source.load_mask(path, shape)
        gt = source.load_gt_objects(frame_id) or {}
        labels = {o["id"]: o.get("label", "") for o in gt.get("objects", [])}
        return ids, {int(k): {"id": int(k), "label": labels.get(int(k), "")}
                     for k in np.unique(ids) if k > 0}
    path = source.stage_file("masks", frame_id, (".png",))
    if path is None:
        raise InputError(source.out / "masks" / f"{frame_id}.png",
                         "no masks for this frame: run `sr3d segment` first")
    ids = source.load_mask(path, shape)
    records = {int(k): {"id": int(k), "label": ""} for k in np.unique(ids) if k > 0}
    meta = path.with_suffix(".json")
    if meta.is_file():
        try:
            for obj in json.loads(meta.read_text(encoding="utf-8")).get("objects", []):
                if int(obj.get("id", -1)) in records:
                    records[int(obj["id"])] = obj
        except (ValueError, OSError, TypeError) as exc:
            raise InputError(meta, f"cannot read instance records ({exc})") from None
    return ids, records


def frame_plane(frame: Frame, ids: np.ndarray, plane_cfg) -> tuple[Plane | None, str | None]:
    """The support plane with the objects left out, or (None, reason)."""
    from sr3d_cli.segment import support_plane

    try:
        return support_plane(frame.depth_m, frame.camera.K, plane_cfg, exclude=ids > 0), None
    except ValueError as exc:
        return None, str(exc)


def mesh_path(source: SceneSource, frame_id: str, obj_id: int, suffix: str = ".ply"):
    return source.out / "meshes" / frame_id / f"{obj_id}{suffix}"


def write_mesh(path, mesh: trimesh.Trimesh) -> None:
    write_bytes(path, mesh.export(file_type="ply", encoding="binary"))


def reconstruct_frame(frame: Frame, reconstructor, plane_cfg, which_masks: str
                      ) -> tuple[int, list[str]]:
    """Reconstruct every instance of a frame; returns (meshes written, object messages)."""
    source, fid = frame.scene, frame.frame_id
    ids, records = load_instances(source, fid, frame.depth_m.shape, which_masks)
    plane, why = frame_plane(frame, ids, plane_cfg)
    written, messages, summary = 0, [], {}
    for k, record in sorted(records.items()):
        try:
            if plane is None and reconstructor.cfg.backend != "onnx":
                raise ValueError(why)
            result = reconstructor(frame.rgb, ids == k, frame.camera.K, plane,
                                   record.get("label", ""))
        except ValueError as exc:  # ObjectError, and model/fit failures of this object
            messages.append(f"object {k}: {exc}")
            summary[str(k)] = {"error": str(exc)}
            continue
        write_mesh(mesh_path(source, fid, k), result.mesh)
        write_json(mesh_path(source, fid, k, ".json"), result.meta)
        summary[str(k)] = {"mesh": f"meshes/{fid}/{k}.ply", **result.meta}
        written += 1
    return written, messages
