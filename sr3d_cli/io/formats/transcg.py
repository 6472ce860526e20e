"""TransCG layout (Fang et al., RA-L 2022), read in place.

``scene*/<view>/rgb{1,2}.png``, ``depth{1,2}.png`` (raw), ``depth{1,2}-gt.png`` (ground truth),
``depth{1,2}-gt-mask.png`` (transparent objects, binary: instances are its components). Suffix 1
is the RealSense D435 (depth in 1/1000 m), suffix 2 the L515 (1/4000 m). Intrinsics come from
``camera_intrinsics/1-camIntrinsics-D435.npy`` and ``2-camIntrinsics-L515.npy`` in the dataset
root, searched upwards from the scene. One scene folder gives one source per camera
(``scene1/cam1``, ``scene1/cam2``); frames are the view folders.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sr3d_cli.errors import InputError
from sr3d_cli.geometry.camera import Camera
from sr3d_cli.io.frames import sort_ids
from sr3d_cli.io.scene import SceneSource

DEPTH_SCALES = {1: 0.001, 2: 0.00025}
CAMERA_HINTS = {1: "d435", 2: "l515"}


class TransCGSource(SceneSource):
    layout = "transcg"
    split_binary_masks = True

    def __init__(self, root: Path, *, cam: int = 1, **kwargs):
        super().__init__(root, **kwargs)
        self.cam = cam

    @staticmethod
    def looks_like(folder: Path) -> bool:
        return any((v / "rgb1.png").is_file() or (v / "rgb2.png").is_file()
                   for v in folder.iterdir() if v.is_dir())

    @classmethod
    def expand(cls, folder: Path, out: Path, name: str, io) -> list[SceneSource]:
        sources = []
        for cam in (1, 2):
            if any((v / f"rgb{cam}.png").is_file() for v in folder.iterdir() if v.is_dir()):
                sub = f"cam{cam}"
                sources.append(cls(folder, cam=cam, out=out / sub,
                                   name=f"{name}/{sub}" if name else sub, io=io))
        return sources

    def frame_ids(self) -> list[str]:
        return sort_ids(v.name for v in self.root.iterdir()
                        if v.is_dir() and (v / f"rgb{self.cam}.png").is_file())

    def rgb_path(self, frame_id: str) -> Path:
        return self.root / frame_id / f"rgb{self.cam}.png"

    def depth_path(self, frame_id: str) -> Path:
        return self.root / frame_id / f"depth{self.cam}.png"

    def gt_depth_path(self, frame_id: str) -> Path | None:
        p = self.root / frame_id / f"depth{self.cam}-gt.png"
        return p if p.is_file() else None

    def gt_mask_path(self, frame_id: str) -> Path | None:
        p = self.root / frame_id / f"depth{self.cam}-gt-mask.png"
        return p if p.is_file() else None

    def gt_objects_path(self, frame_id: str) -> Path | None:
        return None

    def camera_path(self) -> Path:
        if self.io.camera:
            return Path(self.io.camera)
        for folder in [self.root, *self.root.parents][:4]:
            cams = folder / "camera_intrinsics"
            if cams.is_dir():
                files = sorted(cams.glob("*.npy"))
                for f in files:
                    if f.name.startswith(f"{self.cam}-") or \
                            CAMERA_HINTS[self.cam] in f.name.lower():
                        return f
        return self.root.parent.parent / "camera_intrinsics" / \
            f"{self.cam}-camIntrinsics-{CAMERA_HINTS[self.cam].upper()}.npy"

    @property
    def camera(self) -> Camera:
        if self._camera is None:
            path = self.camera_path()
            if path.suffix != ".npy":  # a user-given camera file: its own depth scale
                return super().camera
            try:
                K = np.load(path, allow_pickle=False)
                self._camera = Camera(np.asarray(K, dtype=np.float64).reshape(3, 3), 0, 0,
                                      DEPTH_SCALES[self.cam], str(path))
            except (OSError, ValueError) as exc:
                raise InputError(path, f"cannot read TransCG intrinsics ({exc}); expected a "
                                       "3x3 .npy in camera_intrinsics/") from None
        return self._camera
