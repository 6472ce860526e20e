"""sr3d grasp and grasp evaluation: known boxes and cylinders on a table, hand-made grasps."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.config import Config
from sr3d_cli.geometry.camera import pixel_rays, project
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.revolution import open_vessel, revolve
from sr3d_cli.geometry.raycast import first_hits
from sr3d_cli.geometry.transforms import make_T
from sr3d_cli.grasp import GraspSet
from sr3d_cli.grasp.gripper import Gripper
from sr3d_cli.grasp.planner import (Cloud, Planner, Sections, _across_wall, in_view,
                                    mesh_cloud, observed_cloud, unexplained)
from sr3d_cli.grasp.quality import CONTACTS, TrueScene, judge, overall, summarise
from sr3d_cli.stages import object_class

TABLE_Z = 0.6  # camera looks straight down at a table 0.6 m away
PLANE = Plane(np.array([0.0, 0.0, -1.0]), TABLE_Z)
GRIPPER = Gripper.from_config(Config().grasp)


def _on_table(mesh: trimesh.Trimesh, x: float = 0.0, y: float = 0.0) -> trimesh.Trimesh:
    """The mesh (object z up) standing on the table at (x, y): object +z = camera -z."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    lo = mesh.bounds[0, 2]
    T[:3, 3] = [x, y, TABLE_Z + lo]
    placed = mesh.copy()
    placed.apply_transform(T)
    return placed


def _table_cloud(step: float = 0.004, half: float = 0.2) -> Cloud:
    g = np.arange(-half, half, step)
    xx, yy = np.meshgrid(g, g)
    pts = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, TABLE_Z)], 1)
    return Cloud(pts, np.tile([0.0, 0.0, -1.0], (len(pts), 1)), np.zeros(len(pts), np.int64))


def _plan(mesh: trimesh.Trimesh, **settings):
    """Grasps for a lone mesh on the table, with these grasp settings changed."""
    cfg = Config().grasp
    for key, value in settings.items():
        setattr(cfg, key, value)
    target = mesh_cloud(mesh, np.eye(4), 1.0, 1, 3000)
    scene = Cloud.concat([_table_cloud(), target])
    return Planner(cfg).plan(scene, {1: target}, PLANE)


def _truth(meshes) -> TrueScene:
    return TrueScene.build(list(enumerate(meshes, start=1)), np.zeros((0, 3)), PLANE)


def test_raycast_hits_a_triangle_where_expected():
    tri = np.array([[[0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0]]])
    dist, face = first_hits(np.array([[0.2, 0.2, 0], [2, 2, 0]]), np.array([[0, 0, 2.0]] * 2),
                            tri)
    assert dist[0] == pytest.approx(0.5) and face[0] == 0
    assert np.isinf(dist[1]) and face[1] == -1


def test_the_grippers_lowest_point_is_its_lowest_corner():
    rng = np.random.default_rng(3)
    R = np.linalg.qr(rng.normal(size=(50, 3, 3)))[0]
    t = rng.normal(0, 0.1, (50, 3)) + [0, 0, 0.5]
    w, d = rng.uniform(0.01, 0.08, 50), rng.uniform(0.0, 0.04, 50)
    corners = np.einsum("nij,nkj->nki", R, GRIPPER.corners(w, d)) + t[:, None]
    expected = PLANE.height(corners.reshape(-1, 3)).reshape(50, 24).min(1)
    assert np.allclose(GRIPPER.lowest(R, t, w, d, PLANE), expected, atol=1e-12)
    assert GRIPPER.lowest(R[0], t[0], w[0], d[0], PLANE) == pytest.approx(expected[0])


def test_box_is_grasped_across_its_width():
    """The opening planned is the box's side and the margins; opened wide (the default), the
    same grasps open to the gripper's full width, nothing being near."""
    box = _on_table(trimesh.creation.box(extents=(0.05, 0.03, 0.08)))
    planned, messages = _plan(box, open_wide=False)
    assert not messages and len(planned) >= 3
    margin = Config().grasp.width_margin
    for i in range(len(planned)):
        closing = np.abs(planned.R[i][:, 1])
        across = closing[:2].max()
        assert across > 0.95, "closes along a face normal of the box"
        side = 0.05 if closing[0] > closing[1] else 0.03
        assert planned.widths[i] == pytest.approx(side + 2 * margin, abs=0.004)
    grasps, _ = _plan(box)
    assert np.allclose(grasps.t, planned.t) and np.allclose(grasps.R, planned.R)
    assert np.allclose(grasps.widths, GRIPPER.max_width)
    records = judge(grasps, _truth([box]), GRIPPER)
    summary = summarise(grasps, records, [1], friction=0.5)
    assert summary["top1"] == {"1": True}
    assert summary["top10_success"] >= 0.8


def test_cylinder_is_grasped_across_its_diameter():
    cyl = _on_table(trimesh.creation.cylinder(radius=0.025, height=0.1, sections=64))
    planned, _ = _plan(cyl, open_wide=False)
    assert len(planned) >= 3
    axis = np.array([0.0, 0.0, 1.0])
    for i in range(len(planned)):
        if abs(planned.R[i][:, 1] @ axis) < 0.2:  # across the body (not over the top face)
            assert planned.widths[i] == pytest.approx(0.05 + 0.01, abs=0.004)
    grasps, _ = _plan(cyl)
    records = judge(grasps, _truth([cyl]), GRIPPER)
    assert summarise(grasps, records, [1], friction=0.5)["top1"] == {"1": True}


def test_top1_is_reported_by_object_class():
    """A held box and an object with no grasp: each class's top-1 per frame and over frames,
    adding up to the totals; the class of a ground-truth record is its label, lying apart."""
    box = _on_table(trimesh.creation.box(extents=(0.05, 0.03, 0.08)))
    grasps, _ = _plan(box)
    records = judge(grasps, _truth([box]), GRIPPER)
    frame = summarise(grasps, records, [1, 2], friction=0.5,
                      classes={1: "box", 2: "vial lying"})
    assert frame["top1_by_class"] == {"box": {"objects": 1, "held": 1},
                                      "vial lying": {"objects": 1, "held": 0}}
    assert "top1_by_class" in frame and summarise(grasps, records, [1], 0.5)["top1_by_class"] == {}
    total = overall([frame, frame, summarise(grasps, records, [1], 0.5, classes={1: "box"})])
    assert total["top1_by_class"] == {"box": {"objects": 3, "top1_success": 1.0},
                                      "vial lying": {"objects": 2, "top1_success": 0.0}}
    assert total["objects"] == 5 and total["top1_success"] == pytest.approx(3 / 5)
    assert object_class({"label": "goblet", "pose": "lying"}) == "goblet lying"
    assert object_class({"label": "goblet", "pose": "standing"}) == "goblet"
    assert object_class({"label": "bottle"}) == "bottle"
    assert object_class({"id": 3}) == "unlabelled"


TALL = _on_table(trimesh.creation.cylinder(radius=0.025, height=0.2, sections=64))


def _best_on_tall_cylinder(seed: int, **settings):
    """The best grasp on :data:`TALL` (points drawn with ``seed``) with the grasp config's
    ``settings``; it must hold on the true cylinder."""
    target = mesh_cloud(TALL, np.eye(4), 1.0, 1, 3000, seed=seed)
    cfg = Config().grasp
    for key, value in settings.items():
        setattr(cfg, key, value)
    grasps, _ = Planner(cfg).plan(Cloud.concat([_table_cloud(), target]), {1: target}, PLANE)
    best = grasps.sorted().take(slice(0, 1))
    records = judge(best, _truth([TALL]), GRIPPER)
    assert records[0]["reason"] == "ok" and records[0]["mu"] <= 0.5
    return best


def test_a_tall_cylinder_is_held_lower_than_its_top():
    """The score prefers a grasp centre nearer half the object's height (nearer the centre of
    mass, away from the top, where a model's height error moves the surface most); without that
    term the approach from above wins and the hand takes the very top."""
    heights = {Config().grasp.centre_weight: [], 0.0: []}
    for seed in range(4):
        for weight in heights:
            # the centre term alone (the top-end term: the next test)
            best = _best_on_tall_cylinder(seed, centre_weight=weight, end_weight=0.0)
            heights[weight].append(float(PLANE.height(best.t[0])) / 0.2)
    # measured over 4 point draws: mean 0.824 of the height with the term, 0.856 without
    assert np.mean(heights[0.0]) > 0.84
    assert np.mean(heights[Config().grasp.centre_weight]) < np.mean(heights[0.0]) - 0.02


