"""``sr3d import-bag`` on recordings the tests write with rosbags: a ROS 1 ``.bag`` (topics as
the ROS 1 RealSense driver names them), ROS 2 bags in SQLite (``.db3``) and MCAP storage (the
ROS 2 driver's names) and a RealSense Viewer recording (``/device_0/...``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("rosbags", reason="import-bag needs the bag extra: pip install "
                                      "'sr3d-cli[bag]'")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from sr3d_cli.cli import cli  # noqa: E402
from sr3d_cli.io.scene import SceneSource  # noqa: E402

W, H, FX, FY, CX, CY = 80, 60, 70.0, 72.0, 41.0, 29.5
N = 8
PERIOD_NS = 33_333_333  # 30 fps
T0 = 1_700_000_000 * 10**9
ROS1 = "/camera/color/image_raw", "/camera/aligned_depth_to_color/image_raw", \
    "/camera/color/camera_info"
ROS2 = "/camera/camera/color/image_raw", "/camera/camera/aligned_depth_to_color/image_raw", \
    "/camera/camera/color/camera_info"
VIEWER = "/device_0/sensor_1/Color_0/image/data", "/device_0/sensor_0/Depth_0/image/data", \
    "/device_0/sensor_1/Color_0/info/camera_info"
VIEWER_DEPTH_INFO = "/device_0/sensor_0/Depth_0/info/camera_info"
VIEWER_UNITS = "/device_0/sensor_0/option/Depth Units/value"


def _run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _frames(n: int = N, units: float = 0.001):
    """n frames: a tilted plane of depth (0.4 ... 0.6 m, plus 1 cm per frame) and a colour
    gradient whose blue channel is 10 * k, so a frame's index can be read back from its pixels."""
    v, u = np.mgrid[0:H, 0:W]
    for k in range(n):
        depth = np.round((0.4 + 0.2 * u / W + 0.01 * k) / units).astype(np.uint16)
        rgb = np.stack([(u * 3 + k) % 256, (v * 4) % 256, np.full_like(u, 10 * k)], -1)
        yield depth, rgb.astype(np.uint8)


def _which(rgb) -> int:
    return int(rgb[0, 0, 2]) // 10


class _Bag:
    """Writes messages with the typestore and writer of one recording kind."""

    def __init__(self, path, kind):
        self.ros1 = kind == "bag"
        self.types = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if self.ros1:
            self.writer = Writer1(path)
        else:
            plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
            self.writer = Writer2(path, version=8, storage_plugin=plugin)
        self.conns = {}

    def __enter__(self):
        self.writer.open()
        return self

    def __exit__(self, *exc):
        self.writer.close()

    def header(self, t_ns):
        T = self.types.types
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if self.ros1:
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="camera")
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id="camera")

    def write(self, topic, msgtype, msg, t_ns):
        if topic not in self.conns:
            self.conns[topic] = self.writer.add_connection(topic, msgtype, typestore=self.types)
        data = (self.types.serialize_ros1(msg, msgtype) if self.ros1
                else self.types.serialize_cdr(msg, msgtype))
        self.writer.write(self.conns[topic], t_ns, data)

    def image(self, topic, array, encoding, t_ns):
        T = self.types.types
        msg = T["sensor_msgs/msg/Image"](
            header=self.header(t_ns), height=array.shape[0], width=array.shape[1],
            encoding=encoding, is_bigendian=0, step=array.strides[0],
            data=np.frombuffer(array.tobytes(), dtype=np.uint8))
        self.write(topic, "sensor_msgs/msg/Image", msg, t_ns)

    def info(self, topic, t_ns, K=(FX, FY, CX, CY), size=(W, H)):
        T = self.types.types
        fx, fy, cx, cy = K
        k = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64)
        fields = dict(header=self.header(t_ns), height=size[1], width=size[0],
                      distortion_model="plumb_bob", binning_x=0, binning_y=0,
                      roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0,
                                                                width=0, do_rectify=False))
        arrays = dict(d=np.zeros(5), k=k, r=np.eye(3).ravel(),
                      p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64))
        fields.update({(name.upper() if self.ros1 else name): a for name, a in arrays.items()})
        self.write(topic, "sensor_msgs/msg/CameraInfo",
                   T["sensor_msgs/msg/CameraInfo"](**fields), t_ns)


