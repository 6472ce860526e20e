"""sr3d segment: training-free masks scored against ground truth, imported masks, SAM via ONNX."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.config import PlaneConfig, SegmentConfig
from sr3d_cli.errors import InputError
from sr3d_cli.evaluate import instance_ious
from sr3d_cli.io.atomic import write_png
from sr3d_cli.io.images import read_mask
from sr3d_cli.geometry.camera import depth_to_points
from sr3d_cli.geometry.plane import support_plane
from sr3d_cli.segment import Segmenter, import_masks
from sr3d_cli.segment.training_free import on_table_readings, with_parts_on_axis
from tests import onnx_builders
from tests.scenes import GLASS, generated_frame, solids_on_table


def _segmented_ious(frame, gt: np.ndarray) -> dict[int, float]:
    """Each true object's best IoU against the default training-free segmenter's instances."""
    inst = Segmenter(SegmentConfig(), PlaneConfig())("000000", frame.rgb, frame.depth_m,
                                                     frame.camera.K)
    return instance_ious(inst.ids, gt)


def test_support_plane_recovers_a_tilted_table():
    K = np.array([[500.0, 0, 160], [0, 500, 120], [0, 0, 1]])
    n_true = np.array([0.0, -0.8, -0.6])  # towards the camera, table seen from above
    d_true = 0.5
    v, u = np.mgrid[0:240, 0:320]
    rays = np.stack([(u - 160) / 500, (v - 120) / 500, np.ones_like(u, float)], -1)
    depth = (-d_true / (rays @ n_true)).astype(np.float32)
    rng = np.random.default_rng(0)
    depth += rng.normal(0, 0.001, depth.shape).astype(np.float32)
    depth[50:90, 100:160] = 0.3  # a box in front
    depth[rng.uniform(size=depth.shape) < 0.1] = 0  # dropouts
    plane = support_plane(depth, K, PlaneConfig())
    assert np.degrees(np.arccos(plane.normal @ n_true)) < 0.5
    assert abs(plane.offset - d_true) < 0.003


def test_support_plane_is_the_table_not_a_larger_wall_beside_it():
    """A wall on the left holds more readings than the table (as where the sensor fails on a
    white cloth over the table): the plane chosen is still the one the camera looks down on."""
    K = np.array([[500.0, 0, 160], [0, 500, 120], [0, 0, 1]])
    v, u = np.mgrid[0:240, 0:320]
    rays = np.stack([(u - 160) / 500, (v - 120) / 500, np.ones_like(u, float)], -1)
    table_n, table_d = np.array([0.0, -0.8, -0.6]), 0.5
    wall_n = np.array([0.97, 0.19, -0.15]) / np.linalg.norm([0.97, 0.19, -0.15])
    wall_d = 0.25
    with np.errstate(divide="ignore"):
        table = -table_d / (rays @ table_n)
        wall = -wall_d / (rays @ wall_n)
    on_wall = (u < 190) & (wall > 0) & (wall < 3.0)
    on_table = ~on_wall & ((u < 190) | (v >= 150))  # a cloth over the rest reads nothing
    rng = np.random.default_rng(0)
    depth = np.where(on_wall, wall, np.where(on_table, table, 0.0))
    depth = (depth + rng.normal(0, 0.001, depth.shape) * (depth > 0)).astype(np.float32)
    assert on_wall.sum() > 2 * on_table.sum()  # the largest plane is the wall
    plane = support_plane(depth, K, PlaneConfig())
    assert np.degrees(np.arccos(plane.normal @ table_n)) < 1.0
    assert abs(plane.offset - table_d) < 0.005


@pytest.mark.slow
def test_training_free_masks_match_ground_truth(synth_set):
    """Floors on six generated scenes: mean IoU and the share of objects found (IoU > 0.5)."""
    segmenter = Segmenter(SegmentConfig(), PlaneConfig())
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    ious = []
    for source in discover_scenes(synth_set, IOConfig(), None):
        fid = source.frame_ids()[0]
        frame = source.load_frame(fid)
        inst = segmenter(fid, frame.rgb, frame.depth_m, frame.camera.K)
        gt = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
        ious += list(instance_ious(inst.ids, gt).values())
        for obj in inst.objects:  # records agree with the id image
            ys, xs = np.nonzero(inst.ids == obj["id"])
            assert obj["bbox"] == [xs.min(), ys.min(), xs.max(), ys.max()]
    assert len(ious) >= 8
    assert np.mean(ious) >= 0.75
    assert np.mean(np.array(ious) > 0.5) >= 0.8


@pytest.mark.slow
def test_dropouts_beyond_the_table_are_not_objects(synth_set, monkeypatch):
    """A wall behind the table, riddled with dropouts (as a white wall is for a RealSense):
    none of its holes may become an instance; the objects on the table still do."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes
    from sr3d_cli.segment import training_free

    source = next(iter(discover_scenes(synth_set, IOConfig(), None)))
    fid = source.frame_ids()[0]
    frame = source.load_frame(fid)
    gt = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
    depth = frame.depth_m.copy()
    rows = np.nonzero((gt > 0).any(axis=1))[0]
    wall = slice(0, max(rows.min() - 15, 40))  # the rows above every object
    depth[wall] = 1.6  # a vertical surface far behind the table: not on the plane
    rng = np.random.default_rng(3)
    for _ in range(25):  # blob-shaped dropouts, as big as a small glass
        y = rng.integers(0, wall.stop)
        x = rng.integers(0, depth.shape[1])
        yy, xx = np.ogrid[:depth.shape[0], :depth.shape[1]]
        blob = (yy - y) ** 2 + (xx - x) ** 2 < rng.integers(8, 18) ** 2
        depth[blob & (yy < wall.stop)] = 0
    segmenter = Segmenter(SegmentConfig(), PlaneConfig())
    inst = segmenter(fid, frame.rgb, depth, frame.camera.K)
    on_wall = [o for o in inst.objects if (inst.ids[wall] == o["id"]).sum()
               > 0.5 * (inst.ids == o["id"]).sum()]
    assert on_wall == []
    found = instance_ious(inst.ids, gt)
    assert np.mean([v > 0.5 for v in found.values()]) >= 0.5
    # without the table-footprint gate (and the outline check and the least area, which reject
    # these plain dropouts too) the wall's holes do come out as objects
    monkeypatch.setattr(training_free, "ON_TABLE_SHARE", 0.0)
    monkeypatch.setattr(training_free, "FAINT_SHARE", 0.0)
    monkeypatch.setattr(training_free, "MIN_IMAGE_SHARE", 0.0)
    ungated = segmenter(fid, frame.rgb, depth, frame.camera.K)
    assert len(ungated.objects) > len(inst.objects)


