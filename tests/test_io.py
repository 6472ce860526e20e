import json
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from sr3d_cli.config import IOConfig
from sr3d_cli.errors import InputError
from sr3d_cli.geometry.camera import Camera
from sr3d_cli.io import atomic, images
from sr3d_cli.io.camera_files import fit_camera_to_image, load_camera
from sr3d_cli.io.formats import discover_scenes
from sr3d_cli.io.frames import select_frames

K = np.array([[615.5, 0, 321.25], [0, 614.75, 238.5], [0, 0, 1]])


# ---- depth ------------------------------------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(depth=arrays(np.float32, (5, 7), elements=st.floats(0.0, 60.0, width=32)))
def test_depth_png_round_trip_within_half_a_unit(depth, tmp_path_factory):
    path = tmp_path_factory.mktemp("d") / "d.png"
    images.write_depth(path, depth, 0.001)
    back = images.read_depth(path, 0.001)
    assert back.dtype == np.float32 and back.shape == depth.shape
    assert np.all(np.abs(back - depth) <= 0.0005 + 1e-6)


def test_depth_npy_and_exr_round_trip_and_nan_is_no_reading(tmp_path):
    depth = np.array([[0.5, np.nan], [np.inf, -1.0]], np.float32)
    for suffix in (".npy", ".exr"):
        images.write_depth(tmp_path / f"d{suffix}", depth, 0.001)
        back = images.read_depth(tmp_path / f"d{suffix}", 0.001)
        np.testing.assert_array_equal(back, [[0.5, 0.0], [0.0, 0.0]])


def test_depth_scale_applies_to_integer_files(tmp_path):
    np.save(tmp_path / "u.npy", np.array([[4000, 0]], np.uint16))
    np.testing.assert_allclose(images.read_depth(tmp_path / "u.npy", 0.00025), [[1.0, 0.0]])


def test_values_beyond_uint16_become_holes_not_wrapped():
    units = images.encode_depth_png(np.array([[70.0, 1.0]]), 0.001)
    np.testing.assert_array_equal(units, [[0, 1000]])


def test_the_largest_uint16_value_is_no_reading(tmp_path):
    """Some cameras and exporters mark a missing reading 65535: 65.5 m in millimetres, beyond
    any depth camera's range, so it is read as none (0), and a 16-bit value under it as is."""
    import cv2

    cv2.imwrite(str(tmp_path / "d.png"), np.array([[65535, 65534, 1200, 0]], np.uint16))
    np.testing.assert_allclose(images.read_depth(tmp_path / "d.png", 0.001),
                               [[0.0, 65.534, 1.2, 0.0]], rtol=1e-6)


@pytest.mark.parametrize("content, problem", [
    (b"", "file is empty"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00", "cannot decode image"),
    (b"not an image at all", "cannot decode image"),
])
def test_corrupt_images_name_the_file(tmp_path, content, problem):
    path = tmp_path / "x.png"
    path.write_bytes(content)
    with pytest.raises(InputError, match=problem) as err:
        images.read_depth(path, 0.001)
    assert str(path) in str(err.value)


def test_truncated_png_is_an_input_error(tmp_path):
    path = tmp_path / "t.png"
    atomic.write_png(path, np.random.default_rng(0).integers(0, 65535, (64, 64)).astype(np.uint16))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="t.png: cannot decode"):
        images.read_depth(path, 0.001)


def test_eight_bit_depth_and_rgb_conversions(tmp_path):
    atomic.write_png(tmp_path / "d8.png", np.ones((3, 3), np.uint8))
    with pytest.raises(InputError, match="8-bit"):
        images.read_depth(tmp_path / "d8.png", 0.001)
    atomic.write_png(tmp_path / "grey.png", np.full((2, 2), 7, np.uint8))
    rgb = images.read_rgb(tmp_path / "grey.png")
    assert rgb.shape == (2, 2, 3) and np.all(rgb == 7)
    colour = np.zeros((2, 2, 3), np.uint8)
    colour[..., 0] = 200  # red
    atomic.write_png(tmp_path / "red.png", colour)
    assert images.read_rgb(tmp_path / "red.png")[0, 0].tolist() == [200, 0, 0]