def test_fingers_keep_off_the_top_end_where_a_lip_would_stand():
    """A finger reaching within ``end_band`` of the top end (where a rim's lip or a neck's
    flare stands, which the outline cannot show) costs ``end_weight``: on a tall cylinder the
    best grasp without the term comes from above over the top; with it, from the side below
    the band, and it still holds."""
    reach = {0.0: [], Config().grasp.end_weight: []}
    for seed in range(4):
        for weight in reach:
            best = _best_on_tall_cylinder(seed, end_weight=weight)
            corners = GRIPPER.corners(best.widths, best.depths)[0, :16] @ best.R[0].T + best.t[0]
            reach[weight].append(float(PLANE.height(corners).max()))
    band = Config().grasp.end_band
    assert min(reach[0.0]) > 0.2 - band  # without the term: over the top, every draw
    assert max(reach[Config().grasp.end_weight]) < 0.2 - band


def test_grasps_stay_where_the_camera_sees_the_object():
    """A placed mesh runs past the border where the image cuts its object (a top-cut bottle);
    the planner holds only the part in view, not the made-up rest."""
    K = np.array([[600.0, 0, 319.5], [0, 600, 239.5], [0, 0, 1]])
    cyl = _on_table(trimesh.creation.cylinder(radius=0.025, height=0.2, sections=64), x=0.1)
    placed = mesh_cloud(cyl, np.eye(4), 1.0, 1, 3000)
    scene = Cloud.concat([_table_cloud(), placed])
    shape = (480, 450)  # the image ends 130 px right of its centre
    seen = in_view(placed, K, shape)
    assert 0.3 < len(seen.points) / len(placed.points) < 0.9
    assert (project(seen.points, K)[:, 0] <= shape[1] - 1).all()
    best = {}
    cfg = Config().grasp
    cfg.end_weight = 0.0  # so that the whole mesh's best grasp is the out-of-view top
    for name, target in (("all", placed), ("seen", seen)):
        grasps, _ = Planner(cfg).plan(scene, {1: target}, PLANE)
        best[name] = grasps.sorted().take(slice(0, 5))
    # measured: the whole mesh's best grasp sits at 0.84 of the height, 141 px right of the
    # centre; held where seen, the top five lie within 121 px and 0.55 of the height, the best
    # at 113 px and 0.34
    assert project(best["all"].t[:1], K)[0, 0] > shape[1] - 1
    assert (project(best["seen"].t, K)[:, 0] < shape[1] - 1 - 5).all()
    assert project(best["seen"].t[:1], K)[0, 0] < shape[1] - 1 - 15
    records = judge(best["seen"].take(slice(0, 1)), _truth([cyl]), GRIPPER)
    assert records[0]["reason"] == "ok" and records[0]["mu"] <= 0.5


@pytest.mark.parametrize("shape", ["box", "cylinder", "beaker"])
def test_the_palms_shortcut_on_the_objects_own_points_drops_no_grasp(shape):
    """A depth where the palm holds the object's own points is skipped before its section
    is worked out: the full collision test would reject those frames as well, so the grasps
    are the same with the shortcut off (no point counted as solid). The shortcut must also
    be taken: at the deepest depth most frames' palms are inside the object."""
    mesh = {"box": lambda: _on_table(trimesh.creation.box(extents=(0.05, 0.03, 0.08))),
            "cylinder": lambda: _on_table(trimesh.creation.cylinder(radius=0.025, height=0.1,
                                                                    sections=64)),
            "beaker": _beaker}[shape]()
    cfg = Config().grasp
    planner, g, m = Planner(cfg), GRIPPER, cfg.collision_margin
    target = mesh_cloud(mesh, np.eye(4), 1.0, 1, cfg.mesh_points)
    scene = Cloud.concat([_table_cloud(), target])
    top = float(PLANE.height(target.points).max())
    end = (PLANE.normal, float((target.points @ PLANE.normal).max()))
    R, c, span = planner._frames(target, PLANE, np.random.default_rng(0))
    args = (1, R, c, span, target, scene, PLANE, top, end)
    on = planner._try_frames(*args, solid=np.ones(len(target.points), bool))
    off = planner._try_frames(*args, solid=np.zeros(len(target.points), bool))
    assert on is not None and len(on) >= 10
    assert len(on) == len(off)
    for a, b in zip((on.scores, on.widths, on.depths, on.R, on.t),
                    (off.scores, off.widths, off.depths, off.R, off.t)):
        assert np.array_equal(a, b)
    local = np.einsum("fji,fnj->fin", R, target.points[None] - c[:, None])
    x, y, z = local[:, 0], local[:, 1], local[:, 2]
    d = max(cfg.depths)
    palm = (x > d - g.finger_length - g.palm_depth - m) & (x < d - g.finger_length + m) & \
        (np.abs(y) < g.palm_width / 2 + m - g.max_width / 2) & \
        (np.abs(z) < g.finger_height / 2 + m)
    assert (palm.sum(axis=1) >= cfg.collision_points).mean() > 0.5


def test_grasps_open_only_as_wide_as_their_neighbours_allow():
    """A cylinder 5 cm across with a box 22 mm beside it: each grasp opens from its planned
    opening to the widest share of what the gripper has to spare whose fingers' path stays
    clear of the box (with the collision margin), so every grasp holds the cylinder and
    touches nothing else; opened to the full 8 cm regardless, those closing towards the box
    set a finger in it. Measured over 4 draws: 18 of 40 grasps opened less than fully (at
    58-69 mm), 22 fully; at the full opening 9 would collide."""
    cyl = _on_table(trimesh.creation.cylinder(radius=0.025, height=0.1, sections=64))
    box = _on_table(trimesh.creation.box(extents=(0.03, 0.12, 0.08)), x=0.025 + 0.022 + 0.015)
    target = mesh_cloud(cyl, np.eye(4), 1.0, 1, 3000)
    scene = Cloud.concat([_table_cloud(), target, mesh_cloud(box, np.eye(4), 1.0, 2, 3000)])
    truth = _truth([cyl, box])
    short, full, collide = 0, 0, 0
    for seed in range(4):
        cfg = Config().grasp
        cfg.seed = seed
        grasps, messages = Planner(cfg).plan(scene, {1: target}, PLANE)
        cfg.open_wide = False
        planned, _ = Planner(cfg).plan(scene, {1: target}, PLANE)
        assert not messages and len(grasps) == len(planned) == 10
        assert np.allclose(grasps.t, planned.t) and np.all(grasps.widths >= planned.widths)
        assert np.all(grasps.widths <= GRIPPER.max_width + 1e-9)
        records = judge(grasps, truth, GRIPPER)
        assert all(r["reason"] == "ok" and r["mu"] <= 0.5 and r["object"] == 1
                   for r in records), records
        wide = replace(grasps, widths=np.full(len(grasps), GRIPPER.max_width))
        collide += sum(r["reason"] == "collision" for r in judge(wide, truth, GRIPPER))
        full += int(np.sum(grasps.widths > GRIPPER.max_width - 1e-6))
        short += int(np.sum(grasps.widths < GRIPPER.max_width - 1e-6))
    assert short >= 10 and full >= 10 and collide >= 5, (short, full, collide)


def test_object_wider_than_the_gripper_gets_no_grasp():
    wide = _on_table(trimesh.creation.box(extents=(0.12, 0.12, 0.05)))
    grasps, messages = _plan(wide)
    assert len(grasps) == 0
    assert messages and "0.080 m opening" in messages[0]


def test_an_object_just_under_the_opening_is_held_with_tight_margins():
    """75 mm across: with 4 mm either side the 80 mm opening is too small, with the margins
    halved (``tight_margins``) it fits, and the true scene holds the grasp."""
    drum = _on_table(trimesh.creation.cylinder(radius=0.0375, height=0.05, sections=96))
    grasps, messages = _plan(drum, tight_margins=0.0)
    assert len(grasps) == 0 and "0.080 m opening" in messages[0]
    grasps, messages = _plan(drum, tight_margins=0.5)
    assert not messages and len(grasps) >= 1
    assert np.all(grasps.widths <= GRIPPER.max_width)
    assert np.all(grasps.widths >= 0.075 + 2 * 0.5 * Config().grasp.width_margin - 1e-3)
    summary = summarise(grasps, judge(grasps, _truth([drum]), GRIPPER), [1], friction=0.5)
    assert summary["top1"] == {"1": True}


@pytest.mark.slow
def test_an_object_nothing_holds_on_at_the_friction_gets_its_best_grasp_flagged():
    """A cone cut 30 degrees from its axis, 7 cm across its foot: no two points of it face
    each other well enough to hold at friction 0.5. With ``fallback_friction`` off it gets no
    grasp; with it on it gets its best grasps, a message says what they need, and the true
    cone holds the best one at a friction between the two, as planned."""
    slope = np.radians(30)
    cone = _on_table(revolve([(0, 0), (0.035, 0), (0.035 - 0.04 * np.tan(slope), 0.04),
                              (0, 0.04)], 96))
    grasps, messages = _plan(cone, fallback_friction=0.0)
    assert len(grasps) == 0 and "no grasp" in messages[0]
    grasps, messages = _plan(cone, fallback_friction=2.0)
    assert len(grasps) >= 1
    assert messages == ["object 1: nothing holds at friction 0.5 on the model; the best grasp "
                        "needs up to 2.00"]
    best = judge(grasps.sorted().take(slice(0, 1)), _truth([cone]), GRIPPER)[0]
    assert best["reason"] == "ok" and 0.5 < best["mu"] <= 2.0


