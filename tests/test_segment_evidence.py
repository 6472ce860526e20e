"""The weight-free segmenter against what it must never take for glass (a sensor's dropouts on a
plain cloth, an opaque box and its stereo shadow, a frame with no glass), the colour cues it
uses, its prompts and confidence, and its measured numbers on the shared real frames."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from sr3d_cli.config import PlaneConfig, SegmentConfig
from sr3d_cli.errors import InputError
from sr3d_cli.evaluate import instance_ious
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.segment import Segmenter, read_prompts, to_full_size, to_working_size
from sr3d_cli.segment import training_free as tf
from tests.scenes import GLASS, K_TABLE, solids_on_table, table

SHAPE = (480, 640)


def _table_frame(colour=(200, 200, 200), seed: int = 0):
    """A plain table filling the view: rgb (H, W, 3) uint8 with a little sensor noise, depth (H, W)
    metres of :func:`tests.scenes.table` with 1 mm noise."""
    rng = np.random.default_rng(seed)
    plane = table()
    depth = plane.depth_image(SHAPE, K_TABLE).astype(np.float64)
    depth = np.where(depth > 0, depth + rng.normal(0, 0.001, SHAPE), 0)
    rgb = np.clip(np.array(colour, float) + rng.normal(0, 3, SHAPE + (3,)), 0, 255)
    return rgb.astype(np.uint8), depth, plane


def _segment(rgb, depth):
    return Segmenter(SegmentConfig(), PlaneConfig())("f", rgb, depth, K_TABLE)


def _dropouts(depth, rng, count: int, radius: tuple[int, int]):
    """Blobs of missing readings scattered over the frame (a stereo camera on a texture-less
    surface)."""
    holes = np.zeros(SHAPE, np.uint8)
    for _ in range(count):
        centre = (int(rng.integers(0, SHAPE[1])), int(rng.integers(0, SHAPE[0])))
        axes = (int(rng.integers(*radius)), int(rng.integers(*radius)))
        cv2.ellipse(holes, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, -1)
    return np.where(holes > 0, 0.0, depth)


def test_no_instance_on_a_white_cloth_riddled_with_dropouts():
    rgb, depth, _ = _table_frame((235, 235, 235))
    depth = _dropouts(depth, np.random.default_rng(1), 80, (3, 16))
    assert (depth == 0).mean() > 0.05
    inst = _segment(rgb, depth)
    assert inst.objects == []


def test_no_instance_on_a_frame_with_no_glass():
    rgb, depth, _ = _table_frame((120, 90, 60))
    assert _segment(rgb, depth).objects == []


def test_no_instance_on_an_opaque_box_with_its_stereo_shadow():
    """A red box 6 cm tall standing on a grey table: dense smooth readings above the table and a
    band of missing readings along its left side (the stereo camera's shadow)."""
    rgb, depth, plane = _table_frame((150, 150, 150))
    ids, _, _, box_depth = solids_on_table([(np.array([[0, 0], [0.04, 0], [0.04, 0.06],
                                                       [0, 0.06]]), 0.06, 0.0, 0.0)])
    box = ids > 0
    depth = np.where(box, box_depth, depth)
    rgb[box] = (200, 30, 30)
    ys, xs = np.nonzero(box)
    # the stereo shadow: baseline x fx x (1/z_box - 1/z_table), about 5 px for a D435
    width = int(round(0.05 * K_TABLE[0, 0] * (1 / box_depth[box].min() - 1 / depth[box].max())))
    assert 3 <= width <= 8
    shadow = np.zeros(SHAPE, bool)
    for y in np.unique(ys):
        left = xs[ys == y].min()
        shadow[y, max(left - width, 0):left] = True
    depth[shadow] = 0
    assert box.sum() > 3000
    assert _segment(rgb, depth).objects == []


def test_the_opaque_veto_is_what_rejects_the_box(monkeypatch):
    """The same box in the colour of the table behind it (a grey box on a grey table) is
    not vetoed by its colour: its readings still mark it as opaque evidence, so it is not an
    instance either; a red box with its readings broken like glass's is vetoed by colour only
    (its veto, and its holes in its own colour on its body: without_opaque_dropouts)."""
    rgb, depth, plane = _table_frame((150, 150, 150))
    ids, _, _, box_depth = solids_on_table([(GLASS, 0.1, 0.0, 0.0)])
    body = ids > 0
    broken = np.where(np.random.default_rng(2).random(SHAPE) < 0.5, 0.0, box_depth)
    depth = np.where(body, broken, depth)
    rgb[body] = (200, 30, 30)
    assert _segment(rgb, depth).objects == []
    monkeypatch.setattr(tf, "OPAQUE_COLOUR", np.inf)
    monkeypatch.setattr(tf, "without_opaque_dropouts", lambda found, *args: found)
    found = _segment(rgb, depth)
    assert len(found.objects) == 1
    assert instance_ious(found.ids, ids)[1] > 0.7


def test_touching_opaque_objects_read_like_glass_are_dropped_before_any_split_is_judged(
        monkeypatch):
    """Two dark cases side by side whose readings break like glass's (half of them missing) make
    one region; its colour replaces the table's, so it is dropped without a revolution fit spent
    on judging its split. Judged (the colour rules off: the veto and the holes in their own
    colour on a body, without_opaque_dropouts), the same region takes split_touching's fits and
    comes out as two instances, one per case."""
    rgb, depth, plane = _table_frame((150, 150, 150))
    ids, _, _, body_depth = solids_on_table([(GLASS, 0.1, -0.032, 0.0),
                                             (GLASS, 0.1, 0.034, 0.01)])
    body = ids > 0
    assert cv2.connectedComponents(body.astype(np.uint8))[0] == 2  # touching: one region
    broken = np.where(np.random.default_rng(3).random(SHAPE) < 0.5, 0.0, body_depth)
    depth = np.where(body, broken, depth)
    rgb[body] = (30, 30, 35)
    fits = []
    real_fit = tf.fit_revolution
    monkeypatch.setattr(tf, "fit_revolution", lambda *a, **k: fits.append(1) or real_fit(*a, **k))
    assert _segment(rgb, depth).objects == []
    assert fits == []
    monkeypatch.setattr(tf, "OPAQUE_COLOUR", np.inf)
    monkeypatch.setattr(tf, "without_opaque_dropouts", lambda found, *args: found)
    found = _segment(rgb, depth)
    assert len(fits) >= 3  # the whole and both parts of at least one cut
    assert len(found.objects) == 2
    assert min(instance_ious(found.ids, ids).values()) > 0.7


def test_a_glass_seen_through_is_found_and_grown_to_its_outline():
    """A glass whose readings fail only in a band (its lower half) while its upper half reads
    the table through it; its outline shows as a bright rim. The depth evidence alone covers
    about half of it; grown to the outline, the instance covers the glass."""
    rgb, depth, plane = _table_frame((110, 80, 60))
    ids, _, _, glass_depth = solids_on_table([(GLASS, 0.1, 0.0, 0.0)])
    body = ids > 0
    ys = np.nonzero(body)[0]
    lower = body & (np.arange(SHAPE[0])[:, None] > np.median(ys))
    depth = np.where(lower, 0.0, depth)  # the upper half reads the table behind it
    rim = body & ~(cv2.erode(body.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)
    rgb[rim] = (240, 240, 240)
    rgb[rim & ~lower] = (240, 240, 240)
    depth[rim] = 0  # a real glass's rim breaks the readings
    found = _segment(rgb, depth)
    assert len(found.objects) == 1
    iou = instance_ious(found.ids, ids)[1]
    evidence_only = (lower | rim).sum() / body.sum()
    assert evidence_only < 0.75 and iou > 0.85


def _smooth_front_glass(rgb, depth, seed: int = 3):
    """A 10 cm glass whose front surface a stereo camera reads smoothly (a real D4xx on clear
    plastic), with 15% of its readings missing in blobs and the table's colour through it, a
    brighter rim at its outline. Returns the depth and the true ids ``(H, W)``."""
    ids, _, _, glass_depth = solids_on_table([(GLASS, 0.1, 0.0, 0.0)])
    body = ids > 0
    rng = np.random.default_rng(seed)
    holes = np.zeros(SHAPE, np.uint8)
    ys, xs = np.nonzero(body)
    for _ in range(12):
        k = int(rng.integers(len(ys)))
        cv2.circle(holes, (int(xs[k]), int(ys[k])), 5, 1, -1)
    depth = np.where(body, np.where(holes > 0, 0.0, glass_depth), depth)
    rim = body & ~(cv2.erode(body.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)
    rgb[rim] = np.clip(rgb[rim].astype(int) + 40, 0, 255)
    return depth, ids


def test_a_glass_read_smoothly_as_a_real_camera_does_is_found_whole(monkeypatch):
    """Smooth front-surface readings are an opaque object's mark by depth alone; the glass
    still shows the table through itself and has holes, so it is a standing body and found
    whole. Without that rule (BODY_SEES_TABLE out of reach) nothing is found."""
    rgb, depth, plane = _table_frame((150, 150, 150))
    depth, ids = _smooth_front_glass(rgb, depth)
    hole_share = ((depth == 0) & (ids > 0)).sum() / (ids > 0).sum()
    assert 0.05 < hole_share < 0.3
    found = _segment(rgb, depth)
    assert len(found.objects) == 1
    assert instance_ious(found.ids, ids)[1] > 0.9
    monkeypatch.setattr(tf, "BODY_SEES_TABLE", 1.01)
    assert _segment(rgb, depth).objects == []


def test_two_touching_glasses_read_smoothly_are_two_instances():
    """Two smoothly read glasses side by side, 2 mm apart: their readings close into one
    standing body that no glass evidence holds (their holes are blobs inside them). The body
    is split where both parts fit standing, one instance each."""
    rgb, depth, plane = _table_frame((150, 150, 150))
    ids, _, _, glass_depth = solids_on_table([(GLASS, 0.1, -0.035, 0.0),
                                              (GLASS, 0.1, 0.035, 0.0)])
    rng = np.random.default_rng(5)
    holes = np.zeros(SHAPE, np.uint8)
    ys, xs = np.nonzero(ids > 0)
    for _ in range(20):
        k = int(rng.integers(len(ys)))
        cv2.circle(holes, (int(xs[k]), int(ys[k])), 5, 1, -1)
    depth = np.where(ids > 0, np.where(holes > 0, 0.0, glass_depth), depth)
    for k in (1, 2):
        own = ids == k
        rim = own & ~(cv2.erode(own.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)
        rgb[rim] = np.clip(rgb[rim].astype(int) + 40, 0, 255)
    found = _segment(rgb, depth)
    ious = instance_ious(found.ids, ids)
    assert len(found.objects) == 2 and min(ious.values()) > 0.85


def test_a_glass_on_a_cloth_that_reads_nothing_is_judged_by_the_cloths_colour(monkeypatch):
    """A smoothly read glass standing on a white cloth the sensor returns nothing from (no
    table reading within the window its colour is judged over): it shows the cloth's colour
    through itself, not the table's, and is found. Judged against the table's colour only
    (NaN where the cloth hides the table), it is not."""
    rgb, depth, plane = _table_frame((150, 150, 150))
    depth, ids = _smooth_front_glass(rgb, depth)
    body = ids > 0
    ys, xs = np.nonzero(body)
    cloth = np.zeros(SHAPE, bool)
    cloth[max(ys.min() - 80, 0):ys.max() + 60, max(xs.min() - 120, 0):xs.max() + 120] = True
    depth = np.where(cloth & ~body, 0.0, depth)
    rgb[cloth] = (255 - (255 - rgb[cloth].astype(float)) * 0.35).astype(np.uint8)
    found = _segment(rgb, depth)
    assert len(found.objects) == 1 and instance_ious(found.ids, ids)[1] > 0.95
    plain = tf.table_colour_departure
    monkeypatch.setattr(tf, "table_colour_departure",
                        lambda *a, surroundings=False, **k: plain(*a, **k))
    assert _segment(rgb, depth).objects == []


def test_a_bodys_mask_leaves_the_tables_bumps_beside_it(monkeypatch):
    """A stereo camera reads bumps a few millimetres high on a plain table; three 8 mm bumps
    touching a smoothly read glass join its body through the closing, but stand beside its
    base, not over it, so its mask leaves them (without that rule a third of them is taken:
    IoU 0.939 against 0.982)."""
    rgb, depth, plane = _table_frame((150, 150, 150))
    depth, ids = _smooth_front_glass(rgb, depth)
    body = ids > 0
    ys, xs = np.nonzero(body)
    bumps = np.zeros(SHAPE, np.uint8)
    for cx, cy in ((xs.min() - 6, ys.max() - 15), (xs.max() + 6, ys.max() - 30),
                   (xs.max() + 6, (ys.min() + ys.max()) // 2)):
        cv2.circle(bumps, (int(cx), int(cy)), 10, 1, -1)
    bumps = (bumps > 0) & ~body
    raised = Plane(plane.normal, plane.offset - 0.008).depth_image(SHAPE, K_TABLE)
    noise = np.random.default_rng(1).normal(0, 0.001, SHAPE)
    depth = np.where(bumps, raised + noise, depth)
    found = _segment(rgb, depth)
    assert len(found.objects) == 1
    assert instance_ious(found.ids, ids)[1] > 0.97 and not (found.ids > 0)[bumps].any()
    monkeypatch.setattr(tf, "over_feet", lambda readings, seeds, *args: readings)
    loose = _segment(rgb, depth)
    assert instance_ious(loose.ids, ids)[1] < 0.95 and (loose.ids > 0)[bumps].mean() > 0.25


def test_a_bodys_low_readings_are_kept_under_its_high_ones_not_beside_them():
    """A standing body's readings: high ones (seeds) over rows 10-29 of columns 20-29, low
    ones under them (its foot) and in a ramp beside them (a stereo camera's smoothing across
    its side), and a second group of low readings with no seed. Only the foot is kept."""
    readings = np.zeros((50, 60), bool)
    seeds = np.zeros_like(readings)
    seeds[10:30, 20:30] = True
    readings[10:40, 20:30] = True  # the seeds and the foot under them
    readings[20:40, 30:36] = True  # the ramp beside them
    readings[10:40, 45:50] = True  # another group, no seed
    kept = tf.in_seed_columns(readings, seeds)
    assert kept[10:40, 20:30].all()
    assert not kept[:, 30:].any() and kept.sum() == 300


def test_an_outline_is_read_where_it_is_allowed_to_show():
    """A patch of dropouts on a plain table just below the table's far edge, where the colour
    departs along the whole edge: counted in full, its band shows that edge as an outline;
    read over the table only it shows none. A glass's own rim over the table still shows."""
    departure = np.zeros((60, 80), np.float32)
    departure[:15] = 10.0  # the room beyond the table's far edge
    over_table = np.zeros((60, 80), bool)
    over_table[15:] = True
    patch = np.zeros((60, 80), bool)
    patch[16:30, 20:40] = True  # its band reaches 3 px up, past the edge
    assert tf.shows_outline(patch, departure)
    assert not tf.shows_outline(patch, departure, over_table)
    rimmed = departure.copy()
    rimmed[30:33, 20:40] = 4.0  # a bright rim along the patch's lower side
    assert tf.shows_outline(patch, rimmed, over_table)


def test_the_image_border_is_no_outline():
    """A patch of dropouts on a plain table at the image's bottom edge, whose colour departs
    only in the rows along the border (smoothing against the edge): no outline. The same
    patch with a rim along its top, away from the border, shows one."""
    departure = np.zeros((60, 80), np.float32)
    departure[-3:] = 10.0
    patch = np.zeros((60, 80), bool)
    patch[45:, 20:40] = True
    band = (cv2.dilate(patch.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0) & \
        ~(cv2.erode(patch.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0)
    assert (departure[band] > tf.FAINT_COLOUR).mean() >= tf.FAINT_SHARE  # counted in full
    assert not tf.shows_outline(patch, departure)
    rimmed = departure.copy()
    rimmed[43:46, 20:40] = 4.0
    assert tf.shows_outline(patch, rimmed)


def test_an_outline_is_followed_round_a_rim_but_not_into_other_objects():
    """An open vessel seen from above: its instance is the front arc of the rim (its holes),
    the rim's ellipse (the colour outline) reaches 65 px above it, the floor shows the table.
    One step of growth reaches only the ellipse's lower part; followed step by step, the rim
    closes and the mouth fills. Two objects read smoothly, their faces departing from the
    table's colour, are never taken: a box whose edge a thin line of outline joins to the
    rim (the line and the edge are thin), and one standing behind the rim, touching it along
    30 px, which is taken only when its face is not known as read."""
    shape = (160, 240)
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    inside = ((xx - 100) / 60.0) ** 2 + ((yy - 80) / 40.0) ** 2
    rim = (inside <= 1.0) & (inside >= 0.8)
    arc = rim & (yy >= 105)  # the front of the rim, where the sensor failed
    box = (xx >= 200) & (xx < 236) & (yy >= 30) & (yy < 130)
    edge = box & ~((xx >= 202) & (xx < 234) & (yy >= 32) & (yy < 128))
    line = (yy >= 79) & (yy < 81) & (xx >= 158) & (xx < 202)
    behind = (xx >= 80) & (xx < 120) & (yy >= 4) & (yy < 41)
    outline = rim | box | line | behind
    mouth = inside < 0.8
    once = tf.grow_to_outline(arc, outline, close_radius=5)
    assert not once[mouth].any()
    followed = tf.grow_to_outline(arc, outline, close_radius=5,
                                  surfaces=(box & ~edge) | behind)
    assert followed[mouth].all() and followed[rim].mean() > 0.95
    assert not followed[box].any() and not followed[behind].any()
    assert followed[line].mean() < 0.2
    unread = tf.grow_to_outline(arc, outline, close_radius=5, surfaces=np.zeros(shape, bool))
    assert unread[behind].all() and not unread[box].any()


def test_an_instance_is_cut_to_its_outlines_hull_keeping_its_own_colour_and_readings():
    """A glass (ellipse) whose rim shows in colour, with a plain band of holes joined to its
    side (a stereo camera's shadow the step model misses): the cut keeps the glass and what is
    clearly its (a label's colour, readings 3 cm up) and drops the band. With the outline seen
    on less than half of the instance the cut would take too much: it is left whole."""
    v, u = np.mgrid[0:200, 0:200]
    glass = ((u - 100) / 30.0) ** 2 + ((v - 100) / 60.0) ** 2 <= 1
    rim = glass & ~(cv2.erode(glass.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)
    band = (u >= 40) & (u < 72) & (v >= 60) & (v < 140) & ~glass
    departure = np.where(rim, 6.0, 0.5)
    height = np.zeros(glass.shape)
    cut = tf.within_outline_hull(glass | band, rim, tf.own_pixels(departure, height))
    assert (cut >= glass).all()  # measured: 20 of the 2528 band pixels kept, along the
    assert (cut & band).sum() <= 0.01 * band.sum()  # hull's straight edges
    label = band & (v < 80)
    cap = band & (v >= 120)
    departure[label], height[cap] = 4.0, 0.03
    cut = tf.within_outline_hull(glass | band, rim, tf.own_pixels(departure, height))
    assert (cut >= glass | label | cap).all()
    assert (cut & band & ~label & ~cap).sum() <= 0.01 * band.sum()
    arc = rim & (u > 120)  # the rim seen on its right edge only
    part = tf.within_outline_hull(glass | band, arc,
                                  tf.own_pixels(np.where(arc, 6.0, 0.5), np.zeros_like(height)))
    assert (part == (glass | band)).all()


def test_beyond_the_table_a_glass_stands_out_from_the_rooms_colour():
    """A glass at the table's far edge rises against a white wall, its stereo shadow a band of
    holes on the wall beside its top. Against the table's colour the wall departs, the
    shadow too, and is kept as the glass's own; against the room's, only the glass's rim
    does, and the shadow is cut with the outline's hull."""
    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:100, 0:100]
    footprint = v >= 40  # the table below row 40, the wall above
    rgb = np.where(footprint[..., None], [60, 120, 160], [225, 225, 220]).astype(float)
    rgb = np.clip(rgb + rng.normal(0, 2, rgb.shape), 0, 255).astype(np.uint8)
    depth = np.where(footprint, 1.0, 2.0)
    glass = (u >= 40) & (u < 60) & (v >= 25) & (v < 85)
    rim = glass & ~(cv2.erode(glass.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)
    rgb[rim] = (90, 90, 90)
    # on the wall within the table colour's window (15 px), clear of the edge's blurred row
    # and of the outline points along it (3 px)
    shadow = (u >= 22) & (u < 40) & (v >= 28) & (v < 35)
    depth[glass | shadow] = 0.0
    on_table = footprint & (depth > 0)
    departure = tf.table_colour_departure(rgb, on_table)
    height = np.where(~footprint & (depth > 0), 0.3, 0.0)  # the wall stands over the table
    plain = tf.within_outline_hull(glass | shadow, tf.outline_evidence(departure, on_table),
                                   tf.own_pixels(departure, height))
    assert (plain & shadow).sum() == shadow.sum()
    seen = tf.beside_room(rgb, depth, footprint, departure)
    assert (seen[footprint] == departure[footprint]).all()
    assert np.nanmin(departure[shadow]) > tf.OUTLINE_COLOUR
    clear = shadow & (u < 38)  # the rim's dark colour blurs into the next two columns
    assert np.nanmax(seen[clear]) < tf.OUTLINE_COLOUR < np.nanmin(seen[rim & ~footprint])
    cut = tf.within_outline_hull(glass | shadow, tf.outline_evidence(seen, on_table),
                                 tf.own_pixels(seen, height))
    assert not (cut & clear).any() and (cut & shadow).sum() <= 0.15 * shadow.sum()
    assert (cut & glass).sum() >= 0.97 * glass.sum()
    # a room that reads nothing (out of range) gives no colour to compare with: the table's
    unread = np.where(footprint, depth, 0.0)
    assert np.array_equal(tf.beside_room(rgb, unread, footprint, departure), departure,
                          equal_nan=True)


def test_an_instance_beyond_the_table_keeps_only_the_columns_above_its_base():
    """A glass standing at the table's far edge rises above it in the image; the room's missing
    readings joined to it beyond the edge, to one side, are not the glass."""
    footprint = np.zeros((100, 100), bool)
    footprint[40:] = True  # the table fills the image below row 40
    glass = np.zeros_like(footprint)
    glass[20:80, 30:50] = True  # standing at the far edge, rising 20 rows above it
    room = np.zeros_like(footprint)
    room[5:40, 30:90] = True  # beyond the edge, joined to the glass's top
    kept = tf.within_table_columns(glass | room, footprint)
    assert (kept == (glass | (room & (np.arange(100) < 50 + tf.BEYOND_MARGIN)[None, :]
                               & (np.arange(100) >= 30 - tf.BEYOND_MARGIN)[None, :]))).all()
    assert (tf.within_table_columns(glass, footprint) == glass).all()


def test_an_instance_rises_beyond_the_table_only_above_its_feet():
    """The holes on the table beside a glass at the far edge join it and reach the edge; the
    room's missing readings above them join both. With ``feet``, only the columns where the
    part over the table reaches down to the glass's base keep what lies beyond the table."""
    footprint = np.zeros((100, 100), bool)
    footprint[40:] = True
    glass = np.zeros_like(footprint)
    glass[20:80, 30:50] = True  # its base at row 79, rising 20 rows above the edge
    holes = np.zeros_like(footprint)
    holes[40:55, 50:80] = True  # on the table beside it, up to the edge
    room = np.zeros_like(footprint)
    room[5:40, 50:90] = True  # beyond the edge, above the holes
    mask = glass | holes | room
    columns = np.arange(100)[None, :]
    spanned = tf.within_table_columns(mask, footprint)  # the holes' columns keep the room
    assert (spanned == (glass | holes | (room & (columns < 80 + tf.BEYOND_MARGIN)))).all()
    kept = tf.within_table_columns(mask, footprint, feet=tf.FEET_SHARE)
    assert (kept == (glass | holes | (room & (columns < 50 + tf.BEYOND_MARGIN)))).all()
    assert int(kept.sum()) == 20 * 60 + 15 * 30 + 35 * tf.BEYOND_MARGIN
    assert (tf.within_table_columns(glass, footprint, feet=tf.FEET_SHARE) == glass).all()


def test_colour_departure_is_low_through_glass_and_high_on_an_opaque_colour():
    rgb, depth, plane = _table_frame((110, 80, 60))
    on_table = tf.on_table_readings(depth, K_TABLE, plane)[1]
    rgb[200:240, 300:340] = (30, 160, 30)
    departure = tf.table_colour_departure(rgb, on_table)
    assert np.nanmedian(departure[on_table]) < 1.0
    assert np.nanmedian(departure[205:235, 305:335]) > 2 * tf.OPAQUE_COLOUR
    assert not np.isnan(departure).any()  # the table is everywhere: every pixel has a colour


def test_working_size_halves_a_1280_frame_and_keeps_holes():
    rgb = np.zeros((720, 1280, 3), np.uint8)
    depth = np.ones((720, 1280))
    depth[100:104, 200:204] = 0
    K = np.array([[900.0, 0, 639.5], [0, 900, 359.5], [0, 0, 1]])
    small_rgb, small_depth, small_K = to_working_size(rgb, depth, K)
    assert small_rgb.shape == (360, 640, 3) and small_depth.shape == (360, 640)
    assert (small_depth == 0).sum() == 4  # a 4x4 hole keeps its 2x2 reading
    assert small_K[0, 0] == pytest.approx(450) and small_K[0, 2] == pytest.approx(319.5)
    mask = np.zeros((360, 640), bool)
    mask[50:70, 100:140] = True
    big = to_full_size(mask, (720, 1280))
    assert abs(int(big.sum()) - 4 * 800) <= 2 * (40 + 80)
    same = to_working_size(rgb[:480, :848], depth[:480, :848], K)
    assert same[1].shape == (480, 848)


def test_prompts_files(tmp_path):
    file = tmp_path / "p.json"
    file.write_text(json.dumps({"a": [[1, 2], [3, 4]], "b": []}))
    assert read_prompts(file, "a", "points") == [[1, 2], [3, 4]]
    assert read_prompts(file, "b", "points") == []
    assert read_prompts(file, "c", "points") == []
    folder = tmp_path / "boxes"
    folder.mkdir()
    (folder / "a.json").write_text(json.dumps({"boxes": [[0, 0, 5, 5]]}))
    assert read_prompts(folder, "a", "boxes") == [[0, 0, 5, 5]]
    assert read_prompts(folder, "missing", "boxes") == []
    file.write_text(json.dumps({"a": [[1, 2, 3]]}))
    with pytest.raises(InputError, match=r"p\.json.*\[x, y\]"):
        read_prompts(file, "a", "points")
    file.write_text("{not json")
    with pytest.raises(InputError, match="cannot read points JSON"):
        read_prompts(file, "a", "points")


class _FakeSam:
    """A SAM stand-in: a point prompt gives a 10-px disc around it, scored by its x (for the
    min_score check); a box prompt gives the box."""

    def embed(self, rgb):
        return None, 1.0

    def segment_point(self, embedding, scale, point, shape):
        mask = np.zeros(shape, np.uint8)
        cv2.circle(mask, (int(point[0]), int(point[1])), 10, 1, -1)
        return mask > 0, float(point[0]) / 100

    def segment_box(self, embedding, scale, box, shape):
        mask = np.zeros(shape, bool)
        x0, y0, x1, y1 = (int(v) for v in box)
        mask[y0:y1 + 1, x0:x1 + 1] = True
        return mask, 0.9


def test_point_prompts_give_one_instance_each_and_min_score_drops_the_weak(tmp_path,
                                                                          monkeypatch):
    from sr3d_cli.segment import sam

    points = tmp_path / "points.json"
    points.write_text(json.dumps({"f": [[80, 30], [50, 60], [20, 20]]}))
    cfg = SegmentConfig(backend="sam-onnx", points=str(points), min_area=5, min_score=0.4)
    monkeypatch.setattr(sam, "SamOnnx", lambda encoder, decoder: _FakeSam())
    segmenter = Segmenter(cfg, PlaneConfig())
    rgb = np.zeros((100, 120, 3), np.uint8)
    inst = segmenter("f", rgb, np.ones((100, 120)), K_TABLE)
    assert [o["score"] for o in inst.objects] == [0.8, 0.5]
    assert inst.ids[30, 80] == 1 and inst.ids[60, 50] == 2 and inst.ids[20, 20] == 0
    assert any("segment.min_score" in n for n in inst.notes)


def test_instances_preview_labels_each_instance_with_its_score():
    from sr3d_cli.io.preview import INSTANCE_COLOURS, instances_preview

    rgb = np.full((120, 160, 3), 100, np.uint8)
    ids = np.zeros((120, 160), np.int32)
    ids[40:80, 30:70] = 1
    ids[40:80, 100:140] = 2
    objects = [{"id": 1, "score": 0.91, "bbox": [30, 40, 69, 79]},
               {"id": 2, "score": 0.42, "bbox": [100, 40, 139, 79]}]
    picture = instances_preview(rgb, ids, objects)
    assert picture.shape[0] > 120 and picture.shape[1] == 160  # a legend strip below
    for k, colour in enumerate(INSTANCE_COLOURS[:2]):
        inside = picture[45:75, 35 + 70 * k:65 + 70 * k].reshape(-1, 3).astype(int)
        tint = np.abs(inside - (0.6 * 100 + 0.4 * np.array(colour))).sum(1)
        assert (tint <= 3).mean() > 0.5
    assert (picture[:120][ids == 0] == 100).mean() > 0.8


def test_a_body_that_hides_the_table_joins_only_the_instance_holding_half_of_it():
    """with_bodies: a body read smoothly that does not show the table (a thick plastic's lower
    part) joins the instance that holds half of it or more; one held by less, or by none, is
    left out; a body that shows the table is a new instance even alone."""
    shape = (120, 160)
    top = np.zeros(shape, bool)
    top[20:60, 40:80] = True  # an instance found by its holes: a glass's upper part
    lower = np.zeros(shape, bool)
    lower[30:80, 45:75] = True  # its lower part's readings: 30 of 50 rows inside the instance
    beside = np.zeros(shape, bool)
    beside[30:70, 75:135] = True  # an opaque object: 5 of its 60 columns inside
    alone = np.zeros(shape, bool)
    alone[95:115, 100:150] = True

    def masks(bodies):
        found = tf.with_bodies([tf.Candidate(top, 0.9)], bodies, np.ones(shape, bool),
                               lambda mask, body: True, lambda mask: [mask])
        return [c.mask for c in found]

    low = np.zeros(shape, bool)
    low[40:90, 45:75] = True  # 20 of 50 rows inside: held by less than half
    assert np.array_equal(masks([(lower, False)])[0], top | lower)
    assert len(masks([(lower, False)])) == 1
    assert [m.sum() for m in masks([(low, False)])] == [top.sum()]
    assert np.array_equal(masks([(low, True)])[0], top | low)
    assert [m.sum() for m in masks([(beside, False), (alone, False)])] == [top.sum()]
    found = masks([(alone, True)])
    assert len(found) == 2 and np.array_equal(found[1], alone)


def test_a_body_whose_join_splits_is_kept_beside_the_instance_where_it_is_a_body_itself():
    """with_bodies: where joining a body that shows the table to the instance it overlaps
    splits (two objects touching), the body's part beyond the instance is a new instance if
    that part passes the body tests itself; else (a flat, fully read notebook that joined a
    glass's body) it adds nothing, and without tests neither."""
    shape = (120, 160)
    top = np.zeros(shape, bool)
    top[20:50, 40:80] = True  # an instance found by the holes on a container's lid
    body = np.zeros(shape, bool)
    body[40:100, 45:75] = True  # the container read smoothly: 10 of its 60 rows inside
    rest = body & ~top

    def masks(tests):
        found = tf.with_bodies([tf.Candidate(top, 0.9)], [(body, True)], np.ones(shape, bool),
                               lambda mask, body: False, lambda mask: [mask], tests)
        return [c.mask for c in found]

    asked = []
    found = masks(lambda mask: asked.append(mask) or True)
    assert len(found) == 2 and np.array_equal(found[0], top) and np.array_equal(found[1], rest)
    assert len(asked) == 1 and np.array_equal(asked[0], rest)
    assert [m.sum() for m in masks(lambda mask: None)] == [top.sum()]
    assert [m.sum() for m in masks(lambda mask: False)] == [top.sum()]
    assert [m.sum() for m in masks(None)] == [top.sum()]


def test_the_holes_of_an_opaque_body_in_its_own_colour_are_no_instance():
    """without_opaque_dropouts: a candidate lying in a body that does not show the table and
    that it holds less than half of (an opaque object) is dropped where its colour departs from
    the table's (a dark case that drops out where it is darkest); kept where it shows the
    table's colour, holds half of the body (a glass's lower part read smoothly), lies in it by
    less than half, or the body shows the table."""
    shape = (120, 160)
    body = np.zeros(shape, bool)
    body[40:90, 40:100] = True  # 3000 px read smoothly above the table
    holes = np.zeros(shape, bool)
    holes[50:70, 50:80] = True  # 600 px inside it: a fifth of it
    dark = np.full(shape, 5.0)
    dark[holes] = 3.0  # the holes show the case's colour, under the opaque level

    def kept(candidate, bodies, departure):
        return [c.mask.sum() for c in tf.without_opaque_dropouts(
            [tf.Candidate(candidate, 0.9)], bodies, departure)]

    assert kept(holes, [(body, False)], dark) == []
    assert kept(holes, [(body, True)], dark) == [600]
    assert kept(holes, [(body, False)], np.where(holes, 1.0, dark)) == [600]
    small = np.zeros(shape, bool)
    small[55:80, 50:80] = True  # 750 px, 600 of them held by the candidate
    assert kept(holes, [(small, False)], dark) == [600]
    beside = np.zeros(shape, bool)
    beside[75:115, 50:80] = True  # 1200 px, 450 of them in the body
    assert kept(beside, [(body, False)], dark) == [1200]


@pytest.mark.slow
def test_measured_on_the_shared_real_frames(realdata):
    """The default segmenter on the 11 shared real frames (no masks given). Measured: best IoU
    per true object mean 0.770, 16 of 16 objects at IoU >= 0.5 (two at 0.53 and 0.56), no
    false instance (>= 300 px, IoU < 0.2 with every object); with the holes of an opaque body
    kept (``without_opaque_dropouts``: ClearGrasp 123's earphone case) 0.09 per frame; with a
    region's part beyond the table kept while its cuts are judged (ClearGrasp 123's third
    holder lost with the wall's holes and the table they close in: 0.53 -> 0.22) 0.731 and
    15; without the pieces of a lying object joined
    (``lying_pieces_joined``: ClearGrasp 080's lying bottle in three pieces, 0.88 -> 0.25 and
    two false instances) 0.692, 14 and 0.27; without the bodies that hide the table joined to
    the instance holding half of them too (``BODY_JOINED`` out of reach: ClearGrasp 123's
    holders 0.84 and 0.85 drop to 0.66 and 0.59) 0.665, 14 and 0.27. The 8 views of the
    capped container: mean IoU 0.815; with a body's low readings kept beside its high ones'
    columns too (``in_seed_columns``: the ramp a D4xx's smoothing leaves beside the
    container's sides joins its body) 0.786, and 0.755 over all."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    segmenter = Segmenter(SegmentConfig(), PlaneConfig())
    best, false, frames, container = [], 0, 0, []
    for source in discover_scenes(realdata.parent, IOConfig(), None):
        for fid in source.frame_ids():
            frame = source.load_frame(fid)
            truth = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
            inst = segmenter(fid, frame.rgb, frame.depth_m, frame.camera.K)
            ious = instance_ious(inst.ids, truth)
            best += list(ious.values())
            if "tracebot" in source.name:
                container += list(ious.values())
            false += sum(1 for k, iou in instance_ious(truth, inst.ids).items()
                         if iou < 0.2 and (inst.ids == k).sum() >= 300)
            frames += 1
    assert frames == 11 and len(best) == 16
    assert false == 0
    assert np.mean(best) >= 0.76 and sum(v >= 0.5 for v in best) >= 15  # one at 0.53
    assert len(container) == 8 and np.mean(container) >= 0.8


@pytest.mark.slow
def test_the_container_views_moved_by_a_pixel(realdata):
    """The 8 Tracebot views moved one pixel right (the first column repeated, K's principal
    point moved with them): the segmenter's 2x2 reduction then keeps the other reading of
    each block's row. Measured: the container found in 8 of 8 views, mean best IoU 0.785; with
    a body left out where its join to the instance it overlaps splits, 7 of 8 and 0.66 (view
    000079: the holes on the lid are an instance, the container read smoothly below it is
    another object by the cuts, and was dropped: 0.10); with the regions scored below
    segment.min_score also kept until the end, 6 of 8 and 0.58 (view 000001: the table's
    scattered holes close into a network that encloses a wide patch of the table, score 0.22,
    and take in the container's readings)."""
    best = _moved_scores(realdata.parent / "tracebot-dev", 0, 1)
    assert len(best) == 8
    assert min(best) >= 0.5 and np.mean(best) >= 0.73


@pytest.mark.slow
def test_the_cleargrasp_frames_moved_down_by_a_pixel(realdata):
    """ClearGrasp's D435 frames 080 and 123 moved one pixel down (the first row repeated, K's
    principal point moved with them). Measured: 6 of their 7 objects found, mean best IoU
    0.61; with the instances keeping what lies within 8 px of the table's edge beside their
    feet instead of 32 px, 2 of 7 and 0.41: 080's standing bottle keeps a band of dropouts
    along the table's edge, and a piece of the lying bottle in front of it joins it as one
    lying object (0.31 and 0.25); 123's second holder keeps a patch of the table's right
    edge, which joins it the same way (0.22)."""
    best = []
    for folder in ("cleargrasp-more", "cleargrasp-real"):
        best += _moved_scores(realdata.parent / folder, 1, 0, only="d435")
    assert len(best) == 7
    assert sum(v >= 0.5 for v in best) >= 6 and np.mean(best) >= 0.58


@pytest.mark.slow
def test_the_cleargrasp_holders_moved_right_by_a_pixel(realdata):
    """ClearGrasp's D435 frame 123 moved one pixel right. Measured: the first two of its three
    holders found (0.85 and 0.84; the third, half its region on the table, is lost: 0.0); with
    the instances grown to the outline beyond the table's footprint too, the second holder's
    instance takes the room's colour edge above it and its body no longer joins it (0.30)."""
    best = _moved_scores(realdata, 0, 1, only="d435")
    assert len(best) == 3
    assert sum(v >= 0.5 for v in best) >= 2 and np.mean(best) >= 0.55


@pytest.mark.slow
def test_a_container_moved_down_and_right_keeps_off_the_table_up_to_its_far_edge(realdata):
    """Tracebot view 027 moved one pixel down and right: the container's holes join the band
    of dropouts along the table's far edge. Measured: best IoU 0.78; with that band closing
    in the table between them (``_enclosed`` without the far edge), 0.64: the instance holds
    that table until it is cut to the hull of its colour outline; with the table's own edge
    (where its colour gives way to the room's, TABLE_LINE) counted as an outline, the hull
    reaches the far edge and keeps some of that table: 0.61 (0.46 with the band closing it
    in too)."""
    best = _moved_scores(realdata.parent / "tracebot-dev", 1, 1, only="000027")
    assert len(best) == 1 and best[0] >= 0.7


@pytest.mark.slow
@pytest.mark.parametrize("view, down, right, rule, off",
                         [("000027", 1, 0, "TABLE_CLEAR_SHARE", 0.0),
                          ("000053", 1, 1, "BODY_CUT", 1.01)])
def test_a_moved_view_holds_one_instance_of_its_container(realdata, monkeypatch, view, down,
                                                          right, rule, off):
    """Tracebot views moved by a pixel, each one instance of its container (IoU over 0.7),
    and a second, on no object, with one rule off (the container's then over 0.65).

    027 moved one pixel down: the room's dropouts beyond the table's far edge join the band of
    holes along it, and their part over the table lies mostly in that band (0.59 of it clear
    of the TABLE_EDGE_BAND px along the footprint's edge; the container's 0.88-1.0). Measured:
    IoU 0.78; with no share of the part over the table required to lie clear of the band
    (TABLE_CLEAR_SHARE), a second instance there.

    053 moved one pixel down and right: the holes on the container's lid are a candidate, its
    body below is read smoothly (a standing body), and the two fit better as a lid and a body
    (0.90 and 0.89 against 0.85). That cut runs through the body's readings, one surface
    across it: the body joins the lid. Measured: IoU 0.80; with a cut through a body taken as
    two objects (BODY_CUT out of reach), the body is a second instance (0.68) and the lid's
    holes, parted from it, a false one."""
    from sr3d_cli.segment import training_free

    tracebot = realdata.parent / "tracebot-dev"
    ious = _instances_best(tracebot, down, right, view)
    assert len(ious) == 1 and ious[0] >= 0.72
    monkeypatch.setattr(training_free, rule, off)
    ious = _instances_best(tracebot, down, right, view)
    assert len(ious) == 2 and max(ious) >= 0.65 and min(ious) < 0.2


def test_a_cut_runs_through_one_surface_where_the_readings_go_on_across_it():
    """A body of readings cut across its middle: one surface where the depth goes on across
    the cut, two where it steps by 3 cm there, and no cut through it where one part holds
    under BODY_CUT of it, nor where the readings meet across the cut over a few columns only
    (two objects touching, at one depth where they touch)."""
    from sr3d_cli.segment.training_free import BODY_CUT, _one_surface

    body = np.zeros((40, 40), bool)
    body[5:35, 10:30] = True
    a = np.zeros_like(body)
    a[:20] = True
    depth = np.where(body, 0.6 + 0.001 * np.arange(40)[:, None], 0.0)
    assert _one_surface(a, ~a, body, depth)
    stepped = np.where(a, depth, depth + 0.03) * body
    assert not _one_surface(a, ~a, body, stepped)
    low = np.zeros_like(body)
    low[:5 + int(BODY_CUT * 30) - 2] = True
    assert not _one_surface(low, ~low, body, depth)
    touching = np.zeros_like(body)
    touching[5:20, 10:30] = True
    touching[20:35, 26:40] = True  # a second block below, meeting the first over 4 columns
    flat = np.where(touching, 0.6, 0.0)
    assert not _one_surface(a, ~a, touching, flat)
    touching[20:35, 12:26] = True  # the same blocks meeting over their whole width
    assert _one_surface(a, ~a, touching, np.where(touching, 0.6, 0.0))


@pytest.mark.slow
def test_a_pitcher_near_the_tables_far_edge_keeps_to_its_outline(extsim):
    """extsim scene 9: a pitcher 2 cm in front of the table's far edge, where the room's colour
    departs from the table's along the whole edge. Measured: best IoU 0.85; grown to the
    outline beyond the table's footprint too, the instance joins the room's edge and takes
    the table between (0.77)."""
    assert _extsim_ious(extsim, "scene_0009")["scene_0009"][1] >= 0.83


@pytest.mark.slow
def test_a_pitchers_rim_seen_through_its_near_wall_stays_in_its_mask(extsim, monkeypatch):
    """extsim scene 13: a standing pitcher looked down into, its far rim seen through its
    near wall, where the table's readings are bent 6 mm off its plane. Measured: best IoU
    0.91; without the hull's gaps, 0.81 (a bite out of its top)."""
    from sr3d_cli.segment import training_free

    assert _extsim_ious(extsim, "scene_0013")["scene_0013"][1] >= 0.89
    monkeypatch.setattr(training_free, "with_hull_gaps", lambda found, *args: found)
    assert _extsim_ious(extsim, "scene_0013")["scene_0013"][1] < 0.84


@pytest.mark.slow
def test_open_vessels_seen_from_above_are_found_round_their_rims(extsim):
    """extsim scene 1's water glass and scene 8's glass bowl, looked down into: the floor
    reads the table, the holes cover an arc of the rim. Measured: best IoU 0.92 and 0.87;
    grown by one step only, 0.38 and 0.11 (the bowl's instance a sliver of its front)."""
    best = _extsim_ious(extsim, "scene_0001", "scene_0008")
    assert best["scene_0001"][3] >= 0.88 and min(best["scene_0001"].values()) >= 0.88
    assert best["scene_0008"][1] >= 0.8


@pytest.mark.slow
def test_touching_vessels_part_where_their_readings_stand_apart(extsim, monkeypatch):
    """extsim scene 0: a glass bowl, a wine glass and a lying cup in front of them, one region
    with no neck between them for the watershed. Their readings' feet on the table stand
    apart, and the cut between the two groups draws the region better (parts 0.82 / 0.72
    against 0.70): it holds by the outline. The bowl and the wine glass then draw 0.05 better
    as one lying object than as two, short of the clear gain that joins what such a cut
    parted; the lines between the three then move onto the nearer glasses' outlines
    (cuts_on_colour_edges). Measured: best IoU 0.88 (wine glass), 0.83 (bowl), 0.99 (cup);
    with the lines left where the cuts drew them, 0.84, 0.80, 0.94; joined again at any
    gain, 0.52 and 0.36; with the readings' cut left out, one instance of all three: 0.49,
    0.33, 0.17."""
    from sr3d_cli.segment import training_free

    def best():
        return _extsim_ious(extsim, "scene_0000")["scene_0000"]

    found = best()
    assert found[1] >= 0.86 and found[2] >= 0.82 and found[3] >= 0.97
    with monkeypatch.context() as m:
        m.setattr(training_free, "cuts_on_colour_edges", lambda found, *args, **kwargs: found)
        uncut = best()
    assert uncut[1] < 0.85 and uncut[2] < 0.81 and uncut[3] < 0.95
    joined = training_free.lying_pieces_joined
    monkeypatch.setattr(training_free, "lying_pieces_joined",
                        lambda *args, apart=(), **kwargs: joined(*args, **kwargs))
    found = best()
    assert found[3] >= 0.9 and max(found[1], found[2]) < 0.6
    cuts = training_free._readings_cuts
    monkeypatch.setattr(training_free, "_readings_cuts",
                        lambda *args: (None, cuts(*args)[1]))
    assert max(best().values()) < 0.5


def _two_discs(colour_a, colour_b):
    """A 128x160 frame with a disc ``a`` (radius 30 px) standing in front of a disc ``b`` that
    overlaps it by 20 px, over a grey table, smooth noise (3 levels, blurred over 2 px) on every
    pixel; and the two instances a vertical line at x = 85 cuts their union into (the true
    line between them: a's arc, 5 px to the right of it at its middle).
    Returns (rgb (H, W, 3) uint8, a, b (H, W) bool, [Candidate, Candidate])."""
    h, w = 128, 160
    yy, xx = np.mgrid[:h, :w]
    a = (xx - 60) ** 2 + (yy - 64) ** 2 <= 30 ** 2
    b = ((xx - 100) ** 2 + (yy - 64) ** 2 <= 30 ** 2) & ~a
    rgb = np.full((h, w, 3), 150.0)
    rgb[b], rgb[a] = colour_b, colour_a
    noise = np.random.default_rng(0).normal(0.0, 3.0, (h, w, 3))
    rgb = np.clip(rgb + cv2.GaussianBlur(noise, (0, 0), 2), 0, 255).astype(np.uint8)
    union = a | b
    cut = [tf.Candidate(union & (xx < 85), 1.0), tf.Candidate(union & (xx >= 85), 1.0)]
    return rgb, a, b, cut


def _iou(p: np.ndarray, q: np.ndarray) -> float:
    return float((p & q).sum() / (p | q).sum())


def test_a_cut_between_touching_instances_moves_onto_the_nearer_ones_edge():
    """The line between two touching instances moves onto the colour edge within reach of it
    (the nearer disc's outline): measured IoU 0.943 / 0.930 before, 0.984 / 0.980 after, the
    contrast along the line 24 before, 65 after."""
    rgb, a, b, cut = _two_discs((90, 110, 90), (120, 130, 140))
    assert _iou(cut[0].mask, a) < 0.95 and _iou(cut[1].mask, b) < 0.94
    lab = tf.colour_lab(rgb)
    moved = tf.cuts_on_colour_edges(cut, rgb, lab)
    assert _iou(moved[0].mask, a) > 0.98 and _iou(moved[1].mask, b) > 0.975
    assert not (moved[0].mask & moved[1].mask).any()
    gradient = tf.colour_gradient(lab)
    assert tf.cut_contrast([m.mask for m in moved], gradient) > \
        2 * tf.cut_contrast([c.mask for c in cut], gradient)


def test_a_cut_stays_where_no_colour_edge_stands_out():
    """Two touching instances of one colour: the watershed's line follows the noise (contrast
    6.1 against 7.1, short of a quarter's rise) and the cut is left where it was."""
    rgb, a, b, cut = _two_discs((120, 130, 140), (120, 130, 140))
    moved = tf.cuts_on_colour_edges(cut, rgb, tf.colour_lab(rgb))
    assert all((m.mask == c.mask).all() for m, c in zip(moved, cut))
    assert tf.on_colour_edges([c.mask for c in cut], rgb) is not None


def _bitten_disc(gap_height: float, on_table: bool, read: float = 1.0):
    """A disc instance (radius 30 px) with a 14 px deep bite out of its top, the bite's
    readings ``gap_height`` metres over the table (on it where ``on_table``), the first
    ``read`` share of its rows read: (found, Evidence, valid, bite)."""
    h, w = 100, 100
    yy, xx = np.mgrid[:h, :w]
    disc = (xx - 50) ** 2 + (yy - 50) ** 2 <= 30 ** 2
    bite = disc & (yy < 34) & (np.abs(xx - 50) < 16)
    valid = np.ones((h, w), bool)
    rows = np.flatnonzero(bite.any(axis=1))
    valid[rows[int(read * len(rows)):]] = False
    valid[~bite] = True
    height = np.where(bite & valid, gap_height, 0.0)
    table = ~disc | (bite & on_table)
    ev = tf.Evidence(glass=disc & ~bite, opaque=np.zeros((h, w), bool),
                     footprint=np.ones((h, w), bool), on_table=table & valid,
                     above=np.zeros((h, w), bool), height=height)
    return [tf.Candidate(disc & ~bite, 1.0)], ev, valid, bite


def test_a_hull_gap_read_a_few_millimetres_off_the_table_joins_its_instance():
    """The gap a glass's bent readings leave in its mask (6 mm over the table, off it) is
    added; one reading an object standing beside it (40 mm over), the table itself, or
    mostly nothing, is not."""
    for height, on_table, read, joins in [(0.006, False, 1.0, True), (0.04, False, 1.0, False),
                                          (0.0, True, 1.0, False), (0.006, False, 0.3, False)]:
        found, ev, valid, bite = _bitten_disc(height, on_table, read)
        out = tf.with_hull_gaps(found, ev, valid, np.zeros_like(valid))
        assert (out[0].mask & bite).any() == joins
        assert (out[0].mask >= found[0].mask).all()
    found, ev, valid, bite = _bitten_disc(0.006, False)
    beside = np.zeros_like(valid)
    beside[:34] = True  # the band around an opaque object covers the bite
    assert not (tf.with_hull_gaps(found, ev, valid, beside)[0].mask & bite).any()


def test_touching_groups_link_what_touches_and_leave_the_rest():
    masks = [np.zeros((20, 20), bool) for _ in range(4)]
    masks[0][2:6, 2:6] = True
    masks[1][6:9, 2:6] = True      # below 0, touching it
    masks[2][9:12, 6:9] = True     # touches 1 at a corner (8-connected)
    masks[3][15:18, 15:18] = True  # apart
    assert tf.touching_groups(masks) == [[0, 1, 2]]


def _extsim_ious(root, *names: str) -> dict[str, dict[int, float]]:
    """The default segmenter's best IoU of each true object (by id) in the named extsim
    scenes below ``root``."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    segmenter = Segmenter(SegmentConfig(), PlaneConfig())
    best = {}
    for source in discover_scenes(root, IOConfig(), None):
        if source.name in names:
            fid = source.frame_ids()[0]
            frame = source.load_frame(fid)
            truth = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
            found = segmenter(fid, frame.rgb, frame.depth_m, frame.camera.K)
            best[source.name] = instance_ious(found.ids, truth)
    return best


def _moved_segments(root, down: int, right: int, only: str = ""
                    ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(instance ids, true ids), each (H, W) int, of the real frames below ``root`` (those
    whose key holds ``only``) moved ``down`` and ``right`` pixels, the first rows and columns
    repeated and K's principal point moved with them: the segmenter's 2x2 reduction of a
    1280 px frame then keeps another reading of each block."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    def moved(a: np.ndarray) -> np.ndarray:
        pad = ((down, 0), (right, 0)) + ((0, 0),) * (a.ndim - 2)
        return np.pad(a, pad, mode="edge")[:a.shape[0], :a.shape[1]]

    segmenter = Segmenter(SegmentConfig(), PlaneConfig())
    out = []
    for source in discover_scenes(root, IOConfig(), None):
        for fid in source.frame_ids():
            if only not in source.frame_key(fid):
                continue
            frame = source.load_frame(fid)
            truth = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
            K = frame.camera.K.astype(np.float64).copy()
            K[0, 2] += right
            K[1, 2] += down
            inst = segmenter(fid, moved(frame.rgb), moved(frame.depth_m), K)
            out.append((inst.ids, moved(truth)))
    return out


def test_a_table_split_by_a_glasss_dropouts_is_one_footprint_and_a_far_desk_no_part_of_it(
        monkeypatch):
    """A band of table readings cut in two by a glass's column of dropouts (its foot on the
    image's lower border), the floor beyond the table's far edge reading below it, and a far
    desk at the table's height beyond the floor: the footprint spans both halves of the table
    and the glass between them, and not the desk (its hull with the table's would hold the
    floor: 33% of it reads below the table; the two halves' hull none). With no patch joining
    it is the larger half's hull only, and the glass lies outside it."""
    on_table = np.zeros((240, 320), bool)
    below = np.zeros_like(on_table)
    on_table[160:, :140] = True  # the table's left half
    on_table[160:, 170:] = True  # its right half, the larger
    below[100:160, :] = True  # the floor beyond the table's far edge
    on_table[60:100, 180:300] = True  # a far desk at the table's height
    glass = (200, 155)
    footprint = tf.table_footprint(on_table, below)
    assert footprint[glass] and footprint[170, 20] and footprint[230, 310]
    assert not footprint[80, 240]
    monkeypatch.setattr(tf, "FOOTPRINT_PATCH", 2.0)
    alone = tf.table_footprint(on_table, below)
    assert not alone[glass] and not alone[80, 240] and alone[230, 310]


@pytest.mark.slow
@pytest.mark.parametrize("view, measured", [("000001", 0.596), ("000014", 0.720)])
def test_a_container_whose_foot_the_border_cuts_is_found(realdata, monkeypatch, view,
                                                         measured):
    """Tracebot views 001 and 014 cropped so that the lower border cuts a quarter off the
    container's foot: what is left of the table is a band, cut in two by the container's
    dropouts. Measured: best IoU 0.596 and 0.720 with the footprint over both halves; 0.0
    (nothing found) with the larger half's only (no patch joins)."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    def found() -> float:
        (source,) = discover_scenes(realdata.parent / "tracebot-dev", IOConfig(), None)
        frame = source.load_frame(view)
        truth = source.load_mask(source.gt_mask_path(view), frame.depth_m.shape)
        rows = np.nonzero(truth.any(axis=1))[0]
        keep = slice(0, int(rows[-1] - 0.25 * (rows[-1] - rows[0])))
        inst = Segmenter(SegmentConfig(), PlaneConfig())(view, frame.rgb[keep],
                                                         frame.depth_m[keep], frame.camera.K)
        return instance_ious(inst.ids, truth[keep])[1]

    assert found() == pytest.approx(measured, abs=0.05)
    monkeypatch.setattr(tf, "FOOTPRINT_PATCH", 2.0)
    assert found() < 0.2


def _instances_best(root, down: int, right: int, only: str) -> list[float]:
    """Each instance's best IoU with a true object, in the one frame of
    :func:`_moved_segments`."""
    ((ids, truth),) = _moved_segments(root, down, right, only)
    return [instance_ious(truth, (ids == k).astype(np.int32))[1] for k in np.unique(ids[ids > 0])]


def _moved_scores(root, down: int, right: int, only: str = "") -> list[float]:
    """Best IoU of each true object in the frames of :func:`_moved_segments`."""
    return [iou for ids, truth in _moved_segments(root, down, right, only)
            for iou in instance_ious(ids, truth).values()]


def test_fill_holes_in_the_box_fills_what_scipy_fills():
    """fill_holes works within a region's box: the same pixels as scipy's on the whole image,
    for random blobs with holes, touching the border or not, bool or uint8."""
    from scipy import ndimage

    from sr3d_cli.segment.training_free import fill_holes

    rng = np.random.default_rng(0)
    with_holes = 0
    for k in range(60):
        h, w = rng.integers(5, 90, 2)
        mask = cv2.GaussianBlur(rng.random((h, w)), (0, 0), rng.uniform(0.5, 4)) > 0.5
        if k % 3 == 0:
            mask = mask.astype(np.uint8) * 7
        filled = ndimage.binary_fill_holes(mask)
        assert np.array_equal(fill_holes(mask), filled)
        with_holes += int(filled.sum() > (mask > 0).sum())
    assert with_holes > 10
    assert not fill_holes(np.zeros((4, 4), bool)).any()


def test_convex_hull_from_each_rows_ends_is_the_hull_of_every_pixel():
    """convex_hull takes each row's end pixels only: the same pixels as cv2's hull of every set
    pixel, for random blobs and scattered pixels, bool or uint8; none for an empty mask."""
    from sr3d_cli.geometry.camera import convex_hull

    rng = np.random.default_rng(1)
    for k in range(80):
        h, w = rng.integers(1, 70, 2)
        if k % 2:
            mask = rng.random((h, w)) < rng.uniform(0.001, 0.2)
        else:
            mask = cv2.GaussianBlur(rng.random((h, w)), (0, 0), rng.uniform(0.5, 4)) > 0.6
        ys, xs = np.nonzero(mask)
        every = np.zeros((h, w), np.uint8)
        if len(xs):
            cv2.fillConvexPoly(every, cv2.convexHull(np.column_stack([xs, ys]).astype(np.int32)), 1)
        given = mask.astype(np.uint8) * 3 if k % 3 == 0 else mask
        assert np.array_equal(convex_hull(given), every > 0)
    ring = np.zeros((40, 40), bool)
    cv2.circle(ring.view(np.uint8), (20, 20), 12, 1, 2)
    assert convex_hull(ring)[20, 20] and not ring[20, 20]
    assert not convex_hull(np.zeros((5, 5), bool)).any()


def test_opaque_objects_are_the_parts_whose_median_departure_is_high():
    """A part of opaque evidence is an opaque object when the median colour departure over its
    pixels with a known departure is above OPAQUE_COLOUR (of an even count: the mean of the two
    middle values); a part with no known departure is not."""
    opaque = np.zeros((20, 30), bool)
    opaque[2:6, 2:6] = opaque[2:6, 10:14] = opaque[10:14, 2:6] = opaque[10:14, 20:24] = True
    departure = np.full(opaque.shape, np.nan)
    level = tf.OPAQUE_COLOUR
    departure[2:6, 2:6] = level + 1  # every pixel departs
    departure[2:4, 10:14], departure[4:6, 10:14] = level + 0.5, level - 1  # middle two: -0.25
    departure[10:12, 22:24], departure[12:14, 22:24] = level - 1, level + 3  # half known: +1
    out = tf.opaque_objects(opaque, departure)
    assert out[2:6, 2:6].all()
    assert not out[2:6, 10:14].any()  # the upper middle value alone would call it opaque
    assert not out[10:14, 2:6].any()  # no known departure
    assert out[10:14, 20:24].all()  # the unknown half does not count
    assert not out[~opaque].any()


def test_a_region_is_cut_to_the_tables_columns_before_its_cuts_are_judged(monkeypatch):
    """A glass at the table's far edge rises against a wall whose holes join its own beside
    its top. The regions whose cuts are judged hold the glass's top beyond the edge but none
    of the wall's holes off its columns, and the glass is found."""
    rgb, depth, plane = _table_frame((110, 80, 60))
    ids, _, _, _ = solids_on_table([(GLASS, 0.1, 0.0, 0.0)])
    body = ids > 0
    rows, cols = np.nonzero(body.any(axis=1))[0], np.nonzero(body.any(axis=0))[0]
    edge = rows[0] + 15  # the glass's top 15 rows rise beyond the table's far edge
    wall = np.arange(SHAPE[0])[:, None] < edge
    depth = np.where(wall, 2.0 * depth, depth)  # the wall reads far behind the table's plane
    holes = np.zeros(SHAPE, bool)  # the wall's dropouts, joined to the glass's top
    holes[rows[0]:edge - 2, cols[-1] - 5:cols[-1] + 120] = True
    rim = body & ~(cv2.erode(body.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)
    rgb[rim] = (240, 240, 240)
    depth[body | holes] = 0.0
    judged = []
    split = tf.split_touching

    def recorded(region, *args, **kwargs):
        judged.append(region)
        return split(region, *args, **kwargs)

    monkeypatch.setattr(tf, "split_touching", recorded)
    found = _segment(rgb, depth)
    # off the columns of the glass's part over the table (widened by BEYOND_MARGIN, and by
    # the outline's pixel or two)
    beside = holes & (np.arange(SHAPE[1])[None, :] > cols[-1] + 2 + tf.BEYOND_MARGIN)
    assert judged and not any((r & beside).any() for r in judged)
    assert any((r & body & wall).sum() >= 0.8 * (body & wall).sum() for r in judged)
    assert instance_ious(found.ids, ids)[1] > 0.85


def test_a_body_of_objects_side_by_side_divides_the_candidate_joining_their_tops():
    """with_bodies: a candidate joins the holes on the tops of two objects standing side by
    side, and their readings close into one body that parts into both. The join goes to the
    parts, each pixel to the nearer one; a body that parts into one joins whole."""
    shape = (120, 200)
    tops = np.zeros(shape, bool)
    tops[20:40, 40:160] = True  # the holes on both tops and the few pixels between them
    left = np.zeros(shape, bool)
    left[30:100, 40:85] = True
    right = np.zeros(shape, bool)
    right[30:100, 115:160] = True
    body = left | right
    body[30:40, 85:115] = True  # the readings closed across the gap below the tops

    def masks(parts):
        found = tf.with_bodies([tf.Candidate(tops, 0.9)], [(body, True)],
                               np.ones(shape, bool), lambda mask, body: True,
                               lambda mask: parts)
        return [c.mask for c in found]

    found = masks([left, right])
    assert len(found) == 2
    assert np.array_equal(found[0] | found[1], tops | body) and not (found[0] & found[1]).any()
    near_left = (tops | body) & (np.arange(shape[1]) < 99)
    assert np.array_equal(found[0] & near_left, near_left) and not found[0][:, 101:].any()
    whole = masks([body])
    assert len(whole) == 1 and np.array_equal(whole[0], tops | body)


@pytest.mark.slow
@pytest.mark.parametrize("view", ["000053", "000066", "000092"])
def test_a_container_copied_beside_itself_is_two_instances(realdata, monkeypatch, view):
    """A Tracebot view with its container copied 40 px (at 1280 wide) to its right, the band
    of holes around it copied with it (bench/generalise.py ``beside_itself``): the holes on
    both lids join into one candidate and the readings of both bodies close into one body,
    which parts into the two containers. Measured: best IoUs 0.77 and 0.83 (053), 0.78 and
    0.78 (066), 0.81 and 0.86 (092); with the join kept whole (``nearest_part`` giving the
    whole mask), one instance over both: 0.35-0.41."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    from generalise import beside_itself

    (source,) = discover_scenes(realdata.parent / "tracebot-dev", IOConfig(), None)
    (fid,) = [f for f in source.frame_ids() if view in source.frame_key(f)]
    frame = source.load_frame(fid)
    truth = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
    rgb, depth, ids = beside_itself(frame.rgb, frame.depth_m, truth, 40)

    def best():
        inst = Segmenter(SegmentConfig(), PlaneConfig())(fid, rgb, depth, frame.camera.K)
        return instance_ious(inst.ids, ids)

    ious = best()
    assert min(ious.values()) >= 0.75
    monkeypatch.setattr(tf, "nearest_part", lambda mask, parts: [mask])
    assert max(best().values()) < 0.45


@pytest.mark.parametrize("tone", ["darker", "paler", "noisier"])
def test_a_container_is_found_in_another_exposure_or_a_noisier_sensor(realdata, monkeypatch,
                                                                       tone):
    """Tracebot view 066 with its colour changed as bench/generalise.py ``toned`` does (its
    depth as it is): the container is one instance and nothing else is. Measured: best IoU
    0.83 as given; 0.85 darker, 0.85 paler, 0.83 noisier (the table's colour spread, which
    the colour rules are measured in, 2.0 as given, 1.5, 1.4, 2.7)."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    from generalise import toned

    (source,) = discover_scenes(realdata.parent / "tracebot-dev", IOConfig(), None)
    (fid,) = [f for f in source.frame_ids() if "000066" in source.frame_key(f)]
    frame = source.load_frame(fid)
    truth = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
    rgb = toned(frame.rgb, tone)
    assert np.abs(rgb.astype(int) - frame.rgb).mean() > 3  # the colour did change
    inst = Segmenter(SegmentConfig(), PlaneConfig())(fid, rgb, frame.depth_m, frame.camera.K)
    assert len(inst.objects) == 1
    (iou,) = instance_ious(inst.ids, truth).values()
    assert iou >= 0.8


def test_an_instance_is_placeable_only_as_a_glass_sized_solid_on_the_table():
    """placeable: a 10 cm glass's mask is (its revolution fit draws it at IoU 0.98); the same
    glass at 2 cm is not (fitted 2.1 cm tall, under MIN_OBJECT_SIZE), nor a ring of holes no
    solid on the table draws (IoU 0.17, under MIN_FIT_IOU). A 12 x 20 px sliver reaching the
    image's border is kept (the border may cut an object down to it); 40 px inside, it is not."""
    ids, K, plane, _ = solids_on_table([(GLASS, 0.1, 0.0, 0.0), (GLASS * 0.2, 0.02, 0.15, 0.0)])
    fits = tf._PartFits(K, plane, None)
    glass, small = ids == 1, ids == 2
    assert fits(glass).iou > 0.95 and abs(fits(small).height - 0.02) < 0.003
    assert tf.placeable(glass, fits) and not tf.placeable(small, fits)
    ys, xs = np.nonzero(glass)
    ring = np.zeros(glass.shape, np.uint8)
    cv2.circle(ring, (int(xs.mean()), int(ys.mean())), 40, 1, 6)
    assert fits(ring > 0).iou < 0.3 and not tf.placeable(ring > 0, fits)
    sliver = np.zeros(glass.shape, bool)
    sliver[ys.max() - 20:ys.max(), -12:] = True  # an object cut by the image's right border
    inside = np.roll(sliver, -40, axis=1)
    assert tf.placeable(sliver, fits) and not tf.placeable(inside, fits)


@pytest.mark.slow
def test_the_slivers_of_a_cleargrasp_frame_resampled_to_vga_are_no_instances(realdata,
                                                                              monkeypatch):
    """ClearGrasp's D435 frame 123 resampled to 640x480 (bench/generalise.py ``resampled``):
    its three holders are instances and nothing else. Measured: best IoUs 0.84, 0.59 and
    0.55; with instances of any fit kept (MIN_FIT_IOU 0), a fourth on the holes along the
    geode's edge, fitted at IoU 0.09."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    from generalise import resampled

    (source,) = [s for s in discover_scenes(realdata, IOConfig(), None) if "d435" in s.name]
    (fid,) = source.frame_ids()
    frame = source.load_frame(fid)
    truth = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
    rgb, depth, truth, K = resampled(frame.rgb, frame.depth_m, truth, frame.camera.K)

    def found():
        inst = Segmenter(SegmentConfig(), PlaneConfig())(fid, rgb, depth, K)
        return instance_ious(truth, inst.ids)

    ious = found()
    assert len(ious) == 3 and min(ious.values()) >= 0.5
    monkeypatch.setattr(tf, "MIN_FIT_IOU", 0.0)
    ious = found()
    assert len(ious) == 4 and min(ious.values()) < 0.2


def test_moved_frames_keep_their_truth_on_their_pixels(native_scene, tmp_path, monkeypatch):
    """bench/generalise.py's frames moved by a pixel (``write_frames`` with ``shifted``): the
    colour, the raw depth, the true ids and the true depth move together and K's principal
    point with them, so that a pixel still holds its own truth; the depth is written as float
    metres, not rounded to the 16-bit PNG's step. ``in_steps`` rounds to that step."""
    from sr3d_cli.config import IOConfig
    from sr3d_cli.io.formats import discover_scenes

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    from generalise import in_steps, shifted, write_frames

    def move(frame, truth, gt):
        raw = np.where(frame.depth_m > 0, frame.depth_m + 0.0004, 0.0)  # off the 1 mm step
        rgb, depth, ids, K = shifted(frame.rgb, raw, truth, frame.camera.K, 1, 2)
        return rgb, depth, ids, shifted(frame.rgb, gt, truth, frame.camera.K, 1, 2)[1], K

    out = write_frames(native_scene, tmp_path / "moved", move)
    sources = discover_scenes(out, IOConfig(), None)
    assert len(sources) == 2
    for moved in sources:
        fid = moved.frame_ids()[0]
        frame = moved.load_frame(fid)
        truth = moved.load_mask(moved.gt_mask_path(fid), frame.depth_m.shape)
        gt = moved.load_gt_depth(fid, truth.shape)
        assert frame.camera.K[0, 2] == pytest.approx(15.5 + 2)
        assert frame.camera.K[1, 2] == pytest.approx(11.5 + 1)
        assert np.array_equal(np.argwhere(truth > 0)[[0, -1]], [[9, 12], [14, 19]])
        assert np.all(gt[truth > 0] == pytest.approx(0.45))
        assert frame.depth_m[9, 18] == pytest.approx(0.5004, abs=1e-6)  # read, not rounded
        assert frame.depth_m[9, 12] == 0  # the object's holes moved with it
    assert np.array_equal(in_steps(np.array([0.0, 0.5004, 0.4996])), [0.0, 0.5, 0.5])
