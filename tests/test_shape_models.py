"""Shape models beyond a plain surface of revolution, on small rendered scenes with known truth:
a handle split off a mug's outline (standing or lying) and modelled as a slab, a dome not
taken for a bowl."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from sr3d_cli.config import ReconstructConfig
from sr3d_cli.geometry.camera import Camera, unproject
from sr3d_cli.geometry.revolution import revolve
from sr3d_cli.reconstruct import Reconstructor, configured_fit, mouths
from sr3d_cli.reconstruct.bowls import NARROW_TOP, bowl_instead
from sr3d_cli.reconstruct.handles import handle_slab, split_handle
from sr3d_cli.shape.revolution_fit import fit_revolution
from sr3d_cli.render import RenderMesh, make_renderer
from sr3d_cli.geometry.transforms import place_points
from tests.scenes import K_TABLE, solids_on_table, table, table_point

BODY_R, BODY_H = 0.035, 0.09  # metres: the mug's cylinder
TUBE = 0.008  # metres: the handle's square section
REACH = 0.03  # metres the handle stands out from the wall


def _mug() -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    """The mug in its object frame: the cylinder of unit height (scaled by ``BODY_H``) and,
    in metres, a C-shaped handle of three boxes standing out along +x."""
    body = revolve(np.array([[0, 0], [BODY_R, 0], [BODY_R, BODY_H], [0, BODY_H]]) / BODY_H)
    parts = []
    for extent, centre in (((REACH, TUBE, TUBE), (BODY_R + REACH / 2, 0, 0.07)),
                           ((REACH, TUBE, TUBE), (BODY_R + REACH / 2, 0, 0.02)),
                           ((TUBE, TUBE, 0.05 + TUBE), (BODY_R + REACH - TUBE / 2, 0, 0.045))):
        box = trimesh.creation.box(extent)
        box.apply_translation(centre)
        parts.append(box)
    return body, trimesh.util.concatenate(parts)


def _mug_frame(turn: float = 0.0):
    """A standing cylinder with a C-shaped handle of three boxes on its right (image +x),
    turned ``turn`` deg about the cylinder's axis away from the camera, seen from the tests'
    table camera. Returns (ids (H, W), K, plane, depth (H, W) m, the handle's own depth
    (H, W) m (0 off it))."""
    plane = table()
    up = plane.normal
    t = np.radians(turn)
    x_dir = np.array([1.0, 0, 0])
    x_dir = np.cos(t) * x_dir + np.sin(t) * np.cross(up, x_dir)
    R = np.stack([x_dir, np.cross(up, x_dir), up], 1)
    base = table_point(plane, 0.0, 0.0)
    body, handle = _mug()
    cam = Camera(K_TABLE, 640, 480)
    renderer = make_renderer("numpy")
    meshes = [RenderMesh(body.vertices @ (BODY_H * R).T + base, np.asarray(body.faces), 1),
              RenderMesh(handle.vertices @ R.T + base, np.asarray(handle.faces), 1)]
    out = renderer.render(meshes, cam)
    alone = renderer.render(meshes[1:], cam)
    return out.ids, K_TABLE, plane, out.depth.astype(np.float64), \
        np.where(out.depth == alone.depth, alone.depth, 0.0).astype(np.float64)


def _slab_depth_error(turn: float) -> tuple[float, float]:
    """The handle of :func:`_mug_frame` (``turn``) split off and its slab placed on the body
    fitted without it: (median |depth error| over the handle's seen pixels the slab covers
    (m), the share of those pixels it covers)."""
    ids, K, plane, depth, handle_depth = _mug_frame(turn)
    body, handle = split_handle(ids == 1, K, plane)
    truth = handle_depth > 0
    fit = fit_revolution(body, K, plane, depth=depth)
    slab = handle_slab(handle, int((ids == 1).sum()), fit.T_cam_obj, fit.height, K)
    assert slab is not None and slab.is_watertight and slab.volume > 0
    placed = RenderMesh(place_points(slab.vertices, fit.T_cam_obj, fit.height),
                        np.asarray(slab.faces), 1)
    drawn = make_renderer("numpy").render([placed], Camera(K, 640, 480)).depth
    both = (drawn > 0) & truth
    return float(np.median(np.abs(drawn[both] - handle_depth[both]))), both.sum() / truth.sum()


def test_a_handle_is_split_off_and_the_body_fitted_without_it():
    """The handle's pixels are split off (those of the handle the camera sees, not the
    body's); the body fitted on the rest has the cylinder's radius within 4%, where the whole
    outline widens it by more than 10%."""
    ids, K, plane, depth, handle_depth = _mug_frame()
    mask = ids == 1
    body, handle = split_handle(mask, K, plane)
    truth = handle_depth > 0
    assert handle.sum() > 0.6 * truth.sum()
    assert (handle & ~truth).sum() < 0.05 * handle.sum()
    assert (body | handle).sum() == mask.sum() and not (body & handle).any()

    def radius(m):
        fit = fit_revolution(m, K, plane, depth=depth)
        return np.median(fit.profile[1:-1, 0]) * fit.height, fit

    r_body, fit = radius(body)
    r_all, _ = radius(mask)
    assert r_body == pytest.approx(BODY_R, rel=0.04)
    assert r_all > 1.1 * BODY_R
    # the slab over the handle's pixels lies within a tube's width of the true handle's depth
    error, covered = _slab_depth_error(0.0)
    assert covered > 0.8 and error < TUBE


@pytest.mark.parametrize("turn", [20.0, 30.0, 40.0])
def test_a_handle_turned_towards_the_back_is_placed_in_its_own_plane(turn):
    """Seen from above, a handle turned away from the camera lies farther along its rays than
    the plane across the line of sight, which lifts it above the body's top. Measured, median
    depth error over the handle: 2.8, 7.4, 3.8 mm (20, 30, 40 deg); in the plane across the
    line of sight, no slab at all (the handle stands above the body). Side-on: 6.1 mm (0.6 mm
    in the plane across the line of sight)."""
    error, covered = _slab_depth_error(turn)
    assert covered > 0.8 and error < TUBE


def _lying_mug_frame(turn: float, side: float):
    """The mug of :func:`_mug_frame` lying on the table, its axis ``turn`` deg from the image's
    x axis within the table, its handle standing out sideways along the table (``side`` +1 or
    -1: away from the camera or towards it). Returns (mask (H, W) bool, K, plane, depth (H, W)
    m, the handle's seen pixels (H, W) bool)."""
    plane = table()
    up = plane.normal
    x0 = np.array([1.0, 0, 0]) - up[0] * up
    x0 /= np.linalg.norm(x0)
    t = np.radians(turn)
    axis = np.cos(t) * x0 + np.sin(t) * np.cross(up, x0)
    out_dir = side * np.cross(up, axis)
    R = np.stack([out_dir, np.cross(axis, out_dir), axis], 1)
    base = table_point(plane, 0.0, 0.0) + BODY_R * up - 0.5 * BODY_H * axis
    body, handle = _mug()
    renderer = make_renderer("numpy")
    meshes = [RenderMesh(body.vertices @ (BODY_H * R).T + base, np.asarray(body.faces), 1),
              RenderMesh(handle.vertices @ R.T + base, np.asarray(handle.faces), 1)]
    out = renderer.render(meshes, Camera(K_TABLE, 640, 480))
    alone = renderer.render(meshes[1:], Camera(K_TABLE, 640, 480))
    return out.ids == 1, K_TABLE, plane, out.depth.astype(np.float64), \
        (alone.depth > 0) & (out.depth == alone.depth)


@pytest.mark.parametrize("turn, side", [(0.0, 1.0), (0.0, -1.0), (30.0, 1.0), (30.0, -1.0)])
def test_a_lying_mugs_handle_is_split_off_beside_its_axis(turn, side):
    """A mug lying across the image, its handle beside it: the upright line through the body
    crosses the handle, the body's own long axis does not. Measured: 0.84-0.97 of the handle's
    pixels split off, none of the body's; the lying body fitted without them 34.6-34.7 mm in
    radius (35 true) and 88.7-90.1 mm long (90), IoU 0.98-0.99; with them 38.9-45.2 mm and
    60.4-97.9 mm, IoU 0.82-0.89 (the handle was not split before the long axis was read)."""
    mask, K, plane, depth, truth = _lying_mug_frame(turn, side)
    body, handle = split_handle(mask, K, plane)
    assert (handle & truth).sum() > 0.8 * truth.sum() and not (handle & ~truth).any()
    fit = fit_revolution(body, K, plane, depth=depth)
    whole = fit_revolution(mask, K, plane, depth=depth)
    assert fit.resting == "lying" and fit.iou > 0.97 and whole.iou < 0.9
    assert np.median(fit.profile[1:-1, 0]) * fit.height == pytest.approx(BODY_R, rel=0.03)
    assert fit.height == pytest.approx(BODY_H, rel=0.03)
    assert np.median(whole.profile[1:-1, 0]) * whole.height > 1.1 * BODY_R


def test_a_goblet_stem_and_a_bottle_neck_are_no_handles():
    goblet = [[0, 0], [0.035, 0], [0.035, 0.004], [0.004, 0.008], [0.004, 0.07],
              [0.035, 0.1], [0.04, 0.15], [0, 0.15]]
    bottle = [[0, 0], [0.04, 0], [0.04, 0.16], [0.011, 0.2], [0.011, 0.25], [0, 0.25]]
    ids, K, plane, _ = solids_on_table([(goblet, 0.15, -0.1, 0.0), (bottle, 0.25, 0.1, 0.05)])
    for k in (1, 2):
        body, handle = split_handle(ids == k, K, plane)
        assert not handle.any() and (body == (ids == k)).all()


def test_a_dome_whose_readings_lie_on_it_is_not_taken_for_a_bowl():
    """A closed dome (a 16 cm base narrowing to a 2 cm top, 6 cm tall) draws a bowl's outline
    from above too; its readings lie on the dome, and it stays a closed dome."""
    z = np.linspace(0, 0.06, 13)
    outer = np.column_stack([0.08 - 0.07 * np.sqrt(z / 0.06), z])
    profile = np.vstack([[0, 0], outer, [0, 0.06]])
    ids, K, plane, depth = solids_on_table([(profile, 0.06, 0.0, 0.0)])
    mask = ids == 1
    cfg = ReconstructConfig()
    fit = configured_fit(mask, K, plane, cfg, depth)
    assert fit.resting == "standing"
    r = fit.profile[1:-1, 0]
    assert r[-1] < NARROW_TOP * r.max()  # a dome: bowl_instead weighs the bowl
    assert bowl_instead(fit, mask, K, plane, depth, cfg.iterations,
                        lambda f: mouths(f, cfg)) is None
    rec = Reconstructor(cfg)(np.zeros(ids.shape + (3,), np.uint8), mask, K, plane, depth=depth)
    assert "open_top" not in rec.meta


def test_a_standing_jar_whose_readings_lie_on_its_lid_stays_closed():
    """A lidded jar (40 mm in radius, 90 mm tall) is wide enough at the top to be an open
    vessel by its outline; its readings on the lid keep it shut. With the lid's readings gone
    (a glass's mouth, where the sensor reads the floor inside or nothing), it is opened."""
    profile = [[0, 0], [0.04, 0], [0.04, 0.09], [0, 0.09]]
    ids, K, plane, depth = solids_on_table([(profile, 0.09, 0.0, 0.0)])
    mask = ids == 1
    rgb = np.zeros(ids.shape + (3,), np.uint8)
    cfg = ReconstructConfig()
    lidded = Reconstructor(cfg)(rgb, mask, K, plane, depth=depth)
    assert "open_top" not in lidded.meta
    v = lidded.mesh.vertices * lidded.meta["pose_hint"]["scale"]
    assert v[:, 2].max() == pytest.approx(0.09, abs=0.006)
    assert np.hypot(v[:, 0], v[:, 1])[v[:, 2] > v[:, 2].max() - 1e-6].min() < 1e-9  # a lid
    ys, xs = np.nonzero(mask)
    high = plane.height(unproject(np.column_stack([xs, ys]).astype(float), depth[ys, xs], K))
    on_lid = np.zeros_like(mask)
    on_lid[ys[high > 0.085], xs[high > 0.085]] = True
    assert on_lid.sum() > 500
    opened = Reconstructor(cfg)(rgb, mask, K, plane, depth=np.where(on_lid, 0.0, depth))
    assert opened.meta.get("open_top")
