"""The silhouette rasteriser of mesh fits and pose search, and the one mask IoU.

Projected triangles are filled as OpenCV fills them at a quarter-pixel, in a window of the image
when asked: only the outline matters while a shape or a pose is searched, so no depth test is
needed (every far-side triangle is filled), and hundreds of candidates are drawn per object;
the inside of the outline is filled by one scanline pass, cv2 only draws the triangles along
it (:func:`fill_silhouette`). Full renders (depth, ids and normals for the repaired depth) use
:mod:`sr3d_cli.render`, whose z-buffer takes a pixel when a triangle covers its centre, as
OpenGL does; this fill also takes a pixel its outline touches, and the fits' constants are tuned
to that (see :func:`sr3d_cli.geometry.revolution.silhouette`), so the two stay apart.
"""

from __future__ import annotations

import cv2
import numpy as np

from sr3d_cli.geometry.camera import unproject
from sr3d_cli.geometry.transforms import cross_rows, place_points


SUBPIXEL = 4  # vertex positions are rounded to quarter pixels (cv2's ``shift=2``)
FAR_LIMIT = 4.0  # image sizes beyond the window where vertices are clipped (cv2 is slow on them)
# the widest triangle (quarter pixels, along x or y) whose inside centres are taken without
# cv2: cv2's fill of a larger one can miss a centre just inside an edge (one in ~40,000 random
# triangles of 10-30 px; none in 300,000 of at most 8 px)
INNER_MAX_EXTENT = 32


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


