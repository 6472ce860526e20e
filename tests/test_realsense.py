"""``sr3d import-bag`` on a recording the test writes itself with librealsense's software device.

Skipped, with the reason, when pyrealsense2 (extra ``realsense``) or the libusb it links against
is missing.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from sr3d_cli.errors import InputError
from sr3d_cli.io.realsense import import_rs
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.io.scene import SceneSource

try:
    rs = import_rs()
except InputError as exc:
    pytest.skip(f"import-bag round trip not run: {exc}", allow_module_level=True)

def _run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


W, H, FX, FY, CX, CY = 80, 60, 70.0, 72.0, 41.0, 29.5
DEPTH_UNITS = 1e-4  # metres per unit, as a D405 or a D435 set to high accuracy


def _frames(n: int):
    """n frames: a tilted plane of depth (0.4 ... 0.6 m) and a colour gradient that changes per
    frame, so frames cannot be swapped or dropped unnoticed."""
    v, u = np.mgrid[0:H, 0:W]
    for k in range(n):
        depth = np.round((0.4 + 0.2 * u / W + 0.01 * k) / DEPTH_UNITS).astype(np.uint16)
        rgb = np.stack([(u * 3 + k) % 256, (v * 4) % 256, np.full_like(u, 10 * k)], -1)
        yield depth, rgb.astype(np.uint8)


def _record(path, frames, one_sensor=False):
    """Write a recording of depth (Z16) and colour (RGB8) streams with the same intrinsics and an
    identity extrinsic, so aligning depth to colour must keep every pixel where it is.
    ``one_sensor``: colour comes from the depth sensor, as on a D405."""
    def stream(kind, uid, fmt, bpp):
        intr = rs.intrinsics()
        intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = W, H, FX, FY, CX, CY
        intr.model, intr.coeffs = rs.distortion.none, [0.0] * 5
        s = rs.video_stream()
        s.type, s.index, s.uid, s.width, s.height = kind, 0, uid, W, H
        s.fps, s.bpp, s.fmt, s.intrinsics = 30, bpp, fmt, intr
        return s

    device = rs.software_device()
    depth_sensor = device.add_sensor("Depth")
    colour_sensor = depth_sensor if one_sensor else device.add_sensor("Color")
    depth_profile = depth_sensor.add_video_stream(stream(rs.stream.depth, 0, rs.format.z16, 2))
    colour_profile = colour_sensor.add_video_stream(stream(rs.stream.color, 1, rs.format.rgb8, 3))
    depth_sensor.add_read_only_option(rs.option.depth_units, DEPTH_UNITS)
    identity = rs.extrinsics()
    identity.rotation, identity.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
    depth_profile.register_extrinsics_to(colour_profile, identity)
    recorder = rs.recorder(str(path), device)
    recorded = recorder.query_sensors()  # frames reach the file only through these
    opened = [[depth_profile, colour_profile]] if one_sensor else [depth_profile, colour_profile]
    for sensor, profile in zip(recorded, opened):
        sensor.open(profile)
        sensor.start(lambda frame: None)
    for k, (depth, rgb) in enumerate(frames):
        for sensor, profile, image in ((depth_sensor, depth_profile, depth),
                                       (colour_sensor, colour_profile, rgb)):
            frame = rs.software_video_frame()
            frame.pixels = image.tobytes()
            frame.bpp = 2 if image.ndim == 2 else 3
            frame.stride = W * frame.bpp
            frame.timestamp, frame.frame_number = 1000.0 / 30 * k, k
            frame.domain = rs.timestamp_domain.hardware_clock
            frame.profile = profile.as_video_stream_profile()
            sensor.on_video_frame(frame)
    for sensor in recorded:
        sensor.stop()
        sensor.close()
    del recorder  # closes the file


@pytest.fixture(scope="module", params=["two sensors", "one sensor"])
def recording(tmp_path_factory, request):
    # librealsense 2.56+ records ROS2 (.db3); older SDKs write ROS1 .bag. Playback reads both.
    path = tmp_path_factory.mktemp("rec") / "capture.db3"
    frames = list(_frames(6))
    one = request.param == "one sensor"
    try:
        _record(path, frames, one)
    except RuntimeError as exc:
        if "extension" not in str(exc):
            raise
        path = path.with_suffix(".bag")
        _record(path, frames, one)
    return path, frames


def _which(rgb) -> int:
    """The recorded frame a colour image came from (its blue channel is 10 * k)."""
    return int(rgb[0, 0, 2]) // 10


def test_recording_becomes_a_native_scene_with_the_same_pixels(recording, tmp_path):
    path, frames = recording
    out = tmp_path / "scene"
    result = _run(["import-bag", str(path), str(out)])
    assert result.exit_code == 0, result.output
    camera = json.loads((out / "camera.json").read_text())
    assert camera["depth_scale"] == DEPTH_UNITS
    assert (camera["width"], camera["height"]) == (W, H)
    np.testing.assert_allclose(camera["K"], [[FX, 0, CX], [0, FY, CY], [0, 0, 1]], atol=1e-4)
    scene = SceneSource(out)
    # librealsense's syncer hands out the first frame of each stream unpaired: it is skipped
    imported = [scene.load_frame(f) for f in scene.frame_ids()]
    assert [_which(f.rgb) for f in imported] == list(range(len(frames) - len(imported),
                                                           len(frames)))
    assert len(imported) >= len(frames) - 1
    for frame in imported:
        depth, rgb = frames[_which(frame.rgb)]
        assert np.array_equal(frame.rgb, rgb)
        assert np.allclose(frame.camera.K, [[FX, 0, CX], [0, FY, CY], [0, 0, 1]], atol=1e-4)
        # aligning with an identity extrinsic may leave a one-pixel rim empty; the rest is exact
        seen = frame.depth_m > 0
        assert seen.mean() > 0.95
        np.testing.assert_allclose(frame.depth_m[seen], depth[seen] * DEPTH_UNITS, atol=1e-6)


def test_every_and_limit_pick_frames(recording, tmp_path):
    path, frames = recording
    out = tmp_path / "scene"
    result = _run(["import-bag", str(path), str(out), "--every", "2", "--limit", "1"])
    assert result.exit_code == 0, result.output
    whole = tmp_path / "whole"
    assert _run(["import-bag", str(path), str(whole)]).exit_code == 0
    order = [_which(SceneSource(whole).load_frame(f).rgb) for f in SceneSource(whole).frame_ids()]
    scene = SceneSource(out)
    assert scene.frame_ids() == ["000000"]
    assert _which(scene.load_frame("000000").rgb) == order[0]
    out2 = tmp_path / "scene2"
    assert _run(["import-bag", str(path), str(out2), "--every", "2"]).exit_code == 0
    scene2 = SceneSource(out2)
    assert [_which(scene2.load_frame(f).rgb) for f in scene2.frame_ids()] == order[::2]


def test_a_file_that_is_not_a_recording_is_named(tmp_path):
    bad = tmp_path / "broken.bag"
    bad.write_bytes(b"not a rosbag" * 100)
    result = _run(["import-bag", str(bad), str(tmp_path / "out")])
    assert result.exit_code == 2 and "broken.bag" in result.output
    assert not (tmp_path / "out" / "camera.json").exists()
