"""Objects the generator draws beyond surfaces of revolution (handles, square and flat bottles,
open vessels seen from above): meshes with known truth, and how the pipeline does on them.

The pipeline numbers record what reconstruction and placement achieve now on these shapes,
from the true masks; they are bounds with a modest margin over the measured values, to be
tightened as reconstruction learns shapes that are not of revolution. Seeds here (41-45) are
used by no other test and by no benchmark."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.config import SynthConfig
from sr3d_cli.geometry.camera import Camera
from sr3d_cli.geometry.loft import Handle, loft, superellipse
from sr3d_cli.io.images import read_depth, read_mask
from sr3d_cli.render import NumpyRenderer, RenderMesh, make_renderer
from sr3d_cli.synth.families import (DEFAULT_FAMILIES, FAMILIES, kinds_for, make_shape)
from sr3d_cli.synth.generate import write_scene
from sr3d_cli.synth.layout import OPEN_MIN_ELEVATION_DEG, side_rotation
from sr3d_cli.synth.shapes import KINDS

SAMPLE_DATA = Path(__file__).resolve().parents[1] / "sample_data"
NEW_KINDS = [k for family, kinds in FAMILIES.items() if family != "revolution" for k in kinds]
PIPELINE_SEEDS = (41, 42, 43, 44, 45)
SMALL = "424x240"  # frames of the pipeline tests: small enough to run in a second


def test_every_new_kind_is_a_closed_solid_in_the_object_frame():
    rng = np.random.default_rng(11)
    for kind in NEW_KINDS:
        for _ in range(6):
            shape = make_shape(kind, rng)
            mesh = shape.mesh
            assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, kind
            assert mesh.bounds[0, 2] == pytest.approx(0) and mesh.bounds[1, 2] == pytest.approx(1)
            centre = (mesh.bounds[0, :2] + mesh.bounds[1, :2]) / 2
            if kind not in FAMILIES["handle"]:  # a handle and a spout shift the box along x
                assert np.abs(centre).max() < 1e-6, kind
            assert 0.03 < shape.height < 0.3, kind


def test_a_handle_is_joined_into_the_wall():
    """One surface with a hole through it (genus 1: Euler number 0), not a body with a tube
    pushed into it (two surfaces, Euler number 4); the handle stands out towards +x only, and a
    pitcher's spout towards -x."""
    rng = np.random.default_rng(12)
    for kind in FAMILIES["handle"]:
        for _ in range(4):
            mesh = make_shape(kind, rng).mesh
            assert mesh.euler_number == 0, kind
            assert len(mesh.split(only_watertight=False)) == 1
            v = mesh.vertices
            r = np.hypot(v[:, 0], v[:, 1])
            body = np.percentile(r[v[:, 2] < 0.5], 90)
            assert v[:, 0].max() > body * 1.3  # the handle's reach
            assert np.abs(v[:, 1]).max() < body * 1.05  # nothing sticks out sideways
            rim = v[v[:, 2] > 0.97]
            spout = -rim[:, 0].min() / np.abs(rim[:, 1]).max()  # towards -x against sideways
            assert spout > 1.15 if kind == "pitcher" else spout == pytest.approx(1, abs=0.01)


def test_cross_sections_are_square_rectangular_and_elliptic():
    """Low on the body: a square bottle fills more of its bounding box than a circle (pi / 4)
    does, with equal sides; a rectangular one has unequal sides; a flat one is an ellipse
    (fills pi / 4 of its box) about half as deep as wide."""
    rng = np.random.default_rng(13)
    for kind in ("square_bottle", "rect_bottle", "flat_bottle"):
        for _ in range(4):
            v = make_shape(kind, rng).mesh.vertices
            levels = np.unique(v[:, 2])
            ring = v[v[:, 2] == levels[np.argmin(np.abs(levels - 0.3))], :2]  # one loop
            ring = ring[np.argsort(np.arctan2(ring[:, 1], ring[:, 0]))]
            area = 0.5 * abs(ring[:, 0] @ np.roll(ring[:, 1], -1)
                             - ring[:, 1] @ np.roll(ring[:, 0], -1))
            width, depth = np.ptp(ring, axis=0)
            fill = area / (width * depth)
            if kind == "flat_bottle":
                assert fill == pytest.approx(np.pi / 4, abs=0.02)
                assert 0.35 < depth / width < 0.7
            else:
                assert fill > 0.86
                assert (depth / width == pytest.approx(1, abs=1e-6)) == (kind == "square_bottle")


