"""sr3d reconstruct: surfaces of revolution against known shapes, ONNX and library plug-ins."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.config import IOConfig, ReconstructConfig
from sr3d_cli.errors import InputError
from sr3d_cli.evaluate import chamfer_distance
from sr3d_cli.geometry.camera import project, unproject
from sr3d_cli.geometry.occlusion import occluders, opaque_objects
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.revolution import open_vessel, profile_from_mesh, revolve, silhouette
from sr3d_cli.geometry.silhouette import mask_iou, project_mesh, surface_depth
from sr3d_cli.geometry.transforms import make_T, rotation_about
from sr3d_cli.io.formats import discover_scenes
from sr3d_cli.reconstruct import ObjectError, Reconstructor, check_border, check_mask
from sr3d_cli.shape import revolution_fit
from sr3d_cli.shape.revolution_fit import (FitOptions, RevolutionFit, _resting_tilt,
                                           axial_view_angle, carved, fit_revolution,
                                           fit_silhouette, smoothed, straight_walls,
                                           symmetry_line)
from tests import onnx_builders
from tests.scenes import GLASS, generated_frame, solids_on_table, table_point

K = np.array([[600.0, 0, 319.5], [0, 600, 239.5], [0, 0, 1]])


def _table(elevation_deg: float, distance: float) -> Plane:
    """Table plane seen by a camera looking down at ``elevation_deg`` towards a point at
    ``distance`` along the optical axis."""
    e = np.radians(elevation_deg)
    normal = np.array([0.0, -np.cos(e), -np.sin(e)])  # world up in the camera frame
    point = np.array([0.0, 0.0, distance])
    return Plane(normal, float(-normal @ point))


def _render(profile_m, base, axis, plane=None):
    z = profile_m[1:-1, 1]
    centres = base + z[:, None] * axis
    return silhouette(centres, axis, profile_m[1:-1, 0], K, (480, 640))


def _covered_centres(base, axis, r, h, near):
    """Pixels (of those ``near`` selects) whose centre's ray meets a solid cylinder (base, unit
    axis, radius r, height h), found by stepping along each ray at 0.1 mm: the exact coverage
    that :func:`silhouette` is compared with."""
    v, u = np.nonzero(near)
    rays = np.linalg.inv(K) @ np.vstack([u, v, np.ones(len(u))])
    rays /= np.linalg.norm(rays, axis=0)
    hit = np.zeros(len(u), bool)
    start = np.linalg.norm(base) - h - r
    for t in np.arange(start, start + 2 * (h + r), 0.0001):
        q = (t * rays).T - base
        along = q @ axis
        side = np.linalg.norm(q - along[:, None] * axis, axis=1)
        hit |= (along >= 0) & (along <= h) & (side <= r)
    out = np.zeros(near.shape, bool)
    out[v, u] = hit
    return out


@pytest.mark.parametrize("r", [0.006, 0.03])
def test_silhouette_rows_are_a_pixel_wider_than_the_covered_centres(r):
    # the fit is tuned to this fill (see silhouette's docstring): a change must be deliberate
    plane = _table(40.0, 0.6)
    base = plane.intersect(np.array([0.03, 0.04, 1.0]))
    h = 0.1
    drawn = silhouette(base + np.array([0.0, h])[:, None] * plane.normal, plane.normal,
                       np.array([r, r]), K, (480, 640))
    near = cv2.dilate(drawn.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    exact = _covered_centres(base, plane.normal, r, h, near)
    rows = np.nonzero(exact.sum(1) > 2)[0]
    rows = rows[len(rows) // 4: -len(rows) // 4]  # the straight sides, away from the ends
    extra = drawn[rows].sum(1) - exact[rows].sum(1)
    assert 0.6 < extra.mean() < 1.4
    assert (extra >= 0).all()


def _whole_image_fill(centres, axis, radii, shape):
    """Each frustum's hull filled straight into the whole image: what silhouette must equal."""
    u = np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    theta = np.linspace(0, 2 * np.pi, 32, endpoint=False)[:, None]
    pts = centres[:, None] + radii[:, None, None] * (np.cos(theta) * u + np.sin(theta) * v)
    z = pts[..., 2]
    uv = pts[..., :2] / np.maximum(z, 1e-6)[..., None] * K[[0, 1], [0, 1]] + K[:2, 2]
    fixed = np.rint(uv * 4).astype(np.int32)
    out = np.zeros(shape, np.uint8)
    front = (z > 0.01).all(axis=1)
    for k in range(len(centres) - 1):
        if front[k] and front[k + 1]:
            ring = np.concatenate([fixed[k], fixed[k + 1]])
            cv2.fillConvexPoly(out, cv2.convexHull(ring), 1, cv2.LINE_8, 2)
    return out > 0


def test_a_silhouette_drawn_in_its_box_or_a_window_is_the_whole_images():
    rng = np.random.default_rng(5)
    shape = (480, 640)
    for _ in range(60):  # solids inside, across the image's edges, partly behind the camera
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        base = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4), rng.uniform(0.0, 1.0)])
        centres = base + np.linspace(0, rng.uniform(0.03, 0.4), 30)[:, None] * axis
        radii = rng.uniform(0.002, 0.08, 30)
        whole = _whole_image_fill(centres, axis, radii, shape)
        assert np.array_equal(silhouette(centres, axis, radii, K, shape), whole)
        w, h = int(rng.integers(1, 300)), int(rng.integers(1, 300))
        x, y = int(rng.integers(0, shape[1] - w + 1)), int(rng.integers(0, shape[0] - h + 1))
        assert np.array_equal(silhouette(centres, axis, radii, K, shape, (x, y, w, h)),
                              whole[y:y + h, x:x + w])


def test_a_revolved_profile_has_outward_normals_whichever_way_it_runs():
    """revolve orients the faces by the sign of the volume: a profile listed base to top or
    top to base, closed or an open vessel's, gives a positive volume near the solid's."""
    r, h = 0.03, 0.1
    cylinder = np.array([[0, 0], [r, 0], [r, h], [0, h]])
    vessel = open_vessel([(0, 0), (r, 0), (r, h)], 0.002, 0.004)
    for profile in (cylinder, cylinder[::-1], vessel, vessel[::-1]):
        mesh = revolve(profile, 48)
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume > 0
    assert revolve(cylinder, 48).volume == pytest.approx(np.pi * r ** 2 * h, rel=0.01)


def test_the_fits_fast_helpers_give_numpys_exact_numbers():
    """cross3, _pixels and _extent stand in for np.cross, np.nonzero and the mean of the
    pixels' columns in the fit's inner loop: the fits' decisions turn on the last bit, so
    they must agree to it."""
    from sr3d_cli.geometry.transforms import cross3

    rng = np.random.default_rng(3)
    for a, b in rng.normal(size=(200, 2, 3)):
        assert np.array_equal(cross3(a, b), np.cross(a, b))
    for k in range(20):
        mask = cv2.GaussianBlur(rng.random((90, 120)), (0, 0), 6) > 0.5 + 0.01 * k
        if not mask.any():
            continue
        ys, xs = revolution_fit._pixels(mask)
        assert all(np.array_equal(p, q) and p.dtype == q.dtype
                   for p, q in zip((ys, xs), np.nonzero(mask)))
        top, bottom, column = revolution_fit._extent(mask)
        assert (top, bottom) == (ys.min(), ys.max())
        assert column == float(xs.mean())
    assert revolution_fit._pixels(np.zeros((5, 5), bool))[0].size == 0


def test_a_model_drawn_far_from_a_small_mask_ends_the_fit_without_error():
    """The fit's rotated window is centred between the model's ends and reaches as far as the
    window's diagonal: a 4 px mask at one end of a window that an occluder at the other end
    widens, with the model drawn beside that occluder, leaves none of the mask in it."""
    plane = _table(45.0, 0.6)
    mask = np.zeros((480, 640), bool)
    mask[300:304, 100:104] = True
    occluders = np.zeros((480, 640), bool)
    occluders[296:300, 540:560] = True
    base = plane.intersect(np.array([(450 - K[0, 2]) / K[0, 0], (305 - K[1, 2]) / K[1, 1], 1.0]))
    start = revolution_fit._Model(base, plane.normal.copy(), 0.02, np.full(40, 0.01))
    window = revolution_fit._Frame.along(start, mask, K, occluders)
    assert window.draw(start, K, mask.shape).sum() > 100 and not window.obs.any()
    model, iou = revolution_fit._fit(start, mask, K, plane, "standing", 12,
                                     occluders=occluders)
    assert iou == 0.0
    assert np.all(np.isfinite(model.base)) and model.height > 0


@pytest.mark.parametrize("elevation", [30.0, 60.0])
def test_standing_cylinder_recovered(elevation):
    plane = _table(elevation, 0.6)
    base = plane.intersect(np.array([0.02, 0.05, 1.0]))
    r, h = 0.03, 0.12
    prof = np.array([[0, 0], [r, 0], [r, h], [0, h]])
    mask = _render(prof, base, plane.normal)
    fit = fit_revolution(mask, K, plane)
    assert fit.resting == "standing"
    assert fit.height == pytest.approx(h, rel=0.03)
    assert np.median(fit.profile[1:-1, 0]) * fit.height == pytest.approx(r, rel=0.05)
    assert np.linalg.norm(fit.base - base) < 0.004
    assert fit.iou > 0.95