def test_binary_mask_split_into_components(tmp_path):
    mask = np.zeros((6, 8), np.uint8)
    mask[1:3, 1:3] = 255
    mask[4:6, 5:8] = 255
    atomic.write_png(tmp_path / "m.png", np.dstack([mask] * 3))
    ids = images.read_mask(tmp_path / "m.png", split_binary=True)
    assert sorted(np.unique(ids)) == [0, 1, 2]
    assert ids[1, 1] == 1 and ids[5, 7] == 2
    assert np.array_equal(images.read_mask(tmp_path / "m.png") > 0, mask > 0)


# ---- atomic writes ----------------------------------------------------------------------------

def test_atomic_write_keeps_old_file_when_writing_fails(tmp_path):
    path = tmp_path / "a.json"
    atomic.write_json(path, {"b": 1, "a": [1, 2]})
    assert path.read_text() == '{\n  "a": [\n    1,\n    2\n  ],\n  "b": 1\n}\n'
    with pytest.raises(TypeError):
        atomic.write_json(path, {"x": object()})
    assert json.loads(path.read_text()) == {"a": [1, 2], "b": 1}
    assert os.listdir(tmp_path) == ["a.json"]  # no temporary file left behind


# ---- cameras ----------------------------------------------------------------------------------

def _write(path, text):
    path.write_text(text)
    return path


CAMERA_FILES = {
    "camera.json": json.dumps({"K": K.tolist(), "width": 640, "height": 480,
                               "depth_scale": 0.00025}),
    "open3d.json": json.dumps({"width": 640, "height": 480,
                               "intrinsic_matrix": K.T.ravel().tolist()}),
    "realsense.json": json.dumps({"fx": 615.5, "fy": 614.75, "ppx": 321.25, "ppy": 238.5,
                                  "width": 640, "height": 480, "depth_scale": 0.00025}),
    "ros.yaml": ("image_width: 640\nimage_height: 480\ncamera_name: d435\ncamera_matrix:\n"
                 "  rows: 3\n  cols: 3\n  data: [615.5, 0, 321.25, 0, 614.75, 238.5, 0, 0, 1]\n"),
    "ros_msg.yaml": "width: 640\nheight: 480\nK: [615.5, 0, 321.25, 0, 614.75, 238.5, 0, 0, 1]\n",
    "cleargrasp.yaml": "xres: 640\nyres: 480\nfx: 615.5\nfy: 614.75\ncx: 321.25\ncy: 238.5\n",
}


def test_a_camera_file_with_a_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "camera.json"
    path.write_bytes(b"\xef\xbb\xbf" + CAMERA_FILES["realsense.json"].encode())
    np.testing.assert_allclose(load_camera(path).K, K)


@pytest.mark.parametrize("name", sorted(CAMERA_FILES))
def test_every_camera_format_gives_the_same_intrinsics(tmp_path, name):
    cam = load_camera(_write(tmp_path / name, CAMERA_FILES[name]), depth_scale=0.00025)
    np.testing.assert_allclose(cam.K, K)
    assert (cam.width, cam.height, cam.depth_scale) == (640, 480, 0.00025)


def test_matrix_files_take_their_size_from_the_images(tmp_path):
    np.save(tmp_path / "K.npy", K)
    _write(tmp_path / "K.txt", "\n".join(" ".join(str(v) for v in row) for row in K))
    for name in ("K.npy", "K.txt"):
        cam = load_camera(tmp_path / name)
        assert cam.width == 0
        fitted, notice = fit_camera_to_image(cam, 640, 480)
        assert (fitted.width, fitted.height, notice) == (640, 480, None)
        np.testing.assert_allclose(fitted.K, K)


def test_cleargrasp_prefers_unrounded_parameters(tmp_path):
    _write(tmp_path / "camera_intrinsics.yaml", "xres: 1280\nyres: 720\nfx: 912\nfy: 911\n"
                                                "cx: 642\ncy: 371\n")
    _write(tmp_path / "camera_parameters.txt", "Image Height: 720\nImage Width: 1280\n"
                                               "fx: 912.04\nfy: 910.96\ncx: 641.58\ncy: 371.21\n")
    cam = load_camera(tmp_path / "camera_intrinsics.yaml")
    assert cam.fx == pytest.approx(912.04) and cam.cy == pytest.approx(371.21)