@pytest.mark.slow
def test_a_glass_rising_above_the_tables_far_edge_keeps_its_outline(synth_set):
    """No readings beyond the table's far edge (the room is out of range), and that edge cuts
    the highest object in each frame 30 % down its outline: its outline of holes joins the
    room's and must not be dropped with it. Measured: cut objects' mean IoU 0.73, all objects
    0.81; with the holes judged as one region 0.67 and 0.74, one object at 0.31."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    segmenter = Segmenter(SegmentConfig(), PlaneConfig())
    cut_ious, all_ious = [], []
    for source in discover_scenes(synth_set, IOConfig(), None):
        fid = source.frame_ids()[0]
        frame = source.load_frame(fid)
        gt = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
        rows = {k: np.nonzero((gt == k).any(axis=1))[0] for k in np.unique(gt) if k}
        top = min(rows, key=lambda k: rows[k].min())
        depth = frame.depth_m.copy()
        depth[:int(rows[top].min() + 0.3 * np.ptp(rows[top]))] = 0
        found = instance_ious(segmenter(fid, frame.rgb, depth, frame.camera.K).ids, gt)
        cut_ious.append(found.get(top, 0.0))
        all_ious += list(found.values())
    assert min(cut_ious) >= 0.5
    assert np.mean(cut_ious) >= 0.72
    assert np.mean(all_ious) >= 0.78


def test_an_outline_with_a_narrow_opening_is_filled_but_not_the_table_between_objects():
    """Holes trace a glass's outline but thin out in one place: a hole filling leaks through
    that opening, so the see-through inside (smooth table readings) would be left out and the
    glass come in pieces. Nearly closed gaps are filled; the table boxed in by two objects through
    wide openings is not."""
    from sr3d_cli.segment.training_free import find_candidates

    glass = np.zeros((200, 200), bool)
    glass[40:160, 60:70] = glass[40:160, 110:120] = True  # the sides of a glass
    glass[150:160, 60:120] = True  # its base
    glass[40:50, 60:84] = glass[40:50, 96:120] = True  # its rim, open over 12 px
    none = np.zeros_like(glass)
    (found,) = find_candidates(glass, none, min_area=50, close_radius=3)
    assert found[60:150, 70:110].all()
    assert found.sum() >= 0.97 * 120 * 60
    # the table boxed in by two objects under a shelf of evidence (a Pi shape) stays out
    pi = np.zeros((200, 200), bool)
    pi[40:160, 40:70] = pi[40:160, 130:160] = pi[40:60, 40:160] = True
    (found,) = find_candidates(pi, none, min_area=50, close_radius=3)
    assert not found[80:160, 80:120].any()


def test_the_table_between_a_glass_and_the_far_edges_band_is_not_filled():
    """A glass's evidence reaching up to the band of dropouts along the table's far edge
    closes in a patch between them. Where the patch reads the table it is table, and the band
    does not count as closing it in; a patch that does not read the table is filled as
    before, and so is the table patch where the far edge is not known."""
    from sr3d_cli.segment.training_free import _enclosed, along_far_edge

    footprint = np.zeros((200, 200), bool)
    footprint[30:] = True
    far = along_far_edge(footprint, 8)
    assert far[22:39].all() and not far[39:].any() and not far[:22].any()
    region = np.zeros_like(footprint)
    region[26:35] = True  # the band of dropouts along the far edge
    region[60:150, 60:120] = True  # the glass
    region[34:60, 60:66] = region[34:60, 114:120] = True  # its sides up to the band
    patch = np.zeros_like(footprint)
    patch[35:60, 66:114] = True
    on_table = footprint & ~region
    assert not _enclosed(region, 12, far_edge=far, on_table=on_table)[patch].any()
    assert _enclosed(region, 12, far_edge=far, on_table=on_table & ~patch)[patch].all()
    assert _enclosed(region, 12)[patch].all()


def test_touching_glasses_are_split_but_a_goblet_is_not():
    from sr3d_cli.segment.training_free import split_touching

    glass = [[0, 0], [0.03, 0], [0.033, 0.1], [0, 0.1]]
    ids, K, plane, _ = solids_on_table([(glass, 0.1, -0.032, 0.0), (glass, 0.1, 0.034, 0.01)])
    region = ids > 0
    parts = split_touching(region, K, plane)
    assert len(parts) == 2
    ious = instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), ids)
    assert min(ious.values()) > 0.9
    goblet = [[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01], [0.005, 0.07], [0.03, 0.09],
              [0.04, 0.13], [0.036, 0.16], [0, 0.16]]
    ids, K, plane, _ = solids_on_table([(goblet, 0.16, 0.0, 0.0)])
    assert len(split_touching(ids > 0, K, plane)) == 1


def test_a_part_opaque_as_a_whole_is_not_split_again():
    """Three glasses in a row are cut in two rounds, one per glass. A part the ``opaque``
    predicate marks (here: the part holding two glasses) stays whole, with no fit spent on
    judging its cuts; a region it marks is not split at all."""
    from sr3d_cli.segment import training_free as tf

    ids, K, plane, _ = solids_on_table([(GLASS, 0.1, -0.066, 0.0), (GLASS, 0.1, 0.0, 0.0),
                                        (GLASS, 0.1, 0.066, 0.0)])
    region = ids > 0
    assert cv2.connectedComponents(region.astype(np.uint8))[0] == 2  # one region
    one = max(int((ids == k).sum()) for k in (1, 2, 3))
    parts = tf.split_touching(region, K, plane)
    assert len(parts) == 3
    assert min(instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0),
                             ids).values()) > 0.9

    def pairs(mask):
        return mask is not region and mask.sum() > 1.5 * one

    kept = tf.split_touching(region, K, plane, opaque=pairs)
    assert len(kept) == 2
    assert sorted(round(p.sum() / one) for p in kept) == [1, 2]
    assert tf.split_touching(region, K, plane, opaque=lambda m: True) == [region]


def test_a_frame_fits_each_part_once(monkeypatch):
    """The frame's fits are kept by their masks' pixels: a copy of a mask, or the same parts
    judged again, costs no fit; another mask or occluders do. Three glasses in a row split with
    the frame's fits give the same parts as with their own, and splitting again fits nothing."""
    from sr3d_cli.segment import training_free as tf

    made = []
    fit = tf.fit_revolution
    monkeypatch.setattr(tf, "fit_revolution", lambda *a, **k: made.append(1) or fit(*a, **k))
    ids, K, plane, _ = solids_on_table([(GLASS, 0.1, -0.066, 0.0), (GLASS, 0.1, 0.0, 0.0),
                                        (GLASS, 0.1, 0.066, 0.0)])
    fits = tf._PartFits(K, plane, None)
    one = ids == 1
    first = fits(one)
    assert fits(one.copy()) is first and fits.has(one.copy()) and len(made) == 1
    assert fits(ids == 2) is not first and len(made) == 2
    assert fits(one, ids == 2) is not first and len(made) == 3
    alone = tf.split_touching(ids > 0, K, plane)
    made.clear()
    shared = tf.split_touching(ids > 0, K, plane, fits=fits)
    assert len(shared) == len(alone) == 3
    assert all(np.array_equal(a, b) for a, b in zip(alone, shared))
    spent = len(made)
    assert spent > 0
    assert [p.sum() for p in tf.split_touching(ids > 0, K, plane, fits=fits)] == \
        [p.sum() for p in shared]
    assert len(made) == spent  # every part already fitted


