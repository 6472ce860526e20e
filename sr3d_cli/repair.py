"""Repaired depth: the placed meshes rendered into the sensor's depth inside the object masks.

Inside an object's mask the rendered depth replaces the sensor's (the renderer's z-buffer keeps
the nearest surface where objects overlap); elsewhere the sensor's depth is kept. Mask pixels the
placed mesh does not cover take the nearest rendered depth within a few pixels
(``outside_render: nearest``, the default; farther from the mesh, a part the model lacks such as
a handle, they take their object's nearest rendered depth where the sensor reads nothing or
reads the table behind it), keep the sensor's reading (``keep``) or take the table's depth
(``plane``). Objects that could not be placed are left untouched.

A sensor reading inside a mask that lies more than :data:`NEARER` in front of the placed mesh
stays (``keep_nearer``, the default): a depth camera reads the nearest surface on its ray, and
through glass it reads farther (the table behind it), never nearer; a nearer reading is the
object's own front surface, a cap or label the model misses, or an occluder, and it is a better
estimate there than a model placed too far or drawn too small.

Just outside the masks (``beyond_mask``, the default), the placed mesh also replaces the readings
it hides: the sensor's holes within :data:`HOLE_REACH` px of a mask and readings of the table (or
beyond it) seen through the object, farther than the mesh's surface. A mask that misses part of
its object then still gets that part's depth; readings in front of the mesh (an occluder) and
readings of the room above the table's plane (a wall behind a misplaced mesh) stay the sensor's.
Within the convex hull of an object's mask, any reading farther than the mesh is seen through
it: where a glass stands in front of an opaque object, the segmenter leaves the part that
shows the object behind out of the mask (a dent in the outline), and that object's readings
lie above the table.
Holes within that reach the meshes do not cover (a glass's dropouts the mask and mesh miss) are
inpainted from the depth around them (:func:`fill_holes_near`). A mesh placed from a mask the
image border cuts is less sure of its size and place (the outline's foot or side is out of
view): it changes the pixels of its own mask only.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from sr3d_cli.geometry.camera import (Camera, convex_hull, mask_window, on_image_border,
                                      window_K)
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.transforms import place_points
from sr3d_cli.render import RenderMesh, Renderer

HOLE_REACH = 15  # px from a mask within which the sensor's holes are filled (mesh, else inpainted)
BEHIND = 0.01  # m: a reading this much farther than the mesh's surface is seen through it
NEARER = 0.01  # m: a reading inside a mask this much nearer than the mesh's surface is kept
ON_TABLE = 0.01  # m: a reading no nearer than the table's plane by this reads the table or beyond
INPAINT_RADIUS = 5  # px: the neighbourhood OpenCV's inpainting takes each filled value from


def placed_render_meshes(placed: list[tuple[int, object, np.ndarray, float]]) -> list[RenderMesh]:
    """(id, trimesh, T_cam_obj, scale) -> camera-frame meshes for the renderer."""
    return [RenderMesh(place_points(mesh.vertices, T, scale), np.asarray(mesh.faces), int(k))
            for k, mesh, T, scale in placed]


def reads_table(raw_m: np.ndarray, table: np.ndarray) -> np.ndarray:
    """(H, W) bool: readings ``raw_m`` that lie on the table or beyond it (no nearer than its
    depth ``table`` by :data:`ON_TABLE`), where the table is in view. Both (H, W) metres,
    ``table`` 0 where a ray misses the plane."""
    return (table > 0) & (raw_m >= table - ON_TABLE)


def hidden_beyond(raw_m: np.ndarray, outside: np.ndarray, render_depth: np.ndarray,
                  near: np.ndarray, plane: Plane, K: np.ndarray,
                  hulls: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool: pixels ``outside (H, W) bool`` every mask where the placed meshes hide the
    sensor's reading (see the module docstring): its holes ``near (H, W) bool`` a mask,
    readings of the table seen through them and, within ``hulls (H, W) bool`` (the convex
    hulls of the masks), any reading behind them. raw_m, render_depth : (H, W) metres
    (0 = none)."""
    drawn = (render_depth > 0) & outside
    if not drawn.any():
        return drawn
    table = plane.depth_image(raw_m.shape, K)
    behind = raw_m > render_depth + BEHIND
    through = behind & reads_table(raw_m, table)
    if hulls is not None:
        through |= behind & hulls
    return drawn & (((raw_m <= 0) & near) | through)