def test_laid_down_shapes_rest_with_their_centre_of_mass_over_the_contact():
    """Laid on its side, a non-revolution shape has its centre of mass over the patch it
    touches the table with (a flat bottle lies on its broad face, a mug on body and handle):
    it would not roll or tip."""
    from scipy.spatial import ConvexHull, Delaunay

    rng = np.random.default_rng(14)
    for kind in ("mug", "pitcher", "square_bottle", "rect_bottle", "flat_bottle"):
        for _ in range(3):
            mesh = make_shape(kind, rng).mesh
            R = side_rotation(mesh)
            v = mesh.vertices @ R.T
            com = R @ mesh.center_mass
            low = v[v[:, 2] < v[:, 2].min() + 0.004][:, :2]  # within 0.4% of the height
            hull = low[ConvexHull(low).vertices]
            assert Delaunay(hull).find_simplex(com[:2]) >= 0, kind
            assert abs((R @ [0, 0, 1.0])[2]) < np.sin(np.radians(15)), kind  # the axis lies
            if kind == "flat_bottle":
                x = mesh.vertices
                assert com[2] - v[:, 2].min() == pytest.approx(np.abs(x[:, 1]).max(), rel=0.02)


def test_loft_refuses_patches_off_the_wall_or_overlapping():
    loops = np.array([np.column_stack([superellipse(16, 1, 1, 2), np.full(16, z)])
                      for z in np.linspace(0, 1, 6)])
    path = np.column_stack([np.linspace(1, 1.2, 5), np.zeros(5), np.linspace(0.2, 0.8, 5)])
    with pytest.raises(ValueError, match="runs off"):
        loft(loops, [0, 0, 0], [0, 0, 1], [Handle(((0, 0), (3, 0)), (1, 1), path, (0.1, 0.1))])
    with pytest.raises(ValueError, match="overlap"):
        loft(loops, [0, 0, 0], [0, 0, 1], [Handle(((2, 0), (3, 0)), (1, 1), path, (0.1, 0.1))])
    assert loft(loops, [0, 0, 0], [0, 0, 1]).is_watertight


def test_family_names_resolve_to_kinds_in_one_order():
    assert kinds_for(DEFAULT_FAMILIES) == KINDS
    assert kinds_for(["open", "handle"]) == kinds_for(["handle", "open"]) == \
        ("mug", "pitcher", "bowl", "thin_glass")
    assert kinds_for(["all"]) == tuple(KINDS) + tuple(NEW_KINDS)
    assert kinds_for(["mug", "handle"]) == ("mug", "pitcher")
    with pytest.raises(ValueError, match="unknown family or kind 'teapot'"):
        kinds_for(["teapot"])


def _truth(folder: Path) -> list[tuple]:
    """What a scene's draw put where, independent of the renderer: each object's label, pose,
    scale, T_cam_obj and mesh file digest."""
    objects = json.loads((folder / "gt" / "objects" / "000000.json").read_text())["objects"]
    return [(o["label"], o["pose"], round(o["scale"], 9),
             np.round(np.asarray(o["T_cam_obj"]), 9).tolist(),
             hashlib.sha256((folder / o["mesh"]).read_bytes()).hexdigest()) for o in objects]


def test_default_families_draw_the_bundled_samples(tmp_path):
    """`sr3d synth --seed 0` draws what sample_data holds (objects, poses, meshes), so the
    bundled frames stay regression checks; `--families all` draws other scenes."""
    name = "scene_0000"
    if not (SAMPLE_DATA / name / "camera.json").is_file():
        pytest.fail(f"bundled sample data missing at {SAMPLE_DATA}")
    runner = CliRunner()
    for folder, families in (("a", []), ("b", ["--families", "all"])):
        result = runner.invoke(cli, ["synth", str(tmp_path / folder), "--scenes", "1", "--seed",
                                     "0", "-q", *families])
        assert result.exit_code == 0, result.output
    assert _truth(tmp_path / "a" / name) == _truth(SAMPLE_DATA / name)
    assert _truth(tmp_path / "b" / name) != _truth(SAMPLE_DATA / name)
    result = runner.invoke(cli, ["synth", str(tmp_path / "c"), "--families", "revolution,cup"])
    assert result.exit_code == 2 and "unknown family or kind 'cup'" in result.output