def test_splits_answers_at_the_first_cut_that_holds(monkeypatch):
    """``splits`` says whether ``split_touching`` cuts a region at all: three glasses in a row
    are cut, one goblet is not; it stops judging at the first cut that holds, where
    ``split_touching`` judges every cut and splits the parts again."""
    from sr3d_cli.segment import training_free as tf

    judged = []
    judge = tf._judge_cut
    monkeypatch.setattr(tf, "_judge_cut", lambda *a, **k: judged.append(1) or judge(*a, **k))
    ids, K, plane, _ = solids_on_table([(GLASS, 0.1, -0.066, 0.0), (GLASS, 0.1, 0.0, 0.0),
                                        (GLASS, 0.1, 0.066, 0.0)])
    assert len(tf.split_touching(ids > 0, K, plane)) == 3
    every = len(judged)
    judged.clear()
    assert tf.splits(ids > 0, K, plane)
    assert 1 <= len(judged) < every
    goblet = [[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01], [0.005, 0.07], [0.03, 0.09],
              [0.04, 0.13], [0.036, 0.16], [0, 0.16]]
    ids, K, plane, _ = solids_on_table([(goblet, 0.16, 0.0, 0.0)])
    assert not tf.splits(ids > 0, K, plane)


def test_a_vial_against_a_glass_is_split_by_the_readings_but_a_goblet_or_bottle_is_not():
    """A thin vial touching a glass's side has no neck the watershed could cut at, and the
    outline alone does not split them; the raw readings on the vial (a sensor's sparse front-
    surface returns, here 30% of the pixels) lie off any single solid's surface. A goblet's
    stem and foot and a bottle's neck hang off their bodies the same way, and their readings
    lie on the one solid: they stay whole."""
    from sr3d_cli.segment.training_free import split_touching

    def sparse(depth):
        return np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)

    glass = [[0, 0], [0.03, 0], [0.033, 0.1], [0, 0.1]]
    vial = [[0, 0], [0.011, 0], [0.011, 0.06], [0.009, 0.065], [0.009, 0.075], [0, 0.075]]
    ids, K, plane, depth = solids_on_table([(glass, 0.1, 0.0, 0.0), (vial, 0.075, 0.042, -0.01)])
    region = ids > 0
    assert cv2.connectedComponents(region.astype(np.uint8))[0] == 2  # one region
    assert len(split_touching(region, K, plane)) == 1
    parts = split_touching(region, K, plane, depth=sparse(depth))
    assert len(parts) == 2
    ious = instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), ids)
    assert min(ious.values()) > 0.95
    goblet = [[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01], [0.005, 0.07], [0.03, 0.09],
              [0.04, 0.13], [0.036, 0.16], [0, 0.16]]
    bottle = [[0, 0], [0.035, 0], [0.035, 0.14], [0.012, 0.18], [0.012, 0.22], [0, 0.22]]
    for profile, height in ((goblet, 0.16), (bottle, 0.22)):
        ids, K, plane, depth = solids_on_table([(profile, height, 0.0, 0.0)])
        assert len(split_touching(ids > 0, K, plane, depth=sparse(depth))) == 1


def test_a_cut_its_first_fitted_part_rules_out_is_dropped_without_fitting_the_other(
        monkeypatch):
    """A goblet beside a glass, with readings: the cuts whose first part's fit can hold
    neither by the outline nor by the readings are dropped before the other part is fitted;
    the parts are the same as with every cut's parts fitted, from fewer fits (13 against 16)."""
    from sr3d_cli.segment import training_free
    from sr3d_cli.segment.training_free import split_touching

    glass = [[0, 0], [0.03, 0], [0.033, 0.1], [0, 0.1]]
    goblet = [[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01], [0.005, 0.07], [0.03, 0.09],
              [0.04, 0.13], [0.036, 0.16], [0, 0.16]]
    ids, K, plane, depth = solids_on_table([(goblet, 0.16, 0.0, 0.0), (glass, 0.1, 0.06, 0.0)])
    sparse = np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)
    fits = []
    fit = training_free.fit_revolution

    def counted(*args, **kwargs):
        fits.append(1)
        return fit(*args, **kwargs)

    monkeypatch.setattr(training_free, "fit_revolution", counted)
    pruned = split_touching(ids > 0, K, plane, depth=sparse)
    n_pruned = len(fits)
    fits.clear()
    monkeypatch.setattr(training_free, "_part_may_hold", lambda *args: True)
    every = split_touching(ids > 0, K, plane, depth=sparse)
    assert len(pruned) == len(every) == 2
    assert all(np.array_equal(a, b) for a, b in zip(pruned, every))
    assert n_pruned < len(fits)


@pytest.mark.parametrize("aside, ahead", [(0.05, -0.04),
                                          pytest.param(0.045, -0.05, marks=pytest.mark.slow)])
def test_a_small_vial_against_a_tall_bottle_is_split_by_its_own_readings(aside, ahead, monkeypatch):
    """A 5.5 cm vial in front of a 26 cm bottle's side: one region, of which the vial is under
    4%, so it gets fewer than 30 of the region's 400 sampled readings and the parts cannot gain
    a quarter of the whole's count. Its own readings can still tell: the whole's fit misses
    them and the vial's fit holds them (``OWN_READINGS``). The bottle's neck, a thin part too,
    stays with the bottle (left to neither part, the bottle's IoU would be .885)."""
    from sr3d_cli.segment import training_free
    from sr3d_cli.segment.training_free import split_touching

    bottle = [[0, 0], [0.045, 0], [0.045, 0.16], [0.015, 0.21], [0.015, 0.26], [0, 0.26]]
    vial = [[0, 0], [0.009, 0], [0.009, 0.045], [0.007, 0.05], [0.007, 0.055], [0, 0.055]]
    ids, K, plane, depth = solids_on_table([(bottle, 0.26, 0.0, 0.0), (vial, 0.055, aside, ahead)])
    region = ids > 0
    assert cv2.connectedComponents(region.astype(np.uint8))[0] == 2  # one region
    assert (ids == 2).sum() < 0.04 * region.sum()
    sparse = np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)
    parts = split_touching(region, K, plane, depth=sparse)
    assert len(parts) == 2
    ious = instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), ids)
    assert min(ious.values()) > 0.95
    for rule in ("OWN_READINGS", "OUTLINE_OWN_READINGS"):  # no part can hold more than all
        monkeypatch.setattr(training_free, rule, 1.01)
    assert len(split_touching(region, K, plane, depth=sparse)) == 1


@pytest.mark.slow
def test_a_goblet_and_a_glass_whose_union_draws_a_lying_goblet_are_split_by_readings_above_it(
        tmp_path):
    """Generated frame (seed 4700, frame 0): a 16 cm goblet seen from above and a 9 cm glass
    beside it, their true masks closed into one region. The union draws a lying goblet (the
    glass its foot) 11 cm high at least as well as the two parts' fits draw theirs, and few
    readings lie on any surface, so neither the outline nor the count of readings on the fits
    splits it (IoUs .65 / .35 by those alone); but 30% of the goblet part's readings stand
    above that lying fit's top and none above either part's."""
    from sr3d_cli.segment.training_free import _disk, split_touching

    _, frame, gt = generated_frame(tmp_path, 4700, 0)
    pair = np.where(np.isin(gt, [1, 3]), gt, 0)  # the goblet and the glass
    region = cv2.morphologyEx((pair > 0).astype(np.uint8), cv2.MORPH_CLOSE, _disk(6)) > 0
    assert cv2.connectedComponents(region.astype(np.uint8))[0] == 2  # one region
    plane = support_plane(frame.depth_m, frame.camera.K, PlaneConfig())
    parts = split_touching(region, frame.camera.K, plane, depth=frame.depth_m)
    assert len(parts) == 2
    ious = instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), pair)
    assert min(ious.values()) > 0.95