def test_rescaled_images_rescale_K_with_notice_and_other_sizes_fail():
    cam = Camera(K, 640, 480, source="cam.json")
    half, notice = fit_camera_to_image(cam, 320, 240)
    assert "rescaled" in notice and half.fx == pytest.approx(K[0, 0] / 2)
    # pixel centres: c' = (c + 0.5) / 2 - 0.5
    assert half.cx == pytest.approx((K[0, 2] + 0.5) / 2 - 0.5)
    with pytest.raises(InputError, match="cam.json: intrinsics are for 640x480 but the images "
                                         "are 640x360"):
        fit_camera_to_image(cam, 640, 360)


@pytest.mark.parametrize("text, problem", [
    ('{"fx": 1}', "unrecognised camera file"),
    ('{"fx": 1, "fy": 1, "ppx": 1, "width": 4, "height": 4}', "lacks 'ppy'"),
    ("{not json", "cannot parse camera file"),
    ('{"K": [[0, 0, 1], [0, 1, 1], [0, 0, 1]], "width": 4, "height": 4}', "focal lengths"),
    ('{"K": [[615.5, 0, 0], [0, 614.75, 0], [321.25, 238.5, 1]], "width": 640, "height": 480}',
     r"last row \[321.25, 238.5, 1.0\] \(transposed\? give K's rows"),
    ('{"K": [[615.5, 0, 321.25], [0, 614.75, 238.5], [0, 0, 2]], "width": 640, "height": 480}',
     r"got last row \[0.0, 0.0, 2.0\]\)"),
])
def test_bad_camera_files(tmp_path, text, problem):
    with pytest.raises(InputError, match=problem):
        load_camera(_write(tmp_path / "camera.json", text))
    with pytest.raises(InputError, match="camera file does not exist"):
        load_camera(tmp_path / "nope.json")


# ---- frames and scenes ------------------------------------------------------------------------

def test_frame_selection():
    ids = ["000001", "000002", "000007", "000010"]
    assert select_frames(ids, None) == ids
    assert select_frames(ids, "000007,000001") == ["000001", "000007"]
    assert select_frames(ids, "2-7") == ["000002", "000007"]
    assert select_frames(ids, "000002..000010") == ["000002", "000007", "000010"]
    with pytest.raises(Exception, match="matches no frame"):
        select_frames(ids, "000003")


def test_discover_scenes_below_a_root_and_output_mapping(native_scene, tmp_path):
    scenes = discover_scenes(native_scene.parent, IOConfig(), out=tmp_path / "out")
    assert [s.name for s in scenes] == ["scene"]
    assert scenes[0].output_path("repaired", "000001") == tmp_path / "out/scene/repaired/000001.png"
    assert scenes[0].frame_ids() == ["000000", "000001"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match="empty: no scene folder found"):
        discover_scenes(empty, IOConfig())


def test_upper_case_suffixes_are_read_and_two_files_of_one_frame_named(native_scene, caplog):
    (native_scene / "rgb/000001.png").rename(native_scene / "rgb/000001.PNG")
    (native_scene / "depth/000001.png").rename(native_scene / "depth/000001.PNG")
    np.save(native_scene / "depth/000000.npy", np.full((24, 32), 0.7, np.float32))
    scene = discover_scenes(native_scene, IOConfig())[0]
    assert scene.frame_ids() == ["000000", "000001"]
    frame = scene.load_frame("000001")
    assert frame.rgb.shape == (24, 32, 3) and frame.depth_m[0, 0] == pytest.approx(0.5)
    with caplog.at_level("WARNING"):
        frame = scene.load_frame("000000")
    assert frame.depth_m[0, 0] == pytest.approx(0.5)  # the PNG, the first kind, is read
    assert "000000.png and 000000.npy are the same frame; reading 000000.png" in caplog.text
