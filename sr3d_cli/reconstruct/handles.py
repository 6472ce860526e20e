"""Handles: thin parts of an outline that stick out to one side of a body (a mug's or a
pitcher's handle), split off before the body is fitted and modelled as a slab of their own.

A handle on one side of a surface of revolution widens the width the fit reads on every row it
spans, and the fitted body comes out too wide and too near the camera (a cup's 3 cm handle made
its body 1 cm too wide and put its front surface 2 cm too near). The handle is found in the
image: an opening of the mask with a disc a quarter of the body's width removes what is thinner
than that (a handle's tube, not a bottle's neck), and a removed part is a handle when it is
large, lies outside the convex hull of what the opening kept and to one side of the body's
upright centre line (a goblet's stem and a flask's neck straddle it) or of the kept body's own
long axis (a lying body's axis runs across the image: a lying pitcher's handle stands out
beside it, and the upright line through the body may cross the handle).

Its depth is modelled by a slab over the handle's own pixels, as thick as they are wide, in
the plane through the body's axis that the handle lies in: a closed mesh unioned with the body
as a separate component. A handle seen side-on stands out beside its body in the plane across
the line of sight; one turned towards the back of a body seen from above lies farther along its
rays, and the plane across the line of sight lifts it above the body's top. The image leaves
the turn open within the range of planes that keep the handle within the body's height; the
slab is put in the middle of that range.
"""

from __future__ import annotations

import cv2
import numpy as np
import trimesh
from skimage.measure import marching_cubes

from sr3d_cli.geometry.camera import convex_hull, mask_window, window_K
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.transforms import apply_T

OPEN_SHARE = 0.5  # opening disc diameter, as a share of the mask's widest inscribed radius
MIN_SHARE = 0.02  # smallest handle, as a share of the mask's pixels
SLAB_SHARE = 0.05  # smallest handle given a slab, as a share of its mask's pixels (a mug's or a
# pitcher's handle holds 0.07-0.11 of it; a smaller part split off is a bump of the outline: the
# body is fitted without it, and its pixels are left to repair)
MAX_SHARE = 0.35  # largest handle, as a share of the mask's pixels (more is no handle)
OUTSIDE_SHARE = 0.6  # least share of a handle's pixels outside the body's convex hull
ONE_SIDE = 0.9  # least share of a handle's pixels on one side of the body's centre line
SLAB_STEP = 2  # pixels per cell of the grid the slab is built on
HEIGHT_SLACK = 0.05  # share of the body's height a handle may reach beyond either end of it
PLANE_TURNS = np.radians(np.arange(-75.0, 75.1, 2.5))  # turns about the axis of the handle's
# plane from the one across the line of sight that are tried (a plane turned further is seen
# nearly edge-on)
WINDOW_MARGIN = 2  # pixels of background kept around a mask while its handle is looked for


def split_handle(mask: np.ndarray, K: np.ndarray, plane: Plane
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(body, handle)`` (H, W) bool, splitting ``mask (H, W) bool`` (see the module's
    docstring); ``handle`` is empty when nothing in the outline is a handle. Worked out in a
    window around the mask: a ring of background around it holds every pixel the opening and
    the distances look at, so the result is the whole image's."""
    body, handle = mask.astype(bool), np.zeros_like(mask, dtype=bool)
    box = mask_window(mask, WINDOW_MARGIN)
    if box is not None:
        body[box], handle[box] = _split_in(mask[box], window_K(K, box[1].start, box[0].start),
                                           plane)
    return body, handle


def _split_in(mask: np.ndarray, K: np.ndarray, plane: Plane) -> tuple[np.ndarray, np.ndarray]:
    """:func:`split_handle` of ``mask (h, w) bool`` in its window (``K`` the window's)."""
    none = np.zeros_like(mask, dtype=bool)
    m8 = mask.astype(np.uint8)
    inscribed = float(cv2.distanceTransform(np.pad(m8, 1), cv2.DIST_L2, 5).max())
    d = int(round(OPEN_SHARE * inscribed))
    if d < 3:
        return mask, none
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d | 1, d | 1))
    kept = cv2.morphologyEx(m8, cv2.MORPH_OPEN, disc) > 0
    if not kept.any():
        return mask, none
    ys, xs = np.nonzero(kept)
    body = np.column_stack([xs, ys]).astype(np.float64)
    hull = convex_hull(kept)
    centre = body.mean(axis=0)
    # the upright line through the body, then the body's own long axis (the principal axis of
    # its pixels)
    long_axis = np.linalg.eigh(np.cov((body - centre).T))[1][:, 1]
    lines = [plane.down_at(centre, K), long_axis]
    count, labels = cv2.connectedComponents((mask & ~kept).astype(np.uint8), connectivity=8)
    area = int(mask.sum())
    handle = none.copy()
    for k in range(1, count):
        part = labels == k
        if part.sum() < MIN_SHARE * area:
            continue
        py, px = np.nonzero(part)
        if 1.0 - hull[py, px].mean() >= OUTSIDE_SHARE and \
                any(_beside(np.column_stack([px, py]), body, centre, line) for line in lines):
            handle |= part
    if handle.sum() > MAX_SHARE * area:
        return mask, none
    return mask & ~handle, handle


def _beside(part: np.ndarray, body: np.ndarray, centre: np.ndarray, along: np.ndarray
            ) -> bool:
    """Whether the pixels ``part`` (n, 2) (x, y) lie to one side of the line through ``centre``
    (2,) along the unit ``along`` (2,): :data:`ONE_SIDE` of them on one side, on average
    farther from it than half the width across it of the ``body`` pixels (m, 2)."""
    half_width = 0.5 * len(body) / max(np.ptp(body @ along), 1.0)
    side = (part - centre) @ np.array([-along[1], along[0]])
    return max((side > 0).mean(), (side < 0).mean()) >= ONE_SIDE and \
        np.abs(side).mean() > half_width