@pytest.mark.slow
def test_a_goblet_and_a_beaker_are_split_where_their_readings_stand_not_at_the_foot(
        tmp_path, monkeypatch):
    """Generated frame (seed 4500, frame 23): a 15 cm goblet and a 10 cm beaker touching, one
    region no solid draws well (IoU .71). Cutting the goblet's foot from the rest holds by the
    outline (.91); the cut between the two groups of readings on the table gives parts that
    fit (.98, .86) and hold 30% and 32% of their own readings more than the whole's fit: short
    of OWN_READINGS, enough with the outline's gain, and a cut the readings hold wins (the
    foot cut would give IoUs .36 / .52)."""
    from sr3d_cli.segment import training_free

    _, frame, gt = generated_frame(tmp_path, 4500, 23)

    def ious():  # of the goblet and the beaker
        found = _segmented_ious(frame, gt)
        return found[1], found[2]

    assert min(ious()) > 0.9
    monkeypatch.setattr(training_free, "OUTLINE_OWN_READINGS", training_free.OWN_READINGS)
    assert max(ious()) < 0.6


@pytest.mark.slow
@pytest.mark.parametrize("rule, value, worst", [(None, None, 0.8),
                                                ("OUTLINE_OWN_READINGS", 0.5, 0.5),
                                                ("OUTLINE_REFUTED", 1.0, 0.7)])
def test_a_lying_glass_behind_a_standing_one_is_split_and_the_standing_one_kept_whole(
        tmp_path, monkeypatch, rule, value, worst):
    """Generated frame (seed 5100, frame 18): a lying glass behind a standing one, one region
    a standing solid draws (IoU .86). Their footprint cut draws both better (.96, .90; mean
    +.06), so the outline holds it; and the lying glass's fit holds 33% of its readings, the
    whole's none: short of OWN_READINGS, enough with the outline's gain, so the readings hold
    it too (taken as a region the image's border cuts, where only the readings may hold a
    footprint cut, and without that rule: IoUs .58 / .38). The standing glass's top, where
    the lying one crosses, then fits better cut off, but its fit holds none of that part's
    readings and the whole's 12%: the outline does not hold that cut (else: .66)."""
    from sr3d_cli.segment import training_free

    _, frame, gt = generated_frame(tmp_path, 5100, 18)
    if rule:
        monkeypatch.setattr(training_free, rule, value)
    if rule == "OUTLINE_OWN_READINGS":
        monkeypatch.setattr(training_free, "on_image_border", lambda mask: True)
    found = _segmented_ious(frame, gt)
    glasses = found[1], found[3]  # standing, lying
    assert (min(glasses) > worst) if rule is None else (min(glasses) < worst)


@pytest.mark.parametrize("back", ["beaker", "flask"])
def test_one_object_behind_another_is_split_where_their_readings_stand(back):
    """A beaker or a tall flask straight behind a flask, their outlines filled to one convex
    region (no neck for the watershed, as when the fill between them closes): dropped onto the
    table, the readings on each stand around its own axis, and the cut between the two groups
    holds by the readings. The outline alone keeps them as one."""
    from sr3d_cli.segment.training_free import split_touching

    flask = [[0, 0], [0.045, 0], [0.047, 0.01], [0.04, 0.06], [0.012, 0.1], [0.012, 0.13],
             [0, 0.13]]
    behind = {"beaker": ([[0, 0], [0.04, 0], [0.04, 0.09], [0, 0.09]], 0.09),
              "flask": ([[0, 0], [0.04, 0], [0.042, 0.01], [0.036, 0.08], [0.012, 0.14],
                         [0.012, 0.17], [0, 0.17]], 0.17)}[back]
    ids, K, plane, depth = solids_on_table([(flask, 0.13, 0.0, -0.03), (*behind, 0.0, 0.1)])
    hull = np.zeros(ids.shape, np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(cv2.findNonZero((ids > 0).astype(np.uint8))), 1)
    region = hull > 0
    sparse = np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)
    assert len(split_touching(region, K, plane)) == 1
    parts = split_touching(region, K, plane, depth=sparse)
    assert len(parts) == 2
    ious = instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), ids)
    assert min(ious.values()) > 0.8


@pytest.mark.parametrize("behind, aside", [(0.07, 0.0), (0.06, 0.04), (0.08, 0.02),
                                           (0.065, 0.03)])
def test_a_glass_partly_hidden_behind_another_is_split_from_it(behind, aside):
    """A glass ``behind`` m further than another and ``aside`` m to the side: one region, with
    no neck between them. The part behind, fitted alone, stands where the front glass's outline
    crosses it and its readings miss it; fitted with the front part's pixels as hidden, it
    reaches down behind it, lies behind the front part's fit, and the readings on both parts
    hold the cut (fitted without the hidden pixels, 3 of these 4 stay one region)."""
    from sr3d_cli.segment.training_free import split_touching

    ids, K, plane, depth = solids_on_table([(GLASS, 0.1, 0.0, -0.03),
                                            (GLASS, 0.1, aside, behind - 0.03)])
    region = ids > 0
    sparse = np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)
    parts = split_touching(region, K, plane, depth=sparse)
    assert len(parts) == 2
    ious = instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), ids)
    assert min(ious.values()) > 0.89


@pytest.mark.slow
@pytest.mark.parametrize("seed, index, clear", [(6700, 12, False), (6700, 7, True),
                                                (4300, 8, False)])
def test_a_small_object_or_one_no_solid_draws_with_its_neighbour_is_split(
        tmp_path, monkeypatch, seed, index, clear):
    """Generated frames (numpy renderer). 6700/12: a vial a few pixels from a goblet, one
    region; the vial's evidence is one body, the goblet's covers only part of the goblet, so
    the cut between the bodies leaves much of the goblet out (that part's fit draws it at
    about .65), and the vial's part is under a fifth of the region: the vial's body cut from
    all the rest splits them (vial IoU .93; .13 by the cut between bodies). 6700/7: a goblet
    and a lying beaker behind it, one region no solid draws (about .79); cut, both parts fit
    (about .92), but the goblet part's fit holds fewer of its own readings than the whole's:
    the outline's clear gain holds the cut all the same (without it, an object below .7).
    4300/8: the same kinds of frame. Every object of the three is segmented above .89."""
    from sr3d_cli.segment import training_free

    _, frame, gt = generated_frame(tmp_path, seed, index)
    assert min(_segmented_ious(frame, gt).values()) > 0.89
    if clear:
        monkeypatch.setattr(training_free, "CLEAR_GAIN", 100.0)
        assert min(_segmented_ious(frame, gt).values()) < 0.7