def test_seen_from_steeply_above_a_flask_keeps_its_neck():
    # a conical flask seen 18 degrees off its axis: its body covers the lower neck in the
    # outline, which then says nothing of the neck's width; it must not pinch it shut
    plane = _table(72.0, 0.6)
    base = plane.intersect(np.array([0.0, 0.03, 1.0]))
    h, body, neck = 0.15, 0.048, 0.014
    prof = np.array([[0, 0], [body, 0], [neck, 0.65 * h], [neck, h], [0, h]])
    fit = fit_revolution(_render(prof, base, plane.normal), K, plane)
    assert fit.resting == "standing"
    assert fit.height == pytest.approx(h, rel=0.05)
    r, z = fit.profile[1:-1, 0] * fit.height, fit.profile[1:-1, 1] * fit.height
    upper = r[z > 0.7 * h]
    assert upper.min() > 0.7 * neck and upper.max() < 1.4 * neck, upper / neck


@pytest.mark.parametrize("elevation", [40.0, 48.0])
def test_seen_from_above_a_flask_keeps_a_straight_cone_and_a_goblet_a_thin_stem(elevation):
    # the flask's base covers its cone, which the outline then leaves free: the update dents
    # it (6.9 and 9.6 mm narrow at 40 and 48 degrees), filled straight it is within 3.1 and
    # 4.2 mm. A goblet's stem, covered by its bowl above, must not be filled so (its profile
    # would widen again; it stays within 2.6-5.2 mm at 40 and 48 degrees)
    plane = _table(elevation, 0.6)
    base = plane.intersect(np.array([0.0, 0.03, 1.0]))
    h, body, neck = 0.11, 0.048, 0.015
    prof = np.array([[0, 0], [body, 0], [neck, 0.62 * h], [neck, h], [0, h]])
    fit = fit_revolution(_render(prof, base, plane.normal), K, plane)
    r, z = fit.profile[1:-1, 0] * fit.height, fit.profile[1:-1, 1] * fit.height
    cone = (z > 0.1 * h) & (z < 0.55 * h)
    true_r = body + (neck - body) * z[cone] / (0.62 * h)
    assert fit.resting == "standing"
    assert np.abs(r[cone] - true_r).max() < 0.0045, (r[cone] - true_r).round(4)
    goblet = np.array([[0, 0], [0.032, 0], [0.032, 0.004], [0.006, 0.008], [0.005, 0.07],
                       [0.03, 0.09], [0.04, 0.12], [0.04, 0.16], [0, 0.16]])
    fit = fit_revolution(_render(goblet, base, plane.normal), K, plane)
    r, z = fit.profile[1:-1, 0] * fit.height, fit.profile[1:-1, 1] * fit.height
    assert fit.resting == "standing"
    assert r[(z > 0.035) & (z < 0.065)].max() < 0.01


@pytest.mark.parametrize("elevation, spill", [(48.0, 0), (56.0, 0), (48.0, 1), (40.0, 2)])
def test_seen_from_above_a_beaker_keeps_a_straight_rim(elevation, spill):
    # the rim ellipse covers the upper levels; a taller beaker curling in at the top draws
    # nearly the same outline. ``spill`` rows of a segmentation's overreach above the rim
    # (8 px wide) must not pull the top up either
    plane = _table(elevation, 0.6)
    base = plane.intersect(np.array([0.0, 0.03, 1.0]))
    r, h = 0.042, 0.07
    prof = np.array([[0, 0], [r, 0], [r, h - 0.003], [1.06 * r, h], [0, h]])
    mask = _render(prof, base, plane.normal)
    for _ in range(spill):
        ys, xs = np.nonzero(mask)
        c = int(xs[ys == ys.min()].mean())
        mask[ys.min() - 1, c - 4:c + 4] = True
    fit = fit_revolution(mask, K, plane)
    radii = fit.profile[1:-1, 0] * fit.height
    assert fit.resting == "standing"
    assert fit.height == pytest.approx(h, rel=0.04)
    assert radii[-3:].min() > 0.95 * r, radii[-3:] / r


@pytest.mark.parametrize("elevation", [45.0, 65.0])
def test_a_beaker_with_a_wide_lip_keeps_a_straight_rim(elevation):
    # a 10% lip: the free fit, curling in above it, draws the outline 0.2-0.5% better than the
    # straight one and comes out 13% and 40% too tall (so straight_top_gap is 0.5%)
    plane = _table(elevation, 0.6)
    base = plane.intersect(np.array([0.0, 0.03, 1.0]))
    r, h = 0.035, 0.065
    prof = np.array([[0, 0], [r, 0], [r, h - 0.003], [1.1 * r, h], [0, h]])
    mask = _render(prof, base, plane.normal)
    assert fit_revolution(mask, K, plane).height == pytest.approx(h, rel=0.04)
    loose = FitOptions(straight_top_gap=0.002)
    assert fit_revolution(mask, K, plane, options=loose).height > 1.1 * h


@pytest.mark.parametrize("elevation", [40.0, 56.0, 70.0])
def test_a_straight_wall_is_written_straight(elevation):
    # each level's width is read on one image row in whole pixels: unsmoothed, neighbouring
    # radii zigzag and a cylinder's wall slopes up to 48 degrees level to level
    plane = _table(elevation, 0.6)
    base = plane.intersect(np.array([0.0, 0.03, 1.0]))
    r, h = 0.03, 0.12
    prof = np.array([[0, 0], [r, 0], [r, h], [0, h]])
    fit = smoothed(fit_revolution(_render(prof, base, plane.normal), K, plane),
                   ReconstructConfig().smooth)
    radii, z = fit.profile[3:-3, 0] * fit.height, fit.profile[3:-3, 1] * fit.height
    slope = np.degrees(np.arctan2(np.abs(np.diff(radii)), np.diff(z)))
    assert np.percentile(slope, 90) < 6.0 and slope.max() < 35.0, slope.round(1)


def test_lying_bottle_recovered_with_its_base_at_the_wide_end():
    plane = _table(45.0, 0.55)
    axis = np.array([1.0, 0, 0]) - (np.array([1.0, 0, 0]) @ plane.normal) * plane.normal
    axis = axis / np.linalg.norm(axis)
    r = 0.035
    prof = np.array([[0, 0], [r, 0], [r, 0.13], [0.012, 0.18], [0.012, 0.22], [0, 0.22]])
    base = plane.intersect(np.array([-0.1, 0.02, 1.0])) + r * plane.normal
    mask = _render(prof, base, axis)
    fit = fit_revolution(mask, K, plane)
    assert fit.resting == "lying"
    assert fit.height == pytest.approx(0.22, rel=0.05)
    assert np.degrees(np.arccos(abs(fit.axis @ axis))) < 5
    assert fit.axis @ axis > 0  # base at the wide end
    truth = revolve(prof / 0.22)
    assert chamfer_distance(revolve(fit.profile), truth) < 0.05


@pytest.mark.parametrize("length", [0.06, 0.065])
def test_a_lying_beaker_as_long_as_it_is_wide_is_found_lying(length, monkeypatch):
    """Laid across the view, a 7 cm wide beaker about as long draws a near-square outline whose
    major axis and orientation say nothing of its axis; started only along that major axis, the
    lying fit turns across the true axis and loses to a squat standing one."""
    plane = _table(45.0, 0.55)
    axis = np.array([1.0, 0, 0]) - (np.array([1.0, 0, 0]) @ plane.normal) * plane.normal
    axis = axis / np.linalg.norm(axis)
    r = 0.035
    prof = np.array([[0, 0], [r, 0], [r, length], [0, length]])
    base = plane.intersect(np.array([-0.02, 0.02, 1.0])) + r * plane.normal - 0.5 * length * axis
    mask = _render(prof, base, axis)
    fit = fit_revolution(mask, K, plane)
    # measured: IoU .996 / .926, height 60 / 71 mm, axis 0 / 8 deg off
    assert fit.resting == "lying" and fit.iou > 0.9
    assert fit.height == pytest.approx(length, rel=0.1)
    assert np.degrees(np.arccos(abs(fit.axis @ axis))) < 10
    monkeypatch.setattr(revolution_fit, "SQUARE_OUTLINE", 0.0)  # started along the major axis
    assert fit_revolution(mask, K, plane).resting == "standing"


def _lying_cylinder(plane: Plane, yaw_deg: float, length: float, r: float):
    """A cylinder lying on ``plane``, its axis turned ``yaw_deg`` about the normal from the
    image's x direction: (mask, axis, base)."""
    flat = np.array([1.0, 0, 0]) - (np.array([1.0, 0, 0]) @ plane.normal) * plane.normal
    axis = rotation_about(plane.normal, np.radians(yaw_deg)) @ (flat / np.linalg.norm(flat))
    base = plane.intersect(np.array([-0.02, 0.02, 1.0])) + r * plane.normal - 0.5 * length * axis
    prof = np.array([[0, 0], [r, 0], [r, length], [0, length]])
    return _render(prof, base, axis), axis, base


@pytest.mark.parametrize("yaw", [-60, -20, 0, 35, 70])
def test_a_lying_solids_outline_is_symmetric_about_its_projected_axis(yaw):
    plane = _table(45.0, 0.55)
    mask, axis, base = _lying_cylinder(plane, yaw, 0.06, 0.035)
    ys, xs = np.nonzero(mask)
    direction, share = symmetry_line(mask, xs, ys, np.array([xs.mean(), ys.mean()]))
    ends = project(np.stack([base, base + 0.06 * axis]), K)
    seen = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    # measured: 0.0-1.5 deg off, 0.985-0.999 of the pixels mirrored into the outline
    assert np.degrees(np.arccos(abs(direction @ seen))) < 3
    assert share > 0.95