def handle_plane(handle: np.ndarray, T_cam_obj: np.ndarray, scale: float, K: np.ndarray
                 ) -> np.ndarray | None:
    """The unit normal (3,), in the camera frame, of the plane through the axis of the body
    placed at ``T_cam_obj`` (4, 4) with ``scale`` (metres per object unit) that the
    ``handle (H, W) bool`` pixels are put in (see the module's docstring): of the planes
    turned :data:`PLANE_TURNS` from the one across the line of sight, those that keep every
    handle pixel within the body's height (and :data:`HEIGHT_SLACK`) form a range of turns
    (the one nearest no turn, when there are two), and the plane is turned to its middle (the
    turn the image leaves open within it). None when the handle is empty, the body is seen
    from its axis, or no plane keeps the handle within its height."""
    ys, xs = np.nonzero(handle)
    if not len(ys):
        return None
    axis, mid = T_cam_obj[:3, 2], T_cam_obj[:3, 3] + 0.5 * scale * T_cam_obj[:3, 2]
    across = -mid - (-mid @ axis) * axis  # towards the camera, across the axis
    if np.linalg.norm(across) < 1e-9:
        return None
    across /= np.linalg.norm(across)
    side = np.cross(axis, across)
    rays = np.column_stack([(xs - K[0, 2]) / K[0, 0], (ys - K[1, 2]) / K[1, 1], np.ones(len(xs))])
    to_obj = np.linalg.inv(T_cam_obj)

    def normal(turn: float) -> np.ndarray:
        return np.cos(turn) * across + np.sin(turn) * side

    def within(turn: float) -> bool:
        n = normal(turn)
        along, reach = rays @ n, mid @ n
        if (np.abs(along) < 1e-3).any() or (along * reach <= 0).any():
            return False  # seen edge-on, or the rays meet the plane behind the camera
        z = apply_T(to_obj, rays * (reach / along)[:, None])[:, 2] / scale
        return z.min() >= -HEIGHT_SLACK and z.max() <= 1 + HEIGHT_SLACK

    ok = np.array([within(t) for t in PLANE_TURNS])
    if not ok.any():
        return None
    # the run of turns that keep the handle within the body's height nearest no turn
    first = int(np.argmin(np.where(ok, np.abs(PLANE_TURNS), np.inf)))
    lo = hi = first
    while lo > 0 and ok[lo - 1]:
        lo -= 1
    while hi < len(ok) - 1 and ok[hi + 1]:
        hi += 1
    return normal(0.5 * (PLANE_TURNS[lo] + PLANE_TURNS[hi]))


def handle_slab(handle: np.ndarray, mask_pixels: int, T_cam_obj: np.ndarray, scale: float,
                K: np.ndarray) -> trimesh.Trimesh | None:
    """A closed slab over the ``handle (H, W) bool`` pixels split off a mask of
    ``mask_pixels`` pixels, in the object frame of a body placed at ``T_cam_obj`` (4, 4) with
    ``scale`` (metres per object unit): centred on the plane :func:`handle_plane` finds, as
    thick as the handle is wide in the image. None when the handle holds less than
    :data:`SLAB_SHARE` of the mask, or there is no such plane."""
    if handle.sum() < SLAB_SHARE * mask_pixels:
        return None
    normal = handle_plane(handle, T_cam_obj, scale, K)
    if normal is None:
        return None
    mid = T_cam_obj[:3, 3] + 0.5 * scale * T_cam_obj[:3, 2]
    ys, xs = np.nonzero(handle)
    x0, y0 = xs.min(), ys.min()
    cells = cv2.resize(handle[y0:ys.max() + 1, x0:xs.max() + 1].astype(np.float32), None,
                       fx=1 / SLAB_STEP, fy=1 / SLAB_STEP, interpolation=cv2.INTER_AREA) > 0.5
    if not cells.any():
        return None
    volume = np.zeros((cells.shape[0] + 2, cells.shape[1] + 2, 4), np.float32)
    volume[1:-1, 1:-1, 1:3] = cells[:, :, None]
    verts, faces, _, _ = marching_cubes(volume, 0.5)
    u = x0 + (verts[:, 1] - 1 + 0.5) * SLAB_STEP - 0.5
    v = y0 + (verts[:, 0] - 1 + 0.5) * SLAB_STEP - 0.5
    rays = np.column_stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(len(u))])
    denom = rays @ normal
    if (np.abs(denom) < 1e-6).any():
        return None
    on_plane = rays * ((mid @ normal) / denom)[:, None]
    z = on_plane[:, 2]
    width_px = 2.0 * float(cv2.distanceTransform(np.pad(handle, 1).astype(np.uint8),
                                                 cv2.DIST_L2, 5).max())
    thick = width_px * float(np.median(z)) / K[0, 0]
    unit = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    # the volume's surface runs through layers 0.5 to 2.5: half the thickness either side
    pts = on_plane + ((verts[:, 2] - 1.5) * 0.5 * thick)[:, None] * unit
    if not (pts[:, 2] > 0).all():
        return None
    obj = apply_T(np.linalg.inv(T_cam_obj), pts) / scale
    mesh = trimesh.Trimesh(obj, faces, process=True)
    if not mesh.is_watertight:
        return None
    if mesh.volume < 0:
        mesh.invert()
    return mesh
