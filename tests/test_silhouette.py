import cv2
import numpy as np
import pytest
import trimesh

from sr3d_cli.geometry.revolution import revolve
from sr3d_cli.geometry.silhouette import (face_twins, fill_silhouette, front_triangles,
                                          project_mesh, seen_triangles)
from sr3d_cli.geometry.transforms import rotation_about

K = np.array([[600.0, 0, 320.0], [0, 600.0, 240.0], [0, 0, 1]])


def _reference(uv, faces, shape, origin, zoom):
    """Every far-side triangle filled one by one with cv2 at a quarter pixel: the silhouette
    that fill_silhouette must reproduce pixel for pixel."""
    tri = (uv[faces] - np.asarray(origin)) * zoom
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    far = np.isfinite(tri).all(axis=(1, 2)) & ~((e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) < 0)
    limit = 4.0 * max(shape)
    out = np.zeros(shape, np.uint8)
    for t in np.rint(np.clip(tri[far], -limit, limit) * 4).astype(np.int32):
        cv2.fillConvexPoly(out, t, 1, lineType=cv2.LINE_8, shift=2)
    return out > 0


def _bottle():
    """A bottle with a narrow neck and a lip: a concave profile whose far side folds over
    itself when seen from above or below."""
    z = np.linspace(0.0, 1.0, 40)
    r = 0.3 + 0.12 * np.cos(np.pi * np.clip(z / 0.7, 0, 1)) ** 2 * (z > 0.55) - \
        0.2 * (z > 0.7) + 0.05 * (z > 0.95)
    r = np.where(z > 0.7, np.maximum(r, 0.1), r)
    return revolve(np.column_stack([np.r_[0, r, 0], np.r_[0, z, 1.0]]), sections=64)


MESHES = {
    "bottle": _bottle,
    "torus": lambda: trimesh.creation.torus(major_radius=0.35, minor_radius=0.12,
                                            major_sections=48, minor_sections=24),
    "box": lambda: trimesh.creation.box(extents=(0.5, 0.3, 0.7)),
    "open cylinder": lambda: trimesh.Trimesh(*(lambda c: (c.vertices, c.faces[
        np.abs(c.face_normals[:, 2]) < 0.5]))(trimesh.creation.cylinder(0.3, 0.8, sections=40)),
        process=False),
}


@pytest.mark.parametrize("name", sorted(MESHES))
def test_fill_silhouette_matches_the_triangle_by_triangle_fill(name):
    mesh = MESHES[name]()
    faces = np.asarray(mesh.faces)
    twins = face_twins(faces)
    rng = np.random.default_rng(3)
    drawn = 0
    for k in range(12):
        R = rotation_about(rng.normal(size=3), rng.uniform(0, np.pi))
        t = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), 0.6])
        uv, _ = project_mesh(np.asarray(mesh.vertices), R, t, rng.uniform(0.05, 0.25), K)
        lo, hi = uv.min(0), uv.max(0)
        # windows around the object, some cutting it (triangles across the window's edge),
        # magnified and shrunk
        origin = tuple(lo - (hi - lo) * rng.uniform(-0.3, 0.4, 2))
        zoom = [1.0, 0.45, 0.8][k % 3]
        shape = tuple(int(v) for v in np.ceil((hi - lo)[::-1] * zoom * 1.4) + 3)
        expected = _reference(uv, faces, shape, origin, zoom)
        got = fill_silhouette(uv, faces, shape, origin, zoom, twins)
        assert np.array_equal(got, expected), f"{name}, pose {k}: " \
            f"{int((got != expected).sum())} of {int(expected.sum())} pixels differ"
        assert np.array_equal(fill_silhouette(uv, faces, shape, origin, zoom), expected)
        drawn += int(expected.sum())
    assert drawn > 12 * 200  # the silhouettes are not trivially small


def test_fill_silhouette_skips_no_pixel_with_vertices_on_pixel_centres():
    # vertices and edges exactly on pixel centres and rows: the ties of the inside test
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 1.0]], float)
    faces = np.array([[0, 2, 1], [1, 2, 3], [0, 1, 4], [1, 3, 4], [3, 2, 4], [2, 0, 4]])
    for scale in (8.0, 9.0, 12.5):
        uv = np.column_stack([verts[:, 0] * scale + 3 + verts[:, 2],
                              verts[:, 1] * scale + 2])
        for flip in (faces, faces[:, ::-1]):
            expected = _reference(uv, flip, (20, 20), (0.0, 0.0), 1.0)
            assert np.array_equal(fill_silhouette(uv, flip, (20, 20)), expected)
            assert expected.sum() >= scale ** 2


def test_face_twins_pairs_the_faces_across_each_edge():
    box = trimesh.creation.box()
    twins = face_twins(box.faces)
    assert (twins >= 0).all()
    f, j = np.nonzero(twins >= 0)
    # the face across is across the same edge, wound the other way
    start, end = box.faces[f, j], box.faces[f, (j + 1) % 3]
    across = box.faces[twins[f, j]]
    for s, e, a in zip(start, end, across):
        assert any(a[i] == e and a[(i + 1) % 3] == s for i in range(3))
    # an open surface: its rim edges have no face across
    opened = trimesh.Trimesh(box.vertices, box.faces[2:], process=False)
    assert (face_twins(opened.faces) == -1).sum() == 4


@pytest.mark.parametrize("name", sorted(MESHES))
def test_seen_triangles_match_the_whole_frame_drawing(name):
    # the triangle seen at asked pixels, drawn only near them, against every front triangle
    # drawn into the whole frame: objects inside it, across its edges, close to the camera
    # (vertices clipped far beyond the frame), pixels scattered or bunched near the object
    mesh = MESHES[name]()
    faces = np.asarray(mesh.faces)
    rng = np.random.default_rng(5)
    shape = (480, 640)
    seen = 0
    for k in range(24):
        R = rotation_about(rng.normal(size=3), rng.uniform(0, np.pi))
        t = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.4), rng.uniform(0.2, 1.0)])
        uv, pts = project_mesh(np.asarray(mesh.vertices), R, t, rng.uniform(0.05, 0.6), K)
        n = int(rng.integers(1, 500))
        if k % 2:
            centre = np.nan_to_num(np.nanmean(uv, axis=0), nan=300.0)
            xs = np.clip(np.rint(centre[0] + rng.normal(0, 30, n)), 0, shape[1] - 1)
            ys = np.clip(np.rint(centre[1] + rng.normal(0, 30, n)), 0, shape[0] - 1)
            xs, ys = xs.astype(int), ys.astype(int)
        else:
            xs, ys = rng.integers(0, shape[1], n), rng.integers(0, shape[0], n)
        expected = front_triangles(uv, pts[:, 2], faces, shape)[ys, xs]
        assert np.array_equal(seen_triangles(uv, pts[:, 2], faces, shape, xs, ys), expected)
        seen += int((expected >= 0).sum())
    assert seen > 1000  # most poses show the object at many of the asked pixels
    assert len(seen_triangles(uv, pts[:, 2], faces, shape, xs[:0], ys[:0])) == 0