def test_a_scalene_triangle_has_no_line_of_symmetry_and_an_isosceles_one_has_its_own():
    found = []
    for corners in ([[100, 100], [220, 100], [160, 180]], [[100, 100], [220, 100], [130, 150]]):
        mask = np.zeros((300, 300), np.uint8)
        cv2.fillPoly(mask, [np.array(corners)], 1)
        ys, xs = np.nonzero(mask)
        found.append(symmetry_line(mask > 0, xs, ys, np.array([xs.mean(), ys.mean()])))
    (direction, share), (_, scalene) = found
    # measured: 0.996 of the isosceles triangle's pixels mirrored into it about the vertical,
    # 0.85 of the scalene one's about its best line
    assert abs(direction[1]) == pytest.approx(1.0, abs=1e-6) and share > 0.98
    assert scalene < revolution_fit.SYMMETRY_SHARE


@pytest.mark.parametrize(("length", "r", "yaw"), [(0.065, 0.035, 0.0), (0.05, 0.035, 30.0)])
def test_a_lying_beaker_pointed_obliquely_is_fitted_along_its_line_of_symmetry(
        length, r, yaw, monkeypatch):
    """As long as it is wide and turned towards the camera, a lying beaker draws a near-square
    outline whose major and minor axes are both off its own; the fits started on them settle
    7-12 deg off, the one started on the outline's line of symmetry on the true axis."""
    plane = _table(45.0, 0.55)
    mask, axis, _ = _lying_cylinder(plane, yaw, length, r)
    fit = fit_revolution(mask, K, plane)
    # measured: IoU .991 / .978, axis 0.0 / 0.8 deg off, height 66 / 51 mm
    assert fit.resting == "lying" and fit.iou > 0.97
    assert np.degrees(np.arccos(abs(fit.axis @ axis))) < 2
    assert fit.height == pytest.approx(length, rel=0.05)
    monkeypatch.setattr(revolution_fit, "SYMMETRY_SHARE", 2.0)  # no start on that line
    fit = fit_revolution(mask, K, plane)
    # measured: IoU .926 / .929, axis 7.5 / 12 deg off
    assert fit.iou < 0.95 and np.degrees(np.arccos(abs(fit.axis @ axis))) > 5


GOBLET = np.array([[0, 0], [0.025, 0], [0.025, 0.004], [0.005, 0.006], [0.005, 0.08],
                   [0.01, 0.085], [0.042, 0.14], [0.042, 0.145], [0, 0.145]])


def test_a_lying_body_rests_on_its_hull_under_its_centre_of_mass():
    z = np.linspace(0, 0.1, 30)
    assert _resting_tilt(z, np.full(30, 0.03)) == pytest.approx((0.0, 0.03))
    z, r = GOBLET[1:-1, 1], GOBLET[1:-1, 0]
    theta, h0 = _resting_tilt(z, r)  # on the foot's rim and the cup's brim
    assert theta == pytest.approx(np.arctan2(0.017, 0.14))
    assert h0 == pytest.approx(0.025 * np.cos(theta))
    assert h0 + 0.14 * np.sin(theta) - 0.042 * np.cos(theta) == pytest.approx(0, abs=1e-9)


def test_lying_goblet_recovered_tilted_on_its_foot_and_cup():
    """A goblet on its side rests on its foot's rim and its cup (7 deg); a fit that keeps the
    axis parallel to the table turns the tilt into a wrong profile and height."""
    plane = _table(45.0, 0.55)
    flat = np.array([1.0, 0, 0]) - (np.array([1.0, 0, 0]) @ plane.normal) * plane.normal
    flat /= np.linalg.norm(flat)
    theta, h0 = _resting_tilt(GOBLET[1:-1, 1], GOBLET[1:-1, 0])
    axis = np.cos(theta) * flat + np.sin(theta) * plane.normal
    base = plane.intersect(np.array([-0.08, 0.02, 1.0])) + h0 * plane.normal
    mask = _render(GOBLET, base, axis)
    truth = revolve(GOBLET / 0.145)
    errors = {}
    for tolerance in (0.01, -1.0):  # -1: the tilted fit is never kept
        fit = fit_revolution(mask, K, plane, options=FitOptions(tilt_tolerance=tolerance))
        assert fit.resting == "lying"
        errors[tolerance] = (np.degrees(np.arccos(abs(fit.axis @ axis))),
                             abs(fit.height / 0.145 - 1),
                             chamfer_distance(revolve(fit.profile), truth))
    tilted, level = errors[0.01], errors[-1.0]
    # measured: axis 0.15 deg vs 9.9 deg, height 0.6% vs 3.4%, Chamfer/height 0.078 vs 0.075
    assert tilted[0] < 1.0 and level[0] > 5
    assert tilted[1] < 0.02 < level[1]
    assert tilted[2] < 0.1


BOTTLE = np.array([[0, 0], [0.032, 0], [0.032, 0.13], [0.012, 0.17], [0.012, 0.2], [0, 0.2]])


def _frame_from_above(prof: np.ndarray, elevation: float, x: float, y: float,
                      surface: np.ndarray | None = None, noise: float = 0.002,
                      read_from: float | None = None):
    """A solid of revolution (``prof`` in metres) standing under a camera looking down at
    ``elevation`` deg, its mask and raw depth: 30% true readings of the ``surface`` profile
    (default ``prof``; an open vessel's inside) with ``noise`` metres of noise, 30% see-through
    readings of the table; with ``read_from`` (metres over the table), every pixel whose
    surface lies that high or higher is read (an opaque lid). Returns plane, mask, depth, the
    see-through readings alone, height."""
    plane = _table(elevation, 0.5)
    base = plane.intersect(np.array([x, y, 1.0]))
    h = float(prof[-1, 1])
    mask = _render(prof, base, plane.normal)
    n = plane.normal
    side = np.cross([1.0, 0, 0], n)
    side /= np.linalg.norm(side)
    T = make_T(np.stack([side, np.cross(n, side), n], axis=1), base)
    mesh = revolve((prof if surface is None else surface) / h)
    uv, pts = project_mesh(np.asarray(mesh.vertices), T[:3, :3], T[:3, 3], h, K)
    ys, xs = np.nonzero(mask)
    front = surface_depth(uv, pts, np.asarray(mesh.faces), K, xs, ys, mask.shape)
    table = plane.depth_image(mask.shape, K)[ys, xs]
    rng = np.random.default_rng(3)
    kind = rng.uniform(size=len(xs))
    if read_from is not None:
        on = unproject(np.column_stack([xs, ys]).astype(np.float64), np.nan_to_num(front), K)
        kind[np.isfinite(front) & (plane.height(on) >= read_from)] = 0.0
    depth = np.zeros(mask.shape, np.float32)
    depth[ys, xs] = np.where(kind < 0.3, front + rng.normal(0, noise, len(xs)),
                             np.where(kind < 0.6, table, 0))
    see_through = np.zeros_like(depth)
    see_through[ys, xs] = np.where(kind < 0.6, table, 0)
    return plane, mask, np.nan_to_num(depth), see_through, h


@pytest.mark.parametrize("x", [-0.05, 0.0])
def test_raw_depth_tells_a_standing_bottle_from_a_lying_one_seen_from_above(x):
    plane, mask, depth, see_through, h = _frame_from_above(BOTTLE, 72.0, x, 0.12)
    # from above, a short lying cylinder draws the bottle's outline better
    assert fit_revolution(mask, K, plane).resting == "lying"
    # readings on the glass say how far up its surface is
    fit = fit_revolution(mask, K, plane, depth=depth)
    assert fit.resting == "standing"
    assert fit.height == pytest.approx(h, rel=0.1)
    # see-through readings lie on the table and carry no vote
    assert fit_revolution(mask, K, plane, depth=see_through).resting == "lying"


def test_readings_above_a_straight_top_keep_the_domed_one():
    # a jar with a domed lid seen from 64 degrees: the outline fits a shorter straight top
    # better; the readings on the dome rise above it and rule it out
    r, h = 0.045, 0.08
    t = np.linspace(0, np.pi / 2, 8)[:-1]
    dome = np.column_stack([r * np.cos(t), 0.45 * h + 0.55 * h * np.sin(t)])
    prof = np.vstack([[0, 0], [r, 0], dome, [0.004, h], [0, h]])
    plane, mask, depth, _, _ = _frame_from_above(prof, 64.0, 0.0, 0.1)
    outline = fit_revolution(mask, K, plane, options=FitOptions(allow_lying=False))
    assert outline.height < 0.8 * h  # straight, too short
    fit = fit_revolution(mask, K, plane, depth=depth,
                         options=FitOptions(allow_lying=False, axial_view=0.0))
    assert fit.height > 0.9 * h


def test_readings_high_above_a_lying_fit_make_a_goblet_stand():
    """Seen steeply from above, a tall goblet draws the outline of a short lying one. With 1 cm
    of noise on the glass, few readings lie within the surface band of either fit and the vote
    cannot decide; but the readings on the cup stand far higher above the table than a lying
    goblet reaches, and a ray meets the surface before anything lower behind it."""
    goblet = np.array([[0, 0], [0.035, 0], [0.033, 0.004], [0.005, 0.01], [0.005, 0.07],
                       [0.03, 0.09], [0.04, 0.15], [0.036, 0.2], [0, 0.2]])
    plane, mask, depth, see_through, h = _frame_from_above(goblet, 74.0, 0.0, 0.1)
    front = (depth > 0) & (depth != see_through)
    noisy = np.where(front, depth + np.random.default_rng(5).normal(0, 0.01, depth.shape),
                     see_through).astype(np.float32)
    assert fit_revolution(mask, K, plane).resting == "lying"
    fit = fit_revolution(mask, K, plane, depth=noisy)
    assert fit.resting == "standing"
    assert fit.height == pytest.approx(h, rel=0.15)
    assert fit_revolution(mask, K, plane, depth=see_through).resting == "lying"