def _beaker(radius: float = 0.05, height: float = 0.1, wall: float = 0.002) -> trimesh.Trimesh:
    """An open thin-walled vessel standing on the table (z up in its own frame)."""
    outer = [(0, 0), (radius, 0), (radius, height)]
    return _on_table(revolve(open_vessel(outer, wall, 0.004), 96))


def test_vessel_wider_than_the_gripper_is_pinched_at_the_rim():
    """10 cm across, 8 cm opening: only the 2 mm wall can be held, fingers either side of it."""
    beaker = _beaker()
    planned, messages = _plan(beaker, open_wide=False)
    assert not messages and len(planned) >= 3
    rim_z = TABLE_Z - 0.1
    for i in range(len(planned)):
        assert planned.widths[i] < 0.02
        radial = planned.t[i][:2] / np.linalg.norm(planned.t[i][:2])
        assert abs(planned.R[i][:2, 1] @ radial) > 0.9, "closes across the wall"
        # near the rim (camera z grows downwards): the fingers reach past the wall's top
        assert planned.t[i][2] < rim_z + GRIPPER.finger_length
    # opened wide, the inner finger starts inside the vessel, short of its far wall (the
    # 80 mm opening puts its pad 9 mm from the axis of a 96 mm bore)
    grasps, _ = _plan(beaker)
    assert np.allclose(grasps.t, planned.t) and np.allclose(grasps.widths, GRIPPER.max_width)
    records = judge(grasps, _truth([beaker]), GRIPPER)
    summary = summarise(grasps, records, [1], friction=0.5)
    assert summary["top1"] == {"1": True}
    assert summary["top10_success"] >= 0.8


def _scanned_glass(radius: float = 0.045, height: float = 0.12) -> trimesh.Trimesh:
    """A glass as a scan gives it, standing on the table: its outer surface alone (side and
    floor, one sheet), open at the mouth."""
    solid = revolve(np.array([[0, 0], [radius, 0], [radius, height], [0, height]]), 96)
    top = len(solid.vertices) - 1  # the top cap's centre
    return _on_table(trimesh.Trimesh(solid.vertices,
                                     solid.faces[~(solid.faces == top).any(axis=1)],
                                     process=False))


def test_a_glass_scanned_as_one_sheet_is_pinched_at_the_rim():
    """9 cm across, 8 cm opening, no inner wall in the mesh: every sample lies on one sheet,
    and its other side, 2.5 mm in, is what a pinch across the rim pairs it with (the
    evaluator closes the jaws on the sheet itself). A closed vessel's samples get none, and
    the sheet's samples alone give no antipodal pair within the opening."""
    glass = _scanned_glass()
    assert not glass.is_watertight
    cloud = mesh_cloud(glass, np.eye(4), 1.0, 1, 3000)
    assert len(cloud.points) == 6000
    inner = cloud.points[3000:]
    assert np.allclose(np.linalg.norm(cloud.points[:3000] - inner, axis=1), 0.0025)
    assert np.all(np.einsum("ij,ij->i", cloud.normals[:3000], cloud.normals[3000:]) < -0.999)
    assert len(mesh_cloud(_beaker(), np.eye(4), 1.0, 1, 3000).points) == 3000

    scene = Cloud.concat([_table_cloud(), cloud])
    cfg = Config().grasp
    cfg.open_wide = False
    planned, messages = Planner(cfg).plan(scene, {1: cloud}, PLANE)
    assert not messages and len(planned) >= 3
    assert np.all(planned.widths < 0.02)
    grasps, _ = Planner(Config().grasp).plan(scene, {1: cloud}, PLANE)
    summary = summarise(grasps, judge(grasps, _truth([glass]), GRIPPER), [1], friction=0.5)
    assert summary["top1"] == {"1": True}
    assert summary["top10_success"] >= 0.8

    one_side = cloud.select(np.arange(len(cloud.points)) < 3000)
    grasps, messages = Planner(Config().grasp).plan(
        Cloud.concat([_table_cloud(), one_side]), {1: one_side}, PLANE)
    assert len(grasps) == 0 and "no antipodal pair" in messages[0]


def test_a_wall_with_no_partner_across_the_vessel_closes_along_its_normal():
    """A 9 cm beaker's wall (2.5 mm) has no far partner within the 8 cm opening, so its one pair
    is the near one, a few millimetres long and up to ``pair_radius`` off the normal: its own
    line points anywhere. Measured on the wall's frames: closing within 8 degrees of across the
    wall 46% by the pair's line (median 24.5 degrees off), 100% by the normals (0.6). The only
    long pairs at the wall's heights run down the wall, from the rim's top to the base under
    it (the 75 mm height fits the opening)."""
    beaker = _beaker(0.045, 0.075, 0.0025)
    target = mesh_cloud(beaker, np.eye(4), 1.0, 1, 2400)
    R, c, span = Planner(Config().grasp)._frames(target, PLANE, np.random.default_rng(0))
    height = PLANE.height(c)
    band = (height > 0.01) & (height < 0.065)
    wall, down = band & (span < 0.01), band & (span >= 0.01)
    assert wall.sum() > 100
    assert np.all(np.abs(R[down, :, 1] @ PLANE.normal) > 0.99)
    radial = c[wall, :2] / np.linalg.norm(c[wall, :2], axis=1, keepdims=True)
    across = np.abs(np.einsum("fk,fk->f", R[wall, :2, 1], radial))
    assert np.mean(across > np.cos(np.radians(8))) > 0.95


def test_an_object_with_nothing_held_draws_other_seed_points():
    """Few seeds on a vessel that can only be held at its rim: a draw often finds nothing there;
    ``redraws`` tries other points then, and leaves the draws that held alone."""
    beaker = _beaker()
    target = mesh_cloud(beaker, np.eye(4), 1.0, 1, 2400)
    scene = Cloud.concat([_table_cloud(), target])
    held = {}
    for redraws in (0, 2, 6):
        held[redraws] = set()
        for seed in range(10):
            cfg = Config().grasp
            cfg.seeds, cfg.seed, cfg.redraws = 4, seed, redraws
            cfg.fallback_friction = 0.0  # the redraws alone
            grasps, messages = Planner(cfg).plan(scene, {1: target}, PLANE)
            if len(grasps):
                held[redraws].add(seed)
                assert judge(grasps.sorted().take(slice(0, 1)), _truth([beaker]),
                             GRIPPER)[0]["reason"] == "ok"
            else:
                assert messages and "no collision-free grasp" in messages[0]
    # measured: 2 of 10 seeds hold with one draw, 7 with up to three, 9 with up to seven
    assert held[0] < held[2] < held[6]
    assert len(held[6]) - len(held[0]) >= 5


def _stemmed_block() -> trimesh.Trimesh:
    """A solid 10 cm wide, 9 cm tall block on a 16 mm wide, 10 cm tall stem on a 9 cm foot: only
    the stem, about 7% of the surface, fits the 8 cm opening."""
    parts = [trimesh.creation.cylinder(radius=0.045, height=0.01),
             trimesh.creation.cylinder(radius=0.008, height=0.1),
             trimesh.creation.cylinder(radius=0.05, height=0.09)]
    for part, z in zip(parts, (0.005, 0.06, 0.145)):
        part.apply_translation([0, 0, z])
    return trimesh.util.concatenate(parts)


def test_seeds_spread_along_the_object_find_a_thin_stem():
    """Seeds drawn by area rarely land on a stem; drawn evenly along the object's length, over a
    third of them do, so a small draw (8 points) finds the only place that holds."""
    block = _on_table(_stemmed_block())
    target = mesh_cloud(block, np.eye(4), 1.0, 1, 2400)
    scene = Cloud.concat([_table_cloud(), target])
    held = {}
    for bins in (0, 12):
        held[bins] = 0
        for seed in range(10):
            cfg = Config().grasp
            cfg.seeds, cfg.seed, cfg.redraws, cfg.seed_bins = 8, seed, 0, bins
            cfg.approaches = 7  # as measured (with the default 5, 6 of 10 along the length)
            grasps, _ = Planner(cfg).plan(scene, {1: target}, PLANE)
            if len(grasps):
                held[bins] += 1
                best = grasps.sorted().take(slice(0, 1))
                assert 0.01 < PLANE.height(best.t)[0] < 0.08, "held by the stem"
                assert judge(best, _truth([block]), GRIPPER)[0]["reason"] == "ok"
    # measured: by area 0 of 10 seeds (7 of 10 with 64 points), along the length 10
    assert held[0] <= 3 and held[12] >= 8


