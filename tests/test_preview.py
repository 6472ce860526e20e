"""Pictures people read: every preview carries a colour bar in its units and a legend."""

from __future__ import annotations

import numpy as np

from sr3d_cli.config import GraspConfig
from sr3d_cli.evaluate import error_map_image
from sr3d_cli.grasp import GraspSet
from sr3d_cli.grasp.gripper import Gripper
from sr3d_cli.io import preview

H, W = 60, 80
K = np.array([[80.0, 0, 40], [0, 80.0, 30], [0, 0, 1]])


def _bar_row(key: np.ndarray) -> np.ndarray:
    """The middle row of the colour bar in a key strip: its widest run of non-white,
    non-black pixels."""
    rows = [(np.sum((r.min(-1) < 250) & (r.max(-1) > 5)), i) for i, r in enumerate(key)]
    return key[max(rows)[1]]


def test_depth_preview_has_a_bar_from_near_to_far_and_a_legend():
    rgb = np.full((H, W, 3), 128, np.uint8)
    raw = np.tile(np.linspace(0.4, 0.8, W, dtype=np.float32), (H, 1))
    raw[:, :10] = 0
    ids = np.zeros((H, W), np.int32)
    ids[20:40, 30:50] = 1
    image = preview.preview_image(rgb, raw, raw, ids)
    assert image.shape[1] == 3 * W and image.shape[0] > H + 20
    assert np.array_equal(image[:H, W:2 * W], preview.colour_depth(raw, *np.percentile(
        raw[raw > 0], [1, 99])))  # the picture itself is unchanged by its key
    key = image[H:]
    bar = _bar_row(key)
    m = preview.bar_margin(3 * W)
    assert np.array_equal(bar[m], preview.depth_colours(0.0))  # near end: red
    assert np.array_equal(bar[3 * W - m - 1], preview.depth_colours(1.0))  # far end: blue
    near, far = bar[m].astype(int), bar[3 * W - m - 1].astype(int)
    assert near[0] > near[2] and far[2] > far[0]
    legend_square = np.all(key == preview.OBJECT_OUTLINE, axis=-1)
    assert legend_square.sum() > 10  # the outline colour is explained in the legend
    assert (key.min(-1) < 60).sum() > 200  # text


def test_error_map_key_spans_zero_to_the_max_error_and_explains_holes():
    gt = np.full((H, W), 1.0)
    pred = gt + np.tile(np.linspace(0, 0.05, W), (H, 1))
    pred[:5] = 0
    mask = np.zeros((H, W), bool)
    mask[:30] = True
    image = preview.error_map_figure(error_map_image(pred, gt, mask, max_error=0.05), 0.05)
    assert image.shape[1] == W and image.shape[0] > H
    key = image[H:]
    bar = _bar_row(key)
    m = preview.bar_margin(W)
    # the bar's ends are the map's colours of 0 and max_error
    assert np.array_equal(bar[m], image[10, 0]) and np.array_equal(bar[W - m - 1], image[10, -1])
    assert np.all(key == preview.HOLE, axis=-1).sum() > 4
    assert np.all(key == preview.NOT_SCORED, axis=-1).sum() > 4


def test_grasp_preview_draws_the_gripper_in_score_colours_with_a_key():
    R = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)  # approach along +z (into the view)
    grasps = GraspSet(scores=np.array([1.0, 0.0]), widths=np.array([0.04, 0.04]),
                      heights=np.full(2, 0.02), depths=np.full(2, 0.02),
                      R=np.stack([R, R]), t=np.array([[-0.05, 0, 0.5], [0.05, 0, 0.5]]),
                      object_ids=np.array([1, 2]))
    gripper = Gripper.from_config(GraspConfig())
    rgb = np.full((H, W, 3), 128, np.uint8)
    image = preview.grasp_preview(rgb, grasps, K, gripper)
    assert image.shape[1] == W and image.shape[0] > H
    drawn = image[:H]
    green = np.all(drawn == (0, 255, 0), axis=-1)
    red = np.all(drawn == (255, 0, 0), axis=-1)
    assert green.any() and red.any()
    assert np.argwhere(green)[:, 1].mean() < W / 2 < np.argwhere(red)[:, 1].mean()
    bar = _bar_row(image[H:])
    m = preview.bar_margin(W)
    assert tuple(bar[m]) == (255, 0, 0) and tuple(bar[W - m - 1]) == (0, 255, 0)