def test_seen_down_its_axis_a_bottle_takes_its_profile_from_the_readings():
    """Straight from above the outline is a disc: a bottle, a jar and a glass draw the same one.
    The readings on the neck's top and the shoulder give the height and the profile; a glass
    seen the same way keeps its wide top (and is modelled open)."""
    plane, mask, depth, see_through, h = _frame_from_above(BOTTLE, 88.0, 0.0, 0.0)
    outline = fit_revolution(mask, K, plane, depth=see_through)
    fit = fit_revolution(mask, K, plane, depth=depth)
    assert axial_view_angle(mask, K, plane) < 10
    assert abs(outline.height / h - 1) > 0.15  # the outline alone cannot tell
    assert fit.height == pytest.approx(h, rel=0.05)
    r, z = fit.profile[1:-1, 0] * fit.height, fit.profile[1:-1, 1] * fit.height
    assert r[z > 0.18].mean() == pytest.approx(0.012, abs=0.004)  # the neck
    assert r[z < 0.12].mean() == pytest.approx(0.032, abs=0.004)  # the body
    glass = np.array([[0, 0], [0.03, 0], [0.036, 0.1], [0, 0.1]])
    inside = open_vessel(glass[:-1] / 0.1, 0.03, 0.08) * 0.1
    plane, mask, depth, _, h = _frame_from_above(glass, 88.0, 0.0, 0.0, surface=inside)
    fit = fit_revolution(mask, K, plane, depth=depth)
    assert fit.height == pytest.approx(h, rel=0.05)
    assert fit.profile[-2, 0] >= 0.9 * fit.profile[1:-1, 0].max()


@pytest.mark.parametrize("elevation", [72.0, 78.0])
def test_seen_from_above_a_beaker_is_as_tall_as_its_rim_not_its_readings_noise(elevation):
    """Looked down on, a beaker's height comes from the readings on its rim; glass readings
    scatter along the ray (4 mm here, as sr3d's synthetic sensor draws them), and their high
    percentile lies above the rim by about twice that. Measured: 2.4% and 4.0% too tall with
    the outline placing the ends, 6.4% and 6.9% by the readings alone (at 78 degrees one pixel
    of outline is 4 mm of height)."""
    r, h = 0.042, 0.08
    beaker = np.array([[0, 0], [r, 0], [r, h - 0.003], [1.06 * r, h], [0, h]])
    inside = open_vessel(beaker[:-1] / h, 0.002 / h, 0.004 / h) * h
    plane, mask, depth, _, _ = _frame_from_above(beaker, elevation, 0.0, 0.02, surface=inside,
                                                 noise=0.004)
    fit = fit_revolution(mask, K, plane, depth=depth)
    assert fit.resting == "standing"
    assert fit.height == pytest.approx(h, rel=0.045)


def _goblet_from_above(elevation: float, readings: str = "all"):
    """:data:`GOBLET` (stem 6-80 mm, bowl 42 mm) under a camera ``elevation`` deg above the
    table, open above its stem: plane, mask and raw depth (``readings`` "all": front returns of
    its foot, stem and the inside of its bowl, 4 mm noise, and see-through ones; "see-through":
    only those)."""
    inside = open_vessel(GOBLET[:-1], 0.002, 0.088)
    plane, mask, depth, see_through, _ = _frame_from_above(GOBLET, elevation, 0.0, 0.02,
                                                           surface=inside, noise=0.004)
    return plane, mask, depth if readings == "all" else see_through


@pytest.mark.parametrize("elevation", [66.0, 72.0])
def test_seen_from_above_a_goblets_stem_is_carved_where_the_readings_find_nothing(elevation):
    """Seen steeply from above, a goblet's bowl covers its stem and the outline is fitted by a
    cylinder nearly as wide as the bowl (22-33 mm at the stem's heights from 64 to 72 deg, the
    stem being 5 mm): of the rays that meet that wall, no reading returns from within it,
    where the foot's and the bowl's inside do. Measured: 4.7-5.2 mm from 40 to 65 mm up, the
    rest of the fit kept; the opened model solid up to the stem's top (74-84 mm; 80 true)."""
    plane, mask, depth = _goblet_from_above(elevation)
    fit = fit_revolution(mask, K, plane, depth=depth)
    out = carved(fit, mask, depth, K)
    r, z = fit.profile[1:-1, 0] * fit.height, fit.profile[1:-1, 1] * fit.height
    stem = (z > 0.04) & (z < 0.065)
    assert r[stem].min() > 0.02  # the outline says nothing of the stem
    thinned = out.profile[1:-1, 0] * out.height
    assert thinned[stem].max() < 0.007
    kept = thinned == r
    assert kept[(z < 0.002) | (z > 0.1)].all()  # the foot's lowest level and the bowl
    assert 0.07 < out.solid_below * out.height < 0.1
    rgb = np.zeros(mask.shape + (3,), np.uint8)
    model = Reconstructor(ReconstructConfig())(rgb, mask, K, plane, "", depth)
    assert model.meta.get("open_top")
    v = model.mesh.vertices * model.meta["pose_hint"]["scale"]
    assert np.hypot(v[:, 0], v[:, 1])[(v[:, 2] > 0.04) & (v[:, 2] < 0.065)].max() < 0.007
    on_axis = np.sort(v[np.hypot(v[:, 0], v[:, 1]) < 1e-9, 2])
    assert on_axis[1] > 0.07  # the floor inside the bowl, not down the stem


def test_a_glass_bowl_is_told_from_a_dome_and_its_height_set_by_its_readings(monkeypatch):
    """A glass bowl 60 mm tall (foot 30 mm, rim 82 mm in radius, open, readings of its inside
    and the table through it) seen from 40, 60 and 70 deg above the table at two places: the
    outline draws nearly the same shape for a dome and for bowls of many heights. Refitted
    from several heights and chosen by the readings, it is an open bowl within 15% of its
    height in 5 of the 6 views (60.7-68.3 mm; a dome 45 mm tall in the other); from the
    dome's height alone, in 2 (a dome 39-65 mm tall in three)."""
    from sr3d_cli.reconstruct import bowls

    h = 0.06
    bowl = np.array([[0, 0], [0.03, 0], [0.05, 0.012], [0.066, 0.03], [0.078, 0.048],
                     [0.082, h], [0, h]])
    inside = open_vessel(bowl[:-1] / h, 0.003 / h, 0.006 / h) * h
    views = [_frame_from_above(bowl, elevation, x, y, surface=inside, noise=0.003)[:3]
             for elevation in (40.0, 60.0, 70.0) for x, y in ((0.0, 0.0), (0.05, 0.03))]

    def right() -> int:
        count = 0
        for plane, mask, depth in views:
            rgb = np.zeros(mask.shape + (3,), np.uint8)
            model = Reconstructor(ReconstructConfig())(rgb, mask, K, plane, "", depth)
            count += bool(model.meta.get("open_top")) and \
                abs(model.meta["pose_hint"]["scale"] / h - 1) < 0.15
        return count

    assert right() >= 5
    monkeypatch.setattr(bowls, "BOWL_STARTS", (1.0,))
    assert right() <= 2


@pytest.mark.parametrize("foot, elevation", [(0.004, 64.0), (0.004, 72.0), (0.012, 64.0),
                                             (0.012, 68.0)])
def test_a_carved_goblets_foot_ends_at_its_readings_median_level(foot, elevation, monkeypatch):
    """:data:`GOBLET` with a foot 4 or 12 mm thick, seen steeply from above: the carve pools
    the readings over CARVE_WINDOW levels (3.8 mm each here), so the foot's own readings (4 mm
    of noise) keep the levels above it wide. Measured: with the foot ended at the median level
    of its readings above the lowest level (the table's, seen through it), its top is 3.8-7.6
    mm up for the thin foot and 11.3-11.6 mm for the thick one; left as carved, 15-16 and
    22-23 mm; taking the lowest level's readings too, the thick foot ends at 0 mm."""
    from sr3d_cli.shape import revolution_fit

    goblet = GOBLET.copy()
    goblet[2, 1], goblet[3, 1] = foot, foot + 0.002
    plane, mask, depth, _, _ = _frame_from_above(goblet, elevation, 0.0, 0.02,
                                                 surface=open_vessel(goblet[:-1], 0.002, 0.088),
                                                 noise=0.004)
    fit = fit_revolution(mask, K, plane, depth=depth)

    def top() -> float:
        out = carved(fit, mask, depth, K)
        r, z = out.profile[1:-1, 0] * out.height, out.profile[1:-1, 1] * out.height
        assert r[0] > 0.02  # the foot itself is kept
        return float(z[(r > 0.012) & (z < 0.06)].max())

    assert abs(top() - foot) <= 0.004  # within one level
    monkeypatch.setattr(revolution_fit, "foot_at_readings", lambda fit, *args: fit)
    assert top() > foot + 0.01


def test_a_foot_ends_at_its_readings_but_a_body_under_a_carved_run_stays():
    """foot_at_readings on 40 levels: a foot under a stem from level 5 whose readings above
    the lowest level centre on level 2 keeps levels 0-2 and takes the stem's radius above; the
    same readings under a run from level 18 (45% of the height: a flat bottle carved above its
    shoulder) change nothing, nor do readings on the lowest level alone."""
    from sr3d_cli.shape.revolution_fit import FOOT_SPAN, foot_at_readings

    n = 40
    z = np.linspace(0, 1, n)
    radii = np.full(n, 0.2)
    profile = np.vstack([[0.0, 0.0], np.column_stack([radii, z]), [0.0, 1.0]])
    fit = RevolutionFit(profile, np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.1, "standing", 0.9)
    each = np.zeros(n, np.int64)
    each[:4] = [90, 10, 40, 10]  # the table through the foot, then the foot's top about level 2
    out = foot_at_readings(fit, each, 5, 0.02)
    r = out.profile[1:-1, 0]
    assert (r[:3] == 0.2).all() and (r[3:5] == 0.02).all() and (r[5:] == 0.2).all()
    assert z[18] > FOOT_SPAN
    assert foot_at_readings(fit, each, 18, 0.02) is fit
    table_only = np.zeros(n, np.int64)
    table_only[0] = 90
    assert foot_at_readings(fit, table_only, 5, 0.02) is fit