def test_evaluator_holds_a_wall_between_flat_pads():
    """A rim pinch by hand: on a 3 cm radius the inner pad touches the concave wall along its
    two edges only (the middle is 1.3 mm off), which together hold; the same pads closing across
    a box's diagonal (edge contacts, face normals 45 degrees off the line) still need friction 1."""
    beaker = _beaker(radius=0.03)
    R = np.stack([[0, 0, 1.0], [1.0, 0, 0], [0, -1.0, 0]], axis=1)  # approach down, close x
    x_wall = 0.03 - 0.001
    row = np.concatenate([[1.0, 0.016, 0.02, 0.02], R.ravel(), [x_wall, 0, TABLE_Z - 0.09], [1]])
    rim = judge(GraspSet.from_array(row[None]), _truth([beaker]), GRIPPER)[0]
    assert rim["reason"] == "ok" and rim["mu"] < 0.5  # each edge alone: mu 13
    box = _on_table(trimesh.creation.box(extents=(0.04, 0.04, 0.08)))
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    row = np.concatenate([[1.0, 0.07, 0.02, 0.02], (turn @ R).ravel(),
                          [0, 0, TABLE_Z - 0.06], [1]])
    diagonal = judge(GraspSet.from_array(row[None]), _truth([box]), GRIPPER)[0]
    assert diagonal["reason"] == "ok" and 0.9 < diagonal["mu"] < 1.1


def test_contact_models_on_a_lip_the_grid_of_rays_steps_over():
    """The evaluator's default grid has rows 9.4 mm apart along the finger: a beaker's 3 mm lip
    between two rows is not seen, and a rim pinch on it is judged as on a plain wall; 5 mm
    lower, a row meets the lip and the same pinch fails outright. The whole pad's first touch
    (``contacts="pads"``) rests on the lip's top edge at every height, which stands 3 mm above
    the inner wall's top: the pinch leans 28 degrees (.53), where on the plain rim the inner
    pad's two edges on the concave wall push level with the outer contact (0). GraspNet's one
    ray per jaw (``"line"``) sees the lip only where the closing line through the grasp centre
    crosses it. Measured: plain .30/0/.03 (grid/pads/line) at each height; lipped .30/.53/.03
    and 5730/.53/.03; centre 2 mm under the top: lipped line .60, plain .03."""
    R = np.stack([[0, 0, 1.0], [1.0, 0, 0], [0, -1.0, 0]], axis=1)  # approach down, close x
    plain = _beaker(radius=0.03)
    lipped = _on_table(revolve(open_vessel([(0, 0), (0.03, 0), (0.03, 0.097), (0.0318, 0.1)],
                                           0.002, 0.004), 96))
    mu = {}
    for name, mesh in (("plain", plain), ("lipped", lipped)):
        for centre in (0.085, 0.09, 0.098):
            row = np.concatenate([[1.0, 0.016, 0.02, 0.02], R.ravel(),
                                  [0.03 - 0.001, 0, TABLE_Z - centre], [1]])
            for model in CONTACTS:
                record = judge(GraspSet.from_array(row[None]), _truth([mesh]), GRIPPER,
                               contacts=model)[0]
                assert record["reason"] == "ok"
                mu[name, centre, model] = record["mu"]
    for centre in (0.085, 0.09, 0.098):
        assert mu["plain", centre, "pads"] < 0.05 and 0.45 < mu["lipped", centre, "pads"] < 0.6
    for centre in (0.085, 0.09):
        assert mu["plain", centre, "grid"] < 0.4
        assert mu["plain", centre, "line"] < 0.1 and mu["lipped", centre, "line"] < 0.1
    assert mu["lipped", 0.085, "grid"] < 0.4 and mu["lipped", 0.09, "grid"] > 100
    assert mu["lipped", 0.098, "line"] > 0.5 and mu["plain", 0.098, "line"] < 0.1
    with pytest.raises(ValueError, match="contact model"):
        judge(GraspSet.from_array(row[None]), _truth([plain]), GRIPPER, contacts="rays")


def test_exact_pads_take_the_normal_their_kind_of_contact_has():
    """``contacts="pads"``: a corner or edge of the mesh on a pad's face pushes along the pad's
    normal, the pad's edge on a face along the face's. A box across its diagonal (its edges on
    the pads' faces) holds without friction, where the faces' normals (grid, line) need 1.0;
    the fingertip across a cone's side keeps the cone's slope (27 degrees: .52), and on the
    neck above it holds. Measured: box 1.0/0/1.0 (grid/pads/line); cone .53/.52/.03 (the
    line passes above the cone), neck .03/0/.03."""
    down = np.stack([[0, 0, 1.0], [1.0, 0, 0], [0, -1.0, 0]], axis=1)  # approach down, close x

    def mu(mesh, width, height, depth, turn=np.eye(3), model="pads"):
        row = np.concatenate([[1.0, width, 0.02, depth], (turn @ down).ravel(),
                              [0, 0, TABLE_Z - height], [1]])
        record = judge(GraspSet.from_array(row[None]), _truth([mesh]), GRIPPER,
                       contacts=model)[0]
        assert record["reason"] == "ok"
        return record["mu"]

    box = _on_table(trimesh.creation.box(extents=(0.04, 0.04, 0.08)))
    c = np.cos(np.pi / 4)
    diagonal = np.array([[c, -c, 0], [c, c, 0], [0, 0, 1.0]])
    assert mu(box, 0.07, 0.06, 0.02, diagonal) < 0.05
    for model in ("grid", "line"):
        assert 0.9 < mu(box, 0.07, 0.06, 0.02, diagonal, model) < 1.1
    cone = _on_table(revolve(np.array([[0, 0], [0.05, 0], [0.05, 0.004], [0.015, 0.07],
                                       [0.015, 0.1], [0, 0.1]]), 96))
    assert 0.45 < mu(cone, 0.05, 0.09, 0.03) < 0.6
    assert mu(cone, 0.05, 0.085, 0.01) < 0.05


def _hand_grasp(width: float, centre_height: float, depth: float) -> GraspSet:
    R = np.stack([[0, 0, 1.0], [1.0, 0, 0], [0, -1.0, 0]], axis=1)  # approach down, close x
    row = np.concatenate([[1.0, width, 0.02, depth], R.ravel(),
                          [0, 0, TABLE_Z - centre_height], [1]])
    return GraspSet.from_array(row[None])


def test_evaluator_accepts_antipodal_and_rejects_table_and_too_wide():
    box = _on_table(trimesh.creation.box(extents=(0.05, 0.03, 0.08)))
    truth = _truth([box])
    good = judge(_hand_grasp(0.06, 0.06, 0.02), truth, GRIPPER)[0]
    assert good["reason"] == "ok" and good["mu"] < 0.05 and good["object"] == 1
    through_table = judge(_hand_grasp(0.06, 0.01, 0.04), truth, GRIPPER)[0]
    assert through_table["reason"] == "below table"
    too_wide = judge(_hand_grasp(0.09, 0.06, 0.02), truth, GRIPPER)[0]
    assert too_wide["reason"] == "too wide"
    empty = judge(_hand_grasp(0.06, 0.06, 0.02).take(slice(0, 0)), truth, GRIPPER)
    assert empty == []


def test_graspnet_layout_round_trip():
    g = _hand_grasp(0.06, 0.06, 0.02)
    a = g.to_array()
    assert a.shape == (1, 17) and a[0, 1] == 0.06 and a[0, 16] == 1
    assert np.allclose(a[0, 4:13].reshape(3, 3)[:, 0], [0, 0, 1])  # x = approach
    back = GraspSet.from_array(a)
    assert np.allclose(back.to_array(), a)
    pose = g.hand_poses(0.1034)[0]
    tip = g.t[0] + g.R[0][:, 0] * g.depths[0]
    assert np.allclose(pose[:3, 3] + pose[:3, 2] * 0.1034, tip)  # fingertips 0.1034 along z
    with pytest.raises(ValueError, match="17"):
        GraspSet.from_array(np.zeros((2, 16)))