def test_a_lying_bottle_split_at_a_dent_is_rejoined_but_touching_objects_are_not():
    """A lying bottle whose evidence has a deep dent on one side (where its glass read the
    table) is cut there by :func:`split_touching`: two short solids draw the dented region
    better than one. Grown over the dent (each pixel to the nearest part), one solid draws
    the union better than the two and :func:`rejoined` joins them (asked for parts that both
    stand, as a standing body's split is, it is not cut). Two touching glasses stay
    apart; so do a beaker and a flask behind it whose union one solid draws well (.97 against
    .97 / .89), because their readings stand around two axes; without readings they join."""
    from scipy import ndimage

    from sr3d_cli.segment.training_free import Candidate, rejoined, split_touching

    bottle = [[0, 0], [0.035, 0], [0.035, 0.14], [0.012, 0.18], [0.012, 0.22], [0, 0.22]]
    ids, K, plane, depth = solids_on_table([(bottle, 0.22, -0.05, 0.0, 20.0)])
    whole = ids > 0
    ys, xs = np.nonzero(whole)
    centre = np.array([xs.mean(), ys.mean()])
    across = np.linalg.svd(np.column_stack([xs, ys]) - centre, full_matrices=False)[2][1]
    half = float(((np.column_stack([xs, ys]) - centre) @ across).max())
    dent = np.zeros(whole.shape, np.uint8)
    cv2.circle(dent, tuple(int(v) for v in centre + half * across), int(0.9 * half), 1, -1)
    parts = split_touching(whole & (dent == 0), K, plane)
    assert len(parts) == 2
    assert len(split_touching(whole & (dent == 0), K, plane, standing=True)) == 1  # parts lie
    labels = np.argmax(np.stack([np.zeros_like(whole)] + parts), 0)
    _, (iy, ix) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    grown = labels[iy, ix] * whole
    (one,) = rejoined([Candidate(grown == k, 1.0) for k in (1, 2)], K, plane, depth, whole)
    assert instance_ious(one.mask.astype(np.int32), ids)[1] > 0.99

    ids, K, plane, depth = solids_on_table([(GLASS, 0.1, -0.032, 0.0), (GLASS, 0.1, 0.034, 0.01)])
    touching = [Candidate(ids == k, 1.0) for k in (1, 2)]
    assert len(rejoined(touching, K, plane, depth, ids > 0)) == 2
    flask = [[0, 0], [0.04, 0], [0.042, 0.01], [0.036, 0.08], [0.012, 0.11], [0.012, 0.13],
             [0, 0.13]]
    beaker = [[0, 0], [0.04, 0], [0.04, 0.09], [0, 0.09]]
    ids, K, plane, depth = solids_on_table([(flask, 0.13, 0.0, -0.03), (beaker, 0.09, 0.0, 0.1)])
    sparse = np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)
    pair = [Candidate(ids == k, 1.0) for k in (1, 2)]
    assert len(rejoined(pair, K, plane, sparse, ids > 0)) == 2
    assert len(rejoined(pair, K, plane, np.zeros_like(depth), ids > 0)) == 1


def test_the_pieces_of_a_lying_bottle_are_joined_but_two_lying_glasses_are_not():
    """A lying bottle (22 cm, 227 px long) whose middle gave no evidence, in two pieces 12 or
    20 px apart along its axis: each piece fits lying (IoU .96-.97) and the convex hull of both
    fits lying at least as well, so :func:`lying_pieces_joined` makes them one (IoU .93 with
    the bottle: the hull covers the table beside its neck). Pieces 40 px apart lie beyond the
    reach (25 px); two lying glasses side by side (6 or 8 cm apart) draw worse as one and stay
    apart."""
    from sr3d_cli.segment.training_free import Candidate, lying_pieces_joined

    bottle = [[0, 0], [0.035, 0], [0.035, 0.14], [0.012, 0.18], [0.012, 0.22], [0, 0.22]]
    ids, K, plane, depth = solids_on_table([(bottle, 0.22, -0.05, 0.0, 20.0)])
    ys, xs = np.nonzero(ids > 0)
    pixels = np.column_stack([xs, ys])
    centre = pixels.mean(0)
    along = (pixels - centre) @ np.linalg.svd(pixels - centre, full_matrices=False)[2][0]
    for gap, joined in ((12, True), (20, True), (40, False)):
        pieces = []
        for keep in (along < -gap / 2, along > gap / 2):
            piece = np.zeros(ids.shape, bool)
            piece[ys[keep], xs[keep]] = True
            pieces.append(Candidate(piece, 1.0))
        out = lying_pieces_joined(pieces, K, plane, depth, ids > 0)
        assert len(out) == (1 if joined else 2)
        if joined:
            assert instance_ious(out[0].mask.astype(np.int32), ids)[1] > 0.9
    for apart in (0.06, 0.08):
        ids, K, plane, depth = solids_on_table([(GLASS, 0.1, -0.05, 0.0, 0.0),
                                                (GLASS, 0.1, -0.05, apart, 0.0)])
        pair = [Candidate(ids == k, 1.0) for k in (1, 2)]
        assert len(lying_pieces_joined(pair, K, plane, depth, ids > 0)) == 2


@pytest.mark.slow
def test_a_standing_bottle_a_lying_one_leans_on_is_split_from_it(tmp_path):
    """Generated frame (seed 7100, frame 5, drawn by GL where there is one; the numpy
    renderer's frame splits either way): a lying bottle whose neck rests on a standing one, one
    region no solid draws (IoU .82). Cut, the parts are drawn at .84 and .99, but the standing
    bottle's readings scatter 20 mm either side of its surface, and a fit of the whole (a lying
    bottle 38 cm long) holds more of them than the part's own fit: .44 against .32. The
    outline's clear gain holds the cut with one part under SPLIT_PART_IOU too (without that:
    IoUs .45 / .53)."""
    _, frame, gt = generated_frame(tmp_path, 7100, 5, renderer="auto")
    assert min(_segmented_ious(frame, gt).values()) > 0.9


def test_a_goblet_whose_foot_meets_a_flask_is_split_between_them():
    """The flask in front hides part of the goblet's foot: the two touch along a wide boundary,
    not at a neck, and the goblet itself has a neck (its stem). The split that fits best keeps
    the goblet whole and gives the flask its own mask."""
    from sr3d_cli.segment.training_free import split_touching

    goblet = [[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01], [0.005, 0.07], [0.03, 0.09],
              [0.04, 0.13], [0.036, 0.16], [0, 0.16]]
    flask = [[0, 0], [0.045, 0], [0.047, 0.01], [0.04, 0.06], [0.012, 0.1], [0.012, 0.13],
             [0, 0.13]]
    ids, K, plane, _ = solids_on_table([(goblet, 0.16, 0.0, 0.0), (flask, 0.13, 0.05, -0.07)])
    assert len(np.unique(ids)) == 3
    region = ids > 0
    assert cv2.connectedComponents(region.astype(np.uint8))[0] == 2  # one region
    parts = split_touching(region, K, plane)
    assert len(parts) == 2
    ious = instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), ids)
    assert min(ious.values()) > 0.95


def _evidence(ids: np.ndarray, holes: int = 60, seed: int = 0) -> np.ndarray:
    """Glass evidence over objects ``ids > 0``: all of them but round holes (2 to 5 px) where
    the sensor read the table through the glass."""
    rng = np.random.default_rng(seed)
    ys, xs = np.nonzero(ids)
    punched = np.zeros(ids.shape, np.uint8)
    for _ in range(holes):
        centre = (int(rng.integers(xs.min(), xs.max() + 1)),
                  int(rng.integers(ys.min(), ys.max() + 1)))
        cv2.circle(punched, centre, int(rng.integers(2, 6)), 1, -1)
    return (ids > 0) & (punched == 0)


@pytest.mark.parametrize("gap,behind", [(0.055, 0.0),
                                        pytest.param(0.055, 0.03, marks=pytest.mark.slow),
                                        pytest.param(0.06, 0.0, marks=pytest.mark.slow)])