def _quarter_pixels(tri: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Triangles ``(m, 3, 2)`` (pixels) as cv2 draws them: int32 quarter pixels, far-off
    vertices clipped (they only slow the filling down)."""
    limit = FAR_LIMIT * max(shape)
    return np.rint(np.clip(tri, -limit, limit) * SUBPIXEL).astype(np.int32)


def _fill(out: np.ndarray, tri: np.ndarray, values) -> np.ndarray:
    """Fill triangles ``tri (m, 3, 2)`` (pixels) into ``out`` one by one, in order, each with
    its value from ``values``; returns ``out``."""
    for t, v in zip(_quarter_pixels(tri, out.shape), values):
        cv2.fillConvexPoly(out, t, int(v), lineType=cv2.LINE_8, shift=2)
    return out


def face_twins(faces: np.ndarray) -> np.ndarray:
    """Index ``(m, 3) int64`` of the face across edge ``j`` (vertex ``j`` to ``j + 1``) of each
    of ``faces (m, 3)``, -1 where there is none: a border, or an edge more than two faces
    share, or two faces winding it the same way."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros((0, 3), np.int64)
    start, end = faces.ravel(), np.roll(faces, -1, axis=1).ravel()  # edge 3 f + j
    n = int(faces.max()) + 1
    key = start * n + end
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    repeated = np.zeros(len(key), bool)
    same = sorted_key[1:] == sorted_key[:-1]
    repeated[1:] |= same
    repeated[:-1] |= same
    pos = np.minimum(np.searchsorted(sorted_key, end * n + start), len(key) - 1)
    once = np.empty(len(key), bool)
    once[order] = ~repeated
    found = (sorted_key[pos] == end * n + start) & ~repeated[pos] & once
    return np.where(found, order[pos] // 3, -1).reshape(-1, 3)


def _row_ranges(first: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every ``first[i] + k`` for ``k < count[i]``: (owner i, value), flattened."""
    owner = np.repeat(np.arange(len(count)), count)
    value = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count) + \
        first[owner]
    return owner, value


def _interior(start: np.ndarray, end: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Pixels ``(H, W) bool`` whose centre lies inside the region bounded by the directed
    edges ``start (k, 2)`` -> ``end (k, 2)`` (int quarter pixels; a triangle union's border,
    each triangle wound the same way) and on none of them.

    Winding numbers by scanline: an edge crossing a row of pixel centres adds its direction to
    every centre at or right of the crossing (rows half-open: ``start.y <= y < end.y``)."""
    H, W = shape
    p, q = start.astype(np.int64), end.astype(np.int64)
    down = p[:, 1] < q[:, 1]
    a, b = np.where(down[:, None], p, q), np.where(down[:, None], q, p)
    first = np.clip(-(-a[:, 1] // SUBPIXEL), 0, H)  # rows whose centre y is in [a.y, b.y)
    stop = np.clip(-(-b[:, 1] // SUBPIXEL), 0, H)
    edge, rows = _row_ranges(first, np.maximum(stop - first, 0))
    a, b = a[edge], b[edge]
    den = SUBPIXEL * (b[:, 1] - a[:, 1])
    num = a[:, 0] * (b[:, 1] - a[:, 1]) + (SUBPIXEL * rows - a[:, 1]) * (b[:, 0] - a[:, 0])
    col = -(-num // den)  # first centre at or right of the crossing x = num / den
    winding = np.bincount(rows * (W + 1) + np.clip(col, 0, W),
                          weights=np.where(down, 1.0, -1.0)[edge], minlength=H * (W + 1))
    inside = np.cumsum(winding.reshape(H, W + 1)[:, :W], axis=1) != 0
    on = (num % den == 0) & (col >= 0) & (col < W)  # centres on an edge
    inside[rows[on], col[on]] = False
    flat = (p[:, 1] == q[:, 1]) & (p[:, 1] % SUBPIXEL == 0) & (p[:, 1] >= 0) & \
        (p[:, 1] < SUBPIXEL * H)  # edges along a row of centres
    lo = np.maximum(-(-np.minimum(p[flat, 0], q[flat, 0]) // SUBPIXEL), 0)
    hi = np.minimum(np.maximum(p[flat, 0], q[flat, 0]) // SUBPIXEL, W - 1)
    edge, cols = _row_ranges(lo, np.maximum(hi - lo + 1, 0))
    inside[p[flat, 1][edge] // SUBPIXEL, cols] = False
    ends = np.vstack([p, q])
    ends = ends[(ends % SUBPIXEL == 0).all(1)] // SUBPIXEL  # vertices on a centre
    ends = ends[(ends >= 0).all(1) & (ends[:, 0] < W) & (ends[:, 1] < H)]
    inside[ends[:, 1], ends[:, 0]] = False
    return inside


def fill_silhouette(uv: np.ndarray, faces: np.ndarray, shape: tuple[int, int],
                    origin: tuple[float, float] = (0.0, 0.0), zoom: float = 1.0,
                    twins: np.ndarray | None = None) -> np.ndarray:
    """Silhouette ``shape bool`` of triangles ``faces (m, 3)`` over pixels ``uv (n, 2)``,
    drawn in a window whose top-left pixel is ``origin``, magnified by ``zoom``; ``twins``:
    :func:`face_twins` of ``faces`` (computed when not given).

    The pixels are those cv2 takes filling every far-side triangle one by one (a single
    ``cv2.fillPoly`` call treats overlapping polygons as holes, even-odd rule); either half of
    a closed mesh covers its silhouette, the far half is drawn (the pose search's constants
    assume it). Most triangles need no cv2 call: the centres inside the union of the small
    ones, off its border, are taken at once (:func:`_interior`; cv2 takes each of them for the
    triangle it lies in), and a triangle whose rounded bounding box, the most cv2 takes for
    it, holds only such pixels adds nothing. The others (along the outline, folds, the window's
    edge) are filled with cv2."""
    pix = (uv - np.asarray(origin)) * zoom
    finite = np.isfinite(pix).all(axis=1)
    tri = pix[faces]
    far = np.flatnonzero(finite[faces].all(axis=1) & ~_facing(tri))
    tri4 = _quarter_pixels(np.where(finite[:, None], pix, 0.0), shape)[faces[far]]
    out = _inner_pixels(tri4, far, face_twins(faces) if twins is None else twins,
                        shape).astype(np.uint8)
    for t in tri4[~_boxes_inside(tri4, out)]:
        cv2.fillConvexPoly(out, t, 1, lineType=cv2.LINE_8, shift=2)
    return out > 0


def _inner_pixels(tri4: np.ndarray, index: np.ndarray, twins: np.ndarray,
                  shape: tuple[int, int]) -> np.ndarray:
    """:func:`_interior` of the triangles ``tri4 (m, 3, 2)`` (faces ``index (m,)``, ``twins``
    of all faces) that lie inside the window and keep their winding in quarter pixels; an
    edge is a border unless the face across it is one of those too."""
    H, W = shape
    t = tri4.astype(np.int64)
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    lo, hi = _corners(tri4, np.minimum), _corners(tri4, np.maximum)
    use = (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0) & (lo >= 0).all(axis=1) & \
        (hi[:, 0] < SUBPIXEL * W) & (hi[:, 1] < SUBPIXEL * H) & \
        (hi - lo <= INNER_MAX_EXTENT).all(axis=1)
    used = np.zeros(len(twins) + 1, bool)  # the last entry stands for "no face"
    used[index[use]] = True
    tri, border = tri4[use], ~used[twins[index[use]]]
    return _interior(tri[border], np.roll(tri, -1, axis=1)[border], shape)


def _corners(tri4: np.ndarray, pick) -> np.ndarray:
    """``pick`` (np.minimum or np.maximum) of each triangle's three corners ``(m, 3, 2)``:
    ``(m, 2)``."""
    return pick(pick(tri4[:, 0], tri4[:, 1]), tri4[:, 2])


def _boxes_inside(tri4: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Whether each triangle's ``tri4 (m, 3, 2)`` (quarter pixels) rounded bounding box, the
    most its cv2 fill takes, holds only pixels of ``inside (H, W)`` (or none of the image)."""
    count, area = _box_sums(inside, (0, 0), *_rounded_boxes(tri4))
    return count == area


def _rounded_boxes(tri4: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's ``tri4 (m, 3, 2)`` (quarter pixels) rounded bounding box, the most its
    cv2 fill takes: pixels ``lo (m, 2)`` to ``hi (m, 2)`` (x, y; ``hi`` past the last)."""
    lo = (_corners(tri4, np.minimum) + SUBPIXEL // 2) // SUBPIXEL
    hi = (_corners(tri4, np.maximum) + SUBPIXEL // 2) // SUBPIXEL + 1
    return lo, hi


def _box_sums(image: np.ndarray, origin: tuple[int, int], lo: np.ndarray, hi: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """The set pixels of ``image (h, w)`` bool or 0/1, whose top-left pixel is the image's
    ``origin`` (x, y), in each box ``lo``-``hi`` (:func:`_rounded_boxes`) cut to it, and the
    cut boxes' areas: ``(m,)`` each."""
    h, w = image.shape
    x0, x1 = np.clip(lo[:, 0] - origin[0], 0, w), np.clip(hi[:, 0] - origin[0], 0, w)
    y0, y1 = np.clip(lo[:, 1] - origin[1], 0, h), np.clip(hi[:, 1] - origin[1], 0, h)
    total = cv2.integral(image.astype(np.uint8))
    return total[y1, x1] - total[y0, x1] - total[y1, x0] + total[y0, x0], (x1 - x0) * (y1 - y0)


def front_triangles(uv: np.ndarray, depth: np.ndarray, faces: np.ndarray,
                    shape: tuple[int, int]) -> np.ndarray:
    """Index ``(H, W) int32`` of the triangle seen at each pixel (-1: none), drawn far to near
    (painter's order by mean depth), front faces only. ``uv (n, 2)`` pixels and ``depth (n,)``
    of the vertices; pixels are the image's own (no window)."""
    tri, index = _far_to_near(uv, depth, faces)
    return _fill(np.full(shape, -1, np.int32), tri[index], index)


def _far_to_near(uv: np.ndarray, depth: np.ndarray, faces: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The projected triangles ``(m, 3, 2)`` of ``faces`` and the indices of those facing the
    camera, far to near (painter's order by mean vertex ``depth``, ties in face order)."""
    tri = uv[faces]
    index = np.flatnonzero(np.isfinite(tri).all(axis=(1, 2)) & _facing(tri))
    return tri, index[np.argsort(-depth[faces[index]].mean(axis=1), kind="stable")]


def seen_triangles(uv: np.ndarray, depth: np.ndarray, faces: np.ndarray,
                   shape: tuple[int, int], xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """``front_triangles(uv, depth, faces, shape)[ys, xs]`` ``(n,) int``, the same values,
    drawn only where asked: a triangle none of whose pixels can be asked for (its rounded
    bounding box, the most cv2 takes for it, holds none of ``(xs, ys)``) cannot be the last
    drawn there, and the rest are drawn in order in a box around them, 2 px wider on each side
    that the image does not end (their vertices lie in the box or beyond the image's edge
    alike, so cv2 cuts and fills them as in the whole image, moved by whole pixels)."""
    xs, ys = np.asarray(xs, np.int64), np.asarray(ys, np.int64)
    if len(xs) == 0:
        return np.zeros(0, np.int32)
    H, W = shape
    tri, index = _far_to_near(uv, depth, faces)
    tri4 = _quarter_pixels(tri[index], shape)
    lo, hi = _rounded_boxes(tri4)
    qx0, qy0 = int(xs.min()), int(ys.min())
    asked = np.zeros((int(ys.max()) - qy0 + 1, int(xs.max()) - qx0 + 1), np.uint8)
    asked[ys - qy0, xs - qx0] = 1
    near = _box_sums(asked, (qx0, qy0), lo, hi)[0] > 0
    out = np.full(len(xs), -1, np.int32)
    if not near.any():
        return out
    index, tri4, lo, hi = index[near], tri4[near], lo[near], hi[near]
    bx0, by0 = max(int(lo[:, 0].min()) - 2, 0), max(int(lo[:, 1].min()) - 2, 0)
    bx1, by1 = min(int(hi[:, 0].max()) + 2, W), min(int(hi[:, 1].max()) + 2, H)
    box = np.full((by1 - by0, bx1 - bx0), -1, np.int32)
    for t, v in zip(tri4 - np.array([bx0, by0], np.int32) * SUBPIXEL, index):
        cv2.fillConvexPoly(box, t, int(v), lineType=cv2.LINE_8, shift=2)
    inside = (xs >= bx0) & (xs < bx1) & (ys >= by0) & (ys < by1)
    out[inside] = box[ys[inside] - by0, xs[inside] - bx0]
    return out


def surface_depth(uv: np.ndarray, pts: np.ndarray, faces: np.ndarray, K: np.ndarray,
                  xs: np.ndarray, ys: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Depth ``(n,)`` of a mesh's nearest front surface at pixels ``(xs, ys)`` (NaN: none), exact
    where each pixel's ray meets the plane of the triangle it sees. ``uv`` and ``pts`` come from
    :func:`project_mesh`."""
    seen = seen_triangles(uv, pts[:, 2], faces, shape, xs, ys)
    hit = seen >= 0
    a, b, c = (pts[faces[seen[hit]]][:, j] for j in range(3))
    normal = cross_rows(b - a, c - a)
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