def test_a_carved_bowl_narrows_into_its_stem_below_the_readings_that_find_it():
    """A goblet whose rounded bowl meets its stem at 55 mm, seen steeply from above, where
    the bowl's lower outside (55-95 mm up) returns nothing, as glass met at a grazing angle
    does: the readings find the bowl only from 95 mm. Measured: carved to a flat floor on the
    stem, the stem runs up to 89 mm and the model is 19 and 21 mm too thin at 80 and 90 mm;
    with the bowl narrowing at 45 degrees below the readings, the stem's top is at 68 mm and
    the radius 6 and 1 mm off there."""
    t = np.linspace(0, 1, 9)[1:]
    bowl = [(0.005 + 0.035 * np.sin(np.pi / 2 * a), 0.055 + 0.07 * a) for a in t]
    goblet = np.array([(0, 0), (0.03, 0), (0.03, 0.004), (0.005, 0.01), (0.005, 0.055)] + bowl
                      + [(0.036, 0.165), (0, 0.165)])
    plane, mask, depth, _, _ = _frame_from_above(goblet, 66.0, 0.0, 0.02,
                                                 surface=open_vessel(goblet[:-1], 0.002, 0.063),
                                                 noise=0.004)
    fit = fit_revolution(mask, K, plane, depth=depth)
    ys, xs = np.nonzero(depth > 0)
    p = unproject(np.column_stack([xs, ys]).astype(np.float64), depth[ys, xs], K)
    rel = p - fit.base
    away = np.linalg.norm(rel - (rel @ fit.axis)[:, None] * fit.axis, axis=1)
    under = (plane.height(p) > 0.055) & (plane.height(p) < 0.095) & (away > 0.012)
    depth[ys[under], xs[under]] = 0
    fit = fit_revolution(mask, K, plane, depth=depth)
    out = carved(fit, mask, depth, K)
    r, z = out.profile[1:-1, 0] * out.height, out.profile[1:-1, 1] * out.height
    stem = (r < 0.0075) & (z > 0.012)
    assert 0.05 < z[stem].max() < 0.075
    assert r[(z > 0.02) & (z < 0.05)].max() < 0.0075
    for height, true_r in ((0.08, 0.0239), (0.09, 0.0297)):
        assert abs(np.interp(height, z, r) - true_r) < 0.008


def test_a_wall_the_readings_find_or_a_stem_the_outline_shows_is_not_carved():
    """The carve needs readings that find nothing where others find the glass: a tumbler seen
    from above keeps its wall, a goblet whose readings are all see-through (a sensor that
    returns nothing from it) keeps its fit, and so does a goblet seen from the side, whose
    stem the outline shows thin already."""
    tumbler = open_vessel(GLASS[:-1], 0.002, 0.006)
    plane, mask, depth, _, _ = _frame_from_above(GLASS, 72.0, 0.0, 0.02, surface=tumbler,
                                                 noise=0.004)
    fit = fit_revolution(mask, K, plane, depth=depth)
    assert fit.resting == "standing"
    assert carved(fit, mask, depth, K) is fit
    plane, mask, see_through = _goblet_from_above(72.0, readings="see-through")
    fit = fit_revolution(mask, K, plane)
    assert carved(fit, mask, see_through, K) is fit
    plane, mask, depth = _goblet_from_above(25.0)
    fit = fit_revolution(mask, K, plane, depth=depth)
    r, z = fit.profile[1:-1, 0] * fit.height, fit.profile[1:-1, 1] * fit.height
    assert r[(z > 0.04) & (z < 0.065)].max() < 0.01
    assert carved(fit, mask, depth, K) is fit


def _lying_beaker(towards_camera: bool, lip: float = 1.0):
    """A beaker (r 35 mm, 80 mm long, its lip ``lip`` times as wide) on its side, its mouth
    turned 50 deg from the camera's direction either towards it or away; its mask, raw depth
    (35% true readings with 2 mm noise, the inside included where seen, 30% see-through, the
    rest missing) and a function giving the true depth at the mask's pixels."""
    plane = _table(45.0, 0.55)
    toward = plane.project_direction(np.array([0.0, 0, -1.0]))
    toward /= np.linalg.norm(toward)
    side = np.cross(plane.normal, toward)
    a = np.radians(50)
    axis = (np.cos(a) * toward + np.sin(a) * side) * (1 if towards_camera else -1)
    r, h = 0.035, 0.08
    outer = np.array([[0, 0], [r, 0], [r, h - 0.003], [lip * r, h], [0, h]])
    centre = plane.intersect(np.array([0.0, 0.03, 1.0])) + r * plane.normal
    base = centre - 0.5 * h * axis
    mask = _render(outer, base, axis)
    helper = np.cross(axis, plane.normal)
    T = make_T(np.stack([helper, np.cross(axis, helper), axis], axis=1), base)
    true = revolve(open_vessel(outer[:-1] / h, 0.003 / h, 0.006 / h))
    ys, xs = np.nonzero(mask)

    def depth_of(mesh, T_cam_obj, scale):
        uv, pts = project_mesh(np.asarray(mesh.vertices), T_cam_obj[:3, :3], T_cam_obj[:3, 3],
                               scale, K)
        return surface_depth(uv, pts, np.asarray(mesh.faces), K, xs, ys, mask.shape)

    front = depth_of(true, T, h)
    rng = np.random.default_rng(5)
    kind = rng.uniform(size=len(xs))
    depth = np.zeros(mask.shape, np.float32)
    depth[ys, xs] = np.where(kind < 0.35, front + rng.normal(0, 0.002, len(xs)),
                             np.where(kind < 0.65, plane.depth_image(mask.shape, K)[ys, xs], 0))
    return plane, mask, np.nan_to_num(depth), front, depth_of


def test_a_lying_beaker_is_opened_where_the_camera_sees_into_it():
    """Seen into, the readings inside a lying beaker's mouth open its model there, and the
    model's depth follows the inside; turned away, nothing seen says which end is open and the
    model stays closed."""
    rgb = np.zeros((480, 640, 3), np.uint8)
    plane, mask, depth, front, depth_of = _lying_beaker(towards_camera=True)
    errors = {}
    for share in (0.5, np.inf):  # inf: a lying model is never opened
        rec = Reconstructor(ReconstructConfig(open_explains=share))(rgb, mask, K, plane, "",
                                                                    depth)
        assert rec.meta["resting"] == "lying"
        assert rec.meta.get("open_top", False) == (share == 0.5)
        if share == 0.5:
            assert rec.open_alternative is None  # the end seen open is the mouth
        hint = rec.meta["pose_hint"]
        z = depth_of(rec.mesh, np.array(hint["T_cam_obj"]), hint["scale"])
        assert np.isfinite(z).mean() > 0.97
        errors[share] = float(np.nanmean(np.abs(z - front)))
    # measured: 1.6 mm open, 7.1 mm closed (a lid over the mouth)
    assert errors[0.5] < 0.003 and errors[np.inf] > 3 * errors[0.5]
    # kept closed, turned away or where the readings are not trusted to open it (share inf),
    # the grasp stage's fallback is the model opened at its wider end, in the same object
    # frame (turned away, the camera sees the same depth), and the opening is the true mouth:
    # a lying fit's base is its wider end, here the 6% wider lip's, as generated beakers have
    for towards, share in ((False, 0.5), (True, np.inf)):
        plane, mask, depth, front, depth_of = _lying_beaker(towards, lip=1.06)
        rec = Reconstructor(ReconstructConfig(open_explains=share))(rgb, mask, K, plane, "",
                                                                    depth)
        assert rec.meta["resting"] == "lying" and "open_top" not in rec.meta
        T, scale = np.array(rec.meta["pose_hint"]["T_cam_obj"]), rec.meta["pose_hint"]["scale"]
        closed, opened = depth_of(rec.mesh, T, scale), depth_of(rec.open_alternative, T, scale)
        assert towards or np.nanmean(np.abs(opened - closed)) < 1e-4
        v = rec.open_alternative.vertices
        floor = v[np.hypot(v[:, 0], v[:, 1]) < 0.5 * np.hypot(v[:, 0], v[:, 1]).max(), 2]
        assert np.ptp(floor) < 0.15  # the axis is covered at one end only: the other is open
        mouth = 1.0 if floor.mean() < 0.5 else 0.0
        ends = [T[:3, 3] + scale * z * T[:3, 2] for z in (mouth, 1.0 - mouth)]
        # the true mouth is the end further from the camera when turned away, nearer when not
        assert (np.linalg.norm(ends[0]) > np.linalg.norm(ends[1])) != towards


@pytest.mark.slow
def test_shape_error_on_generated_glassware(synth_set):
    """Chamfer / height against the ground-truth mesh's outer envelope, ground-truth masks."""
    errors = []
    for source in discover_scenes(synth_set, IOConfig(), None):
        fid = source.frame_ids()[0]
        frame = source.load_frame(fid)
        gt = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
        from sr3d_cli.geometry.plane import support_plane
        from sr3d_cli.config import PlaneConfig

        plane = support_plane(frame.depth_m, frame.camera.K, PlaneConfig(), exclude=gt > 0)
        for obj in source.load_gt_objects(fid)["objects"]:
            mask = gt == obj["id"]
            if obj["pose"] != "standing" or mask.sum() < 300 or mask[0].any() or \
                    mask[:, 0].any() or mask[-1].any() or mask[:, -1].any():
                continue
            fit = fit_revolution(mask, frame.camera.K, plane)
            truth = trimesh.load(source.root / obj["mesh"])
            errors.append(chamfer_distance(revolve(fit.profile), revolve(profile_from_mesh(truth))))
    assert len(errors) >= 5
    assert np.median(errors) < 0.03