def test_two_glasses_a_few_pixels_apart_are_split_along_their_own_evidence(gap, behind):
    """Two straight glasses side by side, a few pixels apart: the candidates' closing fills the
    gap along its whole length, so their region has no neck, and the outline alone keeps one
    (fat) solid. Their glass evidence comes in two bodies: cut along them, each part is its
    own glass. One object whose evidence is broken across it (a band of no evidence over a
    goblet's stem or a bottle's shoulder) stays whole."""
    from scipy import ndimage

    from sr3d_cli.segment.training_free import _disk, split_touching

    wide = [[0, 0], [0.03, 0], [0.03, 0.1], [0, 0.1]]
    narrow = [[0, 0], [0.02, 0], [0.02, 0.09], [0, 0.09]]
    ids, K, plane, _ = solids_on_table([(wide, 0.1, 0.0, 0.0), (narrow, 0.09, -gap, behind)])
    assert cv2.connectedComponents((ids > 0).astype(np.uint8))[0] == 3  # apart in the image
    closed = cv2.morphologyEx((ids > 0).astype(np.uint8), cv2.MORPH_CLOSE, _disk(6))
    region = ndimage.binary_fill_holes(closed)
    assert cv2.connectedComponents(region.astype(np.uint8))[0] == 2  # one region

    def ious(parts):
        return instance_ious(np.argmax(np.stack([np.zeros_like(region)] + parts), 0), ids)

    assert min(ious(split_touching(region, K, plane)).values()) < 0.5
    parts = split_touching(region, K, plane, glass=_evidence(ids))
    assert len(parts) == 2
    assert min(ious(parts).values()) > 0.95
    goblet = [[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01], [0.005, 0.07], [0.03, 0.09],
              [0.04, 0.13], [0.036, 0.16], [0, 0.16]]
    bottle = [[0, 0], [0.035, 0], [0.035, 0.14], [0.012, 0.18], [0.012, 0.22], [0, 0.22]]
    for profile, height in ((goblet, 0.16), (bottle, 0.22)):
        ids, K, plane, _ = solids_on_table([(profile, height, 0.0, 0.0)])
        ys = np.nonzero(ids)[0]
        for share in (0.2, 0.35, 0.5, 0.65):
            glass = _evidence(ids)
            row = int(ys.min() + share * np.ptp(ys))
            glass[row - 3:row + 4] = False
            assert cv2.connectedComponents(glass.astype(np.uint8))[0] >= 3
            assert len(split_touching(ids > 0, K, plane, glass=glass)) == 1


def test_a_glass_beside_a_can_does_not_take_in_the_table_between_them(monkeypatch):
    """A glass (missing readings, some read through it) 9 px from an opaque can whose side
    casts a 4 px band of missing readings (a stereo camera's shadow): the glass's mask keeps
    out the table seen between them. Without the band given to the can, the cut to the glass's
    colour outline still keeps them out (the frame shows stereo shadows); without both, it
    takes them in."""
    from sr3d_cli.segment import training_free

    K, plane, u, v, table = _table_view()
    rng = np.random.default_rng(1)
    depth = table + rng.normal(0, 0.0005, table.shape)
    can = (v >= 55) & (v < 185) & (u >= 190) & (u < 250)
    depth[can] = table[can] - 0.08 + rng.normal(0, 0.0005, can.sum())
    depth[(v >= 55) & (v < 185) & (u >= 186) & (u < 190)] = 0  # the can's shadow band
    glass = ((u - 137) / 40.0) ** 2 + ((v - 120) / 55.0) ** 2 <= 1  # right edge at u = 177
    through = np.zeros_like(glass)
    for cy, cx, r in ((100, 125, 9), (140, 150, 8), (115, 160, 6)):
        through |= (v - cy) ** 2 + (u - cx) ** 2 < r * r  # the table read through the glass
    depth[glass & ~through] = 0
    depth = depth.astype(np.float32)
    rgb = np.full(depth.shape + (3,), 128, np.uint8)
    rgb[glass & ~(((u - 137) / 38.0) ** 2 + ((v - 120) / 53.0) ** 2 <= 1)] = 200  # its rim
    gap = (u > 177) & (u < 186) & (v >= 75) & (v < 165)

    def glass_mask():
        found = training_free.segment_training_free(rgb, depth, K, plane,
                                                    grabcut_iterations=0)
        return next(c.mask for c in found if c.mask[120, 137])

    mask = glass_mask()
    assert (mask & glass).sum() / (mask | glass).sum() > 0.95
    assert (mask & gap).sum() < 0.02 * gap.sum()
    monkeypatch.setattr(training_free, "opaque_edges", lambda g, o: np.zeros_like(g))
    assert (glass_mask() & gap).sum() < 0.02 * gap.sum()
    monkeypatch.setattr(training_free, "within_outline_hull", lambda m, *args: m)
    assert (glass_mask() & gap).sum() > 0.5 * gap.sum()


def test_import_splits_binary_masks_and_keeps_ids(tmp_path):
    binary = np.zeros((20, 30), np.uint8)
    binary[2:6, 2:8] = 255
    binary[10:18, 20:28] = 255
    write_png(tmp_path / "a.png", binary)
    inst = import_masks(tmp_path, "a", (20, 30), "glass", min_area=5)
    assert [o["id"] for o in inst.objects] == [1, 2]
    assert inst.objects[1]["bbox"] == [20, 10, 27, 17]
    ids = np.zeros((20, 30), np.uint8)
    ids[2:6, 2:8] = 7
    ids[10:12, 20:22] = 9  # 4 px: below min_area, dropped with a note
    write_png(tmp_path / "b.png", ids)
    inst = import_masks(tmp_path, "b", (20, 30), "glass", min_area=5)
    assert len(inst.objects) == 1 and inst.notes
    with pytest.raises(InputError, match="no imported mask"):
        import_masks(tmp_path, "c", (20, 30), "glass", min_area=5)
    with pytest.raises(InputError, match="30x20"):
        import_masks(tmp_path, "a", (10, 30), "glass", min_area=5)


@pytest.fixture
def sam_files(tmp_path):
    return (onnx_builders.sam_encoder(tmp_path / "enc.onnx"),
            onnx_builders.sam_box_decoder(tmp_path / "dec.onnx"))


def test_sam_onnx_masks_follow_the_box_prompts(tmp_path, sam_files):
    boxes = tmp_path / "boxes.json"
    boxes.write_text(json.dumps({"f": [[10, 5, 20, 30], [40, 10, 60, 20]]}))
    cfg = SegmentConfig(backend="sam-onnx", sam_encoder=str(sam_files[0]),
                        sam_decoder=str(sam_files[1]), boxes=str(boxes), min_area=5)
    inst = Segmenter(cfg, PlaneConfig())("f", np.zeros((48, 80, 3), np.uint8),
                                         np.ones((48, 80), np.float32), np.eye(3))
    assert [o["bbox"] for o in inst.objects] == [[10, 5, 20, 30], [40, 10, 60, 20]]
    assert inst.objects[0]["score"] == pytest.approx(0.9)


