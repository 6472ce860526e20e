"""Camera intrinsics files in the formats users have, all read into one :class:`Camera`.

Recognised by content (the file name does not matter):

- native ``camera.json``: ``{"K": 3x3, "width", "height", "depth_scale"}``
- Open3D ``PinholeCameraIntrinsic`` JSON: ``{"width", "height", "intrinsic_matrix": 9 numbers,
  column-major}``
- RealSense-style JSON: ``{"fx", "fy", "ppx", "ppy", "width", "height"[, "depth_scale"]}``
- ROS CameraInfo YAML: camera_calibration's ``{image_width, image_height, camera_matrix: {data}}``
  or the message's ``{width, height, K: 9 numbers}`` (``k`` in ROS 2)
- ClearGrasp ``camera_intrinsics.yaml``: ``{xres, yres, fx, fy, cx, cy}``, with the unrounded
  ``camera_parameters.txt`` beside it preferred when present
- a 3x3 matrix as ``.npy`` or whitespace/comma separated ``.txt`` (no size: taken from the images)
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sr3d_cli.errors import InputError
from sr3d_cli.geometry.camera import Camera

UNKNOWN_SIZE = 0  # width/height of a bare 3x3 matrix until images give it


def _K(fx, fy, cx, cy) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)


def _from_mapping(data: dict[str, Any], path: Path, depth_scale: float,
                  notes: list[str] | None = None) -> Camera:
    def num(key, src=data):
        value = src[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(path, f"'{key}' must be a number, got {value!r}")
        return float(value)

    def size(key):
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value) or value < 0 or value != int(value):
            raise InputError(path, f"'{key}' must be a whole number of pixels, got {value!r}")
        return int(value)

    scale = data.get("depth_scale", depth_scale)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or \
            not math.isfinite(scale) or scale <= 0:
        raise InputError(path, f"'depth_scale' must be a positive number, got {scale!r}")
    scale = float(scale)
    if "depth_scale" not in data and notes is not None and "xres" not in data:
        notes.append(f"{path}: no depth_scale; assuming io.depth_scale = {depth_scale:g} "
                     "m per depth unit")
    if "K" in data and isinstance(data["K"], list) and len(data["K"]) == 3:  # native
        K = np.asarray(data["K"], dtype=np.float64)
        return Camera(K, size("width"), size("height"), scale, str(path))
    if "intrinsic_matrix" in data:  # Open3D, column-major
        K = np.asarray(data["intrinsic_matrix"], dtype=np.float64).reshape(3, 3).T
        return Camera(K, size("width"), size("height"), scale, str(path))
    if "ppx" in data:  # RealSense rs2_intrinsics
        K = _K(num("fx"), num("fy"), num("ppx"), num("ppy"))
        return Camera(K, size("width"), size("height"), scale, str(path))
    if "camera_matrix" in data:  # ROS camera_calibration YAML
        K = np.asarray(data["camera_matrix"]["data"], dtype=np.float64).reshape(3, 3)
        return Camera(K, size("image_width"), size("image_height"), scale, str(path))
    for key in ("K", "k"):  # ROS CameraInfo message (flat 9 numbers)
        if key in data and "width" in data:
            K = np.asarray(data[key], dtype=np.float64).reshape(3, 3)
            return Camera(K, size("width"), size("height"), scale, str(path))
    if "xres" in data:  # ClearGrasp
        K = _K(num("fx"), num("fy"), num("cx"), num("cy"))
        return Camera(K, size("xres"), size("yres"), scale, str(path))
    raise InputError(path, "unrecognised camera file: expected native, Open3D, RealSense, ROS "
                           "CameraInfo or ClearGrasp intrinsics")


def _cleargrasp_parameters(path: Path) -> dict[str, float] | None:
    """The unrounded ``camera_parameters.txt`` ClearGrasp keeps beside some intrinsics files."""
    txt = path.with_name("camera_parameters.txt")
    if not txt.is_file():
        return None
    values = {}
    for line in txt.read_text(encoding="utf-8", errors="replace").splitlines():
        m = re.match(r"\s*([A-Za-z ]+?)\s*:\s*([-+0-9.eE]+)\s*$", line)
        if m:
            values[m.group(1).strip().lower()] = float(m.group(2))
    keys = {"fx", "fy", "cx", "cy", "image width", "image height"}
    return values if keys <= values.keys() else None


def _matrix_only(K: np.ndarray, path: Path, depth_scale: float) -> Camera:
    if K.shape != (3, 3):
        raise InputError(path, f"expected a 3x3 intrinsic matrix, got shape {K.shape}")
    try:
        return Camera(K, UNKNOWN_SIZE, UNKNOWN_SIZE, depth_scale, str(path))
    except ValueError as exc:
        raise InputError(path, str(exc)) from None


def load_camera(path: str | Path, depth_scale: float = 0.001,
                notes: list[str] | None = None) -> Camera:
    """Read any supported intrinsics file. ``depth_scale`` is used when the file has none (a
    notice naming the file and the scale assumed is appended to ``notes``).

    A bare 3x3 matrix gives a camera with ``width == height == 0``: call
    :func:`fit_camera_to_image` with the image size.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "camera file does not exist")
    suffix = path.suffix.lower()
    try:
        if suffix in (".npy", ".txt") and notes is not None:
            notes.append(f"{path}: a bare matrix has no depth_scale; assuming io.depth_scale = "
                         f"{depth_scale:g} m per depth unit")
        if suffix == ".npy":
            return _matrix_only(np.load(path, allow_pickle=False).astype(np.float64), path,
                                depth_scale)
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark some editors write
        if suffix == ".txt":
            numbers = [float(x) for x in re.split(r"[\s,;\[\]]+", text) if x]
            return _matrix_only(np.asarray(numbers, dtype=np.float64).reshape(-1, 3), path,
                                depth_scale)
        data = json.loads(text) if suffix == ".json" else yaml.safe_load(text)
    except InputError:
        raise
    except (ValueError, OSError, EOFError, TypeError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise InputError(path, f"cannot parse camera file ({exc})") from None
    if not isinstance(data, dict):
        raise InputError(path, "camera file must hold a mapping")
    try:
        cam = _from_mapping(data, path, depth_scale, notes)
    except InputError:
        raise
    except KeyError as exc:
        raise InputError(path, f"camera file lacks {exc}") from None
    except (TypeError, ValueError, OverflowError) as exc:
        raise InputError(path, f"invalid camera file ({type(exc).__name__}: {exc})") from None
    if "xres" in data:
        precise = _cleargrasp_parameters(path)
        if precise:
            cam = Camera(_K(precise["fx"], precise["fy"], precise["cx"], precise["cy"]),
                         int(precise["image width"]), int(precise["image height"]),
                         cam.depth_scale, str(path.with_name("camera_parameters.txt")))
    return cam


def fit_camera_to_image(cam: Camera, width: int, height: int) -> tuple[Camera, str | None]:
    """Match intrinsics to an image size.

    Returns the camera to use and a notice (or None). Equal sizes pass; an exact rescale (the same
    factor on both axes) rescales K with a notice; anything else raises :class:`InputError`.
    """
    if cam.width == UNKNOWN_SIZE:
        fixed = Camera(cam.K, width, height, cam.depth_scale, cam.source)
        return fixed, None
    if (cam.width, cam.height) == (width, height):
        return cam, None
    if cam.width * height == cam.height * width:
        scaled = cam.scaled(width, height)
        return scaled, (f"{cam.source}: intrinsics are for {cam.width}x{cam.height}, images are "
                        f"{width}x{height}; K rescaled by {width / cam.width:g}")
    raise InputError(cam.source or "camera", f"intrinsics are for {cam.width}x{cam.height} but "
                                             f"the images are {width}x{height} (not a rescale)")
