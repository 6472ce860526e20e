"""The silhouette rasteriser of mesh fits and pose search, and the one mask IoU.

Projected triangles are filled with OpenCV at a quarter-pixel, in a window of the image when
asked: only the outline matters while a shape or a pose is searched, so no depth test is needed
(every triangle in front of the camera is filled), and hundreds of candidates are drawn per
object. Full renders (depth, ids and normals for the repaired depth) use :mod:`sr3d_cli.render`,
whose z-buffer takes a pixel when a triangle covers its centre, as OpenGL does; this fill also
takes a pixel its outline touches, and the fits' constants are tuned to that (see
:func:`sr3d_cli.geometry.revolution.silhouette`), so the two stay apart.
"""

from __future__ import annotations

import cv2
import numpy as np

from sr3d_cli.geometry.camera import unproject
from sr3d_cli.geometry.transforms import place_points


def project_mesh(vertices_obj: np.ndarray, R: np.ndarray, t: np.ndarray, scale: float,
                 K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(n, 2)`` and camera-frame points ``(n, 3)`` of object-frame vertices."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    pts = place_points(vertices_obj, T, scale)
    z = np.where(pts[:, 2] > 0.01, pts[:, 2], np.nan)  # behind the near plane: no pixel
    uv = np.column_stack([pts[:, 0] / z * K[0, 0] + K[0, 2], pts[:, 1] / z * K[1, 1] + K[1, 2]])
    return uv, pts


def window_K(K: np.ndarray, origin: tuple[float, float], zoom: float) -> np.ndarray:
    """Intrinsics of a window whose top-left pixel is ``origin``, magnified by ``zoom``."""
    Kw = np.asarray(K, dtype=np.float64).copy()
    Kw[0, 0] *= zoom
    Kw[1, 1] *= zoom
    Kw[0, 2] = (K[0, 2] - origin[0]) * zoom
    Kw[1, 2] = (K[1, 2] - origin[1]) * zoom
    return Kw


def _facing(tri: np.ndarray) -> np.ndarray:
    """Which projected triangles ``(m, 3, 2)`` face the camera. Faces wind counter-clockwise
    seen from outside; with the image's y axis pointing down, that is a negative cross product."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    return (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) < 0


def _fill(out: np.ndarray, tri: np.ndarray, values) -> np.ndarray:
    """Fill triangles ``tri (m, 3, 2)`` (pixels) into ``out`` one by one, in order, each with
    its value from ``values``; returns ``out``."""
    limit = 4.0 * max(out.shape)  # far-off vertices only slow the filling down
    tris = np.rint(np.clip(tri, -limit, limit) * 4).astype(np.int32)  # 2 sub-pixel bits
    for t, v in zip(tris, values):
        cv2.fillConvexPoly(out, t, int(v), lineType=cv2.LINE_8, shift=2)
    return out


def fill_silhouette(uv: np.ndarray, faces: np.ndarray, shape: tuple[int, int],
                    origin: tuple[float, float] = (0.0, 0.0), zoom: float = 1.0) -> np.ndarray:
    """Silhouette ``shape bool`` of triangles ``faces (m, 3)`` over pixels ``uv (n, 2)``,
    drawn in a window whose top-left pixel is ``origin``, magnified by ``zoom``.

    Triangles are filled one by one: a single ``cv2.fillPoly`` call treats overlapping
    polygons as holes (even-odd rule). Either half of a closed mesh covers its silhouette; the
    far half is drawn (the pose search's constants assume it)."""
    pix = (uv - np.asarray(origin)) * zoom
    tri = pix[faces]
    tri = tri[np.isfinite(tri).all(axis=(1, 2)) & ~_facing(tri)]
    return _fill(np.zeros(shape, np.uint8), tri, np.ones(len(tri))) > 0


def front_triangles(uv: np.ndarray, depth: np.ndarray, faces: np.ndarray,
                    shape: tuple[int, int]) -> np.ndarray:
    """Index ``(H, W) int32`` of the triangle seen at each pixel (-1: none), drawn far to near
    (painter's order by mean depth), front faces only. ``uv (n, 2)`` pixels and ``depth (n,)``
    of the vertices; pixels are the image's own (no window)."""
    tri = uv[faces]
    front = np.isfinite(tri).all(axis=(1, 2)) & _facing(tri)
    index = np.flatnonzero(front)
    index = index[np.argsort(-depth[faces[index]].mean(axis=1), kind="stable")]
    return _fill(np.full(shape, -1, np.int32), tri[index], index)


def surface_depth(uv: np.ndarray, pts: np.ndarray, faces: np.ndarray, K: np.ndarray,
                  xs: np.ndarray, ys: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Depth ``(n,)`` of a mesh's nearest front surface at pixels ``(xs, ys)`` (NaN: none), exact
    where each pixel's ray meets the plane of the triangle it sees. ``uv`` and ``pts`` come from
    :func:`project_mesh`."""
    seen = front_triangles(uv, pts[:, 2], faces, shape)[ys, xs]
    hit = seen >= 0
    a, b, c = (pts[faces[seen[hit]]][:, j] for j in range(3))
    normal = np.cross(b - a, c - a)
    rays = unproject(np.column_stack([xs[hit], ys[hit]]), np.ones(int(hit.sum())), K)
    z = np.full(len(xs), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        z[hit] = np.einsum("ij,ij->i", normal, a) / np.einsum("ij,ij->i", normal, rays)
    z[~(z > 0)] = np.nan
    return z


def mask_iou(a: np.ndarray, b: np.ndarray, ignore: np.ndarray | None = None,
             empty: float = 0.0) -> float:
    """Intersection over union of two boolean masks ``(H, W)``, over the pixels outside
    ``ignore (H, W) bool`` when given (where another object may hide either); ``empty`` when
    both are empty there (0: nothing drawn matches nothing seen; 1: two absent objects agree)."""
    if ignore is not None:
        a, b = a & ~ignore, b & ~ignore
    union = np.count_nonzero(a | b)
    return np.count_nonzero(a & b) / union if union else float(empty)