def test_grasp_cli_bad_frames_give_empty_valid_files(synth_set, tmp_path):
    """A frame that cannot be planned fails (exit 1) and still gets valid files saying why."""
    scene = synth_set / "scene_0001"
    runner = CliRunner()
    out = tmp_path / "nomasks"
    result = runner.invoke(cli, ["grasp", str(scene), "--out", str(out), "-q"])
    assert result.exit_code == 1, result.output
    assert "failed: 000000" in result.output and "no masks" in result.output
    doc = json.loads((out / "grasps" / "000000.json").read_text())
    assert doc["grasps"] == [] and "no masks" in doc["failed"][0]
    assert "no masks" in doc["frame_failed"]
    assert np.load(out / "grasps" / "000000.npy").shape == (0, 17)
    # masks but no repaired depth
    result = runner.invoke(cli, ["segment", str(scene), "--out", str(out), "-q"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(cli, ["grasp", str(scene), "--out", str(out), "-q",
                                 "--skip-existing"])  # a failed frame is not done
    assert result.exit_code == 1, result.output
    doc = json.loads((out / "grasps" / "000000.json").read_text())
    assert doc["grasps"] == [] and "no repaired depth" in doc["failed"][0]


@pytest.mark.slow
def test_grasp_end_to_end_beats_raw_depth(synth_set, tmp_path):
    """Repair, plan on repaired and on raw depth, judge both against the true meshes."""
    runner = CliRunner()
    wins = {"repaired": 0, "raw": 0}
    objects = 0
    for name in ("scene_0000", "scene_0002", "scene_0003"):
        scene, out = synth_set / name, tmp_path / name
        assert runner.invoke(cli, ["repair-depth", str(scene), "--out", str(out), "-q"]
                             ).exit_code == 0
        for source in ("raw", "repaired"):
            result = runner.invoke(cli, ["grasp", str(scene), "--out", str(out), "-q",
                                         "--from", source, "--preview", "--hand-poses"])
            assert result.exit_code == 0, result.output
            result = runner.invoke(cli, ["evaluate", str(scene), "--out", str(out), "-q",
                                         "--grasps"])
            assert result.exit_code == 0, result.output
            doc = json.loads((out / "grasp_metrics.json").read_text())
            wins[source] += sum(bool(v) for v in doc["frames"]["000000"]["top1"].values())
        objects += doc["overall"]["objects"]
        by_class = doc["overall"]["top1_by_class"]  # the generator's labels, adding up
        assert sum(t["objects"] for t in by_class.values()) == doc["overall"]["objects"]
        assert sum(t["objects"] * t["top1_success"] for t in by_class.values()) == \
            pytest.approx(doc["overall"]["top1_success"] * doc["overall"]["objects"])
        assert by_class and "top-1 by class: " in result.output
        assert (out / "grasps" / "000000_preview.png").is_file()
        assert np.load(out / "grasps" / "000000_hand_poses.npy").shape[1:] == (4, 4)
    assert wins["repaired"] / objects >= 0.5
    assert wins["repaired"] > wins["raw"]
    # the same grasps judged by the other contact models: valid documents that say which
    for model in ("pads", "line"):
        result = runner.invoke(cli, ["evaluate", str(scene), "--out", str(out), "-q",
                                     "--grasps", "--contacts", model])
        assert result.exit_code == 0, result.output
        doc = json.loads((out / "grasp_metrics.json").read_text())
        assert doc["contacts"] == model and CONTACTS[model] in doc["method"]
        assert doc["overall"]["objects"] >= 1 and 0.0 <= doc["overall"]["top1_success"] <= 1.0
    result = runner.invoke(cli, ["evaluate", str(scene), "--out", str(out), "-q",
                                 "--contacts", "pads"])
    assert result.exit_code != 0 and "--contacts goes with --grasps" in result.output
    # the command line offers exactly the evaluator's contact models
    option = next(p for p in cli.commands["evaluate"].params if p.name == "contacts")
    assert list(option.type.choices) == list(CONTACTS)


@pytest.mark.slow
def test_the_placed_mesh_rescores_the_best_grasps_by_their_exact_contacts():
    """A goblet and a wine glass (curved bowls, a stem, a rim): the planner's patch normals
    average over sampled points, so its best grasps by them need more friction, with the jaws
    closed exactly onto the mesh, than the best found by scoring them again with those exact
    contacts. Measured over 10 seeds, mean exact mu of the best grasp (with the 4 mm height
    margin), by patch normals and rescored: goblet .138 and .089, wine glass 2.64 (one seed's
    best needs 12.3) and .079. Rescoring only the best (not all ten) keeps the cost down."""
    profiles = {
        "goblet": revolve(np.array([[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01],
                                    [0.005, 0.07], [0.03, 0.09], [0.04, 0.13], [0.036, 0.16],
                                    [0, 0.16]]), 64),
        "wine glass": revolve(open_vessel([(0, 0), (0.03, 0), (0.005, 0.01), (0.005, 0.06),
                                           (0.035, 0.09), (0.04, 0.13)], 0.002, 0.07), 64)}
    for name, solid in profiles.items():
        mesh = _on_table(solid)
        target = mesh_cloud(mesh, np.eye(4), 1.0, 1, 2400)
        scene = Cloud.concat([_table_cloud(), target])
        best = {}
        for surfaces in (None, {1: np.asarray(mesh.triangles)}):
            mus = []
            for seed in range(10):
                cfg = Config().grasp
                cfg.seed = seed
                grasps, _ = Planner(cfg).plan(scene, {1: target}, PLANE, surfaces)
                record = judge(grasps.sorted().take(slice(0, 1)), _truth([mesh]), GRIPPER)[0]
                assert record["reason"] == "ok", name
                mus.append(record["mu"])
            best[surfaces is not None] = np.mean(mus)
            if surfaces is not None:
                assert max(mus) <= 0.3, name
        assert best[True] <= {"goblet": 0.85, "wine glass": 0.9}[name] * best[False], (name, best)


def _best_held(model: trimesh.Trimesh, truth: TrueScene, seeds: int = 10, **settings) -> list:
    """Planned on ``model`` (its surface as the scene, its triangles for the exact check) with
    the grasp config changed by ``settings``, for each of ``seeds`` draws: whether the best
    grasp holds ``truth`` at friction 0.5."""
    target = mesh_cloud(model, np.eye(4), 1.0, 1, 2400)
    scene = Cloud.concat([_table_cloud(), target])
    held = []
    for seed in range(seeds):
        cfg = Config().grasp
        cfg.seed = seed
        for key, value in settings.items():
            setattr(cfg, key, value)
        grasps, _ = Planner(cfg).plan(scene, {1: target}, PLANE, {1: np.asarray(model.triangles)})
        record = judge(grasps.sorted().take(slice(0, 1)), truth, GRIPPER)[0]
        held.append(record["reason"] == "ok" and record["mu"] <= 0.5)
    return held


@pytest.mark.slow
def test_the_best_grasps_hold_on_a_model_whose_height_is_a_few_millimetres_off():
    """A 10 cm wide beaker with a lip (too wide for the gripper: held only by its rim) fitted
    4% too tall or too short, as sr3d's fits often are: planned on the model, judged on the
    true beaker. Scored at the model's exact height, the best rim pinch often rests a pad on
    the lip, where the true one is not; with the contacts also found 4 mm up and down, the best
    holds. Measured over 10 seeds each: held at friction 0.5 by .3 (too tall) and .7 (too
    short) of the best grasps without the margin, .9 and .9 with it. The slope margin is off
    here, to see this one alone: with both, .5 and .7 (the turned pinches that hold overlap
    the wall briefly, near the rim, where the height error bites; on whole frames the slope
    margin gains more than this loses)."""
    profile = np.asarray(open_vessel([(0, 0), (0.047, 0), (0.049, 0.003), (0.049, 0.126),
                                      (0.052, 0.129)], 0.0025, 0.0047))
    truth = _truth([_on_table(revolve(profile, 64))])
    held = {tolerance: sum((_best_held(_on_table(revolve(profile * [1.0, stretch], 64)), truth,
                                       height_tolerance=tolerance, tilt_tolerance=0.0)
                            for stretch in (1.04, 0.96)), []) for tolerance in (0.0, 0.004)}
    assert np.mean(held[0.004]) >= 0.85, held
    assert np.mean(held[0.004]) >= np.mean(held[0.0]) + 0.25, held


@pytest.mark.slow
def test_the_best_grasps_hold_on_a_model_whose_wall_leans_a_few_degrees_off():
    """A 10 cm wide lipped beaker (held only by its rim) whose model's wall leans 3 degrees
    outwards, as sr3d's fits of straight walls often do (the rim in place, the base 6 mm
    narrower): planned on the model, judged on the true beaker. Parallel pads set to the
    model's wall meet the true wall at opposite ends, one near the rim and the other low
    down, and slip; with the contacts also found with the grasp turned 4 degrees either way
    against the wall's slope (``tilt_tolerance``), the best grasps are those that still hold.
    Measured over 10 seeds: the best grasp held at friction 0.5 for 2 without the margin, 6
    with it."""
    def beaker(lean_deg):
        d = 0.123 * np.tan(np.radians(lean_deg))
        profile = [(0, 0), (0.047 - d, 0), (0.049 - d, 0.003), (0.049, 0.126), (0.052, 0.129)]
        return _on_table(revolve(np.asarray(open_vessel(profile, 0.0025, 0.0047)), 64))

    truth, model = _truth([beaker(0.0)]), beaker(3.0)
    held = {tilt: _best_held(model, truth, tilt_tolerance=tilt) for tilt in (0.0, 4.0)}
    assert np.mean(held[4.0]) >= 0.5, held
    assert np.mean(held[4.0]) >= np.mean(held[0.0]) + 0.3, held


def test_only_a_pinch_across_one_wall_is_turned_against_the_walls_slope():
    """The slope margin is for a pinch across one wall, whose jaws do not close around the
    model's axis (one finger inside a rim). Across a body, a neck or a stem the jaws close
    around it, and their pads, two walls apart, are checked as planned: turned 4 degrees,
    47 mm pads move 3.3 mm at their ends, past the evaluator's 1 mm contact tie, and a grasp
    across a bottle that holds would fail the check (the margin on every object lowers
    grasp top-1 on whole frames)."""
    axis, on_axis = np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 0.55])
    assert _across_wall(np.array([0.049, 0.0, 0.48]), 0.013, axis, on_axis)      # a rim
    assert not _across_wall(np.array([0.003, 0.0, 0.52]), 0.07, axis, on_axis)   # a body
    assert not _across_wall(np.array([0.0, 0.002, 0.57]), 0.017, axis, on_axis)  # a stem
    cylinder = _on_table(trimesh.creation.cylinder(radius=0.03, height=0.12, sections=64))
    target = mesh_cloud(cylinder, np.eye(4), 1.0, 1, 2400)
    scene = Cloud.concat([_table_cloud(), target])
    best = []
    for tilt in (0.0, 4.0):
        cfg = Config().grasp
        cfg.tilt_tolerance = tilt
        grasps, _ = Planner(cfg).plan(scene, {1: target}, PLANE,
                                      {1: np.asarray(cylinder.triangles)})
        best.append(grasps.sorted())
    assert len(best[0]) > 0
    assert np.array_equal(best[0].scores, best[1].scores)
    assert np.allclose(best[0].t, best[1].t)