def test_bad_masks_are_refused_with_the_reason():
    cfg = ReconstructConfig(allow_border=False)
    mask = np.zeros((50, 60), bool)
    with pytest.raises(ObjectError, match="empty"):
        check_mask(mask, cfg)
    mask[10:14, 10:14] = True
    with pytest.raises(ObjectError, match="16 px"):
        check_mask(mask, cfg)
    mask[0:30, 20:40] = True
    check_mask(mask, cfg)
    with pytest.raises(ObjectError, match="border"):
        check_border(mask, cfg, K)
    assert check_border(mask, ReconstructConfig(), K) == "base or side"


def _cut_bottle(u: float, v: float):
    """A 0.30 m bottle (radius 0.03 m) standing where the ray through pixel (u, v) meets a table
    seen from 30 degrees; its mask as the 640 x 480 image cuts it."""
    plane = _table(30.0, 0.6)
    base = plane.intersect(np.linalg.solve(K, [u, v, 1.0]))
    r, h = 0.03, 0.30
    prof = np.array([[0, 0], [r, 0], [r, h], [0, h]])
    return plane, base, r, _render(prof, base, plane.normal)


def test_a_bottle_whose_top_the_image_cuts_is_fitted_from_its_base_and_width():
    plane, base, r, mask = _cut_bottle(330.0, 200.0)
    assert mask[0].any() and not (mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())
    result = Reconstructor(ReconstructConfig())(np.zeros((480, 640, 3), np.uint8), mask, K, plane)
    meta = result.meta
    assert meta["cut_by_border"] == "top" and meta["resting"] == "standing"
    T = np.array(meta["pose_hint"]["T_cam_obj"])
    assert np.linalg.norm(T[:3, 3] - base) < 0.004
    assert np.degrees(np.arccos(T[:3, 2] @ plane.normal)) < 2
    height = meta["pose_hint"]["scale"]
    assert meta["silhouette_iou"] > 0.95
    # the model runs at least to the border, with the bottle's width there
    radius = result.mesh.vertices[:, 0].max() * height
    assert radius == pytest.approx(r, rel=0.05)
    top = project((base + height * plane.normal)[None], K)[0]
    assert top[1] < 5  # its top cap reaches past row 0


@pytest.mark.parametrize("u, v", [(15.0, 380.0), (330.0, 470.0)])
def test_an_object_the_border_cuts_at_its_side_or_base_is_refused_only_when_asked(u, v):
    plane, _, _, mask = _cut_bottle(u, v)
    assert mask[0].any() or mask[-1].any() or mask[:, 0].any()
    rgb = np.zeros((480, 640, 3), np.uint8)
    with pytest.raises(ObjectError, match="border lower than the upper half"):
        Reconstructor(ReconstructConfig(allow_border=False))(rgb, mask, K, plane)
    meta = Reconstructor(ReconstructConfig())(rgb, mask, K, plane).meta
    assert meta["cut_by_border"] == "base or side" and meta["silhouette_iou"] > 0.97


def test_a_bottle_whose_base_the_image_cuts_is_fitted_standing_near_its_place():
    """The 30 cm bottle cut about 3 cm above its foot by the image's bottom row (and at its top
    by the top row): standing, upright, its radius within 15% and its base within 4 cm of the
    true ones (measured: 34.3 mm against 30, 32 mm off). Its size and place are a guess from
    the outline that remains; the sensor's holes there would be far worse."""
    plane, base, r, mask = _cut_bottle(330.0, 470.0)
    result = Reconstructor(ReconstructConfig())(np.zeros((480, 640, 3), np.uint8), mask, K, plane)
    meta = result.meta
    assert meta["resting"] == "standing"
    T = np.array(meta["pose_hint"]["T_cam_obj"])
    assert np.degrees(np.arccos(min(1.0, T[:3, 2] @ plane.normal))) < 1
    assert np.linalg.norm(T[:3, 3] - base) < 0.04
    v = result.mesh.vertices * meta["pose_hint"]["scale"]
    assert np.hypot(v[:, 0], v[:, 1]).max() == pytest.approx(r, rel=0.15)


def _object_mask():
    mask = np.zeros((120, 160), bool)
    mask[30:90, 60:100] = True
    return np.zeros((120, 160, 3), np.uint8), mask


def test_onnx_density_grid_gives_the_sphere(tmp_path):
    path = onnx_builders.density_sphere(tmp_path / "grid.onnx")
    cfg = ReconstructConfig(backend="onnx", onnx_model=str(path))
    rgb, mask = _object_mask()
    out = Reconstructor(cfg)(rgb, mask, np.eye(3), None)
    assert out.mesh.is_watertight and out.mesh.volume > 0
    assert out.mesh.bounds[1][2] - out.mesh.bounds[0][2] == pytest.approx(1.0)
    # before normalisation the iso-surface radius is sqrt(0.25 - 25 / 1e4)
    from sr3d_cli.reconstruct.onnx_models import DensityGridModel

    raw = DensityGridModel(cfg)(rgb, mask)
    radius = np.linalg.norm(raw.vertices, axis=1)
    assert np.median(radius) == pytest.approx(np.sqrt(0.25 - 0.0025), abs=0.01)


def test_onnx_triplane_pair_gives_the_sphere(tmp_path):
    enc, dec = onnx_builders.triplane_pair(tmp_path / "enc.onnx", tmp_path / "dec.onnx")
    cfg = ReconstructConfig(backend="onnx", onnx_model=str(enc), onnx_decoder=str(dec),
                            onnx_resolution=40)
    from sr3d_cli.reconstruct.onnx_models import TriplaneModel

    rgb, mask = _object_mask()
    raw = TriplaneModel(cfg)(rgb, mask)
    radius = np.linalg.norm(raw.vertices, axis=1)
    assert np.median(radius) == pytest.approx(np.sqrt(0.25 - 0.0025), abs=0.02)
    assert raw.is_watertight


def test_onnx_problems_are_clear(tmp_path):
    path = onnx_builders.density_sphere(tmp_path / "grid.onnx")
    cfg = ReconstructConfig(backend="onnx", onnx_model=str(path), onnx_threshold=1e9)
    rgb, mask = _object_mask()
    with pytest.raises(ValueError, match="never crosses the threshold"):
        Reconstructor(cfg)(rgb, mask, np.eye(3), None)
    enc, _ = onnx_builders.triplane_pair(tmp_path / "enc.onnx", tmp_path / "dec.onnx")
    with pytest.raises(InputError, match="expected"):
        Reconstructor(ReconstructConfig(backend="onnx", onnx_model=str(enc),
                                        onnx_decoder=str(path)))


