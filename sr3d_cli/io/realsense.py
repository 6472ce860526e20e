"""RealSense ``.bag`` recordings to native scene folders (extra ``realsense``: pyrealsense2).

Depth is aligned to the colour stream, so the scene uses the colour intrinsics; the depth scale
is the device's (metres per unit, written to camera.json); frames are numbered in recording order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sr3d_cli.errors import InputError
from sr3d_cli.io.atomic import write_json, write_png

INSTALL_HINT = "pip install 'sr3d-cli[realsense]'  (pyrealsense2)"


def import_rs():
    try:
        import pyrealsense2 as rs
    except ImportError:
        raise InputError(Path("pyrealsense2"), f"reading .bag files needs the realsense extra: "
                                               f"{INSTALL_HINT}") from None
    return rs


def import_bag(bag: Path, out: Path, every: int = 1, limit: int | None = None) -> int:
    """Write ``out/{rgb,depth}/<NNNNNN>.png`` and ``out/camera.json``; returns frames written."""
    rs = import_rs()
    if not Path(bag).is_file():
        raise InputError(bag, "no such recording")
    pipeline, config = rs.pipeline(), rs.config()
    try:
        config.enable_device_from_file(str(bag), repeat_playback=False)
        config.enable_stream(rs.stream.depth)
        config.enable_stream(rs.stream.color)
        profile = pipeline.start(config)
    except RuntimeError as exc:
        raise InputError(bag, f"cannot play the recording ({exc}); it needs depth and colour "
                              "streams") from None
    try:
        device = profile.get_device()
        device.as_playback().set_real_time(False)
        scale = float(device.first_depth_sensor().get_depth_scale())
        align = rs.align(rs.stream.color)
        written, index = 0, 0
        while limit is None or written < limit:
            ok, frames = pipeline.try_wait_for_frames(2000)
            if not ok:
                break
            index += 1
            if (index - 1) % every:
                continue
            frames = align.process(frames)
            depth, colour = frames.get_depth_frame(), frames.get_color_frame()
            if not depth or not colour:
                continue
            if written == 0:
                intr = colour.profile.as_video_stream_profile().intrinsics
                K = [[intr.fx, 0.0, intr.ppx], [0.0, intr.fy, intr.ppy], [0.0, 0.0, 1.0]]
                write_json(out / "camera.json", {"K": K, "width": intr.width,
                                                 "height": intr.height, "depth_scale": scale})
            rgb = np.asanyarray(colour.get_data())
            if colour.profile.format() == rs.format.bgr8:
                rgb = rgb[..., ::-1]
            fid = f"{written:06d}"
            write_png(out / "rgb" / f"{fid}.png", np.ascontiguousarray(rgb))
            write_png(out / "depth" / f"{fid}.png", np.asanyarray(depth.get_data()).astype(np.uint16))
            written += 1
    finally:
        pipeline.stop()
    if written == 0:
        raise InputError(bag, "no frame with both depth and colour")
    return written