def fill_holes_near(depth: np.ndarray, near: np.ndarray) -> None:
    """Inpaint (OpenCV, Telea, millimetres) ``depth (H, W) float32`` metres in place where it is
    0 and ``near (H, W) bool`` (within reach of a mask), from the depth around each hole, in a
    window around them; other holes stay."""
    left = (depth <= 0) & near
    box = mask_window(left, HOLE_REACH + 2 * INPAINT_RADIUS)
    if box is None:
        return
    window = depth[box]
    filled = cv2.inpaint(window * 1000, (window <= 0).astype(np.uint8), INPAINT_RADIUS,
                         cv2.INPAINT_TELEA) / 1000
    here = left[box]
    window[here] = filled[here]


def compose_depth(raw_m: np.ndarray, ids: np.ndarray, render_depth: np.ndarray,
                  placed_ids: list[int], *, plane: Plane | None = None, K: np.ndarray | None = None,
                  outside_render: str = "nearest", max_gap: int = 6,
                  beyond_mask: bool = False, keep_nearer: bool = False,
                  render_ids: np.ndarray | None = None) -> np.ndarray:
    """Repaired depth ``(H, W) float32`` metres.

    raw_m : sensor depth; ids : instance ids (H, W); render_depth : depth of the placed meshes
    (0 = empty); placed_ids : the objects that were placed; render_ids : (H, W) the id of the
    placed mesh drawn at each pixel (0 = none), where known; beyond_mask : also replace the
    readings the meshes hide just outside the masks (needs ``plane`` and ``K``; given
    ``render_ids``, not those of objects whose masks reach the image border); keep_nearer :
    keep the readings inside the masks that lie over :data:`NEARER` in front of the meshes.
    Mask pixels over ``max_gap`` px from the meshes: :func:`beyond_the_model` (the table's
    readings seen through a part there are known as such only given ``plane`` and ``K``).
    """
    out = raw_m.astype(np.float32).copy()
    inside = np.isin(ids, placed_ids)
    hit = inside & (render_depth > 0)
    replaced = hit & ~((raw_m > 0) & (raw_m < render_depth - NEARER)) if keep_nearer else hit
    out[replaced] = render_depth[replaced]
    if beyond_mask and plane is not None and K is not None:
        # in a window around the masks and meshes, wide enough for fill_holes_near's own
        box = mask_window(inside | (render_depth > 0), 2 * (HOLE_REACH + INPAINT_RADIUS))
        if box is not None:
            window, drawn = out[box], render_depth[box]
            if render_ids is not None:
                cut = [k for k in placed_ids if on_image_border(ids == k)]
                if cut:
                    drawn = np.where(np.isin(render_ids[box], cut), 0.0, drawn)
            off = (~inside[box]).astype(np.uint8)
            by_mask = cv2.distanceTransform(off, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) <= HOLE_REACH
            hulls = np.zeros(drawn.shape, bool)
            for k in placed_ids:
                hulls |= convex_hull(ids[box] == k)
            hidden = hidden_beyond(raw_m[box], ids[box] == 0, drawn, by_mask, plane,
                                   window_K(K, box[1].start, box[0].start), hulls)
            window[hidden] = drawn[hidden]
            fill_holes_near(window, by_mask)
    miss = inside & ~hit
    if not miss.any() or not hit.any():
        return out
    if outside_render == "nearest":
        # a mask a little larger than the placed mesh: the nearest rendered surface, within
        # ``max_gap`` pixels; further away, see :func:`beyond_the_model`
        dist, (iy, ix) = ndimage.distance_transform_edt(~(render_depth > 0), return_indices=True)
        near = miss & (dist <= max_gap)
        out[near] = render_depth[iy[near], ix[near]]
        beyond_the_model(out, raw_m, ids, render_depth, miss & ~near, placed_ids, plane, K)
    elif outside_render == "plane" and plane is not None and K is not None:
        out[miss] = plane.depth_image(raw_m.shape, K)[miss]
    return out


