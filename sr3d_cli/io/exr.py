"""OpenEXR depth files (ClearGrasp stores float16 metres in three identical channels).

opencv-python-headless is built without OpenEXR, so this uses the ``OpenEXR`` package, an extra.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from sr3d_cli.errors import InputError, MissingExtraError
from sr3d_cli.io.atomic import write_bytes


def _openexr():
    try:
        import OpenEXR
    except ImportError:
        raise MissingExtraError("reading EXR depth", "OpenEXR", "exr") from None
    return OpenEXR


def read_exr(path: str | Path) -> np.ndarray:
    """First channel of an EXR file as float32, shape (H, W)."""
    OpenEXR = _openexr()
    try:
        with OpenEXR.File(str(path)) as exr:
            channels = exr.channels()
            if not channels:
                raise InputError(path, "EXR file has no channels")
            name = "Y" if "Y" in channels else sorted(channels)[0]
            pixels = np.asarray(channels[name].pixels)
    except InputError:
        raise
    except Exception as exc:  # OpenEXR raises bare RuntimeError/OSError for damaged files
        raise InputError(path, f"cannot read EXR ({exc})") from None
    if pixels.ndim == 3:
        pixels = pixels[..., 0]
    return pixels.astype(np.float32)


def write_exr(path: str | Path, depth_m: np.ndarray) -> None:
    """Write a float32 single-channel EXR atomically (OpenEXR writes to a named file, so it
    goes to a private temporary file first)."""
    OpenEXR = _openexr()
    data = np.ascontiguousarray(depth_m, dtype=np.float32)
    fd, tmp = tempfile.mkstemp(suffix=".exr")
    os.close(fd)
    try:
        with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                          {"Y": data}) as exr:
            exr.write(tmp)
        write_bytes(path, Path(tmp).read_bytes())
    finally:
        os.unlink(tmp)
