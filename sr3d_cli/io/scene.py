"""Scene folders: where each input lives and where each stage writes, for every layout.

A :class:`SceneSource` answers "which frames are there" and "where is file X of frame F"; the
readers in :mod:`sr3d_cli.io.images` do the decoding. Layout quirks live in subclasses
(:mod:`sr3d_cli.io.formats`). Outputs always go to the native layout under ``out``.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sr3d_cli.config import IOConfig
from sr3d_cli.errors import InputError
from sr3d_cli.geometry.camera import Camera
from sr3d_cli.io import images
from sr3d_cli.io.camera_files import fit_camera_to_image, load_camera
from sr3d_cli.io.frames import sort_ids

log = logging.getLogger("sr3d")


@dataclass
class Frame:
    """One RGB-D frame, checked for consistency.

    rgb : (H, W, 3) uint8 RGB.
    depth_m : (H, W) float32 raw sensor depth, metres, 0 = no reading.
    camera : intrinsics matching (H, W).
    """

    scene: "SceneSource"
    frame_id: str
    rgb: np.ndarray
    depth_m: np.ndarray
    camera: Camera

    @property
    def key(self) -> str:
        return self.scene.frame_key(self.frame_id)


class SceneSource:
    """A native scene folder (see DESIGN.md, "Scene folder")."""

    layout = "native"
    split_binary_masks = False
    CAMERA_NAMES = ("camera.json", "camera.yaml", "camera_info.yaml", "camera_intrinsics.yaml",
                    "intrinsics.json", "K.txt", "K.npy")

    def __init__(self, root: Path, *, out: Path | None = None, name: str = "",
                 io: IOConfig | None = None):
        self.root = Path(root)
        self.out = Path(out) if out is not None else self.root
        self.name = name
        self.io = io or IOConfig()
        self._camera: Camera | None = None
        self._notices: set[str] = set()

    # ---- naming -----------------------------------------------------------------------------
    def frame_key(self, frame_id: str) -> str:
        return f"{self.name}/{frame_id}" if self.name else frame_id

    def __repr__(self) -> str:
        return f"{type(self).__name__}({str(self.root)!r})"

    # ---- inputs -----------------------------------------------------------------------------
    def frame_ids(self) -> list[str]:
        folder = self.root / "rgb"
        return sort_ids(p.stem for p in folder.iterdir()
                        if p.is_file() and p.suffix.lower() in images.RGB_SUFFIXES
                        and not p.name.startswith("."))

    def orphan_depth(self, frame_ids: list[str]) -> list[Path]:
        """Depth files without a colour image among ``frame_ids`` (native layout: the frames
        are the colour images, so these would be left out silently)."""
        folder, known = self.root / "depth", set(frame_ids)
        if self.layout != "native" or not folder.is_dir():
            return []
        return sorted(p for p in folder.iterdir()
                      if p.is_file() and p.suffix.lower() in images.DEPTH_SUFFIXES
                      and not p.name.startswith(".") and p.stem not in known)

    @staticmethod
    def _found(folder: Path, frame_id: str, suffixes):
        """The files ``folder/<frame_id><suffix>`` that exist, in the order of ``suffixes``,
        each suffix in lower or upper case (frames are listed whatever its case); a generator,
        so that a caller wanting the first looks no further."""
        for suffix in suffixes:
            for case in dict.fromkeys((suffix, suffix.upper())):
                p = folder / f"{frame_id}{case}"
                if p.is_file():
                    yield p
                    break

    def _find(self, folder: Path, frame_id: str, suffixes) -> Path | None:
        return next(self._found(folder, frame_id, suffixes), None)

    def _input(self, folder: Path, frame_id: str, suffixes) -> Path:
        """A frame's input file under ``folder``; a notice names the others where several
        kinds exist (``000001.png`` and ``000001.npy``), as only the first is read."""
        found = list(self._found(folder, frame_id, suffixes))
        if len(found) > 1:
            self._notice(f"{folder}: {' and '.join(p.name for p in found)} are the same "
                         f"frame; reading {found[0].name}")
        return found[0] if found else folder / f"{frame_id}.png"

    def rgb_path(self, frame_id: str) -> Path:
        return self._input(self.root / "rgb", frame_id, images.RGB_SUFFIXES)

    def depth_path(self, frame_id: str) -> Path:
        return self._input(self.root / "depth", frame_id, images.DEPTH_SUFFIXES)

    def gt_depth_path(self, frame_id: str) -> Path | None:
        return self._find(self.root / "gt" / "depth", frame_id, images.DEPTH_SUFFIXES)

    def gt_mask_path(self, frame_id: str) -> Path | None:
        return self._find(self.root / "gt" / "masks", frame_id, (".png",))

    def gt_objects_path(self, frame_id: str) -> Path | None:
        return self._find(self.root / "gt" / "objects", frame_id, (".json",))

    def camera_path(self) -> Path:
        if self.io.camera:
            return Path(self.io.camera)
        for name in self.CAMERA_NAMES:
            if (self.root / name).is_file():
                return self.root / name
        return self.root / self.CAMERA_NAMES[0]

    @property
    def camera(self) -> Camera:
        """Intrinsics as found in the scene (size not yet matched to the images)."""
        if self._camera is None:
            notes: list[str] = []
            self._camera = load_camera(self.camera_path(), self.io.depth_scale, notes)
            for note in notes:
                self._notice(note)
        return self._camera

    # ---- outputs ----------------------------------------------------------------------------
    def output_path(self, stage: str, frame_id: str, suffix: str = ".png") -> Path:
        return self.out / stage / f"{frame_id}{suffix}"

    # ---- loading ----------------------------------------------------------------------------
    def _notice(self, message: str | None) -> None:
        if message and message not in self._notices:
            self._notices.add(message)
            log.warning("notice: %s", message)

    def read_depth_checked(self, path: Path, shape: tuple[int, int] | None = None) -> np.ndarray:
        """Read a depth file, check its size and that its scale gives a plausible median."""
        depth = images.read_depth(path, self.camera.depth_scale)
        if shape is not None and depth.shape != shape:
            raise InputError(path, f"depth is {depth.shape[1]}x{depth.shape[0]} but the colour "
                                   f"image is {shape[1]}x{shape[0]}")
        valid = depth[depth > 0]
        if not valid.size:
            raise InputError(path, "no valid depth reading (every pixel is 0 or NaN)")
        if valid.size:
            median = float(np.median(valid))
            if not (self.io.min_median_depth <= median <= self.io.max_median_depth):
                raise InputError(path, f"median depth is {median:.4g} m, outside "
                                       f"[{self.io.min_median_depth:g}, "
                                       f"{self.io.max_median_depth:g}] m: is depth_scale "
                                       f"{self.camera.depth_scale:g} m/unit right?")
        return depth

    def load_frame(self, frame_id: str) -> Frame:
        rgb = images.read_rgb(self.rgb_path(frame_id))
        depth = self.read_depth_checked(self.depth_path(frame_id), rgb.shape[:2])
        camera, notice = fit_camera_to_image(self.camera, rgb.shape[1], rgb.shape[0])
        self._notice(notice)
        return Frame(self, frame_id, rgb, depth, camera)

    def load_gt_depth(self, frame_id: str, shape: tuple[int, int]) -> np.ndarray | None:
        path = self.gt_depth_path(frame_id)
        return None if path is None else self.read_depth_checked(path, shape)

    def load_mask(self, path: Path | None, shape: tuple[int, int]) -> np.ndarray | None:
        if path is None:
            return None
        mask = images.read_mask(path, split_binary=self.split_binary_masks)
        if mask.shape != shape:
            raise InputError(path, f"mask is {mask.shape[1]}x{mask.shape[0]} but the images are "
                                   f"{shape[1]}x{shape[0]}")
        return mask

    def load_gt_objects(self, frame_id: str) -> dict | None:
        path = self.gt_objects_path(frame_id)
        if path is None:
            return None
        try:
            document = json.loads(path.read_text(encoding="utf-8"))
        except (ValueError, OSError) as exc:
            raise InputError(path, f"cannot read JSON ({exc})") from None
        if not isinstance(document, dict) or not isinstance(document.get("objects", []), list):
            raise InputError(path, "expected a mapping with an 'objects' list")
        return document

    # ---- predictions (evaluate) -------------------------------------------------------------
    def stage_file(self, stage: str, frame_id: str, suffixes) -> Path | None:
        """A stage output of a frame (e.g. ``masks``, ``repaired``): under the output root first,
        then under the input root."""
        for base in (self.out, self.root):
            hit = self._find(base / stage, frame_id, suffixes)
            if hit is not None:
                return hit
        return None

    def prediction_path(self, pred: str, frame_id: str) -> Path | None:
        """Depth file of a prediction. ``depth`` is the raw sensor; any other name is a folder
        looked up as a stage output (output root, then input root), then as given (absolute or
        relative to the working directory)."""
        if pred == "depth":
            path = self.depth_path(frame_id)
            return path if path.is_file() else None
        folder = Path(pred)
        if not folder.is_absolute():
            hit = self.stage_file(pred, frame_id, images.DEPTH_SUFFIXES)
            if hit is not None:
                return hit
        return self._find(folder, frame_id, images.DEPTH_SUFFIXES)