def test_library_picks_by_label_then_by_shape(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    tall = revolve(np.array([[0, 0], [0.02, 0], [0.02, 0.2], [0, 0.2]]))
    squat = revolve(np.array([[0, 0], [0.05, 0], [0.05, 0.06], [0, 0.06]]))
    tall.export(lib / "test_tube.ply")
    (squat.apply_scale(1000)).export(lib / "dish_mm.stl")  # millimetres: normalised on load
    plane = _table(50.0, 0.5)
    base = plane.intersect(np.array([0.0, 0.05, 1.0]))
    mask = _render(np.array([[0, 0], [0.045, 0], [0.045, 0.05], [0, 0.05]]), base, plane.normal)
    rec = Reconstructor(ReconstructConfig(backend="library", library=str(lib)))
    assert rec(np.zeros((480, 640, 3), np.uint8), mask, K, plane, "").meta["library_mesh"] \
        == "dish_mm"
    out = rec(np.zeros((480, 640, 3), np.uint8), mask, K, plane, "a test_tube")
    assert out.meta["library_mesh"] == "test_tube"
    assert out.mesh.bounds[1][2] == pytest.approx(1.0)


def test_cli_reconstruct_writes_watertight_meshes_and_object_messages(synth_set, tmp_path):
    out = tmp_path / "out"
    scene = str(synth_set / "scene_0001")
    runner = CliRunner()
    result = runner.invoke(cli, ["reconstruct", scene, "--out", str(out), "-q"])
    assert result.exit_code == 1 and "run `sr3d segment` first" in result.output
    result = runner.invoke(cli, ["reconstruct", scene, "--out", str(out), "--masks", "gt", "-q"])
    assert result.exit_code == 0, result.output
    plys = sorted((out / "meshes" / "000000").glob("*.ply"))
    assert plys
    for ply in plys:
        mesh = trimesh.load(ply)
        assert mesh.is_watertight and mesh.volume > 0
        assert mesh.bounds[0][2] == pytest.approx(0) and mesh.bounds[1][2] == pytest.approx(1)
        meta = json.loads(ply.with_suffix(".json").read_text())
        assert meta["resting"] in ("standing", "lying")


CONTAINER = np.array([[0, 0], [0.03, 0], [0.03, 0.1], [0, 0.1]])  # a lidded tub, metres


def _container_frame(elevation: float, x: float, y: float, lid: bool):
    """:func:`_frame_from_above` of :data:`CONTAINER`: with ``lid``, its lid read wherever the
    camera sees it (an opaque lid), else open (its inside read, glass 2 mm thick). Returns
    plane, mask, depth."""
    h = float(CONTAINER[-1, 1])
    if lid:
        frame = _frame_from_above(CONTAINER, elevation, x, y, noise=0.004, read_from=h - 0.001)
    else:
        frame = _frame_from_above(CONTAINER, elevation, x, y, noise=0.004,
                                  surface=open_vessel(CONTAINER[:-1], 0.002, 0.006))
    return frame[:3]


def test_a_lid_read_from_low_down_keeps_a_top_shut_that_the_fit_misplaces():
    """A lidded tub 10 cm tall seen from 30 and 40 deg above the table, its lid read, fitted
    8 mm short or 8 mm tall (as the Tracebot containers are from their masks): along the rays
    the lid then lies over ``DEPTH_BAND`` off the closed model's, and the closed model holds
    4-36 readings more than the opened one, or 31-47 fewer, under the 30 that keep it shut in
    11 of the 12 views: the top came out open. By their height over the table the lid's
    readings lie at the rim; an open tub's inside and the table through its floor lie below
    it, and it stays open. Seen from nearly level (cos 0.16 between the line of sight and the
    axis) the rim's image holds only the rim, and the readings say nothing."""
    from sr3d_cli.reconstruct import lids, open_mouth

    cfg = ReconstructConfig()
    shut = []
    for elevation in (30.0, 40.0):
        for x, y in ((0.0, 0.0), (0.05, 0.03), (-0.04, 0.06)):
            for lid in (True, False):
                plane, mask, depth = _container_frame(elevation, x, y, lid)
                for height in (0.092, 0.108):
                    r = 0.03 / height
                    fit = RevolutionFit(np.array([[0, 0], [r, 0], [r, 1], [0, 1]]),
                                        plane.intersect(np.array([x, y, 1.0])),
                                        plane.normal.copy(), height, "standing", 0.95)
                    if lid:
                        shut.append(open_mouth(fit, cfg, mask, K, plane, depth) is None)
                    else:
                        assert open_mouth(fit, cfg, mask, K, plane, depth) is not None
    assert all(shut) and len(shut) == 12
    plane, mask, depth = _container_frame(20.0, 0.0, 0.0, True)
    fit = RevolutionFit(np.array([[0, 0], [0.3, 0], [0.3, 1], [0, 1]]),
                        plane.intersect(np.array([0.0, 0.0, 1.0])), plane.normal.copy(), 0.1,
                        "standing", 0.95)
    assert not lids.lid_read(fit, mask, K, plane, depth)


def test_an_open_beaker_looked_into_stands_by_the_readings_inside_it(tmp_path):
    """A 12.6 cm beaker seen from 64 degrees above the table (generated scene 20 of seed
    1500): its outline fits a short lying solid about as well as the standing one, so the raw
    readings vote. Most of them lie inside the beaker, on its floor and inner wall, which only
    the open standing model has: counted on the lidded one, the lying fit takes 70 of them
    against 29, and the beaker is laid down (a 42 mm depth error over it). A change to the
    generator redraws the scene: then pick another such beaker from generated frames."""
    from sr3d_cli.config import PlaneConfig
    from sr3d_cli.geometry.plane import support_plane

    source, frame, ids = generated_frame(tmp_path, 1500, 20, renderer="auto")
    truth = next(o for o in source.load_gt_objects("000000")["objects"] if o["id"] == 3)
    assert truth["label"] == "beaker"
    K_frame = frame.camera.K
    plane = support_plane(frame.depth_m, K_frame, PlaneConfig(), exclude=ids > 0)
    mask = ids == 3
    # without the open models the readings are counted on the closed solids only
    assert fit_revolution(mask, K_frame, plane, depth=frame.depth_m).resting == "lying"
    rec = Reconstructor(ReconstructConfig())(frame.rgb, mask, K_frame, plane, "", frame.depth_m)
    assert rec.meta["resting"] == "standing" and rec.meta["open_top"]
    axis = np.asarray(rec.meta["pose_hint"]["T_cam_obj"])[:3, 2]
    assert axis @ plane.normal > np.cos(np.radians(3))
    # measured: 13.95 cm (the hidden rim makes it 10% tall; the lying fit is 13.5 cm long)
    assert rec.meta["pose_hint"]["scale"] == pytest.approx(truth["scale"], rel=0.12)


def _wall_fit(lean_deg: float, resting: str = "standing", bulge: float = 0.0) -> RevolutionFit:
    """A 100 mm fit whose wall (40 mm radius at the base) leans ``lean_deg`` outwards, with a
    lip at the top and ``bulge`` metres of bow at mid-height."""
    h = 0.1
    z = np.linspace(0.005, 0.095, 30)
    r = 0.04 + np.tan(np.radians(lean_deg)) * z + bulge * np.sin(np.pi * z / h)
    r[-2:] += 0.002  # lip
    prof = np.vstack([[0.0, 0.0], np.column_stack([r, z]), [0.0, h]]) / h
    return RevolutionFit(prof, np.zeros(3), np.array([0.0, 0.0, 1.0]), h, resting, 1.0)


def test_straight_walls_sets_a_slightly_leaning_wall_upright_and_nothing_else():
    fit = straight_walls(_wall_fit(1.0), 2.0)
    r, z = fit.profile[1:-1, 0] * fit.height, fit.profile[1:-1, 1] * fit.height
    wall = (z >= 0.01) & (z <= 0.09)
    # the fitted lean (1 deg: 1.4 mm over the wall) is gone, the lip and the ends stay
    assert np.ptp(r[wall]) < 1e-9
    assert abs(np.median(r[wall]) - (0.04 + np.tan(np.radians(1.0)) * 0.05)) < 2e-4
    assert r[-1] - r[wall].max() > 0.0015
    assert np.allclose(fit.profile[[0, -1]], _wall_fit(1.0).profile[[0, -1]])
    # a real taper (4 deg), a bowed wall (4 mm), a lying fit or 0 deg: unchanged
    for other, deg in ((_wall_fit(4.0), 2.0), (_wall_fit(0.5, bulge=0.004), 2.0),
                       (_wall_fit(4.0, "lying"), 2.0), (_wall_fit(1.0), 0.0)):
        assert np.array_equal(straight_walls(other, deg).profile, other.profile)


def _standing_fit(radii: np.ndarray, z: np.ndarray, plane: Plane, x: float, y: float
                  ) -> RevolutionFit:
    """A standing fit of ``radii`` (L,) at heights ``z`` (L,), metres, on ``plane`` under the
    pixel ray through (x, y, 1)."""
    h = float(z[-1])
    prof = np.vstack([[0.0, 0.0], np.column_stack([radii, z]), [0.0, h]]) / h
    return RevolutionFit(prof, plane.intersect(np.array([x, y, 1.0])), plane.normal, h,
                         "standing", 1.0)


def test_an_open_vessels_rim_curled_inwards_is_widened_unless_its_outline_shows_it():
    """A glass bowl 60 mm tall (76 mm in radius at 45 mm, 82 mm at its rim) fitted with its
    top 15 mm curled in to 66 mm, seen from 40-70 deg above the table at two places: widened
    to its widest level, it draws the bowl's outline better (measured IoU 0.81-0.85 curled,
    0.88-0.93 widened). A tulip glass (42 mm in radius at its bowl, 30 mm at its rim) fitted
    exactly, seen from 10-45 deg, keeps its rim drawn in."""
    from sr3d_cli.reconstruct import widened_rim

    h = 0.06
    bowl = np.array([[0.03, 0], [0.05, 0.012], [0.066, 0.03], [0.078, 0.048], [0.082, h]])
    z = np.linspace(0, h, 21)
    r = np.interp(z, bowl[:, 1], bowl[:, 0])
    curled = np.where(z > 0.045, np.interp(z, [0.045, h], [r[z <= 0.045][-1], 0.066]), r)
    for elevation in (40.0, 55.0, 70.0):
        plane = _table(elevation, 0.5)
        for x, y in ((0.0, 0.0), (0.05, 0.03)):
            mask = fit_silhouette(_standing_fit(r, z, plane, x, y), K, (480, 640))
            fit = _standing_fit(curled, z, plane, x, y)
            before = mask_iou(fit_silhouette(fit, K, mask.shape), mask)
            wide = widened_rim(fit, mask, K)
            assert wide is not fit and before < 0.86 and wide.iou > before + 0.06
            assert wide.profile[-2, 0] * h == pytest.approx(r[z <= 0.045].max())
    tulip = np.array([[0.005, 0.01], [0.004, 0.09], [0.03, 0.11], [0.042, 0.15], [0.036, 0.19],
                      [0.03, 0.2]])
    for elevation in (10.0, 20.0, 30.0, 45.0):
        plane = _table(elevation, 0.5)
        fit = _standing_fit(tulip[:, 0], tulip[:, 1], plane, 0.0, 0.0)
        assert widened_rim(fit, fit_silhouette(fit, K, (480, 640)), K) is fit


def test_straight_walls_keeps_the_wall_upright_up_to_the_lip():
    """A lip spread over the top 15 mm (as the fit and the smoothing leave a beaker's): the wall
    goes upright to the level below the top, the top keeps the lip; a top narrower than the
    wall (a bottle's shoulder) is left as fitted."""
    h = 0.1
    z = np.linspace(0.005, 0.1, 39)
    flared = 0.04 + 0.0025 * np.clip((z - 0.085) / 0.015, 0, 1)
    # spread from 85% of the height: 1.7 mm wider at 90%, which the wall's own line (10-85%)
    # must not take in, or the wall does not count as straight and nothing is set upright
    low_flare = 0.04 + 0.005 * np.clip((z - 0.085) / 0.015, 0, 1)
    narrowed = 0.04 - 0.01 * np.clip((z - 0.085) / 0.015, 0, 1)
    for r, top_kept in ((flared, True), (low_flare, True), (narrowed, False)):
        prof = np.vstack([[0.0, 0.0], np.column_stack([r, z]), [0.0, h]]) / h
        fit = RevolutionFit(prof, np.zeros(3), np.array([0.0, 0.0, 1.0]), h, "standing", 1.0)
        out = straight_walls(fit, 2.0).profile[1:-1, 0] * h
        assert out[-1] == pytest.approx(r[-1])
        if top_kept:
            assert np.allclose(out[:-1], 0.04) and out[-1] - out[-2] > 0.002
        else:
            assert np.allclose(out[z > 0.09], r[z > 0.09])
    # lying, the mouth may be either end: a lip spread at the base end is cut back too, and
    # a shoulder narrowing at the other is kept
    r = 0.04 + 0.005 * np.clip((0.015 - z) / 0.01, 0, 1) \
        - 0.01 * np.clip((z - 0.085) / 0.015, 0, 1)
    prof = np.vstack([[0.0, 0.0], np.column_stack([r, z]), [0.0, h]]) / h
    fit = RevolutionFit(prof, np.zeros(3), np.array([1.0, 0.0, 0.0]), h, "lying", 1.0)
    out = straight_walls(fit, 2.0).profile[1:-1, 0] * h
    assert out[0] == pytest.approx(r[0]) and np.allclose(out[1:][z[1:] < 0.085], 0.04)
    assert np.allclose(out[z > 0.09], r[z > 0.09])


@pytest.mark.parametrize("behind, aside", [(0.06, 0.04), (0.08, 0.02)])
def test_a_glass_whose_foot_an_opaque_solid_in_front_hides_stands_where_it_stands(behind,
                                                                                  aside):
    """As below, but what stands in front is opaque: no instance, only the depth camera's
    readings on it. They make it an occluder (:func:`opaque_objects`), so the fit reaches down
    behind it as behind a glass; readings on the table, a speck of noise and the glass's own
    readings are no object."""
    ids, K2, plane, depth = solids_on_table([(GLASS, 0.1, 0.0, -0.03),
                                             (GLASS, 0.1, aside, behind - 0.03)])
    back, true_base = ids == 2, table_point(plane, aside, behind - 0.03)
    sparse = np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)
    readings = np.where(ids == 1, depth, sparse)  # the front solid read in full
    ys, xs = np.mgrid[:depth.shape[0], :depth.shape[1]]
    table_depth = plane.intersect_pixels(np.column_stack([xs.ravel(), ys.ravel()]), K2)[:, 2]
    readings = np.where(ids == 0, np.nan_to_num(table_depth.reshape(depth.shape)), readings)
    readings[5:9, 5:9] = 0.3  # a speck of noise near the camera: 16 pixels
    glasses = np.where(ids == 2, 2, 0)
    solids = opaque_objects(glasses, readings, K2, plane)
    assert set(np.unique(solids)) == {0, 2, 3}
    assert ((solids == 3) == (ids == 1)).mean() > 0.99
    front = occluders(solids, 2, K2, plane)
    assert front is not None and occluders(glasses, 2, K2, plane) is None
    fit = fit_revolution(back, K2, plane, depth=sparse, occluders=front)
    assert fit.resting == "standing"
    assert np.linalg.norm(fit.base - true_base) < 0.008
    assert np.linalg.norm(fit_revolution(back, K2, plane, depth=sparse).base - true_base) > 0.01


