"""TransCG and BOP layouts read in place; --format; align --bop; --shard and --skip-existing."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.config import IOConfig
from sr3d_cli.io.atomic import write_png
from sr3d_cli.io.formats import describe, discover_scenes
from sr3d_cli.io.formats.bop import bop_scene_gt

K = np.array([[60.0, 0, 19.5], [0, 60.0, 14.5], [0, 0, 1]])
H, W = 30, 40


def _depth_png(value_m: float, scale: float, hole: bool = False) -> np.ndarray:
    d = np.full((H, W), round(value_m / scale), np.uint16)
    if hole:
        d[10:20, 15:25] = 0
    return d


def make_transcg(root: Path) -> Path:
    """dataset/camera_intrinsics + dataset/scenes/scene1/{1,2}/ with both cameras."""
    (root / "camera_intrinsics").mkdir(parents=True)
    np.save(root / "camera_intrinsics" / "1-camIntrinsics-D435.npy", K)
    np.save(root / "camera_intrinsics" / "2-camIntrinsics-L515.npy", K * [[1], [1], [1]])
    for view in ("1", "2"):
        v = root / "scenes" / "scene1" / view
        for cam, scale in ((1, 0.001), (2, 0.00025)):
            write_png(v / f"rgb{cam}.png", np.full((H, W, 3), 100, np.uint8))
            write_png(v / f"depth{cam}.png", _depth_png(0.6, scale, hole=True))
            write_png(v / f"depth{cam}-gt.png", _depth_png(0.6, scale))
            mask = np.zeros((H, W), np.uint8)
            mask[10:20, 15:25] = 255
            mask[2:6, 2:6] = 255
            write_png(v / f"depth{cam}-gt-mask.png", mask)
    return root


def make_bop(root: Path) -> Path:
    """dataset/test/000001 with scene_camera.json (depth_scale 0.1 mm/unit), masks, scene_gt."""
    scene = root / "test" / "000001"
    cams, gt = {}, {}
    for i in range(2):
        fid = f"{i:06d}"
        write_png(scene / "rgb" / f"{fid}.png", np.full((H, W, 3), 90, np.uint8))
        write_png(scene / "depth" / f"{fid}.png", _depth_png(0.7, 0.0001))
        for k in range(2):
            m = np.zeros((H, W), np.uint8)
            m[5 + 10 * k:12 + 10 * k, 5:15] = 255
            write_png(scene / "mask_visib" / f"{fid}_{k:06d}.png", m)
        cams[str(i)] = {"cam_K": K.ravel().tolist(), "depth_scale": 0.1}
        gt[str(i)] = [{"obj_id": 3, "cam_R_m2c": np.eye(3).ravel().tolist(),
                       "cam_t_m2c": [10.0, 20.0, 700.0]}]
    (scene / "scene_camera.json").write_text(json.dumps(cams))
    (scene / "scene_gt.json").write_text(json.dumps(gt))
    return root


def test_transcg_is_read_in_place_per_camera(tmp_path):
    root = make_transcg(tmp_path / "transcg")
    scenes = discover_scenes(root, IOConfig(), tmp_path / "out")
    assert [s.name for s in scenes] == ["scenes/scene1/cam1", "scenes/scene1/cam2"]
    assert describe(scenes) == "2 scenes: transcg x2"
    for s in scenes:
        assert s.frame_ids() == ["1", "2"]
        f = s.load_frame("2")
        assert f.depth_m[0, 0] == pytest.approx(0.6, abs=1e-4)  # 1/1000 and 1/4000 m units
        assert f.depth_m[15, 20] == 0
        assert np.allclose(f.camera.K, K)
        ids = s.load_mask(s.gt_mask_path("1"), (H, W))
        assert sorted(np.unique(ids)) == [0, 1, 2]  # binary mask split into components
        assert s.load_gt_depth("1", (H, W))[15, 20] == pytest.approx(0.6, abs=1e-4)
    assert scenes[1].camera.depth_scale == 0.00025
    only = discover_scenes(root / "scenes" / "scene1", IOConfig(format="transcg"), None)
    assert len(only) == 2


def test_bop_is_read_in_place(tmp_path):
    root = make_bop(tmp_path / "bop")
    (scene,) = discover_scenes(root, IOConfig(), None)
    assert scene.layout == "bop" and scene.frame_ids() == ["000000", "000001"]
    f = scene.load_frame("000001")
    assert f.depth_m[0, 0] == pytest.approx(0.7, abs=1e-4)  # 7000 units x 0.1 mm
    ids = scene.load_mask(scene.gt_mask_path("000000"), (H, W))
    assert sorted(np.unique(ids)) == [0, 1, 2]
    obj = scene.load_gt_objects("000000")["objects"][0]
    assert np.allclose(np.asarray(obj["T_cam_obj"])[:3, 3], [0.01, 0.02, 0.7])
    assert obj["scale"] == 0.001 and obj["mesh"].endswith("models/obj_000003.ply")


def test_bop_scene_gt_round_trip():
    T = np.eye(4)
    T[:3, 3] = [0.1, -0.05, 0.8]
    doc = bop_scene_gt({"000004": [{"id": 2, "T_cam_obj": T.tolist(), "scale": 0.12}]})
    entry = doc["4"][0]
    assert entry["obj_id"] == 2 and np.allclose(entry["cam_t_m2c"], [100, -50, 800])
    assert np.allclose(np.reshape(entry["cam_R_m2c"], (3, 3)), np.eye(3))


def test_format_option_and_auto_notice(tmp_path):
    root = make_transcg(tmp_path / "transcg")
    runner = CliRunner()
    result = runner.invoke(cli, ["evaluate", str(root), "--pred", "depth", "--out",
                                 str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    assert "format auto: found 2 scenes: transcg x2" in result.output
    result = runner.invoke(cli, ["evaluate", str(root), "--format", "bop", "--out",
                                 str(tmp_path / "o")])
    assert result.exit_code == 2 and "no bop scene folder" in result.output


def test_shard_splits_frames_stably_and_completely(tmp_path, native_scene):
    from sr3d_cli.cli.stage_loop import in_shard

    keys = [f"scene/{i:06d}" for i in range(200)]
    parts = [[k for k in keys if in_shard(k, (i, 3))] for i in range(3)]
    assert sorted(sum(parts, [])) == keys and all(len(p) > 40 for p in parts)
    runner = CliRunner()
    outs = []
    for i in range(2):
        out = tmp_path / f"shard{i}"
        result = runner.invoke(cli, ["segment", str(native_scene), "--out", str(out), "-q",
                                     "--shard", f"{i}/2"])
        assert result.exit_code == 0, result.output
        outs.append({p.name for p in (out / "masks").glob("*.png")} if (out / "masks").is_dir()
                    else set())
    assert outs[0].isdisjoint(outs[1]) and len(outs[0] | outs[1]) == 2
    bad = runner.invoke(cli, ["segment", str(native_scene), "--shard", "2/2"])
    assert bad.exit_code == 2 and "--shard" in bad.output


def test_shard_auto_reads_slurm_and_kubernetes():
    from sr3d_cli.cli.stage_loop import parse_shard

    # sbatch --array=0-9: ids 0..9
    assert parse_shard("auto", {"SLURM_ARRAY_TASK_ID": "3", "SLURM_ARRAY_TASK_MIN": "0",
                                "SLURM_ARRAY_TASK_COUNT": "10"}) == (3, 10)
    # --array=1-10 (ids from 1) and --array=0-18:2 (a step; older Slurm: no _COUNT)
    assert parse_shard("auto", {"SLURM_ARRAY_TASK_ID": "1", "SLURM_ARRAY_TASK_MIN": "1",
                                "SLURM_ARRAY_TASK_COUNT": "10"}) == (0, 10)
    assert parse_shard("auto", {"SLURM_ARRAY_TASK_ID": "18", "SLURM_ARRAY_TASK_MIN": "0",
                                "SLURM_ARRAY_TASK_STEP": "2",
                                "SLURM_ARRAY_TASK_MAX": "18"}) == (9, 10)
    assert parse_shard("auto", {"JOB_COMPLETION_INDEX": "4", "SR3D_SHARD_COUNT": "5"}) == (4, 5)
    for env in ({}, {"JOB_COMPLETION_INDEX": "4"}, {"SLURM_ARRAY_TASK_ID": "2"}):
        with pytest.raises(click.BadParameter, match="SLURM_ARRAY_TASK_ID"):
            parse_shard("auto", env)
    with pytest.raises(click.BadParameter, match="shard 5 of 5"):
        parse_shard("auto", {"JOB_COMPLETION_INDEX": "5", "SR3D_SHARD_COUNT": "5"})


def test_shard_auto_splits_a_batch_like_explicit_shards(tmp_path, native_scene, monkeypatch):
    runner = CliRunner()
    outs = []
    for i in range(2):
        monkeypatch.setenv("JOB_COMPLETION_INDEX", str(i))
        monkeypatch.setenv("SR3D_SHARD_COUNT", "2")
        out = tmp_path / f"auto{i}"
        result = runner.invoke(cli, ["segment", str(native_scene), "--out", str(out), "-q",
                                     "--shard", "auto"])
        assert result.exit_code == 0, result.output
        explicit = tmp_path / f"explicit{i}"
        assert runner.invoke(cli, ["segment", str(native_scene), "--out", str(explicit), "-q",
                                   "--shard", f"{i}/2"]).exit_code == 0
        outs.append(sorted(p.name for p in out.rglob("*.png")))
        assert outs[-1] == sorted(p.name for p in explicit.rglob("*.png"))
    assert len(outs[0]) + len(outs[1]) > 0 and not set(outs[0]) & set(outs[1])
    monkeypatch.delenv("JOB_COMPLETION_INDEX")
    bad = runner.invoke(cli, ["segment", str(native_scene), "--shard", "auto"])
    assert bad.exit_code == 2 and "JOB_COMPLETION_INDEX" in bad.output


@pytest.mark.slow
def test_align_bop_writes_scene_gt(synth_set, tmp_path):
    scene, out = synth_set / "scene_0004", tmp_path / "out"
    runner = CliRunner()
    assert runner.invoke(cli, ["repair-depth", str(scene), "--out", str(out), "-q"]
                         ).exit_code == 0
    result = runner.invoke(cli, ["align", str(scene), "--out", str(out), "-q", "--bop",
                                 "--skip-existing"])
    assert result.exit_code == 0, result.output
    doc = json.loads((out / "scene_gt.json").read_text())
    poses = json.loads((out / "poses" / "000000.json").read_text())["objects"]
    assert len(doc["0"]) == len(poses) > 0
    assert np.allclose(doc["0"][0]["cam_t_m2c"], np.asarray(poses[0]["T_cam_obj"])[:3, 3] * 1000)