def test_new_families_are_deterministic_and_meet_the_contract(tmp_path):
    from sr3d_cli.io.contract import check_frame
    from sr3d_cli.io.scene import SceneSource

    cfg = SynthConfig(seed=46, views=1, objects=[2, 3], resolutions=[SMALL])
    renderer = make_renderer("auto")
    labels = set()
    for i in range(3):
        digests = []
        for run in ("a", "b"):
            write_scene(tmp_path / run / f"s{i}", i, cfg, renderer, ["all"])
            files = sorted(p for p in (tmp_path / run / f"s{i}").rglob("*") if p.is_file())
            digests.append([hashlib.sha256(p.read_bytes()).hexdigest() for p in files])
        assert digests[0] == digests[1]
        source = SceneSource(tmp_path / "a" / f"s{i}")
        problems, ious = check_frame(source, "000000", NumpyRenderer())
        assert problems == [] and min(ious.values()) > 0.9
        labels |= {o["label"] for o in source.load_gt_objects("000000")["objects"]}
    assert labels - set(KINDS)  # the new families are drawn


def test_open_vessels_are_seen_from_above(tmp_path):
    """A scene with an open glass is seen from at least OPEN_MIN_ELEVATION_DEG up (less a few
    degrees: the camera aims near, not at, each object), so its inner floor shows."""
    cfg = SynthConfig(seed=47, views=2, objects=[1, 1], distractors=[0, 0], resolutions=[SMALL])
    for i in range(3):
        folder = tmp_path / f"s{i}"
        write_scene(folder, i, cfg, make_renderer("auto"), ["thin_glass"])
        for fid in ("000000", "000001"):
            obj = json.loads((folder / "gt" / "objects" / f"{fid}.json").read_text())["objects"][0]
            T = np.asarray(obj["T_cam_obj"])
            eye = -T[:3, :3].T @ T[:3, 3]  # the camera in the object frame (z up the table)
            assert np.degrees(np.arctan2(eye[2], np.hypot(eye[0], eye[1]))) > \
                OPEN_MIN_ELEVATION_DEG - 8


def _pipeline_on(kind: str, seed: int, root: Path) -> dict:
    """One object of ``kind`` standing in a small frame; sr3d repair-depth from the true mask.
    Returns the placed height over the true one less 1, the placed model's silhouette IoU with
    the true mask, the object's depth MAE (mm) and whether it was fitted standing or lying."""
    scene, out = root / f"{kind}{seed}", root / f"{kind}{seed}_out"
    cfg = SynthConfig(seed=seed, views=1, resolutions=[SMALL], objects=[1, 1],
                      distractors=[0, 0], lying_fraction=0.0)
    write_scene(scene, 0, cfg, make_renderer("auto"), [kind])
    result = CliRunner().invoke(cli, ["repair-depth", str(scene), "--out", str(out),
                                      "--set", "reconstruct.masks=gt", "-q"])
    assert result.exit_code == 0, result.output
    truth = json.loads((scene / "gt" / "objects" / "000000.json").read_text())["objects"][0]
    placed = json.loads((out / "poses" / "000000.json").read_text())["objects"]
    assert [p["id"] for p in placed] == [truth["id"]]
    cam = json.loads((scene / "camera.json").read_text())
    mask = read_mask(scene / "gt" / "masks" / "000000.png") == truth["id"]
    mesh = trimesh.load(out / placed[0]["mesh"], force="mesh", process=False)
    T, scale = np.asarray(placed[0]["T_cam_obj"]), float(placed[0]["scale"])
    render = NumpyRenderer().render(
        [RenderMesh(scale * mesh.vertices @ T[:3, :3].T + T[:3, 3], np.asarray(mesh.faces), 1)],
        Camera(np.asarray(cam["K"]), cam["width"], cam["height"]))
    model = render.ids == 1
    gt = read_depth(scene / "gt" / "depth" / "000000.png", cam["depth_scale"])
    repaired = read_depth(out / "repaired" / "000000.png", cam["depth_scale"])
    return {"height": scale / truth["scale"] - 1,
            "iou": (model & mask).sum() / (model | mask).sum(),
            "mae_mm": 1000 * np.abs(repaired - gt)[mask].mean(),
            "resting": json.loads((out / placed[0]["mesh"]).with_suffix(".json").read_text())[
                "resting"]}


