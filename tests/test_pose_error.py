"""Pose error against known truth: a pose moved by a known rotation, translation or scale gives
that error; a turn about the axis of a surface of revolution gives none."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from sr3d_cli.geometry.revolution import revolve
from sr3d_cli.geometry.transforms import make_T, rotation_about
from sr3d_cli.pose_error import match_instances, pose_error, rotation_error_deg, summarise

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "scene_0000"
GLASS = np.array([[0, 0], [0.3, 0], [0.34, 1.0], [0, 1.0]])  # profile (r, z), unit height
Z = np.array([0.0, 0.0, 1.0])


def _truth() -> np.ndarray:
    """A true pose 0.6 m in front of the camera, tilted 20 degrees about x."""
    return make_T(rotation_about(np.array([1.0, 0, 0]), np.radians(20)), [0.05, -0.02, 0.6])


def _turned(T: np.ndarray, axis: np.ndarray, degrees: float) -> np.ndarray:
    """``T`` turned by ``degrees`` about its own object-frame ``axis`` (origin fixed)."""
    return make_T(T[:3, :3] @ rotation_about(axis, np.radians(degrees)), T[:3, 3])


def test_rotation_error_is_the_angle_and_symmetric_only_counts_the_axis():
    R = rotation_about(np.array([1.0, 2, 3]), 0.3)
    about_z = R @ rotation_about(Z, np.radians(50))
    tilted = R @ rotation_about(np.array([1.0, 0, 0]), np.radians(15))
    assert rotation_error_deg(about_z, R, symmetric=False) == pytest.approx(50, abs=1e-6)
    assert rotation_error_deg(about_z, R, symmetric=True) == pytest.approx(0, abs=1e-6)
    assert rotation_error_deg(tilted, R, symmetric=True) == pytest.approx(15, abs=1e-6)
    assert rotation_error_deg(tilted, R, symmetric=False) == pytest.approx(15, abs=1e-6)


def test_a_turn_about_the_axis_of_a_revolution_mesh_is_no_error():
    glass, T = revolve(GLASS), _truth()
    e = pose_error(_turned(T, Z, 40), 0.1, glass, T, 0.1, glass)
    assert e["symmetric"] is True
    assert e["rotation_deg"] == pytest.approx(0, abs=1e-6)
    assert e["translation_mm"] == pytest.approx(0, abs=1e-9)
    assert e["scale_pct"] == pytest.approx(0, abs=1e-9)
    assert e["add_s_mm"] < 1.0  # the same surface: only the sampling's spacing


def test_a_known_rotation_of_an_asymmetric_mesh_gives_that_angle():
    box = trimesh.creation.box([0.6, 0.3, 1.0])
    box.apply_translation([0, 0, 0.5])  # origin at the base centre
    T = _truth()
    e = pose_error(_turned(T, Z, 30), 0.1, box, T, 0.1, box)
    assert e["symmetric"] is False
    assert e["rotation_deg"] == pytest.approx(30, abs=1e-6)
    assert e["axis_deg"] == pytest.approx(0, abs=1e-6)  # turned about its z axis
    tilted = pose_error(_turned(T, np.array([0, 1.0, 0]), 12), 0.1, box, T, 0.1, box)
    assert tilted["rotation_deg"] == pytest.approx(12) and tilted["axis_deg"] == pytest.approx(12)
    assert e["translation_mm"] == pytest.approx(0, abs=1e-9)
    assert 3.0 < e["add_s_mm"] < 30.0  # corners moved by up to 34 mm, the faces overlap


def test_a_known_translation_gives_that_error_and_half_of_it_as_add_s_on_a_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    sphere.apply_translation([0, 0, 0.5])
    T = _truth()
    moved = T.copy()
    moved[:3, 3] += [0.006, 0.0, 0.008]  # 10 mm
    e = pose_error(moved, 0.1, sphere, T, 0.1, sphere)
    assert e["translation_mm"] == pytest.approx(10, abs=1e-9)
    # a sphere moved by d << radius: each point is |d cos(angle)| from the moved surface, d/2
    # on average
    assert e["add_s_mm"] == pytest.approx(5.0, abs=0.5)


def test_scale_error_compares_placed_heights_of_different_meshes():
    glass, T = revolve(GLASS), _truth()
    tall = revolve(GLASS * [1, 2])  # the same shape at twice the height
    assert pose_error(T, 0.11, glass, T, 0.1, glass)["scale_pct"] == pytest.approx(10)
    same = pose_error(T, 0.05, tall, T, 0.1, glass)
    assert same["scale_pct"] == pytest.approx(0, abs=1e-9)
    assert pose_error(T, 0.055, tall, T, 0.1, glass)["scale_pct"] == pytest.approx(10)


def test_instances_match_one_to_one_by_best_iou():
    true = np.zeros((10, 20), int)
    true[2:8, 1:6], true[2:8, 10:16] = 1, 2
    pred = np.zeros_like(true)
    pred[2:8, 2:6] = 7  # IoU 24/30 with true 1
    pred[2:8, 10:12] = 3  # IoU 12/36 with true 2: below the threshold
    pred[0:2, 17:20] = 9  # on nothing
    matches = match_instances(pred, true)
    assert matches == {1: (7, pytest.approx(24 / 30))}


def test_summary_counts_matched_objects_and_takes_medians():
    rows = [{"pred_id": 1, "rotation_deg": 1.0, "axis_deg": 1.0, "translation_mm": 2.0,
             "scale_pct": 3.0, "add_s_mm": 4.0},
            {"pred_id": 2, "rotation_deg": 3.0, "axis_deg": 0.0, "translation_mm": 4.0,
             "scale_pct": 5.0, "add_s_mm": 6.0},
            {"pred_id": None}]
    s = summarise(rows)
    assert (s["objects"], s["matched"]) == (3, 2)
    assert s["median_rotation_deg"] == 2.0 and s["mean_add_s_mm"] == 5.0


def test_evaluate_reports_pose_errors_of_placed_objects(tmp_path):
    """The true objects of a sample frame placed with known errors: object 1 moved 5 mm and
    turned 25 degrees about its axis, object 2 not placed."""
    from sr3d_cli.cli import cli
    from sr3d_cli.io.atomic import write_json

    scene = tmp_path / "scene"
    shutil.copytree(SAMPLE, scene)
    truth = json.loads((scene / "gt" / "objects" / "000000.json").read_text())["objects"]
    (scene / "masks").mkdir()
    shutil.copy(scene / "gt" / "masks" / "000000.png", scene / "masks" / "000000.png")
    first = truth[0]
    (scene / "meshes" / "000000").mkdir(parents=True)
    shutil.copy(scene / first["mesh"], scene / "meshes" / "000000" / f"{first['id']}.ply")
    T = _turned(np.asarray(first["T_cam_obj"]), Z, 25)
    T[:3, 3] += [0.003, 0.004, 0.0]
    write_json(scene / "poses" / "000000.json",
               {"objects": [{"id": first["id"], "mesh": f"meshes/000000/{first['id']}.ply",
                             "T_cam_obj": T.tolist(), "scale": first["scale"]}]})
    result = CliRunner().invoke(cli, ["evaluate", str(scene), "--pred", "depth", "-q"])
    assert result.exit_code == 0, result.output
    assert "# poses: 1 of 2 true objects placed" in result.output
    rows = list(csv.DictReader((scene / "pose_metrics.csv").open()))
    placed = next(r for r in rows if r["id"] == str(first["id"]))
    assert float(placed["translation_mm"]) == pytest.approx(5.0, abs=1e-3)
    assert float(placed["rotation_deg"]) == pytest.approx(0, abs=1e-3)
    assert float(placed["scale_pct"]) == pytest.approx(0, abs=1e-6)
    assert placed["symmetric"] == "True"
    missed = next(r for r in rows if r["id"] == str(truth[1]["id"]))
    assert missed["pred_id"] == "" and missed["rotation_deg"] == ""
    document = json.loads((scene / "metrics.json").read_text())
    assert document["poses"]["summary"]["matched"] == 1