def test_sam_onnx_is_prompted_with_the_kept_instances_boxes_only(tmp_path, sam_files,
                                                                   monkeypatch):
    """Without prompts of the user's, SAM gets the boxes of the training-free instances that
    score at least segment.min_score: a low-scored one is no object to prompt for."""
    from sr3d_cli.segment import TrainingFree

    kept, low = np.zeros((48, 80), bool), np.zeros((48, 80), bool)
    kept[5:30, 10:20] = True
    low[10:20, 40:60] = True
    monkeypatch.setattr(TrainingFree, "__call__", lambda self, fid, rgb, depth, K:
                        ([kept, low], [0.8, 0.2]))
    cfg = SegmentConfig(backend="sam-onnx", sam_encoder=str(sam_files[0]),
                        sam_decoder=str(sam_files[1]), min_area=5, min_score=0.3)
    inst = Segmenter(cfg, PlaneConfig())("f", np.zeros((48, 80, 3), np.uint8),
                                         np.ones((48, 80), np.float32), np.eye(3))
    assert [o["bbox"] for o in inst.objects] == [[10, 5, 19, 29]]


def test_sam_tensor_mismatch_is_one_clear_error(tmp_path, sam_files):
    bad = onnx_builders.sam_box_decoder(tmp_path / "bad.onnx", masks_name="mask_logits")
    cfg = SegmentConfig(backend="sam-onnx", sam_encoder=str(sam_files[0]), sam_decoder=str(bad))
    with pytest.raises(InputError) as err:
        Segmenter(cfg, PlaneConfig())
    text = str(err.value)
    assert "bad.onnx" in text and "expected" in text and "masks" in text and "mask_logits" in text
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    with pytest.raises(InputError, match="not a loadable ONNX"):
        Segmenter(SegmentConfig(backend="sam-onnx", sam_encoder=str(tmp_path / "junk.onnx"),
                                sam_decoder=str(bad)), PlaneConfig())
    with pytest.raises(InputError, match="not found"):
        Segmenter(SegmentConfig(backend="sam-onnx", sam_encoder=str(tmp_path / "none.onnx"),
                                sam_decoder=str(bad)), PlaneConfig())


def test_cli_segment_writes_masks_and_records(synth_set, tmp_path):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["segment", str(synth_set / "scene_0000"), "--out", str(out),
                                      "-q", "--prompt", "glass cup"])
    assert result.exit_code == 0, result.output
    ids = read_mask(out / "masks" / "000000.png")
    meta = json.loads((out / "masks" / "000000.json").read_text())
    assert sorted(np.unique(ids[ids > 0]).tolist()) == [o["id"] for o in meta["objects"]]
    assert all(o["label"] == "glass cup" for o in meta["objects"])


def test_cli_segment_bad_model_is_a_usage_error(native_scene, tmp_path):
    result = CliRunner().invoke(cli, ["segment", str(native_scene), "--backend", "sam-onnx",
                                      "--set", f"segment.sam_encoder={tmp_path}/x.onnx"])
    assert result.exit_code == 2
    assert "x.onnx" in result.output and "not found" in result.output


CAPPED = [[0, 0], [0.03, 0], [0.034, 0.09], [0.03, 0.09], [0.03, 0.13], [0, 0.13]]  # (r, z) m
TALL_BEHIND = [[0, 0], [0.04, 0], [0.04, 0.2], [0, 0.2]]


