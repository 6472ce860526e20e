"""One in-memory state per frame: repair-depth fits the table once for the stages after segment,
reads back nothing it wrote, reports problems as values, and gives what the stages give run one
by one from their files."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli import stages
from sr3d_cli.cli import cli
from sr3d_cli.errors import Problem
from sr3d_cli.geometry import plane as plane_module
from sr3d_cli.io.images import read_depth


def _counting(monkeypatch, calls: Counter, module, name: str) -> None:
    original = getattr(module, name)

    def counted(*args, **kwargs):
        calls[name] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)


@pytest.mark.slow
def test_repair_depth_in_memory_matches_the_stages_run_alone(synth_set, tmp_path, monkeypatch):
    scene = synth_set / "scene_0002"
    runner = CliRunner()
    calls: Counter = Counter()
    for name in ("load_instances", "load_mesh", "load_pose_document", "occluders"):
        _counting(monkeypatch, calls, stages, name)
    _counting(monkeypatch, calls, plane_module, "fit_support_plane")
    together = tmp_path / "together"
    result = runner.invoke(cli, ["repair-depth", str(scene), "--out", str(together), "-q"])
    assert result.exit_code == 0, result.output
    # the segmenter's table at its working size, then one for reconstruct, align and repair;
    # what stands in front of each instance once, for reconstruct and align; no mask, mesh
    # or pose file read back
    instances = json.loads((together / "masks" / "000000.json").read_text())["objects"]
    assert len(instances) >= 2
    assert calls == Counter(fit_support_plane=2, occluders=len(instances))
    monkeypatch.undo()

    alone = tmp_path / "alone"
    for command in ("segment", "reconstruct", "align", "repair-depth"):
        result = runner.invoke(cli, [command, str(scene), "--out", str(alone), "-q"])
        assert result.exit_code == 0, (command, result.output)
    poses = [json.loads((out / "poses" / "000000.json").read_text())["objects"]
             for out in (together, alone)]
    assert len(poses[0]) >= 2
    assert [(o["id"], o["T_cam_obj"], o["scale"]) for o in poses[0]] == \
        [(o["id"], o["T_cam_obj"], o["scale"]) for o in poses[1]]
    depth = [read_depth(out / "repaired" / "000000.png", 0.001) for out in (together, alone)]
    assert np.array_equal(depth[0], depth[1])


def test_a_missing_mesh_is_reported_once_by_the_stage_that_made_none(native_scene, tmp_path):
    """The 6x8-pixel object is too small to reconstruct: align's 'no mesh' follows from that
    and is not reported a second time."""
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["repair-depth", str(native_scene), "--out", str(out),
                                      "--masks", "gt", "--frames", "000000"])
    assert result.exit_code == 1
    failed = json.loads((out / "repaired" / "000000.json").read_text())["frame_failed"]
    assert failed == "no object placed (object 1: mask has 48 px (< reconstruct.min_pixels " \
                     "100))"
    poses = json.loads((out / "poses" / "000000.json").read_text())
    assert poses["failed"] == ["object 1: no mesh: run `sr3d reconstruct` first"]


def test_problems_name_their_object():
    assert str(Problem("no mesh", 3, upstream=True)) == "object 3: no mesh"
    assert str(Problem("nothing to grasp")) == "nothing to grasp"
