"""BOP layout (Hodan et al.), one scene folder read in place.

``scene_camera.json`` (per image: ``cam_K`` 3x3 row-major, ``depth_scale`` in millimetres per
depth unit), ``rgb/`` (or ``gray/``), ``depth/``, ``mask_visib/<image>_<instance>.png`` (one binary
mask per ground-truth instance: instance k is id k + 1), and, when present, ``scene_gt.json``
(``cam_R_m2c``, ``cam_t_m2c`` in mm, ``obj_id``) with the models in ``../../models*/obj_XXXXXX.ply``
(millimetres). Frame ids are the image stems.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sr3d_cli.errors import InputError
from sr3d_cli.geometry.camera import Camera
from sr3d_cli.io import images
from sr3d_cli.io.scene import Frame, SceneSource


def _load_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(path, f"cannot read JSON ({exc})") from None


class BOPSource(SceneSource):
    layout = "bop"

    @staticmethod
    def looks_like(folder: Path) -> bool:
        return (folder / "scene_camera.json").is_file() and (folder / "depth").is_dir()

    def frame_ids(self) -> list[str]:
        return super().frame_ids() if (self.root / "rgb").is_dir() else []

    def camera_path(self) -> Path:
        return Path(self.io.camera) if self.io.camera else self.root / "scene_camera.json"

    def _scene_camera(self) -> dict:
        if not hasattr(self, "_cams"):
            self._cams = _load_json(self.camera_path())
        return self._cams

    def camera_for(self, frame_id: str) -> Camera:
        path = self.camera_path()
        cams = self._scene_camera()
        entry = cams.get(str(int(frame_id)) if frame_id.isdigit() else frame_id)
        if entry is None:
            raise InputError(path, f"no entry for image {frame_id}")
        try:
            K = np.asarray(entry["cam_K"], dtype=np.float64).reshape(3, 3)
            scale = float(entry.get("depth_scale", 1.0)) / 1000.0  # mm per unit -> m per unit
            return Camera(K, 0, 0, scale, str(path))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(path, f"image {frame_id}: bad cam_K/depth_scale ({exc})") from None

    @property
    def camera(self) -> Camera:
        if self._camera is None:
            ids = self.frame_ids()
            if not ids:
                raise InputError(self.root / "rgb", "no images")
            self._camera = self.camera_for(ids[0])
        return self._camera

    def load_frame(self, frame_id: str) -> Frame:
        self._camera = self.camera_for(frame_id)  # BOP intrinsics may change per image
        return super().load_frame(frame_id)

    def gt_mask_path(self, frame_id: str) -> Path | None:
        hits = sorted((self.root / "mask_visib").glob(f"{frame_id}_*.png"))
        return hits[0] if hits else None

    def load_mask(self, path: Path | None, shape: tuple[int, int]) -> np.ndarray | None:
        if path is None or path.parent.name != "mask_visib":
            return super().load_mask(path, shape)
        frame_id = path.name.rsplit("_", 1)[0]
        ids = np.zeros(shape, np.int32)
        for p in sorted(path.parent.glob(f"{frame_id}_*.png")):
            m = images.read_mask(p)
            if m.shape != shape:
                raise InputError(p, f"mask is {m.shape[1]}x{m.shape[0]} but the images are "
                                    f"{shape[1]}x{shape[0]}")
            ids[(m > 0) & (ids == 0)] = int(p.stem.rsplit("_", 1)[1]) + 1
        return ids

    def gt_objects_path(self, frame_id: str) -> Path | None:
        p = self.root / "scene_gt.json"
        return p if p.is_file() else None

    def load_gt_objects(self, frame_id: str) -> dict | None:
        path = self.gt_objects_path(frame_id)
        if path is None:
            return None
        entries = _load_json(path).get(str(int(frame_id)) if frame_id.isdigit() else frame_id,
                                       [])
        models = next((d for d in (self.root.parent.parent / "models",
                                   self.root.parent.parent / "models_eval") if d.is_dir()),
                      self.root.parent.parent / "models")
        objects = []
        for k, e in enumerate(entries):
            T = np.eye(4)
            T[:3, :3] = np.asarray(e["cam_R_m2c"], dtype=np.float64).reshape(3, 3)
            T[:3, 3] = np.asarray(e["cam_t_m2c"], dtype=np.float64) / 1000.0
            objects.append({"id": k + 1, "label": f"obj_{int(e['obj_id']):06d}",
                            "mesh": str(models / f"obj_{int(e['obj_id']):06d}.ply"),
                            "T_cam_obj": T.tolist(), "scale": 0.001})
        return {"objects": objects}


def bop_scene_gt(poses_by_frame: dict[str, list[dict]]) -> dict:
    """Our poses as a BOP ``scene_gt.json``: R row-major, t in mm. Our meshes are unit-free
    (object frame of DESIGN.md), so each entry also carries ``scale`` (metres per mesh unit);
    ``obj_id`` is the instance id."""
    doc = {}
    for fid, objects in poses_by_frame.items():
        key = str(int(fid)) if fid.isdigit() else fid
        doc[key] = [{"obj_id": int(o["id"]),
                     "cam_R_m2c": np.asarray(o["T_cam_obj"])[:3, :3].ravel().tolist(),
                     "cam_t_m2c": (np.asarray(o["T_cam_obj"])[:3, 3] * 1000).tolist(),
                     "scale": float(o["scale"])} for o in objects]
    return doc