@pytest.mark.parametrize("behind", [0.1, 0.16])
def test_a_glass_gets_its_opaque_cap_but_not_the_object_behind_it(behind):
    ids, K, plane, depth = solids_on_table([(CAPPED, 0.13, 0.0, 0.0),
                                            (TALL_BEHIND, 0.2, 0.0, behind)])
    obj, other = ids == 1, ids == 2
    assert (cv2.dilate(obj.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)[other].sum() > 150
    glass = obj & (plane.height(depth_to_points(depth, K)) < 0.09)  # the cap reads, the glass not
    raw = np.where((obj & ~glass) | other, depth, 0.0)
    found = with_parts_on_axis(glass, K, plane, raw, on_table_readings(raw, K, plane)[0])

    def iou(a, b):
        return (a & b).sum() / (a | b).sum()

    # measured: the glass part alone 0.401, with its cap 1.000; nothing of the one behind
    assert iou(glass, obj) < 0.45 and iou(found, obj) > 0.99
    assert not (found & other).any()


def _table_view():
    """A 320x240 camera (f = 500 px) over a table tilted towards it, seen at 0.7-1 m:
    (K, plane, u, v, table) with ``u``, ``v`` the pixel grids and ``table`` (H, W) the table's
    depth in metres."""
    from sr3d_cli.geometry.plane import Plane

    K = np.array([[500.0, 0, 160], [0, 500, 120], [0, 0, 1]])
    plane = Plane(np.array([0.0, -0.8, -0.6]), 0.5)  # its normal towards the camera
    v, u = np.mgrid[0:240, 0:320]
    return K, plane, u, v, plane.depth_image(u.shape, K)


def _segmented_masks(K, plane, depth, rgb, baseline: float = 0.05) -> list[np.ndarray]:
    from sr3d_cli.segment import training_free

    return [c.mask for c in training_free.segment_training_free(
        rgb, depth, K, plane, grabcut_iterations=0, stereo_baseline=baseline)]


def _shadowed_scene():
    """A glass (holes, a few patches of the table read through it) on :func:`_table_view`'s
    table and, 3 px to its right, a box standing 0.25 m proud of the table whose left side
    casts a stereo shadow: a strip of holes as wide as its disparity step over the table."""
    K, plane, u, v, table = _table_view()
    depth = table + np.random.default_rng(1).normal(0, 0.0005, table.shape)
    box = (v >= 55) & (v < 185) & (u >= 200) & (u < 260)
    depth[box] = table[box] - 0.25
    step = 500 * 0.05 * (1 / (table - 0.25) - 1 / table)  # px per row, a 5 cm baseline
    shadow = (v >= 55) & (v < 185) & (u < 200) & (u >= 200 - np.floor(step))
    depth[shadow] = 0
    glass = ((u - 137) / 40.0) ** 2 + ((v - 120) / 55.0) ** 2 <= 1  # right edge at u = 177
    through = np.zeros_like(glass)
    for cy, cx, r in ((100, 125, 9), (140, 150, 8), (115, 160, 6)):
        through |= (v - cy) ** 2 + (u - cx) ** 2 < r * r  # the table read through the glass
    depth[glass & ~through] = 0
    rgb = np.full(depth.shape + (3,), 128, np.uint8)
    rgb[glass & ~(((u - 137) / 38.0) ** 2 + ((v - 120) / 53.0) ** 2 <= 1)] = 200  # its rim
    rgb[box] = 40
    return K, plane, depth.astype(np.float32), rgb, glass & ~through, shadow


def test_a_stereo_cameras_shadow_beside_a_box_is_no_glass():
    """The strip of holes a stereo camera leaves along a nearer surface's left side, as wide as
    its disparity step, is its shadow; the glass's own holes run between the table's readings
    and are none. A frame shows such shadows when holes stand at the left of its depth steps
    (a renderer or camera without them reads straight across). Segmented, the glass is the
    one instance; taken as glass (no baseline), the shadow comes out as an object of its own."""
    from sr3d_cli.segment import training_free

    K, plane, depth, rgb, holes, shadow = _shadowed_scene()
    assert shadow.sum() > 1500  # measured: 13-16 px wide over 130 rows
    found = training_free.stereo_shadow(depth, K[0, 0], 0.05)
    assert (found & shadow).sum() >= 0.97 * shadow.sum()
    assert (found & holes).sum() == 0
    assert (found & (depth > 0)).sum() == 0
    table = depth.copy()  # the same box seen by a camera that casts no shadow: the table
    table[shadow] = np.broadcast_to(depth[:, [5]], depth.shape)[shadow]  # read up to its side
    assert training_free.stereo_shadow(table, K[0, 0], 0.05) is None  # no stereo frame

    v, u = np.mgrid[0:240, 0:320]
    glass = ((u - 137) / 40.0) ** 2 + ((v - 120) / 55.0) ** 2 <= 1
    (mask,) = _segmented_masks(K, plane, depth, rgb)
    assert (mask & glass).sum() / (mask | glass).sum() > 0.9
    assert (mask & shadow).sum() == 0
    on_shadow = [m for m in _segmented_masks(K, plane, depth, rgb, baseline=0.0)
                 if (m & shadow).sum() > 0.5 * m.sum()]
    assert len(on_shadow) == 1 and (on_shadow[0] & shadow).sum() > 0.9 * shadow.sum()


def _far_edge_scene(band_columns: tuple[int, int], glass_at: tuple[int, int, int, int]):
    """A table whose far edge (row 50) meets the room, with a ragged band of holes along it
    over ``band_columns`` and a glass (holes, a rim) of centre and half-axes ``glass_at``
    (u, v, a, b) px, on :func:`_table_view`'s table; returns (K, plane, depth, rgb, band,
    glass)."""
    K, plane, u, v, table = _table_view()
    depth = table + np.random.default_rng(1).normal(0, 0.0005, u.shape)
    depth[v < 50] = 2.0  # the room beyond the table's far edge
    rgb = np.full(depth.shape + (3,), 128, np.uint8)
    rgb[v < 50] = (200, 190, 180)
    band = (np.abs(v - 50) < 7 + 3 * np.sin(u / 9.0)) & (u > band_columns[0]) & \
        (u < band_columns[1])
    depth[band] = 0
    cu, cv, a, b = glass_at
    glass = ((u - cu) / a) ** 2 + ((v - cv) / b) ** 2 <= 1
    depth[glass] = 0
    rgb[glass & ~(((u - cu) / (a - 2)) ** 2 + ((v - cv) / (b - 2)) ** 2 <= 1)] = 200  # its rim
    return K, plane, depth.astype(np.float32), rgb, band, glass


def test_a_band_of_dropouts_along_the_tables_far_edge_is_no_object(monkeypatch):
    """Where the table ends against the room, a stereo camera often leaves a ragged band of
    holes along the edge: it is no object, on three counts: it shows no outline over the
    table (the room's colour beyond the edge does not count), over half its pixels lie within
    TABLE_EDGE_BAND px of the table footprint's edge, and so does most of its part over the
    table (TABLE_CLEAR_SHARE); a glass on the table still is. Without the three rules the
    band comes out as an instance; with any one of them, it does not."""
    from sr3d_cli.segment import training_free

    K, plane, depth, rgb, band, glass = _far_edge_scene((40, 140), (200, 150, 30, 45))
    (mask,) = _segmented_masks(K, plane, depth, rgb)
    assert (mask & glass).sum() / (mask | glass).sum() > 0.9

    def on_band():
        return [m for m in _segmented_masks(K, plane, depth, rgb)
                if (m & band).sum() > 0.5 * m.sum()]

    shows = training_free.shows_outline
    monkeypatch.setattr(training_free, "shows_outline",
                        lambda mask, departure, within=None: shows(mask, departure))
    assert on_band() == []
    monkeypatch.setattr(training_free, "TABLE_EDGE_SHARE", 1.0)
    assert on_band() == []
    monkeypatch.setattr(training_free, "TABLE_CLEAR_SHARE", 0.0)
    found = on_band()
    assert len(found) == 1 and (found[0] & band).sum() > 0.5 * band.sum()
    monkeypatch.setattr(training_free, "TABLE_EDGE_SHARE", 0.5)
    assert on_band() == []
    monkeypatch.setattr(training_free, "TABLE_EDGE_SHARE", 1.0)
    monkeypatch.setattr(training_free, "shows_outline", shows)
    assert on_band() == []


def test_a_glass_whose_top_meets_the_band_along_the_far_edge_keeps_only_its_columns(
        monkeypatch):
    """A glass whose top reaches the band of holes along the table's far edge: like beyond
    the table, along its edge the instance keeps only the columns over its feet (the parts of
    the ragged band that dip more than TABLE_EDGE_BAND px into the table count as over the
    table, but not as feet). Measured: IoU with the glass 0.780, 73 of the 1534 band pixels
    beside the glass's columns taken; with the band counted as table 0.659 and 815 (the part
    of the band beyond the footprint is still cut to the feet's columns)."""
    from sr3d_cli.segment import training_free

    scene = _far_edge_scene((30, 200), (110, 100, 25, 46))
    band, glass = scene[4], scene[5]
    u = np.arange(band.shape[1])[None, :]
    beside = band & ((u < 110 - 25 - training_free.BEYOND_MARGIN - 1) |
                     (u > 110 + 25 + training_free.BEYOND_MARGIN + 1))

    def measured():
        (mask,) = _segmented_masks(*scene[:4])
        return (mask & glass).sum() / (mask | glass).sum(), (mask & beside).sum()

    iou, taken = measured()
    assert iou > 0.75 and taken < 0.1 * beside.sum()
    monkeypatch.setattr(training_free, "along_table_edge", lambda f, reach: np.zeros_like(f))
    iou_whole, taken_whole = measured()
    assert iou_whole < iou - 0.07 and taken_whole > 0.5 * beside.sum()


def test_a_few_stray_readings_do_not_take_a_footprint_group_of_their_own():
    """Two readings far off (a glass's readings scatter along the ray) among many on a beaker
    straight behind a flask: the 2-means on the readings' feet still parts the two objects,
    each part drawing its own object (IoU over .8), not a sliver around the strays."""
    from sr3d_cli.segment.training_free import FOOTPRINT_APART, _footprint_cut

    flask = [[0, 0], [0.045, 0], [0.047, 0.01], [0.04, 0.06], [0.012, 0.1], [0.012, 0.13],
             [0, 0.13]]
    beaker = [[0, 0], [0.04, 0], [0.04, 0.09], [0, 0.09]]
    ids, K, plane, depth = solids_on_table([(flask, 0.13, 0.0, -0.03), (beaker, 0.09, 0.0, 0.1)])
    hull = np.zeros(ids.shape, np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(cv2.findNonZero((ids > 0).astype(np.uint8))), 1)
    region = hull > 0
    ys, xs = np.nonzero(region & (ids > 0))
    keep = np.random.default_rng(0).random(len(xs)) < 0.3
    xs, ys = xs[keep], ys[keep]
    raw = depth[ys, xs].copy()
    raw[:2] *= 1.5  # two stray readings, far beyond the surfaces
    a, b = _footprint_cut(region, xs, ys, raw, K, plane, FOOTPRINT_APART, 150)
    ious = instance_ious(np.where(a, 1, np.where(b, 2, 0)), ids)
    assert min(ious.values()) > 0.8