# kind: (median |height error|, worst |height error|, median IoU, worst IoU, median MAE mm,
# worst MAE mm) over PIPELINE_SEEDS. Measured with the revolution reconstruction, the mug's
# handle split off and modelled as a slab (heights -0.011 -0.099 +0.082 -0.043 -0.031 |
# +0.032 +0.006 +0.051 -0.004 +0.001 | +0.096 -0.014 +0.083 -0.033 +0.086; IoU .960 .882 .956
# .948 .967 | .889 .948 .964 .946 .929 | .962 .918 .937 .899 .930; MAE 2.4 21.1 5.4 5.0 3.9 |
# 8.2 3.7 4.8 2.8 5.1 | 6.2 9.2 5.0 24.6 7.8 mm). The bowl, fitted as a dome and taken for a
# bowl where it is squat and its readings do not prefer the dome (reconstruct.bowls.WIDE_LOW;
# the fourth, 2.6 times as many readings on the dome, stays one): heights -0.273 -0.295
# -0.468 -0.691 -0.390, IoU .972 .955 .806 .926 .803, MAE 7.1 11.1 12.9 16.5 17.4 mm (all
# left domes: MAE 20.0 20.6 18.4 16.5 18.1 mm).
PIPELINE_BOUNDS = {
    "bowl": (0.42, 0.72, 0.82, 0.78, 14.0, 19.0),
    "mug": (0.06, 0.12, 0.93, 0.86, 6.5, 25.0),
    "square_bottle": (0.03, 0.08, 0.92, 0.86, 7.0, 11.0),
    "thin_glass": (0.11, 0.13, 0.91, 0.87, 10.0, 30.0),
}


@pytest.mark.slow
@pytest.mark.parametrize("kind", sorted(PIPELINE_BOUNDS))
def test_pipeline_from_true_masks_on_new_shapes(kind, tmp_path):
    """A handled mug, a square bottle, a thin open glass and a bowl seen from above, each
    alone in a 424x240 frame: reconstructed height, silhouette IoU of the placed model against
    the true mask and object depth MAE, over five seeds."""
    rows = [_pipeline_on(kind, seed, tmp_path) for seed in PIPELINE_SEEDS]
    height = np.abs([r["height"] for r in rows])
    iou = np.array([r["iou"] for r in rows])
    mae = np.array([r["mae_mm"] for r in rows])
    h_med, h_max, iou_med, iou_min, mae_med, mae_max = PIPELINE_BOUNDS[kind]
    assert np.median(height) < h_med and height.max() < h_max, height
    assert np.median(iou) > iou_med and iou.min() > iou_min, iou
    assert np.median(mae) < mae_med and mae.max() < mae_max, mae


FLAT_SEEDS = range(58, 68)  # ten flat bottles, seen 23-61 degrees off their axes


@pytest.mark.slow
def test_flat_bottles_take_their_height_from_the_readings(tmp_path):
    """A flat bottle's outline is no surface of revolution's: seen 30-40 degrees off its axis,
    the outline fit's height is a guess (seeds 58 and 67: 23% and 13% too tall), and the
    readings' fit gives it. Ten flat bottles standing alone, from the true masks: mean
    |height error| 0.065 (0.095 with the readings' fit only within 25 degrees of the axis),
    mean object MAE 10.2 mm."""
    rows = [_pipeline_on("flat_bottle", seed, tmp_path) for seed in FLAT_SEEDS]
    assert np.mean([abs(r["height"]) for r in rows]) < 0.08
    assert np.mean([r["mae_mm"] for r in rows]) < 10.5


FLAT_FROM_ABOVE = (41, 50, 51, 55, 56, 75, 77, 93, 98)  # of seeds 40-99: within 20 degrees