def record(path, kind, names=ROS2, frames=None, *, depth_info=None, units=None,
           depth_lag_ns=2_000_000, colour_encoding="rgb8"):
    """Write a recording: per frame a colour image, an info message and a depth image stamped
    ``depth_lag_ns`` later (as a driver's two streams are); returns the frames written."""
    frames = list(frames if frames is not None else _frames())
    colour, depth, info = names
    with _Bag(path, kind) as bag:
        if units is not None:
            msg = bag.types.types["std_msgs/msg/Float32"](data=units)
            bag.write(VIEWER_UNITS, "std_msgs/msg/Float32", msg, T0)
        for k, (d, rgb) in enumerate(frames):
            t = T0 + k * PERIOD_NS
            image = rgb[..., ::-1] if colour_encoding == "bgr8" else rgb
            bag.image(colour, np.ascontiguousarray(image), colour_encoding, t)
            bag.info(info, t)
            if depth_info is not None:
                bag.info(VIEWER_DEPTH_INFO, t, *depth_info)
            bag.image(depth, d, "16UC1", t + depth_lag_ns)
    return frames


KINDS = {"bag": ("capture.bag", ROS1), "db3": ("capture_db3", ROS2),
         "mcap": ("capture_mcap", ROS2)}


@pytest.fixture(scope="module", params=list(KINDS))
def recording(tmp_path_factory, request):
    name, names = KINDS[request.param]
    path = tmp_path_factory.mktemp(request.param) / name
    frames = record(path, request.param, names)
    return path, frames, request.param


def test_recording_becomes_a_native_scene_with_the_same_pixels(recording, tmp_path):
    path, frames, _ = recording
    out = tmp_path / "scene"
    result = _run(["import-bag", path, out])
    assert result.exit_code == 0, result.output
    assert f"{N} frames written" in result.output
    camera = json.loads((out / "camera.json").read_text())
    assert camera["depth_scale"] == 0.001
    assert (camera["width"], camera["height"]) == (W, H)
    assert camera["K"] == [[FX, 0, CX], [0, FY, CY], [0, 0, 1]]
    scene = SceneSource(out)
    imported = [scene.load_frame(f) for f in scene.frame_ids()]
    assert [_which(f.rgb) for f in imported] == list(range(N))
    for frame in imported:
        depth, rgb = frames[_which(frame.rgb)]
        assert np.array_equal(frame.rgb, rgb)
        np.testing.assert_array_equal(np.round(frame.depth_m / 0.001), depth)
    stamps = json.loads((out / "recording.json").read_text())["frames"]
    assert stamps["000003"]["stamp_ns"] == T0 + 3 * PERIOD_NS


@pytest.mark.parametrize("kind", ["db3", "mcap"])
def test_the_file_inside_a_ros2_bag_folder_is_read_too(tmp_path, kind):
    path = tmp_path / "capture"
    record(path, kind, ROS2, _frames(3))
    inner = next(path.glob(f"*.{kind}"))
    result = _run(["import-bag", inner, tmp_path / "a"])
    assert result.exit_code == 0, result.output
    assert len(SceneSource(tmp_path / "a").frame_ids()) == 3
    alone = tmp_path / "moved" / inner.name  # without its metadata.yaml
    alone.parent.mkdir()
    inner.rename(alone)
    result = _run(["import-bag", alone, tmp_path / "b"])
    assert result.exit_code == 0, result.output
    assert len(SceneSource(tmp_path / "b").frame_ids()) == 3


def test_every_start_end_and_limit_pick_frames(recording, tmp_path):
    path, _, _ = recording

    def picked(*flags):
        out = tmp_path / f"s{len(list(tmp_path.iterdir()))}"
        result = _run(["import-bag", path, out, *flags])
        assert result.exit_code == 0, result.output
        scene = SceneSource(out)
        return [_which(scene.load_frame(f).rgb) for f in scene.frame_ids()]

    assert picked("--every", "3") == [0, 3, 6]
    assert picked("--every", "2", "--limit", "2") == [0, 2]
    period = PERIOD_NS * 1e-9
    assert picked("--start", f"{2.5 * period}", "--end", f"{5.5 * period}") == [3, 4, 5]
    assert picked("--start", f"{1.5 * period}", "--every", "2") == [2, 4, 6]