@pytest.mark.parametrize("behind, aside", [(0.06, 0.04), (0.08, 0.02), (0.065, 0.03),
                                           (0.09, 0.0)])
def test_a_glass_whose_foot_a_glass_in_front_hides_stands_where_it_stands(behind, aside):
    """A glass standing ``behind`` m further than another and ``aside`` m to the side: the front
    one hides its foot and the lower part of one side. Fitted to its mask alone, the outline
    ends where the front glass crosses it, and the fit stands there or lies down (74-86 mm from
    the true base; with its readings, 12-54 mm). The front glass's pixels count as hidden
    (neither matched nor missed): the fit reaches down behind it (1-7 mm). Straight behind,
    only the top third shows; the readings on it then say how much nearer it stands."""
    ids, K2, plane, depth = solids_on_table([(GLASS, 0.1, 0.0, -0.03),
                                             (GLASS, 0.1, aside, behind - 0.03)])
    back, true_base = ids == 2, table_point(plane, aside, behind - 0.03)
    sparse = np.where(np.random.default_rng(0).random(depth.shape) < 0.3, depth, 0.0)
    front = occluders(ids, 2, K2, plane)
    assert occluders(ids, 1, K2, plane) is None  # nothing stands in front of the front glass
    near = cv2.dilate(back.astype(np.uint8), np.ones((21, 21), np.uint8)) > 0
    assert not (front & (ids != 1)).any() and front[near & (ids == 1)].all()
    plain = fit_revolution(back, K2, plane, depth=sparse)
    assert np.linalg.norm(plain.base - true_base) > 0.01
    fit = fit_revolution(back, K2, plane, depth=sparse, occluders=front)
    assert fit.resting == "standing"
    assert np.linalg.norm(fit.base - true_base) < 0.008
    assert fit.height == pytest.approx(0.1, rel=0.08)


def test_without_spill_takes_thin_spikes_beside_another_instance_only():
    """Spikes two pixels wide along another instance are spill, but not along one in front
    (there the outline is the other's); a stem three pixels wide away from every other
    instance, and a mask with no neighbour, stay whole."""
    from sr3d_cli.geometry import occlusion

    ids = np.zeros((90, 90), np.int32)
    ids[5:17, 25:56] = 2  # the instance behind
    ids[20:61, 20:61] = 1
    for x in (30, 40, 50):
        ids[17:20, x:x + 2] = 1  # spikes of 1 reaching up to 2
    ids[61:76, 39:42] = 1  # a stem
    trimmed = occlusion.without_spill(ids, 1)
    assert not trimmed[17:19].any()  # the row next to the body stays (the disc's tip)
    assert trimmed[61:76, 39:42].all() and trimmed[20:61, 20:61].all()
    assert (ids == 1).sum() - trimmed.sum() == 3 * 4
    assert np.array_equal(occlusion.without_spill(ids, 1, front=ids == 2), ids == 1)
    alone = np.where(ids == 2, 0, ids)
    assert np.array_equal(occlusion.without_spill(alone, 1), alone == 1)
    thin = np.zeros_like(ids)
    thin[5:17, 25:56] = 2
    thin[17:40, 30:33] = 1  # all of it thin and beside 2: kept whole
    assert np.array_equal(occlusion.without_spill(thin, 1), thin == 1)


def test_a_lying_glass_seen_obliquely_is_fitted_again_from_flat_ends(extsim, monkeypatch):
    """extsim scene 6: a water glass (125 mm long, 40 mm in radius) lying with its mouth
    towards the camera, 40 degrees off its axis. From its true mask the outline fit stops
    with a bulge near one end (48 mm radius) at IoU 0.90; started again from flat ends and
    shortened it reaches IoU 0.97 with the glass's radius (40 mm). Its ends still narrow and
    it comes out too long (162 mm): the refit mends the width, not the length."""
    from sr3d_cli import reconstruct
    from sr3d_cli.config import Config
    from sr3d_cli.geometry.plane import support_plane

    cfg = Config()
    source = [s for s in discover_scenes(extsim, cfg.io, None) if s.name == "scene_0006"][0]
    frame = source.load_frame("000000")
    ids = source.load_mask(source.gt_mask_path("000000"), frame.depth_m.shape)
    K = frame.camera.K
    plane = support_plane(frame.depth_m, K, cfg.plane, exclude=ids > 0)
    mask = ids == 2

    def fitted():
        return reconstruct.configured_fit(mask, K, plane, cfg.reconstruct, frame.depth_m,
                                          (ids > 0) & ~mask)

    fit = fitted()
    monkeypatch.setattr(reconstruct, "flat_ended", lambda first, *args: first)
    first = fitted()

    def widest(f):
        return f.profile[:, 0].max() * f.height

    assert first.resting == fit.resting == "lying"
    # measured: 0.896 -> 0.972, widest radius 47.7 -> 39.8 mm
    assert first.iou < 0.91 and fit.iou > 0.96
    assert widest(first) > 0.046 and abs(widest(fit) - 0.040) < 0.002


@pytest.mark.slow
def test_a_bowls_ridge_along_the_pitcher_behind_it_is_left_out_of_its_fit(extsim, tmp_path,
                                                                          monkeypatch):
    """extsim scene 14: the segmenter's instance of the glass bowl (IoU 0.995) keeps a ridge
    of a few pixels along the pitcher behind it at the top of its outline, which the outline
    fit takes for its far rim. Measured, whole `repair-depth`, object MAE over the bowl's
    true mask: 7.4 mm without the ridge, 25.6 mm with it."""
    from sr3d_cli.geometry import occlusion
    from sr3d_cli.io.images import read_depth

    def bowl_mae(out) -> float:
        result = CliRunner().invoke(cli, ["repair-depth", str(extsim / "scene_0014"), "--out",
                                          str(out), "-q"], catch_exceptions=False)
        assert result.exit_code == 0
        truth = cv2.imread(str(extsim / "scene_0014" / "gt" / "masks" / "000000.png"),
                           cv2.IMREAD_UNCHANGED) == 1
        gt = read_depth(extsim / "scene_0014" / "gt" / "depth" / "000000.png", 0.001)
        repaired = read_depth(out / "repaired" / "000000.png", 0.001)
        return float(np.abs(repaired - gt)[truth].mean() * 1000)

    assert bowl_mae(tmp_path / "a") < 9.0
    monkeypatch.setattr(occlusion, "SPILL_SHARE", 0.0)
    assert bowl_mae(tmp_path / "b") > 20