def _goblet(stem_top: float = 0.06, height: float = 0.18) -> trimesh.Trimesh:
    """A goblet standing on the table: a foot 68 mm wide, a stem 10 mm thick from 10 mm up to
    ``stem_top``, and a bowl flaring from there to 84 mm wide (as the synthetic goblets)."""
    t = np.linspace(0, 1, 10)[1:]
    r = 0.005 + 0.037 * np.sin(np.pi * 0.62 * t) / np.sin(np.pi * 0.62)
    r[-3:] = np.linspace(r[-4], 0.036, 4)[1:]
    outer = [(0, 0), (0.034, 0), (0.032, 0.004), (0.005, 0.01), (0.005, stem_top)]
    outer += list(zip(r, stem_top + (height - stem_top) * t))
    return _on_table(revolve(np.asarray(open_vessel(outer, 0.002, stem_top + 0.008)), 64))


def _on_axis(heights) -> np.ndarray:
    """Points on the axis of :func:`_on_table`'s objects at these heights above the table."""
    heights = np.asarray(heights, dtype=np.float64)
    return np.stack([np.zeros_like(heights), np.zeros_like(heights), TABLE_Z - heights], 1)


def test_sections_measure_how_far_pads_stay_from_a_change_of_section():
    """How far pads 10 mm above and below a grasp centre stay inside the straight run of the
    section around it (a cylinder or a cone, up to a kink): on a goblet's stem (10 to 60 mm
    up), most at its middle and none at the foot or the bowl; on a cylinder the base is no
    edge (the table keeps the fingers off it) and the top is one (a rim's lip, a neck's
    flare)."""
    down = np.array([0.0, 0.0, -1.0])  # the objects' height axis in the camera frame
    stem = Sections.of(np.asarray(_goblet().triangles), down)
    heights = np.array([0.014, 0.025, 0.035, 0.045, 0.058])
    pads = np.full(len(heights), 0.01)
    margin = stem.margin(stem.height(_on_axis(heights)), pads, pads, 0.005)
    # measured: -5, 6, 16, 8, -5 mm (the run: from the top of the foot's cone, 10 mm up, to
    # where the flaring bowl leaves the tolerance, 3 mm above the junction)
    assert margin[2] == margin.max() and margin[2] > 0.012
    assert 0 < margin[1] < margin[2] and 0 < margin[3] < margin[2]
    assert margin[0] < 0 and margin[4] < 0
    cylinder = _on_table(trimesh.creation.cylinder(radius=0.03, height=0.12, sections=64))
    body = Sections.of(np.asarray(cylinder.triangles), down)
    heights = np.array([0.005, 0.06, 0.115])
    pads = np.full(3, 0.01)
    margin = body.margin(body.height(_on_axis(heights)), pads, pads, 0.005)
    assert margin == pytest.approx([0.105, 0.05, 0.0], abs=0.0015)


def test_a_run_ending_under_a_wider_part_ends_junction_drop_lower():
    """``drop``: the stem's run ends that much lower under the bowl (carved models put the
    junction too high), so the pads' best place moves down the stem; a bottle's body ends
    under its narrower shoulder as without the drop, and a cylinder's top is no junction."""
    down = np.array([0.0, 0.0, -1.0])
    stem = Sections.of(np.asarray(_goblet().triangles), down)
    heights = np.array([0.025, 0.03, 0.035, 0.04, 0.045])
    pads = np.full(len(heights), 0.01)
    plain = stem.margin(stem.height(_on_axis(heights)), pads, pads, 0.005)
    dropped = stem.margin(stem.height(_on_axis(heights)), pads, pads, 0.005, 0.01)
    # measured: 6, 11, 16, 14, 8 mm -> 6, 11, 9, 4, -2 mm: the upper end 10 mm lower
    assert np.argmax(plain) == 2 and np.argmax(dropped) == 1
    assert dropped[3:] == pytest.approx(plain[3:] - 0.01, abs=0.0015)
    assert dropped[:2] == pytest.approx(plain[:2])
    for solid in (revolve(np.array([(0, 0), (0.03, 0), (0.03, 0.1), (0.012, 0.13), (0.012, 0.17),
                                    (0, 0.17)]), 64),
                  trimesh.creation.cylinder(radius=0.03, height=0.12, sections=64)):
        body = Sections.of(np.asarray(_on_table(solid).triangles), down)
        heights = np.array([0.04, 0.06, 0.08])
        pads = np.full(3, 0.01)
        at = body.height(_on_axis(heights))
        assert body.margin(at, pads, pads, 0.005, 0.01) == \
            pytest.approx(body.margin(at, pads, pads, 0.005))


def test_on_a_placed_model_the_centre_term_favours_the_middle_of_a_stem():
    """With a placed model, the centre term counts how far the pads stay inside their straight
    run (``run_scale``), not how near the centre is to half the object's height: on a goblet that
    height lies in the bowl, and the stem grasp nearest it sits right under the junction,
    where a carved model's junction is often 10-55 mm off (the grasp then touches the true
    flare or hits the bowl). A stem grasp at the stem's middle outscores one under the
    junction; by half the height it is the other way round (see :meth:`Planner.score`)."""
    goblet = _goblet()
    triangles = np.asarray(goblet.triangles)
    down = np.array([0.0, 0.0, -1.0])
    target = mesh_cloud(goblet, np.eye(4), 1.0, 1, 2400)
    end = (down, float((target.points @ down).max()))
    centres = _on_axis([0.035, 0.05])
    R = np.repeat(np.eye(3)[None], 2, 0)  # from the side, closing across the stem
    args = (np.full(2, 0.1), np.full(2, 0.018), R, centres, PLANE, 0.18, np.full(2, 0.02), end)
    planner = Planner(Config().grasp)
    with_model = planner.score(*args, Sections.of(triangles, down))
    by_height = planner.score(*args)
    assert with_model[0] > with_model[1] + 0.05
    assert by_height[1] > by_height[0]


def _lying_vessel(outer: list):
    """A vessel of outer profile ``outer`` [(r, z), ...] metres (base first, the last point its
    mouth's lip) lying on the table with its axis along camera x, placed as a closed solid
    and offered its open form (wall 2 mm, floor 4 mm): the closed model's surface points
    (target), the scene cloud, its triangles {1: (m, 3, 3)}, the open form as a fallback
    {1: (scene, target, triangles)} and the true scene (the open vessel)."""
    h, widest = outer[-1][1], max(r for r, _ in outer)
    T = make_T(np.array([[0, 0, 1.0], [0, 1.0, 0], [-1.0, 0, 0]]),
               np.array([-h / 2, 0, TABLE_Z - widest]))

    def lying(profile):
        mesh = revolve(np.asarray(profile), 96)
        mesh.apply_transform(T)
        return mesh

    closed, opened = lying(outer + [(0, h)]), lying(open_vessel(outer, 0.002, 0.004))
    target = mesh_cloud(closed, np.eye(4), 1.0, 1, 3000)
    other = mesh_cloud(opened, np.eye(4), 1.0, 1, 3000)
    scene = Cloud.concat([_table_cloud(), target])
    fallback = {1: (Cloud.concat([_table_cloud(), other]), other, np.asarray(opened.triangles))}
    return target, scene, {1: np.asarray(closed.triangles)}, fallback, _truth([opened])