def test_a_viewer_recording_with_registered_depth_uses_its_depth_units(tmp_path):
    path = tmp_path / "viewer.bag"
    units = 1e-4  # a D405, or a D4xx set to high accuracy
    frames = record(path, "bag", VIEWER, _frames(4, units), depth_info=((FX, FY, CX, CY), (W, H)),
                    units=units, colour_encoding="bgr8")
    out = tmp_path / "scene"
    result = _run(["import-bag", path, out])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "camera.json").read_text())["depth_scale"] == units
    frame = SceneSource(out).load_frame("000002")
    depth, rgb = frames[2]
    assert np.array_equal(frame.rgb, rgb)  # bgr8 turned to RGB
    np.testing.assert_allclose(frame.depth_m, depth * units, atol=1e-7)
    forced = tmp_path / "forced"
    assert _run(["import-bag", path, forced, "--depth-scale", "0.0002"]).exit_code == 0
    assert json.loads((forced / "camera.json").read_text())["depth_scale"] == 0.0002


def test_unaligned_depth_is_refused_with_how_to_record_it(tmp_path):
    path = tmp_path / "viewer.bag"
    record(path, "bag", VIEWER, _frames(2), depth_info=((60.0, 60.0, 40.0, 30.0), (W, H)))
    out = tmp_path / "scene"
    result = _run(["import-bag", path, out])
    assert result.exit_code == 2
    assert "viewer.bag" in result.output and "not aligned" in result.output
    assert "align_depth.enable:=true" in result.output
    assert not out.exists()


def test_topics_can_be_named(tmp_path):
    path = tmp_path / "custom"
    names = "/rig/rgb", "/rig/depth_registered/image_raw", "/rig/calib"
    record(path, "mcap", names, _frames(3))
    result = _run(["import-bag", path, tmp_path / "a"])
    assert result.exit_code == 2 and "--colour-topic" in result.output
    assert "/rig/rgb" in result.output  # the image topics it saw are listed
    result = _run(["import-bag", path, tmp_path / "b", "--colour-topic", "/rig/rgb",
                   "--info-topic", "/rig/calib"])
    assert result.exit_code == 0, result.output
    assert len(SceneSource(tmp_path / "b").frame_ids()) == 3
    result = _run(["import-bag", path, tmp_path / "c", "--colour-topic", "/rig/nothing"])
    assert result.exit_code == 2 and "/rig/nothing" in result.output


def test_depth_far_from_any_colour_stamp_is_not_paired(tmp_path):
    lagging = tmp_path / "lagging.bag"  # 0.4 frame late: still its own colour frame
    frames = record(lagging, "bag", ROS1, _frames(3), depth_lag_ns=int(0.4 * PERIOD_NS))
    assert _run(["import-bag", lagging, tmp_path / "ok"]).exit_code == 0
    scene = SceneSource(tmp_path / "ok")
    for k, fid in enumerate(scene.frame_ids()):
        frame = scene.load_frame(fid)
        assert _which(frame.rgb) == k
        np.testing.assert_array_equal(np.round(frame.depth_m / 0.001), frames[k][0])
    path = tmp_path / "skewed.bag"
    record(path, "bag", ROS1, _frames(3), depth_lag_ns=10 * PERIOD_NS)
    result = _run(["import-bag", path, tmp_path / "out"])
    assert result.exit_code == 2 and "within half a frame" in result.output


@pytest.mark.parametrize("name,content,message", [
    ("broken.bag", b"not a rosbag" * 100, "cannot read the recording"),
    ("notes.txt", b"hello", "not a recording"),
    ("missing.bag", None, "no such recording"),
])
def test_a_file_that_is_not_a_recording_is_named(tmp_path, name, content, message):
    bad = tmp_path / name
    if content is not None:
        bad.write_bytes(content)
    result = _run(["import-bag", bad, tmp_path / "out"])
    assert result.exit_code == 2 and name in result.output and message in result.output
    assert not (tmp_path / "out" / "camera.json").exists()
