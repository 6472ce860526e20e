import numpy as np
import pytest
import trimesh

from sr3d_cli.geometry.camera import Camera, project
from sr3d_cli.geometry.transforms import rotation_about
from sr3d_cli.render import NumpyRenderer, RenderMesh, make_renderer, opencv_to_opengl

CAM = Camera(np.array([[600.0, 0, 330.3], [0, 610.0, 250.7], [0, 0, 1]]), 640, 480)


def _scene():
    cyl = trimesh.creation.cylinder(radius=0.04, height=0.15, sections=64)
    R = rotation_about([1, 0.3, 0], 0.6)
    verts = cyl.vertices @ R.T + [0.03, -0.02, 0.5]
    # a tilted plane behind the cylinder (z = 0.7 + 0.6 y) that also passes behind the camera,
    # so some triangles straddle the near plane and must be clipped
    plane = np.array([[-2, -2, -0.5], [2, -2, -0.5], [2, 2, 1.9], [-2, 2, 1.9]])
    return [RenderMesh(verts, cyl.faces, 1, cyl.vertex_normals @ R.T),
            RenderMesh(plane, np.array([[0, 1, 2], [0, 2, 3]]), 7)]


def test_numpy_renderer_depth_is_exact_on_a_plane():
    plane = np.array([[-1, -1, 0.8], [1, -1, 0.8], [1, 1, 0.8], [-1, 1, 0.8]])
    out = NumpyRenderer().render([RenderMesh(plane, np.array([[0, 1, 2], [0, 2, 3]]), 3)], CAM)
    assert np.all(out.ids == 3)
    np.testing.assert_allclose(out.depth, 0.8, atol=1e-6)
    np.testing.assert_allclose(np.abs(out.normals[..., 2]), 1.0, atol=1e-6)


def test_numpy_silhouette_matches_projected_vertices():
    mesh = _scene()[0]
    out = NumpyRenderer().render([mesh], CAM)
    uv = project(mesh.vertices, CAM.K)
    assert out.ids[out.ids > 0].size > 1000
    v, u = np.nonzero(out.ids == 1)
    assert abs(u.min() - uv[:, 0].min()) < 1.5 and abs(u.max() - uv[:, 0].max()) < 1.5
    assert abs(v.min() - uv[:, 1].min()) < 1.5 and abs(v.max() - uv[:, 1].max()) < 1.5


def test_backends_agree_on_depth_ids_and_normals():
    try:
        gl = make_renderer("pyrender")
    except Exception as exc:  # pragma: no cover - machines without EGL/OSMesa
        pytest.skip(f"no OpenGL context here ({exc})")
    a = NumpyRenderer().render(_scene(), CAM)
    b = gl.render(_scene(), CAM)
    for obj_id in (1, 7):
        A, B = a.ids == obj_id, b.ids == obj_id
        assert (A & B).sum() / (A | B).sum() > 0.995
    both = (a.ids == b.ids) & (a.ids > 0)
    diff = np.abs(a.depth - b.depth)[both]
    assert np.median(diff) < 1e-5 and np.percentile(diff, 99) < 5e-5  # metres
    cos = (a.normals * b.normals).sum(-1)[both]
    assert np.median(np.degrees(np.arccos(np.clip(cos, -1, 1)))) < 1.0


@pytest.mark.parametrize("backend", ["numpy", "pyrender"])
def test_a_render_without_normals_has_the_same_depth_and_ids(backend):
    """What a repaired depth asks for (normals=False): the same depth and ids to the bit, no
    normals (pyrender leaves its colour pass out)."""
    try:
        renderer = make_renderer(backend)
    except Exception as exc:  # pragma: no cover - machines without EGL/OSMesa
        pytest.skip(f"no OpenGL context here ({exc})")
    full = renderer.render(_scene(), CAM)
    bare = renderer.render(_scene(), CAM, normals=False)
    assert bare.normals is None and full.normals is not None
    assert np.array_equal(bare.depth, full.depth) and np.array_equal(bare.ids, full.ids)
    assert (full.ids == 1).sum() > 1000


def test_auto_falls_back_to_numpy_with_one_notice(monkeypatch, caplog):
    import sr3d_cli.render as render

    def broken():
        raise RuntimeError("no EGL display")

    monkeypatch.setattr(render, "_CACHE", {})
    monkeypatch.setattr(render.PyrenderRenderer, "__init__", lambda self: broken())
    with caplog.at_level("WARNING", logger="sr3d"):
        r = render.make_renderer("auto")
    assert isinstance(r, NumpyRenderer)
    assert [rec.getMessage() for rec in caplog.records] == [
        "notice: no OpenGL context (RuntimeError: no EGL display); rendering with the numpy "
        "fallback"]


def test_opencv_to_opengl_flips_y_and_z():
    T = opencv_to_opengl(np.eye(4))
    np.testing.assert_array_equal(T, np.diag([1.0, -1.0, -1.0, 1.0]))
    np.testing.assert_array_equal(opencv_to_opengl(T), np.eye(4))


def test_grey_image_is_brightest_facing_the_light():
    out = NumpyRenderer().render(_scene(), CAM)
    grey = out.grey()
    assert grey.dtype == np.uint8 and grey[out.ids == 0].max(initial=0) == 0
    assert grey[out.ids > 0].max() > 200
