"""Image and depth codecs: the one place that knows how depth is encoded in files.

In memory, depth is ``depth_m : (H, W) float32`` metres along the optical axis, 0 = no reading.
On disk: uint16 PNG with ``depth_scale`` metres per unit (0 = no reading), float ``.npy`` or
``.exr`` in metres (NaN, inf, <= 0 = no reading).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from sr3d_cli.errors import InputError
from sr3d_cli.io.atomic import write_npy, write_png

DEPTH_SUFFIXES = (".png", ".npy", ".exr", ".tif", ".tiff")
RGB_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def decode_image(path: Path, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    """Decode an image file as stored (dtype and channels kept); errors name the file."""
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except FileNotFoundError:
        raise InputError(path, "file does not exist") from None
    except OSError as exc:
        raise InputError(path, f"cannot read file ({exc.strerror or exc})") from None
    if data.size == 0:
        raise InputError(path, "file is empty")
    image = cv2.imdecode(data, flags)
    if image is None:
        raise InputError(path, "cannot decode image (truncated or not an image)")
    return image


def read_rgb(path: str | Path) -> np.ndarray:
    """Colour image as ``(H, W, 3) uint8`` RGB. Grey is expanded, alpha dropped, 16-bit scaled."""
    path = Path(path)
    image = decode_image(path, cv2.IMREAD_UNCHANGED)
    if image.dtype == np.uint16:
        image = (image.astype(np.float32) / 257.0 + 0.5).astype(np.uint8)
    elif image.dtype != np.uint8:
        raise InputError(path, f"colour image has dtype {image.dtype}; expected 8-bit")
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    elif image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    else:
        raise InputError(path, f"colour image has {image.shape[2]} channels")
    return image


def clean_depth(depth: np.ndarray) -> np.ndarray:
    """float32 copy with NaN, inf and non-positive values set to 0 (no reading)."""
    depth = np.asarray(depth, dtype=np.float32).copy()
    depth[~np.isfinite(depth) | (depth < 0)] = 0.0
    return depth


def read_depth(path: str | Path, depth_scale: float) -> np.ndarray:
    """Depth file to ``(H, W) float32`` metres, 0 = no reading.

    Integer images (PNG, TIFF, integer ``.npy``) are multiplied by ``depth_scale``, their
    largest value (65535 in 16 bits) read as no reading: some cameras and exporters mark a
    missing reading so, and at any depth camera's scale it lies beyond its range (65.5 m in
    millimetres). Float files are taken as metres.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".exr":
        from sr3d_cli.io.exr import read_exr

        raw = read_exr(path)
    elif suffix == ".npy":
        try:
            raw = np.load(path, allow_pickle=False)
        except FileNotFoundError:
            raise InputError(path, "file does not exist") from None
        except (ValueError, OSError, EOFError) as exc:
            raise InputError(path, f"cannot read .npy ({exc})") from None
    else:
        raw = decode_image(path, cv2.IMREAD_UNCHANGED)
    raw = np.asarray(raw)
    if raw.ndim == 3 and raw.shape[2] >= 1 and np.all(raw == raw[..., :1]):
        raw = raw[..., 0]
    if raw.ndim != 2:
        raise InputError(path, f"depth must be one channel, got shape {raw.shape}")
    if raw.dtype.kind == "f":
        return clean_depth(raw)
    if raw.dtype.kind in "ui":
        if raw.dtype == np.uint8:
            raise InputError(path, "depth is 8-bit; expected uint16 (or float metres)")
        depth = raw.astype(np.float64) * depth_scale
        depth[raw == np.iinfo(raw.dtype).max] = 0.0
        return clean_depth(depth)
    raise InputError(path, f"depth has unsupported dtype {raw.dtype}")


def encode_depth_png(depth_m: np.ndarray, depth_scale: float) -> np.ndarray:
    """Metres to uint16 units of ``depth_scale``; no reading and out-of-range values become 0."""
    depth = clean_depth(depth_m)
    units = np.rint(depth.astype(np.float64) / depth_scale)
    units[(units > np.iinfo(np.uint16).max)] = 0
    return units.astype(np.uint16)


def write_depth(path: str | Path, depth_m: np.ndarray, depth_scale: float) -> Path:
    """Write depth by suffix: ``.png`` uint16 with ``depth_scale``, ``.npy`` float32 metres."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        return write_npy(path, clean_depth(depth_m))
    if path.suffix.lower() == ".exr":
        from sr3d_cli.io.exr import write_exr

        write_exr(path, clean_depth(depth_m))
        return path
    return write_png(path, encode_depth_png(depth_m, depth_scale))


def read_mask(path: str | Path, *, split_binary: bool = False) -> np.ndarray:
    """Instance mask as ``(H, W) int32`` ids, 0 = background.

    Identical colour channels are collapsed. With ``split_binary`` a mask holding one non-zero
    value is split into connected components numbered 1..n (ordered by top-left pixel).
    """
    path = Path(path)
    mask = decode_image(path, cv2.IMREAD_UNCHANGED)
    if mask.ndim == 3:
        if not np.all(mask == mask[..., :1]):
            raise InputError(path, "mask has differing colour channels; expected instance ids")
        mask = mask[..., 0]
    if mask.dtype not in (np.uint8, np.uint16):
        raise InputError(path, f"mask has dtype {mask.dtype}; expected uint8 or uint16")
    mask = mask.astype(np.int32)
    if split_binary and len(np.unique(mask[mask > 0])) <= 1:
        mask = split_components(mask > 0)
    return mask


def split_components(binary: np.ndarray) -> np.ndarray:
    """Label 8-connected components of a boolean image as ``(H, W) int32`` ids 1..n."""
    count, labels = cv2.connectedComponents(binary.astype(np.uint8), connectivity=8)
    return labels.astype(np.int32)
