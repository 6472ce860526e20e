"""``sr3d report --rerun FILE.rrd``: every frame's images, placed meshes and grasps in a Rerun
recording (extra viz). Skipped, with the reason, where rerun-sdk is not installed."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.grasp import GraspSet
from sr3d_cli.io.atomic import write_json, write_npy, write_png
from sr3d_cli.io.images import read_depth, write_depth
from tests.conftest import make_native_scene


def _rerun_cli(*args) -> str:
    result = subprocess.run([sys.executable, "-m", "rerun", *map(str, args)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stdout + result.stderr


def _scene(root):
    """Two frames; frame 000000 has every output (masks, repaired depth, a placed mesh, two
    grasps), 000001 only its inputs."""
    make_native_scene(root, 2)
    fid = "000000"
    ids = np.zeros((24, 32), np.uint8)
    ids[8:14, 10:18] = 1
    write_png(root / "masks" / f"{fid}.png", ids)
    write_depth(root / "repaired" / f"{fid}.png",
                read_depth(root / "gt" / "depth" / f"{fid}.png", 0.001), 0.001)
    mesh = trimesh.creation.cylinder(radius=0.3, height=1.0)
    (root / "meshes" / fid).mkdir(parents=True)
    mesh.export(root / "meshes" / fid / "1.ply")
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.45)
    write_json(root / "poses" / f"{fid}.json",
               {"objects": [{"id": 1, "mesh": f"meshes/{fid}/1.ply", "T_cam_obj": T.tolist(),
                             "scale": 0.05}]})
    R = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)
    grasps = GraspSet(scores=np.array([0.9, 0.2]), widths=np.array([0.03, 0.03]),
                      heights=np.full(2, 0.02), depths=np.full(2, 0.02), R=np.stack([R, R]),
                      t=np.array([[0, 0, 0.4], [0.01, 0, 0.4]]), object_ids=np.array([1, 1]))
    write_npy(root / "grasps" / f"{fid}.npy", grasps.to_array())
    return root


def test_report_writes_a_rerun_recording_of_every_frame(tmp_path):
    pytest.importorskip("rerun", reason="--rerun needs the viz extra: pip install "
                                        "'sr3d-cli[viz]' (rerun-sdk)")
    scene = _scene(tmp_path / "scene")
    rrd = tmp_path / "batch.rrd"
    result = CliRunner().invoke(cli, ["report", str(scene), "-o", str(tmp_path / "r.html"),
                                      "--rerun", str(rrd)])
    assert result.exit_code == 0, result.output
    assert "2 frames logged" in result.output
    _rerun_cli("rrd", "verify", rrd)
    printed = _rerun_cli("rrd", "print", "-vv", rrd)
    rows = {m.group(2): int(m.group(1))
            for m in re.finditer(r"with (\d+) rows \([^)]*\) - (/[\w/]+)", printed)}
    # both frames' inputs; the outputs only frame 000000 has (cleared at 000001)
    assert rows["/world/camera/rgb"] == 2 and rows["/world/camera/raw_depth"] == 2
    for entity in ("/world/camera/repaired_depth", "/world/camera/masks", "/world/objects/1",
                   "/world/grasps"):
        assert entity in printed, entity
    assert "LineStrips3D" in printed and "Mesh3D" in printed


def test_without_rerun_the_install_command_is_given(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_rerun(name, *args, **kwargs):
        if name == "rerun" or name.startswith("rerun."):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    scene = make_native_scene(tmp_path / "scene", 1)
    monkeypatch.setattr(builtins, "__import__", no_rerun)
    result = CliRunner().invoke(cli, ["report", str(scene), "-o", str(tmp_path / "r.html"),
                                      "--rerun", str(tmp_path / "x.rrd")])
    assert result.exit_code == 2 and "pip install 'sr3d-cli[viz]'" in result.output
