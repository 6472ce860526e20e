"""ClearGrasp real-data layout, read in place.

Per frame ``NNN``: ``NNN-transparent-rgb-img.jpg`` (input colour), ``NNN-transparent-depth-img.exr``
(raw depth, metres), ``NNN-opaque-depth-img.exr`` (painted-object depth: ground truth),
``NNN-mask.png`` (binary mask of all transparent objects: instances are its connected components),
and ``camera_intrinsics.yaml`` (``camera_parameters.txt`` preferred where present).
"""

from __future__ import annotations

import re
from pathlib import Path

from sr3d_cli.io.frames import sort_ids
from sr3d_cli.io.scene import SceneSource

_RGB = re.compile(r"^(.+)-transparent-rgb-img\.(jpg|jpeg|png)$", re.IGNORECASE)


class ClearGraspSource(SceneSource):
    layout = "cleargrasp"
    split_binary_masks = True
    CAMERA_NAMES = ("camera_intrinsics.yaml",)

    @staticmethod
    def looks_like(folder: Path) -> bool:
        return any(_RGB.match(p.name) for p in folder.iterdir() if p.is_file())

    def frame_ids(self) -> list[str]:
        return sort_ids(m.group(1) for p in self.root.iterdir() if (m := _RGB.match(p.name)))

    def _first(self, frame_id: str, *names: str) -> Path:
        for name in names:
            p = self.root / f"{frame_id}-{name}"
            if p.is_file():
                return p
        return self.root / f"{frame_id}-{names[0]}"

    def rgb_path(self, frame_id: str) -> Path:
        return self._first(frame_id, "transparent-rgb-img.jpg", "transparent-rgb-img.png")

    def depth_path(self, frame_id: str) -> Path:
        return self._first(frame_id, "transparent-depth-img.exr")

    def gt_depth_path(self, frame_id: str) -> Path | None:
        p = self._first(frame_id, "opaque-depth-img.exr")
        return p if p.is_file() else None

    def gt_mask_path(self, frame_id: str) -> Path | None:
        p = self._first(frame_id, "mask.png")
        return p if p.is_file() else None

    def gt_objects_path(self, frame_id: str) -> Path | None:
        return None
