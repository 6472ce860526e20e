"""Bad files of every kind sr3d reads, through the command line: the exit code says so, one line
names the file (or the config key) and the problem, no traceback without -v, and what the other
frames wrote is intact."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.io.atomic import write_png
from tests.conftest import make_native_scene

# the tiny scene's 48-pixel object is reconstructed and placed with this
SMALL = ["--set", "reconstruct.min_pixels=10"]
REPAIR = ["repair-depth", "--masks", "gt", *SMALL, "-q"]


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def lines(output: str) -> list[str]:
    return [line for line in re.split(r"[\r\n]", output) if line.strip()]


def assert_clean(result, code: int, *needles: str) -> None:
    """Exit ``code``, every needle in the output, no traceback, each error on a line of its
    own (never glued to a progress bar)."""
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output, result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)
    errors = [line for line in lines(result.output) if "error:" in line]
    assert all(line.startswith("error:") for line in errors), errors
    if code:
        assert errors, result.output


def snapshot(root: Path, *frames: str) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and any(f in p.name or f in p.parent.name for f in frames)
            and p.parts[len(root.parts)] in ("masks", "meshes", "poses", "repaired")}


@pytest.fixture
def repaired_scene(tmp_path):
    """The tiny 3-frame scene, repaired once (every frame placed its object)."""
    scene = make_native_scene(tmp_path / "scene", 3)
    assert_clean(run(*REPAIR[:1], scene, *REPAIR[1:]), 0)
    return scene


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _random(path: Path) -> None:
    path.write_bytes(np.random.default_rng(7).integers(0, 256, 300, dtype=np.uint8).tobytes())


def _npy(array):
    def damage(path: Path) -> None:
        path.unlink()
        np.save(path.with_suffix(".npy"), array)
    return damage


def _npy_truncated(path: Path) -> None:
    path.unlink()
    np.save(path.with_suffix(".npy"), np.full((24, 32), 0.5, np.float32))
    _truncate(path.with_suffix(".npy"))


def _jpeg_truncated(path: Path) -> None:
    import cv2

    ok, buf = cv2.imencode(".jpg", np.full((24, 32, 3), 120, np.uint8))
    path.unlink()
    path.with_suffix(".jpg").write_bytes(buf.tobytes()[:100])


def _exr(damage):
    def apply(path: Path) -> None:
        from sr3d_cli.io.exr import write_exr

        path.unlink()
        write_exr(path.with_suffix(".exr"), np.full((24, 32), 0.5, np.float32))
        damage(path.with_suffix(".exr"))
    return apply


BAD_FRAME_FILES = {
    "rgb-png-truncated": ("rgb/000001.png", _truncate, "cannot decode image"),
    "rgb-png-random": ("rgb/000001.png", _random, "cannot decode image"),
    "rgb-png-empty": ("rgb/000001.png", lambda p: p.write_bytes(b""), "file is empty"),
    "rgb-jpeg-truncated": ("rgb/000001.png", _jpeg_truncated, "rgb/000001.jpg"),
    "rgb-wrong-size": ("rgb/000001.png",
                       lambda p: write_png(p, np.zeros((10, 10, 3), np.uint8)),
                       "depth is 32x24 but the colour image is 10x10"),
    "depth-png-truncated": ("depth/000001.png", _truncate, "cannot decode image"),
    "depth-png-random": ("depth/000001.png", _random, "cannot decode image"),
    "depth-png-8bit": ("depth/000001.png",
                       lambda p: write_png(p, np.full((24, 32), 50, np.uint8)), "8-bit"),
    "depth-png-all-zero": ("depth/000001.png",
                           lambda p: write_png(p, np.zeros((24, 32), np.uint16)),
                           "no valid depth reading"),
    "depth-png-wrong-size": ("depth/000001.png",
                             lambda p: write_png(p, np.full((10, 10), 500, np.uint16)),
                             "depth is 10x10 but the colour image is 32x24"),
    "depth-npy-truncated": ("depth/000001.png", _npy_truncated, "depth/000001.npy"),
    "depth-npy-random": ("depth/000001.png",
                         lambda p: (p.unlink(), _random(p.with_suffix(".npy"))),
                         "depth/000001.npy"),
    "depth-npy-3d": ("depth/000001.png",
                     _npy(np.dstack([np.full((24, 32), 0.5, np.float32),
                                     np.full((24, 32), 0.6, np.float32)])), "one channel"),
    "depth-npy-complex": ("depth/000001.png", _npy(np.zeros((24, 32), np.complex64)),
                          "depth/000001.npy"),
    "depth-npy-all-nan": ("depth/000001.png", _npy(np.full((24, 32), np.nan, np.float32)),
                          "no valid depth reading"),
    "depth-npy-all-inf": ("depth/000001.png", _npy(np.full((24, 32), np.inf, np.float32)),
                          "no valid depth reading"),
    "depth-exr-truncated": ("depth/000001.png", _exr(_truncate), "depth/000001.exr"),
    "depth-exr-random": ("depth/000001.png", _exr(_random), "depth/000001.exr"),
    "mask-truncated": ("gt/masks/000001.png", _truncate, "cannot decode image"),
    "mask-wrong-size": ("gt/masks/000001.png",
                        lambda p: write_png(p, np.ones((10, 10), np.uint8)),
                        "mask is 10x10 but the images are 32x24"),
    "mask-colour": ("gt/masks/000001.png",
                    lambda p: write_png(p, np.dstack([np.ones((24, 32), np.uint8),
                                                      np.zeros((24, 32), np.uint8),
                                                      np.zeros((24, 32), np.uint8)])),
                    "differing colour channels"),
}


@pytest.mark.parametrize("case", sorted(BAD_FRAME_FILES))
def test_a_bad_frame_file_fails_that_frame_alone(repaired_scene, case):
    if "exr" in case:
        pytest.importorskip("OpenEXR")
    rel, damage, problem = BAD_FRAME_FILES[case]
    before = snapshot(repaired_scene, "000000", "000002")
    damage(repaired_scene / rel)
    result = run(*REPAIR[:1], repaired_scene, *REPAIR[1:])
    assert_clean(result, 1, problem, "failed: 000001", "2 frames done, 1 failed")
    assert snapshot(repaired_scene, "000000", "000002") == before


BAD_CAMERAS = {
    "truncated": ("camera.json", lambda p: _truncate(p), "cannot parse camera file"),
    "random": ("camera.json", _random, "cannot parse camera file"),
    "nan-focal": ("camera.json", lambda p: p.write_text(
        '{"K": [[NaN, 0, 15.5], [0, 50, 11.5], [0, 0, 1]], "width": 32, "height": 24}'),
        "finite"),
    "inf-centre": ("camera.json", lambda p: p.write_text(
        '{"K": [[50, 0, Infinity], [0, 50, 11.5], [0, 0, 1]], "width": 32, "height": 24}'),
        "finite"),
    "negative-focal": ("camera.json", lambda p: p.write_text(
        '{"K": [[-50, 0, 15.5], [0, 50, 11.5], [0, 0, 1]], "width": 32, "height": 24}'),
        "focal lengths must be positive"),
    "no-size": ("camera.json", lambda p: p.write_text(
        '{"K": [[50, 0, 15.5], [0, 50, 11.5], [0, 0, 1]]}'), "lacks 'width'"),
    "zero-depth-scale": ("camera.json", lambda p: p.write_text(
        '{"K": [[50, 0, 15.5], [0, 50, 11.5], [0, 0, 1]], "width": 32, "height": 24, '
        '"depth_scale": 0}'), "'depth_scale' must be a positive number"),
    "text-depth-scale": ("camera.json", lambda p: p.write_text(
        '{"K": [[50, 0, 15.5], [0, 50, 11.5], [0, 0, 1]], "width": 32, "height": 24, '
        '"depth_scale": "mm"}'), "'depth_scale' must be a positive number"),
    "a-list": ("camera.json", lambda p: p.write_text("[1, 2, 3]"), "must hold a mapping"),
    "yaml-random": ("camera.yaml", _random, "camera.yaml"),
    "npy-2x3": ("K.npy", lambda p: np.save(p, np.ones((2, 3))), "expected a 3x3"),
    "txt-words": ("K.txt", lambda p: p.write_text("fx fy cx cy"), "cannot parse camera file"),
}


@pytest.mark.parametrize("case", sorted(BAD_CAMERAS))
def test_a_bad_camera_file_fails_its_scene_naming_the_file(tmp_path, case):
    scene = make_native_scene(tmp_path / "scene", 2)
    name, damage, problem = BAD_CAMERAS[case]
    if name != "camera.json":
        (scene / "camera.json").unlink()
    damage(scene / name)
    result = run("evaluate", scene, "--pred", "depth", "-q")
    assert_clean(result, 1, name, problem, "2 failed")


@pytest.mark.parametrize("setting, key", [
    ("plane.iterations=-5", "'plane.iterations' in --set: must be > 0"),
    ("grasp.friction=.nan", "'grasp.friction' in --set: expected a finite number"),
    ("io.depth_scale=0", "'io.depth_scale' in --set: must be > 0"),
    ("synth.distance=[0.9, 0.3]", "'synth.distance' in --set: expected [min, max]"),
    ("segment.min_area=big", "'segment.min_area' in --set: expected an integer"),
    ("plane.min_share=1.5", "'plane.min_share' in --set: must be >= 0 and <= 1"),
    ("grasp.depths=[0.01, -0.02]", "'grasp.depths' in --set: must be > 0"),
    ("reconstruct.sides=3", "unknown key 'reconstruct.sides' in --set"),
])
def test_a_bad_config_value_is_a_usage_error_naming_the_key(tmp_path, setting, key):
    scene = make_native_scene(tmp_path / "scene", 1)
    result = run("repair-depth", scene, "--set", setting, "-q")
    assert_clean(result, 2, key)
    assert not (scene / "masks").exists()  # refused before any work


def test_a_config_file_of_random_bytes_names_the_file(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 1)
    bad = tmp_path / "bad.yaml"
    _random(bad)
    assert_clean(run("segment", scene, "--config", bad, "-q"), 2, "bad.yaml")


# ---- stage outputs and models read back ---------------------------------------------------

def test_a_damaged_mesh_fails_its_frame_naming_the_file(repaired_scene):
    before = snapshot(repaired_scene, "000000", "000002")
    _truncate(repaired_scene / "meshes" / "000001" / "1.ply")
    result = run("grasp", repaired_scene, "--masks", "gt", "-q", *SMALL)
    assert_clean(result, 1, "meshes/000001/1.ply", "failed: 000001")
    assert snapshot(repaired_scene, "000000", "000002") == before


def test_a_mesh_with_nan_vertices_fails_its_frame_naming_the_file(repaired_scene):
    import trimesh

    path = repaired_scene / "meshes" / "000001" / "1.ply"
    mesh = trimesh.load(path, process=False)
    mesh.vertices[0] = np.nan
    path.write_bytes(mesh.export(file_type="ply"))
    result = run("grasp", repaired_scene, "--masks", "gt", "--frames", "000001", "-q")
    assert_clean(result, 1, "meshes/000001/1.ply", "non-finite vertices")


def test_grasps_with_nan_are_refused_naming_the_file(repaired_scene):
    from sr3d_cli.io.atomic import write_npy

    (repaired_scene / "gt" / "objects").mkdir(parents=True)
    (repaired_scene / "gt" / "objects" / "000000.json").write_text('{"objects": []}')
    write_npy(repaired_scene / "grasps" / "000000.npy", np.full((2, 17), np.nan))
    result = run("evaluate", repaired_scene, "--grasps", "--frames", "000000", "-q")
    assert_clean(result, 1, "grasps/000000.npy", "non-finite")


@pytest.mark.parametrize("content, problem", [
    ("{not json", "cannot read poses"),
    ('{"objects": [{"id": 1, "T_cam_obj": [[NaN, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.5], '
     '[0, 0, 0, 1]], "scale": 0.1}]}', "T_cam_obj must be a finite 4x4"),
    ('{"objects": [{"id": 1, "T_cam_obj": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.5], '
     '[0, 0, 0, 1]], "scale": -1}]}', "scale must be a finite number > 0"),
    ('{"objects": "none"}', "'objects' list"),
])
def test_a_bad_poses_file_fails_grasp_naming_it(repaired_scene, content, problem):
    (repaired_scene / "poses" / "000001.json").write_text(content)
    result = run("grasp", repaired_scene, "--masks", "gt", "--frames", "000001", "-q")
    assert_clean(result, 1, "poses/000001.json", problem)


def test_bad_ground_truth_objects_and_grasps_name_the_file(repaired_scene):
    (repaired_scene / "gt" / "objects").mkdir(parents=True)
    _random(repaired_scene / "gt" / "objects" / "000000.json")
    result = run("evaluate", repaired_scene, "--grasps", "--frames", "000000", "-q")
    assert_clean(result, 1, "000000")  # no grasps yet, or the objects file: named, one line
    (repaired_scene / "grasps").mkdir()
    _random(repaired_scene / "grasps" / "000000.npy")
    result = run("evaluate", repaired_scene, "--grasps", "--frames", "000000", "-q")
    assert_clean(result, 1, "grasps/000000.npy", "cannot read grasps")


def test_a_bad_onnx_model_is_a_usage_error_naming_it(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 1)
    model = tmp_path / "model.onnx"
    _random(model)
    result = run("reconstruct", scene, "--backend", "onnx", "--masks", "gt",
                 "--set", f"reconstruct.onnx_model={model}", "-q")
    assert_clean(result, 2, "model.onnx")


def test_a_bad_library_mesh_is_named(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 1)
    library = tmp_path / "library"
    library.mkdir()
    _random(library / "cup.obj")
    result = run("reconstruct", scene, "--library", library, "--masks", "gt", *SMALL, "-q")
    assert "Traceback" not in result.output
    assert result.exit_code in (1, 2) and "cup.obj" in result.output, result.output


def test_a_recording_of_random_bytes_is_a_usage_error(tmp_path):
    bag = tmp_path / "rec.bag"
    _random(bag)
    result = run("import-bag", bag, tmp_path / "out", "-q")
    assert_clean(result, 2, "rec.bag")


def test_masks_json_of_random_bytes_is_named(repaired_scene):
    result = run("segment", repaired_scene, "--frames", "000000", "-q")
    assert result.exit_code in (0, 1)
    _random(repaired_scene / "masks" / "000000.json")
    result = run("grasp", repaired_scene, "--frames", "000000", "--from", "raw", "-q")
    assert_clean(result, 1, "masks/000000.json", "cannot read instance records")


# ---- the reported problems ---------------------------------------------------------------

def test_an_object_with_too_few_points_fails_the_frame_with_its_reason(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 1)
    result = run("grasp", scene, "--from", "raw", "--masks", "gt")
    assert_clean(result, 1, "failed: 000000: no grasp for any object",
                 "surface points, too few")
    doc = json.loads((scene / "grasps" / "000000.json").read_text())
    assert doc["grasps"] == [] and "too few" in doc["frame_failed"]


def test_grasp_without_masks_fails(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 2)
    assert_clean(run("grasp", scene, "-q"), 1, "no masks", "0 frames done, 2 failed")


def test_depth_without_a_colour_image_fails_naming_it(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 2)
    (scene / "rgb" / "000001.png").rename(scene / "rgb" / "frame_b.png")
    result = run("evaluate", scene, "--pred", "depth", "-q")
    assert_clean(result, 1, "depth/000001.png: depth without a colour image")
    (scene / "rgb" / "000000.png").unlink()
    (scene / "rgb" / "frame_b.png").unlink()
    assert_clean(run("segment", scene, "-q"), 1, "0 frames done, 2 failed")


def test_all_zero_depth_names_the_file_without_traceback(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 2)
    write_png(scene / "depth" / "000000.png", np.zeros((24, 32), np.uint16))
    result = run("segment", scene, "-q")
    assert_clean(result, 1, "depth/000000.png: no valid depth reading")
    verbose = run("segment", scene, "-v", "--frames", "000000")
    assert verbose.exit_code == 1


def test_an_unwritable_output_folder_is_refused_before_any_work(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 2)
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    result = run("segment", scene, "--out", blocker / "out", "-q")
    assert_clean(result, 2, "cannot write outputs here")
    assert not (scene / "masks").exists()
    result = run("evaluate", scene, "--out", blocker / "out", "-q")
    assert_clean(result, 2, "cannot write outputs here")


@pytest.mark.skipif(not hasattr(__import__("os"), "geteuid") or __import__("os").geteuid() == 0,
                    reason="root writes into read-only folders")
def test_a_read_only_output_folder_is_refused_before_any_work(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 2)
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        assert_clean(run("segment", scene, "--out", out, "-q"), 2, "cannot write outputs here")
    finally:
        out.chmod(0o755)


def test_messages_sit_above_the_progress_bar_and_the_summary_names_failures(repaired_scene,
                                                                            tmp_path):
    write_png(repaired_scene / "depth" / "000001.png", np.zeros((24, 32), np.uint16))
    report = tmp_path / "report.json"
    result = run("repair-depth", repaired_scene, "--masks", "gt", *SMALL,
                 "--report", report)  # progress bar on
    assert_clean(result, 1, "2 frames done, 1 failed",
                 "  failed: 000001: ")
    doc = json.loads(report.read_text())
    assert doc["done"] == 2 and doc["failed"] == 1 and doc["exit_code"] == 1
    assert doc["failures"][0]["item"] == "000001"
    assert "no valid depth reading" in doc["failures"][0]["reason"]
    cam = json.loads((repaired_scene / "camera.json").read_text())  # a notice per frame load
    cam.update(K=(2 * np.asarray(cam["K"]) + [[0, 0, .5], [0, 0, .5], [0, 0, -1]]).tolist(),
               width=64, height=48)
    (repaired_scene / "camera.json").write_text(json.dumps(cam))
    warned = run("repair-depth", repaired_scene, "--masks", "gt", *SMALL, "--frames", "000000")
    notices = [line for line in lines(warned.output) if "notice:" in line]
    assert notices and all(line.startswith("notice: ") for line in notices), warned.output
    assert "K rescaled by 0.5" in notices[0]


def test_a_camera_without_depth_scale_gets_a_notice(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 1)
    cam = json.loads((scene / "camera.json").read_text())
    del cam["depth_scale"]
    (scene / "camera.json").write_text(json.dumps(cam))
    result = run("evaluate", scene, "--pred", "depth")
    assert result.exit_code == 0, result.output
    assert "camera.json: no depth_scale; assuming io.depth_scale = 0.001" in result.output
    quiet = run("evaluate", scene, "--pred", "depth", "--set", "io.depth_scale=0.0005")
    assert "io.depth_scale = 0.0005" in quiet.output


def test_new_files_get_the_umask_permissions_and_keep_their_mode(tmp_path):
    import os

    from sr3d_cli.io import atomic

    path = atomic.write_bytes(tmp_path / "a.bin", b"x")
    assert path.stat().st_mode & 0o777 == 0o666 & ~atomic._UMASK[0]
    os.chmod(path, 0o640)
    atomic.write_bytes(path, b"y")
    assert path.stat().st_mode & 0o777 == 0o640 and path.read_bytes() == b"y"
    saved = list(atomic._UMASK)
    try:
        atomic._UMASK[:] = [0o077]
        assert atomic.write_bytes(tmp_path / "b.bin", b"z").stat().st_mode & 0o777 == 0o600
        atomic._UMASK[:] = [0o022]
        assert atomic.write_bytes(tmp_path / "c.bin", b"z").stat().st_mode & 0o777 == 0o644
    finally:
        atomic._UMASK[:] = saved
    assert not list(tmp_path.glob(".*.tmp"))


def test_repair_depth_reads_cleargrasp_named_masks_in_place(tmp_path):
    scene = make_native_scene(tmp_path / "scene", 2)
    masks = tmp_path / "cleargrasp_masks"
    masks.mkdir()
    for fid in ("000000", "000001"):  # binary 0/255, as ClearGrasp's -mask.png
        mask = (np.asarray(__import__("cv2").imread(str(scene / "gt" / "masks" / f"{fid}.png"),
                                                     -1)) > 0).astype(np.uint8) * 255
        write_png(masks / f"{fid}-mask.png", mask)
    result = run("repair-depth", scene, "--masks", masks, *SMALL, "-q")
    assert_clean(result, 0)
    poses = json.loads((scene / "poses" / "000001.json").read_text())
    assert [o["id"] for o in poses["objects"]] == [1]
    assert_clean(run("repair-depth", scene, "--masks", tmp_path / "nowhere", "-q"), 2,
                 "neither segment, gt nor a folder")


def test_all_frames_done_exits_zero(repaired_scene):
    result = run("evaluate", repaired_scene, "--pred", "depth", "--pred", "repaired", "-q")
    assert_clean(result, 0)