@pytest.mark.slow
def test_a_wide_lying_vessel_closed_in_the_model_is_planned_on_its_open_fallback():
    """A beaker 10.8 cm across lying on its side, its mouth turned away from the camera: the
    model is a closed solid (nothing seen tells an open end from a closed one), too wide for
    the 8 cm opening anywhere. Offered the vessel opened at that end, the planner pinches its
    wall at the mouth; an object its own model gives grasps keeps them. The height margin of
    the exact check runs along the beaker's own axis, here across the table: moved up and
    down the table normal instead, a pinch on the side wall meets the curved wall off its
    pads' middle and every one fails the check. Measured over 10 seeds: the best grasp held
    the true (open) beaker at friction 0.5 for 10 with the margin along the axis, 4 along the
    table normal, none without the fallback. The slope margin, ``tight_margins`` and
    ``fallback_friction`` are off here, to see these alone: with the slope margin, 7 of 10
    along the axis (no pinch at this mouth, whose lip flares, holds turned 4 degrees, and the
    pick among those that fail is arbitrary; scoring a pinch that fails only turned as one at
    the friction limit gives 9 here, but loses grasps on whole frames). Those counts are with
    64 seeds and 7 approaches, which this test sets: with the default 80 and 5 the table
    normal also holds 10 of 10 here, which would hide the axis's effect."""
    r, h = 0.052, 0.09
    axis = np.array([1.0, 0, 0])
    target, scene, surfaces, fallback, truth = _lying_vessel(
        [(0, 0), (r, 0), (r, h - 0.003), (1.04 * r, h)])
    held = {"axis": [], "table normal": []}
    for seed in range(10):
        cfg = Config().grasp
        cfg.seed = seed
        cfg.tilt_tolerance = 0.0
        cfg.fallback_friction = 0.0  # the closed model's rim gives grasps above 0.5
        cfg.tight_margins = 0.0  # tight margins hold 9 of 10 along the table normal too
        cfg.seeds, cfg.approaches = 64, 7  # as measured (see above)
        cfg.open_wide = False  # the planned opening tells a pinch across the wall
        planner = Planner(cfg)
        if seed < 3:
            alone, messages = planner.plan(scene, {1: target}, PLANE, surfaces)
            assert len(alone) == 0 and "0.080 m opening" in messages[0]
        for along, axes in (("axis", {1: axis}), ("table normal", None)):
            grasps, messages = planner.plan(scene, {1: target}, PLANE, surfaces, fallback, axes)
            assert len(grasps) and all("nothing holds" in m for m in messages)
            assert np.all(grasps.widths < 0.02)  # across the wall
            record = judge(grasps.sorted().take(slice(0, 1)), truth, GRIPPER)[0]
            held[along].append(record["reason"] == "ok" and record["mu"] <= 0.5)
    assert np.mean(held["axis"]) >= 0.9, held
    assert np.mean(held["axis"]) >= np.mean(held["table normal"]) + 0.3, held
    # a cylinder the gripper spans keeps its own grasps, the fallback unused
    narrow = _on_table(trimesh.creation.cylinder(radius=0.03, height=0.1, sections=64))
    target = mesh_cloud(narrow, np.eye(4), 1.0, 1, 3000)
    scene = Cloud.concat([_table_cloud(), target])
    own, _ = Planner(Config().grasp).plan(scene, {1: target}, PLANE)
    offered, _ = Planner(Config().grasp).plan(scene, {1: target}, PLANE, None, fallback)
    assert len(own) and np.array_equal(own.to_array(), offered.to_array())


def test_a_lying_cups_grasps_also_hold_on_its_open_form():
    """A cup 83 mm across at its lipped mouth and 46 mm long lying on its side, placed as a
    closed solid (the image leaves its mouth open or shut) and offered its open form: the
    grasps that hold on the closed model are also closed on the open one, and the worse
    counts. Closing along the axis holds on the closed model's lid, and on the true cup's lip
    only where the pads meet it flat; measured over 10 seeds: on the closed model alone the
    best grasp closes along the axis for 9 and holds the true (open) cup for 7, with the
    open form checked too, 5 and 10."""
    r, h = 0.039, 0.046
    axis = np.array([1.0, 0, 0])
    target, scene, surfaces, fallback, truth = _lying_vessel(
        [(0, 0), (0.8 * r, 0), (r, h - 0.004), (1.06 * r, h)])
    held, along = {}, {}
    for name, offered in (("closed", None), ("open too", fallback)):
        held[name], along[name] = 0, 0
        for seed in range(10):
            cfg = Config().grasp
            cfg.seed = seed
            grasps, _ = Planner(cfg).plan(scene, {1: target}, PLANE, surfaces, offered,
                                          {1: axis})
            best = grasps.sorted().take(slice(0, 1))
            record = judge(best, truth, GRIPPER)[0]
            held[name] += record["reason"] == "ok" and record["mu"] <= 0.5
            along[name] += abs(best.R[0][:, 1] @ axis) > 0.9
    assert along["closed"] >= 8 and held["closed"] <= 7, (along, held)
    assert held["open too"] == 10, (along, held)