@pytest.mark.slow
def test_flat_bottles_seen_from_above_stand(tmp_path):
    """Seen within 20 degrees of its axis, a standing flat bottle draws a rectangle that a
    short lying solid fits better than a standing one (whose height the outline leaves open:
    IoUs .92-.96 against .72-.83). Most of the readings lie above that lying fit's top, and
    above the standing outline fit's too, but not above the readings' fit, which then stands:
    the nine flat bottles of seeds 40-99 seen so, from the true masks, all stand, median
    |height error| 0.043 and mean object MAE 15.2 mm (five of them lying 38-55% short, 0.383
    and 19.8 mm, where a refuted standing outline fit left the lying one)."""
    rows = [_pipeline_on("flat_bottle", seed, tmp_path) for seed in FLAT_FROM_ABOVE]
    assert [r["resting"] for r in rows] == ["standing"] * len(rows)
    assert np.median([abs(r["height"]) for r in rows]) < 0.1
    assert np.mean([r["mae_mm"] for r in rows]) < 17.0


RIM_BAND = 0.02  # of the height: the vertices this near the top of an open vessel are its rim


def _through_mouth(scene: Path) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(H, W) bool`` of a one-object synth frame whose rays pass through the true
    open vessel's mouth (the disc its rim spans) and meet its inside further on, and the
    depth ``(H, W)`` metres of that disc, a lid over the mouth, along each ray."""
    truth = json.loads((scene / "gt" / "objects" / "000000.json").read_text())["objects"][0]
    cam = json.loads((scene / "camera.json").read_text())
    mesh = trimesh.load(scene / truth["mesh"], force="mesh", process=False)
    top = mesh.vertices[:, 2] > 1 - RIM_BAND
    rim = truth["scale"] * np.hypot(*mesh.vertices[top, :2].T).max()
    T = np.asarray(truth["T_cam_obj"])
    axis, centre = T[:3, 2], T[:3, :3] @ [0, 0, truth["scale"]] + T[:3, 3]
    ys, xs = np.mgrid[:cam["height"], :cam["width"]]
    rays = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.linalg.inv(np.asarray(cam["K"])).T
    lid = (centre @ axis) / (rays @ axis)  # z (m) where each ray meets the mouth's plane
    off = rays * lid[..., None] - centre
    radial = np.linalg.norm(off - (off @ axis)[..., None] * axis, axis=-1)
    gt = read_depth(scene / "gt" / "depth" / "000000.png", cam["depth_scale"])
    mask = read_mask(scene / "gt" / "masks" / "000000.png") == truth["id"]
    return mask & (lid > 0) & (radial < rim) & (gt > lid + 0.002), lid


# kind: (worst depth MAE through the mouth, mm; worst share of those pixels nearer the lid than
# the truth) over PIPELINE_SEEDS[:3]. Measured: thin glass 6.3 8.3 4.4 mm, 4.4 5.0 3.5%
# (the repaired depth 53-63 mm behind the lid, the truth 56-71 mm); bowl 18.4 23.7 19.7 mm,
# 18.9 22.2 0.0% (31-49 mm behind the lid, the truth 31-43 mm).
MOUTH_BOUNDS = {"thin_glass": (10.0, 0.08), "bowl": (27.0, 0.3)}


@pytest.mark.parametrize("kind", sorted(MOUTH_BOUNDS))
def test_open_vessels_are_rendered_inside_their_mouths(kind, tmp_path):
    """A thin glass and a bowl standing alone, seen from above, from the true mask: where the
    camera looks into the true mouth, the repaired depth follows the inside (wall and floor),
    not a lid over the mouth."""
    worst_mae, worst_lidlike = MOUTH_BOUNDS[kind]
    for seed in PIPELINE_SEEDS[:3]:
        _pipeline_on(kind, seed, tmp_path)
        scene = tmp_path / f"{kind}{seed}"
        cam = json.loads((scene / "camera.json").read_text())
        gt = read_depth(scene / "gt" / "depth" / "000000.png", cam["depth_scale"])
        repaired = read_depth(tmp_path / f"{kind}{seed}_out" / "repaired" / "000000.png",
                              cam["depth_scale"])
        inside, lid = _through_mouth(scene)
        assert inside.sum() > 500  # the inside is in view
        err, to_lid = np.abs(repaired - gt)[inside], np.abs(repaired - lid)[inside]
        assert 1000 * err.mean() < worst_mae, (seed, 1000 * err.mean())
        assert (to_lid < err).mean() < worst_lidlike, (seed, (to_lid < err).mean())
