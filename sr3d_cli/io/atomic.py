"""Atomic file writing: a temporary file in the same folder, flushed, then renamed over the target.

A run killed at any moment leaves either the old file or the new one, never part of one.
Every writer in sr3d goes through :func:`write_bytes`. Files get the permissions a plain
``open()`` would give them (0666 less the umask: 0644 by default); a file written over keeps
its own.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np


_UMASK: list[int] = []


def _new_file_mode() -> int:
    """0666 less the process umask (read once: reading it means setting it)."""
    if not _UMASK:
        mask = os.umask(0o022)
        os.umask(mask)
        _UMASK.append(mask)
    return 0o666 & ~_UMASK[0]


def write_bytes(path: str | Path, data: bytes) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        mode = path.stat().st_mode & 0o7777
    except OSError:
        mode = _new_file_mode()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return obj.as_posix()
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")


def dumps_json(data: Any) -> str:
    """JSON text with sorted keys and indentation, so files diff cleanly."""
    return json.dumps(data, indent=2, sort_keys=True, default=_jsonable, allow_nan=False) + "\n"


def write_json(path: str | Path, data: Any) -> Path:
    return write_bytes(path, dumps_json(data).encode("utf-8"))


def write_text(path: str | Path, text: str) -> Path:
    return write_bytes(path, text.encode("utf-8"))


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write a uint8/uint16 image; (H, W, 3) arrays are RGB (converted to OpenCV's BGR here)."""
    image = np.asarray(image)
    if image.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"PNG needs uint8 or uint16, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - OpenCV always encodes these dtypes
        raise OSError(f"could not encode {path}")
    return write_bytes(path, buf.tobytes())


def write_npy(path: str | Path, array: np.ndarray) -> Path:
    import io

    buf = io.BytesIO()
    np.save(buf, np.asarray(array), allow_pickle=False)
    return write_bytes(path, buf.getvalue())