def test_the_open_fallback_is_planned_without_the_closed_models_depth(tmp_path):
    """A beaker 10.4 cm across lying with its mouth turned 40 deg from the camera, its model
    kept closed (the readings did not open it) with the fallback opened at the mouth. The
    repaired depth, rendered from the closed model, shows the lid over the mouth: the grasp
    stage plans the fallback without the object's own depth, whose lid points every pinch
    of the rim meets (no grasp at all). The best grasp pinches the wall at
    the mouth and holds the true open beaker."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.geometry.camera import Camera
    from sr3d_cli.geometry.transforms import place_points
    from sr3d_cli.io.atomic import write_json, write_png
    from sr3d_cli.io.formats import discover_scenes
    from sr3d_cli.io.images import write_depth
    from sr3d_cli.render import RenderMesh, make_renderer
    from sr3d_cli.stages import grasp_frame, load_grasps
    from tests.scenes import K_TABLE, table, table_point

    plane = table()
    r, h = 0.052, 0.09
    outer = [(0, 0), (r, 0), (r, h - 0.003), (1.04 * r, h)]
    toward = plane.project_direction(np.array([0.0, 0, -1.0]))
    toward /= np.linalg.norm(toward)
    a = np.radians(40)
    axis = np.cos(a) * toward + np.sin(a) * np.cross(plane.normal, toward)  # base -> mouth
    x = np.cross(plane.normal, axis)
    base = table_point(plane, 0.0, 0.05) + 1.04 * r * plane.normal - 0.5 * h * axis
    T = make_T(np.stack([x, np.cross(axis, x), axis], axis=1), base)
    closed = revolve(np.asarray(outer + [(0, h)]) / h)
    opened = revolve(open_vessel(outer, 0.002, 0.004) / h)
    camera = Camera(K_TABLE, 640, 480)
    drawn = make_renderer("numpy").render(
        [RenderMesh(place_points(closed.vertices, T, h), np.asarray(closed.faces), 1)], camera)
    depth = np.where(drawn.ids == 1, drawn.depth, plane.depth_image((480, 640), K_TABLE))
    scene, out = tmp_path / "scene", tmp_path / "out"
    write_json(scene / "camera.json", {"K": K_TABLE.tolist(), "width": 640, "height": 480,
                                       "depth_scale": 0.001})
    write_png(scene / "rgb" / "000000.png", np.zeros((480, 640, 3), np.uint8))
    write_depth(scene / "depth" / "000000.png", depth, 0.001)
    write_png(out / "masks" / "000000.png", drawn.ids.astype(np.uint16))
    write_json(out / "masks" / "000000.json", {"objects": [{"id": 1, "label": "beaker"}]})
    (out / "meshes" / "000000").mkdir(parents=True)
    closed.export(out / "meshes" / "000000" / "1.ply")
    opened.export(out / "meshes" / "000000" / "1_open.ply")
    write_json(out / "meshes" / "000000" / "1.json", {"open_alternative": "1_open.ply"})
    write_json(out / "poses" / "000000.json",
               {"objects": [{"id": 1, "mesh": "meshes/000000/1.ply", "T_cam_obj": T.tolist(),
                             "scale": h}], "failed": [], "plane": plane.to_json()})
    write_depth(out / "repaired" / "000000.png", depth, 0.001)
    source, = discover_scenes(scene, IOConfig(), out)
    cfg = Config()
    cfg.grasp.open_wide = False  # the planned opening tells a pinch across the wall
    count, messages, _ = grasp_frame(source.load_frame("000000"), Planner(cfg.grasp),
                                     cfg.plane)
    assert count > 0 and not messages, messages
    grasps = load_grasps(source, "000000").sorted()
    assert np.all(grasps.widths < 0.02)  # across the wall
    mouth = base + h * axis
    assert np.linalg.norm(grasps.t[0] - mouth) < 1.1 * r  # at the mouth's rim
    true = opened.copy()
    true.vertices = place_points(opened.vertices, T, h)
    truth = TrueScene.build([(1, true)], np.zeros((0, 3)), plane)
    record = judge(grasps.take(slice(0, 1)), truth, GRIPPER)[0]
    assert record["reason"] == "ok" and record["mu"] <= 0.5, record


K_VIEW = np.array([[600.0, 0, 319.5], [0, 600, 239.5], [0, 0, 1]])  # the camera of _readings
VIEW = (480, 640)
GLASS_NOISE = 0.004  # m, depth noise sd of a glass's front-surface readings (synth.noise_glass)


def _readings(mesh: trimesh.Trimesh, noise: float = GLASS_NOISE, share: float = 0.5,
              seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A depth sensor's view of ``mesh`` from the camera at the origin (``K_VIEW``, 640 x 480),
    as of glass: a random ``share`` of the pixels on it read its surface, with depth noise
    ``noise`` m (sd), the rest nothing. Returns (depth (H, W) m, 0 = no reading; mask (H, W)
    int, 1 on the mesh)."""
    rng = np.random.default_rng(seed)
    u, v = project(mesh.vertices, K_VIEW).T
    u0, u1 = int(max(u.min() - 2, 0)), int(min(u.max() + 3, VIEW[1]))
    v0, v1 = int(max(v.min() - 2, 0)), int(min(v.max() + 3, VIEW[0]))
    rays = pixel_rays(VIEW, K_VIEW)[v0:v1, u0:u1].reshape(-1, 3)  # z = 1: distance = depth
    tri = np.asarray(mesh.triangles)
    dist = np.concatenate([first_hits(np.zeros((len(r), 3)), r, tri)[0]
                           for r in np.array_split(rays, max(len(rays) // 2000, 1))])
    hit = np.isfinite(dist).reshape(v1 - v0, u1 - u0)
    read = hit & (rng.random(hit.shape) < share)
    depth, ids = np.zeros(VIEW), np.zeros(VIEW, np.int64)
    ids[v0:v1, u0:u1][hit] = 1
    depth[v0:v1, u0:u1][read] = dist.reshape(hit.shape)[read] + \
        rng.normal(0, noise, int(read.sum()))
    return depth, ids


def test_observed_readings_take_the_median_of_their_surface():
    """Each reading becomes the median of the readings on its surface around it: a glass's
    front-surface returns (sd 4 mm) come out within about a millimetre of the surface, and
    see-through readings of the table 5 cm behind, mixed among them, neither pull them nor
    are pulled."""
    rng = np.random.default_rng(0)
    front = np.full(VIEW, 0.6) + rng.normal(0, GLASS_NOISE, VIEW)
    through = rng.random(VIEW) < 0.3
    depth = np.where(through, 0.65, front)
    depth[rng.random(VIEW) < 0.3] = 0.0  # holes
    ids = np.zeros(VIEW, np.int64)
    ids[100:300, 200:400] = 3
    cloud = observed_cloud(depth, K_VIEW, ids)
    inside = (ids == 3) & (depth > 0)
    assert len(cloud.points) == inside.sum() and np.all(cloud.labels == 3)
    z = cloud.points[:, 2]
    near = z < 0.625
    assert near.sum() == (inside & ~through).sum()
    # measured: sd 1.1 mm (4.0 mm read), mean off by 0.01 mm; the see-through ones at 0.65
    assert np.std(z[near]) < 0.0015 and abs(np.mean(z[near]) - 0.6) < 0.0005
    assert np.allclose(z[~near], 0.65)
    assert np.allclose(cloud.points[:, :2] / z[:, None],
                       observed_cloud(np.where(depth > 0, 1.0, 0.0), K_VIEW, ids).points[:, :2])
    assert len(observed_cloud(depth, K_VIEW, ids, stride=2).points) == inside[::2, ::2].sum()


def test_readings_a_placed_model_accounts_for_are_explained():
    """A model's readings (sd 4 mm along their rays) are explained by it, up to a few near its
    outline; a handle beside it, and the part of a wider object past it, are not."""
    cylinder = trimesh.creation.cylinder(radius=0.03, height=0.1, sections=64)
    truth = _on_table(cylinder, x=0.1)
    model = Sections.of(np.asarray(truth.triangles), PLANE.normal)
    depth, ids = _readings(truth)
    observed = observed_cloud(depth, K_VIEW, ids)
    left = unexplained(observed, [model])
    # measured: 6 of 2423 (each reading alone, without its surface's median: 247)
    assert len(left.points) < 0.01 * len(observed.points)
    # a handle's grip, 1 cm off the body's side (on the camera's side of it)
    handle = _on_table(trimesh.creation.box(extents=(0.012, 0.01, 0.05)), x=0.1 - 0.046)
    handle.apply_translation([0, 0, -0.025])
    depth, ids = _readings(handle)
    on_handle = observed_cloud(depth, K_VIEW, ids)
    assert len(unexplained(on_handle, [model]).points) > 0.9 * len(on_handle.points)
    wider = _on_table(trimesh.creation.cylinder(radius=0.04, height=0.1, sections=64), x=0.1)
    depth, ids = _readings(wider)
    seen = observed_cloud(depth, K_VIEW, ids)
    off_axis = np.linalg.norm((seen.points - [0.1, 0, 0])[:, :2], axis=1)
    past = off_axis > 0.03 + 0.005
    assert np.isin(np.flatnonzero(past), np.flatnonzero(model.outside(seen.points, 0.003))).all()
    assert len(unexplained(seen, [model]).points) >= 0.8 * past.sum()


def test_grasps_the_observation_contradicts_are_dropped_on_a_shifted_model():
    """The placed model sits 1 cm off the true cylinder, away from the camera (a fit on a
    glass often does); the sensor's readings (half of the pixels, sd 4 mm) show the true near
    side. Planned at the model's own opening, most of the ten best grasps on the model alone
    close a finger through the true cylinder; with the readings those are dropped and the
    grasps left hold it. Opened wide (the default), the fingers start clear of the true
    cylinder and the model's grasps hold without the readings too."""
    cylinder = trimesh.creation.cylinder(radius=0.03, height=0.1, sections=64)
    truth_mesh, model = _on_table(cylinder, x=0.1), _on_table(cylinder, x=0.11)
    depth, ids = _readings(truth_mesh)
    observed = observed_cloud(depth, K_VIEW, ids)
    target = mesh_cloud(model, np.eye(4), 1.0, 1, 2400)
    scene = Cloud.concat([_table_cloud(), target])
    truth = _truth([truth_mesh])
    top1, top10 = {}, {}
    for seed in range(4):
        for wide in (False, True):
            cfg = Config().grasp
            cfg.seed, cfg.open_wide = seed, wide
            for use in (False, True):
                grasps, _ = Planner(cfg).plan(scene, {1: target}, PLANE,
                                              {1: np.asarray(model.triangles)},
                                              observed=observed if use else None)
                summary = summarise(grasps, judge(grasps, truth, GRIPPER), [1], friction=0.5)
                top1.setdefault((wide, use), []).append(summary["top1"]["1"])
                top10.setdefault((wide, use), []).append(summary["top10_success"])
    # measured over 4 draws at the planned opening: top-1 held 1 of 4 and top-10 .2 on the
    # model alone; with the readings 4 of 4 and 1.0 (6 to 10 grasps left). Opened wide: the
    # model alone 4 of 4 and .975, with the readings 4 of 4 and 1.0
    assert np.mean(top10[False, False]) <= 0.4
    assert all(top1[False, True]) and np.mean(top10[False, True]) >= 0.9
    assert all(top1[True, False]) and np.mean(top10[True, False]) >= 0.9
    assert all(top1[True, True]) and np.mean(top10[True, True]) >= 0.9


def test_the_readings_of_a_right_model_drop_no_grasp_that_holds():
    """Where the model is right, its noisy readings (sd 4 mm) contradict almost nothing: the
    grasps keep holding, nearly all of them the same as without the readings."""
    cylinder = _on_table(trimesh.creation.cylinder(radius=0.03, height=0.1, sections=64),
                         x=0.1)
    depth, ids = _readings(cylinder)
    observed = observed_cloud(depth, K_VIEW, ids)
    target = mesh_cloud(cylinder, np.eye(4), 1.0, 1, 2400)
    scene = Cloud.concat([_table_cloud(), target])
    truth = _truth([cylinder])
    kept, total = 0, 0
    for seed in range(4):
        cfg = Config().grasp
        cfg.seed = seed
        alone, _ = Planner(cfg).plan(scene, {1: target}, PLANE, {1: np.asarray(cylinder.triangles)})
        seen, _ = Planner(cfg).plan(scene, {1: target}, PLANE, {1: np.asarray(cylinder.triangles)},
                                    observed=observed)
        summary = summarise(seen, judge(seen, truth, GRIPPER), [1], friction=0.5)
        assert summary["top1"] == {"1": True} and summary["top10_success"] == 1.0
        rows = seen.to_array()
        kept += sum(any(np.allclose(a, b) for b in rows) for a in alone.to_array())
        total += len(alone)
    assert kept >= 0.9 * total  # measured: 39 of 40
