"""RealSense recordings to native scene folders (extra ``realsense``: pyrealsense2).

Both recording formats librealsense writes are read: ROS1 ``.bag`` (SDK up to 2.55, the
RealSense Viewer's default for years) and ROS2 ``.db3`` (newer SDKs); playback picks by content.

Depth is aligned to the colour stream, so the scene uses the colour intrinsics; the depth scale
is the device's (metres per unit, written to camera.json); frames are numbered in recording order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sr3d_cli.errors import InputError
from sr3d_cli.io.atomic import write_json, write_png

INSTALL_HINT = "pip install 'sr3d-cli[realsense]'  (pyrealsense2)"
LIBUSB_HINT = "apt install libusb-1.0-0  (Debian/Ubuntu)"


def import_rs():
    """pyrealsense2, or an InputError that says what to install (the wheel, or the libusb it
    links against: the wheel does not bundle it)."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        if "libusb" in str(exc):
            raise InputError(Path("pyrealsense2"), f"pyrealsense2 is installed but the system "
                                                   f"library libusb-1.0 is missing: "
                                                   f"{LIBUSB_HINT}") from None
        raise InputError(Path("pyrealsense2"), f"reading recordings needs the realsense extra: "
                                               f"{INSTALL_HINT}") from None
    return rs


def _open_playback(rs, bag: Path):
    """Playback device (not real time, so no frame is dropped) with its depth and colour sensors
    started, paused, into one syncer. Not ``rs.pipeline``: its playback starts before real time
    can be switched off, and frames are lost at random (seen in tests/test_realsense.py)."""
    try:
        device = rs.context().load_device(str(bag))
    except RuntimeError as exc:
        raise InputError(bag, f"cannot play the recording ({exc})") from None
    playback = device.as_playback()
    playback.set_real_time(False)
    chosen = {}
    for sensor in device.query_sensors():
        for profile in sensor.get_stream_profiles():
            kind = profile.stream_type()
            if kind in (rs.stream.depth, rs.stream.color) and kind not in chosen:
                chosen[kind] = (sensor, profile)
    missing = [name for kind, name in ((rs.stream.depth, "depth"), (rs.stream.color, "colour"))
               if kind not in chosen]
    if missing:
        raise InputError(bag, f"the recording has no {' or '.join(missing)} stream")
    try:
        scale = float(device.first_depth_sensor().get_depth_scale())
    except RuntimeError:
        raise InputError(bag, "the depth sensor records no depth scale") from None
    per_sensor: dict[int, tuple] = {}  # a D405 streams colour from its depth sensor
    for sensor, profile in chosen.values():
        per_sensor.setdefault(id(sensor), (sensor, []))[1].append(profile)
    syncer = rs.syncer(64)
    playback.pause()  # else the first sensor started can play its whole stream alone
    for sensor, profiles in per_sensor.values():
        sensor.open(profiles if len(profiles) > 1 else profiles[0])
        sensor.start(syncer)
    playback.resume()
    return playback, [s for s, _ in per_sensor.values()], syncer, scale


def _pairs(rs, playback, syncer):
    """Framesets holding both depth and colour, in recording order. The syncer hands out the
    first frame of each stream alone while it learns the streams; those are skipped."""
    while True:
        ok, frames = syncer.try_wait_for_frames(500)
        if ok:
            if frames.get_depth_frame() and frames.get_color_frame():
                yield frames
        elif playback.current_status() == rs.playback_status.stopped:
            return


def import_bag(bag: Path, out: Path, every: int = 1, limit: int | None = None) -> int:
    """Write ``out/{rgb,depth}/<NNNNNN>.png`` and ``out/camera.json``; returns frames written."""
    rs = import_rs()
    if not Path(bag).is_file():
        raise InputError(bag, "no such recording")
    playback, sensors, syncer, scale = _open_playback(rs, Path(bag))
    align = rs.align(rs.stream.color)
    written = 0
    try:
        for index, frames in enumerate(_pairs(rs, playback, syncer)):
            if limit is not None and written >= limit:
                break
            if index % every:
                continue
            frames = align.process(frames)
            depth, colour = frames.get_depth_frame(), frames.get_color_frame()
            if written == 0:
                intr = colour.profile.as_video_stream_profile().intrinsics
                K = [[intr.fx, 0.0, intr.ppx], [0.0, intr.fy, intr.ppy], [0.0, 0.0, 1.0]]
                write_json(out / "camera.json", {"K": K, "width": intr.width,
                                                 "height": intr.height,
                                                 "depth_scale": float(f"{scale:.7g}")})
            rgb = np.asanyarray(colour.get_data())
            if colour.profile.format() == rs.format.bgr8:
                rgb = rgb[..., ::-1]
            fid = f"{written:06d}"
            write_png(out / "rgb" / f"{fid}.png", np.ascontiguousarray(rgb))
            write_png(out / "depth" / f"{fid}.png", np.asanyarray(depth.get_data()).astype(np.uint16))
            written += 1
    finally:
        for sensor in sensors:
            sensor.stop()
            sensor.close()
    if written == 0:
        raise InputError(bag, "no frame with both depth and colour")
    return written
