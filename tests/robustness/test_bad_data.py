"""What sr3d does with odd data: a clear message naming the file, the batch goes on, no
traceback unless -v, nothing already written is lost."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sr3d_cli.cli import cli
from sr3d_cli.errors import InputError
from sr3d_cli.io.camera_files import load_camera
from sr3d_cli.io.images import read_depth, read_mask, read_rgb
from sr3d_cli.stages import load_mesh
from tests.conftest import make_native_scene

READERS = {
    "rgb.png": read_rgb,
    "depth.png": lambda p: read_depth(p, 0.001),
    "depth.npy": lambda p: read_depth(p, 0.001),
    "mask.png": read_mask,
    "camera.json": load_camera,
    "camera.yaml": load_camera,
    "K.npy": load_camera,
    "mesh.ply": load_mesh,
    "mesh.obj": load_mesh,
    "depth.exr": lambda p: read_depth(p, 0.001),
}


@settings(max_examples=100, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(sorted(READERS)), data=st.binary(max_size=300))
def test_readers_never_crash_on_arbitrary_bytes(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data)
    try:
        READERS[name](path)
    except InputError as exc:
        assert str(path) in str(exc)


@settings(max_examples=30, deadline=None)
@given(arr=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32),
                    min_size=12, max_size=12))
def test_float_depth_nan_inf_and_negative_are_no_reading(arr):
    import tempfile

    a = np.asarray(arr, np.float32).reshape(3, 4)
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "d.npy"
        np.save(p, a)
        out = read_depth(p, 0.001)
    assert out.dtype == np.float32 and np.isfinite(out).all() and (out >= 0).all()
    good = np.isfinite(a) & (a > 0)
    assert np.array_equal(out[good], a[good])


def _scene(tmp_path, n=3):
    return make_native_scene(tmp_path / "scene", n)


def _run(args):
    return CliRunner().invoke(cli, args)


def test_one_corrupt_frame_fails_alone_without_traceback(tmp_path):
    scene = _scene(tmp_path)
    (scene / "depth" / "000001.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    result = _run(["evaluate", str(scene), "--pred", "depth"])
    assert result.exit_code == 1
    assert "000001" in result.output and "cannot decode image" in result.output
    assert "Traceback" not in result.output
    assert "2 frames done, 1 failed" in result.output or "1 failed" in result.output
    verbose = _run(["evaluate", str(scene), "--pred", "depth", "-v"])
    assert verbose.exit_code == 1


def test_depth_in_the_wrong_unit_names_the_scale(tmp_path):
    scene = _scene(tmp_path, 1)
    # a camera file stating metres per unit where the sensor wrote millimetres
    (scene / "camera.json").write_text((scene / "camera.json").read_text().replace(
        '"depth_scale": 0.001', '"depth_scale": 1.0'))
    result = _run(["evaluate", str(scene), "--pred", "depth"])
    assert result.exit_code == 1 and "depth_scale" in result.output and "median" in result.output


def test_sizes_that_disagree_and_missing_files(tmp_path):
    scene = _scene(tmp_path)
    from sr3d_cli.io.atomic import write_png

    write_png(scene / "depth" / "000000.png", np.full((10, 10), 500, np.uint16))
    (scene / "depth" / "000002.png").unlink()
    (scene / "rgb" / "notes.txt").write_text("extra files are ignored")
    result = _run(["evaluate", str(scene), "--pred", "depth"])
    assert result.exit_code == 1
    assert "depth/000000.png: depth is 10x10 but the colour image is 32x24" in result.output
    assert "000002: no prediction 'depth'" in result.output
    assert "1 frames done, 2 failed" in result.output
    # the ground truth of another size is named, not the mask that agrees with the frame
    write_png(scene / "gt" / "depth" / "000001.png", np.full((12, 16), 500, np.uint16))
    result = _run(["evaluate", str(scene), "--pred", "depth", "--frames", "000001"])
    assert result.exit_code == 1
    assert "gt/depth/000001.png: depth is 16x12 but the colour image is 32x24" in result.output


def test_unreadable_config_is_a_usage_error_naming_the_file(tmp_path):
    scene = _scene(tmp_path, 1)
    bad = tmp_path / "bad.yaml"
    bad.write_text("segment: [unclosed\n")
    result = _run(["segment", str(scene), "--config", str(bad)])
    assert result.exit_code == 2 and "bad.yaml" in result.output
    assert "Traceback" not in result.output


def _outputs(root: Path) -> dict[str, bytes]:
    """Every output file but the run logs (log/: they hold timings)."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and ".tmp" not in p.name and p.parent.name != "log"}


@pytest.mark.slow
def test_killed_run_resumes_with_skip_existing_and_matches_a_clean_run(synth_set, tmp_path):
    """Run a batch, kill it mid-way, rerun with --skip-existing: every output file is whole and
    byte-identical to a clean run's."""
    src = tmp_path / "data"
    for name in ("scene_0000", "scene_0001", "scene_0002", "scene_0003"):
        shutil.copytree(synth_set / name, src / name)
    clean, killed = tmp_path / "clean", tmp_path / "killed"
    cmd = [sys.executable, "-m", "sr3d_cli", "segment", str(src), "-q", "--out"]
    subprocess.run(cmd + [str(clean)], check=True, timeout=300)
    proc = subprocess.Popen(cmd + [str(killed)], start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and len(list(killed.rglob("masks/*.json"))) < 1:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    partial = _outputs(killed) if killed.is_dir() else {}
    for name, data in partial.items():  # what the killed run left is whole
        assert data == _outputs(clean)[name], name
    subprocess.run(cmd + [str(killed), "--skip-existing"], check=True, timeout=300)
    assert _outputs(killed) == _outputs(clean)


def test_import_bag_without_the_extra_says_how_to_install(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_rosbags(name, *args, **kwargs):
        if name.startswith("rosbags"):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    (tmp_path / "rec.bag").write_bytes(b"x")
    monkeypatch.setattr(builtins, "__import__", no_rosbags)
    result = _run(["import-bag", str(tmp_path / "rec.bag"), str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "pip install 'sr3d-cli[bag]'" in result.output
