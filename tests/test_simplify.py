"""Stand-ins for silhouettes: the outer profile recovered, silhouettes kept, triangles cut."""

import numpy as np
import pytest
import trimesh

from sr3d_cli.geometry.revolution import open_vessel, revolve
from sr3d_cli.geometry.silhouette import fill_silhouette, mask_iou, project_mesh
from sr3d_cli.geometry.simplify import clustered_stand_in, outer_profile, revolution_stand_in
from sr3d_cli.geometry.transforms import rotation_about

K = np.array([[600.0, 0, 320.0], [0, 600.0, 240.0], [0, 0, 1]])
OUTER = [(0.0, 0.0), (0.25, 0.0), (0.28, 0.05), (0.3, 0.6), (0.36, 1.0)]
CUP = revolve(open_vessel(OUTER, wall=0.03, base=0.06), sections=48)


def _goblet():
    """A stem glass: a bowl on a thin stem on a foot, a finely sampled curved profile."""
    z = np.linspace(0.0, 1.0, 60)
    r = np.where(z < 0.04, 0.3, np.where(z < 0.45, 0.04, 0.04 + 0.3 * np.sin(
        np.pi / 2 * np.clip((z - 0.45) / 0.3, 0, 1))))
    return revolve(np.column_stack([np.r_[0, r, 0], np.r_[0, z, 1.0]]), sections=48)


def test_outer_profile_of_an_open_vessel_is_its_outer_wall_closed_at_the_rim():
    profile = outer_profile(CUP.vertices, CUP.faces, max_points=600)
    np.testing.assert_allclose(profile[[0, 1, -1]], [(0, 0), (0.25, 0), (0, 1.0)], atol=2e-5)
    wall = np.array(OUTER[1:])  # (r, z) from the base's edge to the rim
    np.testing.assert_allclose(profile[1:-1, 0], np.interp(profile[1:-1, 1], wall[:, 1],
                                                           wall[:, 0]), atol=2e-5)
    assert set(np.round(wall[:, 1], 4)) <= set(np.round(profile[:, 1], 4))
    assert len(profile) == len(OUTER) + 2  # and where the inner base meets the wall's height


def test_no_profile_for_a_handle_a_gap_on_the_axis_or_too_many_points():
    stacked = trimesh.util.concatenate([  # two bodies on the axis, a gap between them
        revolve(np.array([[0, 0], [0.3, 0.1], [0.3, 0.4], [0, 0.45]])),
        revolve(np.array([[0, 0.55], [0.3, 0.6], [0.3, 0.9], [0, 1.0]]))])
    assert outer_profile(stacked.vertices, stacked.faces, max_points=600) is None
    handle = trimesh.creation.box(extents=(0.05, 0.1, 0.5))  # a slab beside the wall
    handle.apply_translation([0.0, 0.4, 0.5])
    with_handle = trimesh.util.concatenate([CUP, handle])
    assert outer_profile(with_handle.vertices, with_handle.faces, max_points=600) is None
    assert outer_profile(CUP.vertices, CUP.faces, max_points=5) is None
    assert revolution_stand_in(CUP, 0.002, 24, max_points=5) is None


def _silhouettes(mesh, stand_in, seed: int, views: int = 12):
    """(mesh's, stand-in's) silhouettes ``(170, 170) bool`` from ``views`` random views (seeded),
    each in the window around the mesh's own, as the placing draws them."""
    rng = np.random.default_rng(seed)
    for _ in range(views):
        R = rotation_about(np.array([0, 0, 1.0]), rng.uniform(0, 2 * np.pi)) @ \
            rotation_about(np.array([1.0, 0, 0]), rng.uniform(-2.5, -0.3))
        t = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), 0.6])
        full_uv, _ = project_mesh(mesh.vertices, R, t, 0.12, K)
        origin = tuple(full_uv.min(axis=0) - 30)
        uv, _ = project_mesh(stand_in.vertices, R, t, 0.12, K)
        yield (fill_silhouette(full_uv, mesh.faces, (170, 170), origin),
               fill_silhouette(uv, stand_in.faces, (170, 170), origin))


@pytest.mark.parametrize("name,mesh", [("cup", CUP), ("goblet", _goblet())])
def test_the_stand_in_casts_the_silhouettes_of_the_mesh_with_fewer_triangles(name, mesh):
    stand_in = revolution_stand_in(mesh, 0.002, 24, max_points=600)
    assert len(stand_in.faces) <= len(mesh.faces) / 2
    drawn = list(_silhouettes(mesh, stand_in, seed=3))
    ious = [mask_iou(full, sil) for full, sil in drawn]
    areas = [sil.sum() / full.sum() - 1 for full, sil in drawn]
    assert min(ious) > 0.985 and np.mean(ious) > 0.99  # 0.991 / 0.992 measured (goblet)
    assert abs(np.mean(areas)) < 0.005  # -0.3% (goblet)


def test_a_scan_clustered_casts_its_silhouettes_with_a_sixth_of_its_triangles():
    """A mesh with no stand-in of revolution and many triangles (a scan: a handled mug, finely
    subdivided, 141 000 triangles) clustered on 64 cubes to its extent: an eighth of the
    triangles, the same silhouettes (IoU 0.989 at least, 0.991 on average, as the placing
    draws them in 170 px windows)."""
    handle = trimesh.creation.torus(0.25, 0.05, major_sections=48, minor_sections=16)
    handle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    handle.apply_translation([0.36, 0, 0.5])
    scan = trimesh.util.concatenate([CUP, handle]).subdivide().subdivide().subdivide()
    stand_in = clustered_stand_in(scan, 64)
    assert len(scan.faces) > 100000 and len(stand_in.faces) < len(scan.faces) / 6
    ious = [mask_iou(full, sil) for full, sil in _silhouettes(scan, stand_in, seed=4)]
    assert min(ious) > 0.98, ious
