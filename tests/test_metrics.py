import math

import numpy as np
import pytest

from sr3d_cli.evaluate import depth_metrics, error_map_image, mean_metrics


def test_metrics_on_a_hand_made_frame():
    gt = np.array([[1.0, 2.0], [4.0, 0.0]])  # gt 0 = invalid, never counted
    pred = np.array([[1.1, 0.0], [4.0, 3.0]])  # one hole at (0, 1)
    mask = np.ones((2, 2), bool)
    m = depth_metrics(pred, gt, mask, holes="full")
    # errors: 0.1, -2 (hole counts as 0), 0
    assert m["pixels"] == 3
    assert m["coverage"] == pytest.approx(2 / 3)
    assert m["mae"] == pytest.approx((0.1 + 2 + 0) / 3)
    assert m["rmse"] == pytest.approx(math.sqrt((0.01 + 4) / 3))
    assert m["rel"] == pytest.approx((0.1 / 1 + 2 / 2 + 0) / 3)
    assert m["delta_1.05"] == pytest.approx(100 / 3)  # only the exact pixel
    assert m["delta_1.10"] == pytest.approx(100 / 3)  # 1.1/1.0 is not < 1.10
    assert m["delta_1.25"] == pytest.approx(200 / 3)


def test_ignore_holes_counts_only_valid_predictions():
    gt = np.array([[1.0, 2.0], [4.0, 0.0]])
    pred = np.array([[1.1, np.nan], [4.0, 3.0]])
    m = depth_metrics(pred, gt, np.ones((2, 2)), holes="ignore")
    assert m["pixels"] == 2
    assert m["mae"] == pytest.approx(0.05)
    assert m["coverage"] == pytest.approx(2 / 3)


def test_mask_restricts_pixels_and_empty_mask_gives_nan():
    gt = np.full((3, 3), 2.0)
    pred = gt + np.arange(9).reshape(3, 3) * 0.01
    mask = np.zeros((3, 3), bool)
    mask[1, 1] = True
    assert depth_metrics(pred, gt, mask)["mae"] == pytest.approx(0.04)
    empty = depth_metrics(pred, gt, np.zeros((3, 3)))
    assert empty["pixels"] == 0 and math.isnan(empty["rmse"])


def test_shape_mismatch_and_bad_mode_raise():
    with pytest.raises(ValueError, match="shapes differ"):
        depth_metrics(np.zeros((2, 2)), np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="holes"):
        depth_metrics(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), holes="zero")


def test_mean_over_frames_skips_empty_frames():
    rows = [
        {"pixels": 10, "coverage": 1.0, "rmse": 1.0, "rel": 0.1, "mae": 0.5,
         "delta_1.05": 10.0, "delta_1.10": 20.0, "delta_1.25": 30.0},
        {"pixels": 30, "coverage": 0.5, "rmse": 3.0, "rel": 0.3, "mae": 1.5,
         "delta_1.05": 30.0, "delta_1.10": 40.0, "delta_1.25": 50.0},
        depth_metrics(np.ones((2, 2)), np.ones((2, 2)), np.zeros((2, 2))),
    ]
    m = mean_metrics(rows)
    assert m["frames"] == 2 and m["pixels"] == 40
    assert m["rmse"] == pytest.approx(2.0) and m["coverage"] == pytest.approx(0.75)


def test_error_map_colours_holes_and_background():
    gt = np.full((4, 4), 1.0)
    pred = gt.copy()
    pred[0, 0] = 0
    pred[1, 1] = 1.2
    mask = np.zeros((4, 4), bool)
    mask[:2, :2] = True
    img = error_map_image(pred, gt, mask, max_error=0.1)
    assert img.shape == (4, 4, 3) and img.dtype == np.uint8
    assert tuple(img[0, 0]) == (255, 0, 255)
    assert tuple(img[3, 3]) == (40, 40, 40)
    assert img[1, 1, 0] > 100 and img[0, 1, 2] > 100  # large error red, zero error blue


def _transcg_reference(pred, gt, mask, near=0.3, far=1.5):
    """TransCG's utils/metrics.py written out for one image: process_depth zeroes readings
    outside [near, far] in both images; zero_mask = gt > 0; masked sums over mask & zero_mask."""
    pred = np.where((pred < near) | (pred > far), 0, pred)
    gt = np.where((gt < near) | (gt > far), 0, gt)
    out = {}
    for name, sel in (("object", (mask > 0) & (gt > 0)), ("all", gt > 0)):
        n = sel.sum()
        err = (pred - gt) * sel
        with np.errstate(divide="ignore", invalid="ignore"):
            thres = np.maximum(pred / (gt + 1e-8), gt / pred)
        out[name] = {"rmse": np.sqrt((err ** 2).sum() / n), "mae": np.abs(err).sum() / n,
                     "rel": (np.abs(err) / (gt + 1e-8)).sum() / n,
                     "delta_1.05": 100 * ((thres < 1.05) & sel).sum() / n}
    return out


def test_transcg_protocol_matches_the_reference_formulas():
    from sr3d_cli.evaluate import PROTOCOLS, protocol_metrics

    rng = np.random.default_rng(4)
    gt = rng.uniform(0.2, 1.8, (12, 16))  # some of it outside 0.3-1.5 m
    pred = gt + rng.normal(0, 0.03, gt.shape)
    pred[rng.random(gt.shape) < 0.2] = 0  # holes
    mask = np.zeros(gt.shape, np.uint8)
    mask[3:9, 4:12] = 2
    got = protocol_metrics(pred, gt, mask, PROTOCOLS["transcg"])
    ref = _transcg_reference(pred.astype(np.float32), gt.astype(np.float32), mask)
    assert set(got) == {"object", "all"}
    for name in ("object", "all"):
        for key, value in ref[name].items():
            assert got[name][key] == pytest.approx(value, rel=1e-5), (name, key)
    assert got["all"]["pixels"] == int(((gt >= 0.3) & (gt <= 1.5)).sum())


def test_protocol_resolution_resizes_by_nearest_neighbour():
    from sr3d_cli.evaluate import PROTOCOLS, parse_resolution, protocol_metrics

    gt = np.full((4, 8), 1.0)
    pred = gt.copy()
    pred[:, ::2] = 1.1  # every other column off by 0.1 m
    mask = np.ones((4, 8))
    native = protocol_metrics(pred, gt, mask, PROTOCOLS["native"])["object"]
    half = protocol_metrics(pred, gt, mask, PROTOCOLS["native"], resolution=(4, 2))["object"]
    assert native["pixels"] == 32 and native["mae"] == pytest.approx(0.05)
    assert half["pixels"] == 8 and half["mae"] == pytest.approx(0.1)  # nearest keeps even columns
    assert PROTOCOLS["cleargrasp"].resolution == (256, 144)
    assert parse_resolution("320x240") == (320, 240) and parse_resolution("native") is None
    with pytest.raises(ValueError, match="WIDTHxHEIGHT"):
        parse_resolution("320*240")


def test_median_relative_error():
    gt = np.full((1, 5), 1.0)
    pred = np.array([[1.01, 1.02, 1.03, 1.5, 0.0]])
    m = depth_metrics(pred, gt, np.ones((1, 5)))
    assert m["rel_median"] == pytest.approx(0.03) and m["rel"] == pytest.approx(1.56 / 5)