def beyond_the_model(out: np.ndarray, raw_m: np.ndarray, ids: np.ndarray,
                     render_depth: np.ndarray, far: np.ndarray, placed_ids: list[int],
                     plane: Plane | None = None, K: np.ndarray | None = None) -> None:
    """Depth for the mask pixels ``far (H, W) bool`` that the placed mesh leaves uncovered by
    more than a few pixels: a part of the object its model lacks (a handle, a spout, a lid's
    rim) or a wider mask. Each takes, in ``out (H, W) float32`` metres, the rendered depth of
    its own object's nearest covered pixel where the sensor read nothing there or, given the
    table's ``plane`` and the camera's ``K (3, 3)``, read the table (or beyond it)
    :data:`BEHIND` beyond that depth: seen through the part. Other readings stay: one in
    front is the part's own surface or an occluder, one above the table behind it (a wall, a
    box) is what a mask reaching past its object holds. raw_m, render_depth : (H, W) metres
    (0 = none); ids : (H, W) instance ids."""
    for k in np.unique(ids[far & np.isin(ids, placed_ids)]):
        mine = ids == k
        box = mask_window(mine, 0)
        own = mine[box] & (render_depth[box] > 0)
        if not own.any():
            continue
        _, (iy, ix) = ndimage.distance_transform_edt(~own, return_indices=True)
        nearest = render_depth[box][iy, ix]
        raw = raw_m[box]
        lost = raw <= 0
        if plane is not None and K is not None:
            table = plane.depth_image(raw.shape, window_K(K, box[1].start, box[0].start))
            lost |= (raw > nearest + BEHIND) & reads_table(raw, table)
        fix = far[box] & mine[box] & lost
        out[box][fix] = nearest[fix]


def repair_frame(raw_m: np.ndarray, ids: np.ndarray, camera: Camera, renderer: Renderer,
                 placed: list, *, plane: Plane | None = None, outside_render: str = "nearest",
                 beyond_mask: bool = False, keep_nearer: bool = False) -> np.ndarray:
    if not placed:
        return raw_m.astype(np.float32).copy()
    render = renderer.render(placed_render_meshes(placed), camera, normals=False)
    return compose_depth(raw_m, ids, render.depth, [p[0] for p in placed], plane=plane,
                         K=camera.K, outside_render=outside_render, beyond_mask=beyond_mask,
                         keep_nearer=keep_nearer, render_ids=render.ids)


def plane_fill(raw_m: np.ndarray, mask: np.ndarray, plane: Plane, K: np.ndarray) -> np.ndarray:
    """Baseline: the table's depth inside the object masks."""
    out = raw_m.astype(np.float32).copy()
    table = plane.depth_image(raw_m.shape, K)
    fill = mask & (table > 0)  # rays above the horizon never meet the table: keep the sensor
    out[fill] = table[fill]
    return out


def inpaint_fill(raw_m: np.ndarray, mask: np.ndarray, radius: int = 5) -> np.ndarray:
    """Baseline: OpenCV (Telea) inpainting of the object masks and the sensor's holes."""
    import cv2

    holes = (mask | (raw_m <= 0)).astype(np.uint8)
    # cv2.inpaint on float32 loses precision on values near 1: work in millimetres
    filled = cv2.inpaint(raw_m.astype(np.float32) * 1000, holes, radius,
                         cv2.INPAINT_TELEA) / 1000
    out = raw_m.astype(np.float32).copy()
    out[mask] = filled[mask]
    return out
