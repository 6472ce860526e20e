"""Training-free segmentation of transparent objects from depth failures and colour.

Glass and clear plastic break active depth sensors in recognisable ways: clusters of missing
readings (often tracing the silhouette), readings of the table *through* the object, and noisy
front-surface returns. Opaque objects stand on the same table with smooth readings above it.
The steps:

1. heights above the fitted support plane for every valid reading;
2. evidence of glass: holes where the table should be seen, plus rough readings above the table
   (the local residual against a median filter is far above the sensor's noise there); the
   room's holes beyond the table are dropped, but not a glass outline joined to them;
3. opaque evidence: smooth readings clearly above the table (these veto a candidate); the thin
   runs of missing readings along an opaque object's edge (a stereo camera's shadow) are its,
   not glass, so a glass next to a can does not take in the table between them;
4. candidates: morphological closing of the evidence, filling of regions enclosed or nearly
   enclosed by it (an outline of holes around a see-through object), opening to drop thin
   artefacts such as the dropouts along opaque edges, and an area floor;
5. each candidate refined by GrabCut in a window around it (colour edges), seeded with the
   evidence as probable foreground and the opaque pixels as background;
6. a region of touching objects split at its narrow necks (distance-transform watershed), at
   thin parts hanging off it, between separate bodies of its glass evidence (two glasses a few
   pixels apart, whose gap the closing filled), or between groups of its readings that stand
   apart on the table (one object behind another), kept split only where solids of revolution
   on the table explain the parts clearly better than the whole (the revolution fit of
   :mod:`sr3d_cli.shape.revolution_fit`);
7. a region or part whose colour replaces the table's as a whole not split, only dropped;
   instances that are too small or too large to be an object on the table dropped, those
   whose colour replaces the table's (an opaque object: glass shows the table through itself,
   :func:`table_colour_departure`) and those with no outline in colour at all (a sensor's
   dropout on a plain surface, :func:`shows_outline`, which reads the outline over the table
   only); each kept instance grown to its colour outline over the table's footprint
   (:func:`grow_to_outline`), as a real glass's depth evidence covers only part of it, and
   the outline followed on round a rim (an open vessel looked down into shows the table
   through its floor, its holes an arc of the rim);
8. a standing instance joined to the readings inside its fitted solid's volume above it (an
   opaque cap or lid reads well and gives no glass evidence: :func:`with_parts_on_axis`);
9. in a frame from a stereo camera (:func:`casts_stereo_shadows`), each instance cut to the
   hull of its colour outline (:func:`within_outline_hull`): the holes and bumps such a
   camera leaves beside a glass show the table's plain colour;
10. the lines between touching instances moved onto the colour edge beside them where one
   stands out (:func:`cuts_on_colour_edges`): a cut judged by the shapes the parts draw runs
   where their silhouettes meet best, the nearer glass's outline a few pixels away;
11. outside a stereo camera's frames, the gaps in each instance's convex hull whose readings
   are the table bent off its plane by the glass added to it (:func:`with_hull_gaps`);
12. an instance no solid of revolution on the table draws well, or only one smaller than any
   glassware, dropped (:func:`placeable`), unless it reaches the image's border.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from sr3d_cli.geometry.camera import (convex_hull, depth_to_points, mask_window, on_image_border,
                                      unproject, window_K)
from sr3d_cli.geometry.occlusion import down_direction, in_front
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.shape.revolution_fit import (DEPTH_BAND, DEPTH_MIN_POINTS, DEPTH_SAMPLES,
                                           FitOptions, above_top, evenly, fit_revolution,
                                           fit_silhouette, off_table_readings, raw_support,
                                           stands_behind)


ON_TABLE_SHARE = 0.3  # least share of a candidate over the table's footprint
SPLIT_GAIN = 0.03  # silhouette IoU a split of touching objects must gain (split_touching)
SPLIT_READINGS = 0.25  # share of the whole's readings on its surface a split must add (ditto)
SPLIT_PART_IOU = 0.85  # silhouette IoU both parts of a split made by the readings must reach
SPLIT_PIECES = 4  # most watershed pieces a region is cut into for split judging
SPLIT_SHARE = 0.2  # least share of a region each part of an outline cut keeps (a sliver of
# background fits anything)
CLEAR_GAIN = 2.0  # times the gain a cut of a whole no solid draws needs to hold by its outline
# whatever its parts' own readings say (split_touching)
HIDDEN_READINGS = 0.15  # share of its readings a part fitted with hidden pixels must explain
OWN_READINGS = 0.5  # share of a part's own readings its fit must hold and the whole's miss
OUTLINE_OWN_READINGS = 0.25  # OWN_READINGS where the outline gains too
OUTLINE_REFUTED = 0.1  # share of a part's own readings its fit may miss that the whole's holds
FOOTPRINT_APART = 0.03  # metres between two groups of readings on the table (_footprint_cut)
FOOTPRINT_PATCH = 0.1  # least share of the largest patch of table readings another patch
# holds to join the table's footprint (table_footprint) ...
FOOTPRINT_BELOW = 0.2  # ... and the largest share of the joined hull's pixels reading below
# the table (on the shared real and extsim frames cut at a glass's foot: a table's two halves
# 0.04-0.17, a far desk or the room beyond the floor 0.28-0.62)
BORDER_REACH = 0.1  # share of the image width along its sides where holes may be the
# camera's own (a stereo camera's invalid left band is baseline x fx / depth wide: ~100 px at
# 0.5 m for a D415 at 1280 px); see evidence_maps
ENCLOSED_SHARE = 0.8  # share of a gap's surroundings the region must hold to fill it (_enclosed)
TABLE_GAP = 0.5  # share of a gap's pixels reading the table for it to be table (_enclosed)
HULL_GAP_LEAST = 20  # px: smallest gap in an instance's convex hull judged (with_hull_gaps)
HULL_GAP_READ = 0.5  # least share of such a gap's pixels with a reading
EDGE_REACH, EDGE_SHARE, EDGE_THIN = 8, 0.8, 4.0  # an opaque object's edge band (opaque_edges)
SHADOW_STEP = 0.005  # m: a reading this much nearer than the one across a run of holes casts a
# stereo shadow on it (stereo_shadow)
SHADOW_SLACK = 1.0  # px added to the shadow's width (the reading's own edge, rounding)
SHADOW_MIN_STEP, SHADOW_MIN_EDGES, SHADOW_SIGNATURE = 4.0, 20, 0.8  # casts_stereo_shadows
TABLE_EDGE_BAND, TABLE_EDGE_SHARE = 8, 0.5  # an instance with over this share of its pixels
# within this many px of the table footprint's edge is a band of dropouts along it (measured on
# the shared real frames: the far edge's bands 0.59-0.77, objects at most 0.20)
TABLE_CLEAR_SHARE = 0.65  # least share of an instance's part over the table's footprint that
# lies clear of that band (the shared real frames as given, moved by a pixel, at 640x480 and
# beside themselves: objects 0.88-1.0, the room's dropouts beyond the far edge joined to the
# band 0.45-0.59; a small generated glass near a far edge made by dropping every reading
# above a row 0.73)
TABLE_LINE = 3  # px either side of the table footprint's edge where its colour gives way to the
# room's (colour smoothed over 3 px): no object's outline (within_outline_hull)
TABLE_EDGE_TRIM = 32  # px from the table footprint's edge within which an instance keeps only
# the columns above its feet in a stereo camera's frame: the dropouts along the edge spread
# that far on the shared real frames once the 2x2 reduction keeps another reading of each
# block, and join an object near the edge (a container beside its top, a bottle or a holder
# beside it); elsewhere TABLE_EDGE_BAND
MIN_IMAGE_SHARE = 0.001  # least share of the image an instance covers (400 px at 848x480): the
# clusters of dropouts a real stereo camera scatters over a plain table are smaller
OPAQUE_COLOUR = 3.5  # median colour departure from the table around it (table_colour_departure)
# above which an instance is an opaque object: glass shows the table through itself
LEAST_SPREAD = 2.0  # CIELAB units: the table's colour spread is taken as at least a just
# noticeable difference, so a perfectly plain table does not turn every shade into a departure
COLOUR_WINDOW = 31  # pixels: the neighbourhood the table's local colour is taken from
FAINT_COLOUR, FAINT_SHARE = 1.5, 0.02  # an instance is a dropout, not glass, when under this
# share of the band around its edge departs from the table's colour by this much (shows_outline)
OUTLINE_COLOUR = 2.5  # colour departure that marks a glass's outline, rim or highlight
HULL_LEAST = 0.5  # least share of an instance its outline's hull must keep (within_outline_hull)
OUTLINE_REACH = 25  # pixels around an instance searched for its outline (grow_to_outline)
FOLLOWED_THICKNESS = 3  # px: radius of the disc that opens what following an outline adds
OPAQUE_BAND = 8  # pixels around opaque evidence an instance is not grown into
CUT_REACH = 8  # px either side of the line between two touching instances it may move by
CUT_CONTRAST_GAIN = 0.25  # share by which the colour contrast along that line must rise for the
# moved line to be kept (cuts_on_colour_edges): on the real frames a cut moved by a watershed of
# their faint colour raised it by 5-17% and was no better; the cuts through extsim's glasses by
# 35-100%
MIN_OBJECT_SIZE = 0.03  # m: an instance's revolution fit must be at least this tall or wide:
# glassware is bigger (the smallest true objects on the shared real, extsim and generated
# frames: 44 mm), slivers of dropouts or of an object's edge are not (19-28 mm: ClearGrasp 080
# and Tracebot 014 resampled to 640x480, seed 1100's frame 4)
MIN_FIT_IOU = 0.5  # least silhouette IoU of an instance's revolution fit: the true objects on
# those frames fit at 0.75 or better (a pitcher with its handle 0.88), the outline of a patch of
# holes along a geode's edge at 0.09 (ClearGrasp 123 resampled to 640x480)
MAX_IMAGE_SHARE = 0.4  # most share of the image one instance covers: a region that large is the
# table or the room failing as a whole, not an object standing on it
BODY_SEED_HEIGHT = 0.015  # metres over the table: a reading this high is an object, not the
# correlated bumps a stereo camera reads on a plain table at 1 m (at most 12 mm on the real frames)
BODY_FEET_REACH = 0.01  # metres: a body's low readings stand over its footprint within this of
# the foot of its high ones (standing_bodies): a glass's wall and the sensor's noise at a metre
BODY_HEIGHT = 0.025  # metres: the 95th percentile height of a standing body's readings
BODY_SEES_TABLE = 0.15  # least share of a body's pixels that show the table's colour: a glass
# shows what is behind it (real glass 0.20-0.93, opaque objects on the real frames 0.02-0.09)
BODY_HOLES = 0.05  # least share of a body's pixels without a reading: a sensor fails somewhere
# on every glass; an opaque object's readings are dense (its dropouts run along its edge)
BODY_INSIDE = 0.8  # share of a body inside one instance that makes it a part of that instance
BODY_JOINED = 0.5  # share of a body that does not show the table one instance must hold for the
# body to join it: the glass's lower part, read smoothly (ClearGrasp 123's holders: 0.56 and 0.66
# held, 87-89% of each body inside its holder; an earphone case beside a false instance: 0.20)
BODY_SHARED = 0.1  # share of a body each of two instances holding it makes it touching objects
BODY_CUT = 0.25  # share of a body each part of a cut holds where the cut runs through it
SURFACE_STEP = 0.01  # metres: the median step in depth across a cut between a body's readings
# either side of it under which they are one surface (_one_surface)
SURFACE_ACROSS = 0.3  # pairs of neighbouring readings across such a cut, per column of the
# body: a cut across a container's read body (0.36-0.47 on the Tracebot views) against two
# objects whose readings meet where they touch (generated goblet and lying beaker 0.08-0.25)
OPAQUE_DROPOUTS = 0.5  # share of an instance inside an opaque body that makes it that body's
# dropouts (without_opaque_dropouts; ClearGrasp 123's earphone case: 0.54-0.69 in every view)
SEE_THROUGH_WINDOW = 91  # pixels: the table's colour around a body is taken beyond its width
TABLE_LIKE = 1.5  # colour departure under which a pixel shows the table's colour
BEYOND_MARGIN = 3  # pixels: an object's part beyond the table's far edge stays within this of
# the columns its part over the table spans (within_table_columns)
FEET_SHARE = 0.25  # share of its height over the table above its lowest row within which an
# instance's columns reach down: its feet, the only columns it rises in beyond the table
ON_AXIS_MARGIN = 0.005  # metres beyond a standing glass's fitted radius within which readings
# above the table belong to it (a cap or lid is no wider than its body; reading noise)
ON_AXIS_REACH = 0.4  # metres along a standing glass's axis searched for its opaque parts


@dataclass
class Candidate:
    """mask : (H, W) bool; score : share of the region backed by depth evidence, in [0, 1]."""

    mask: np.ndarray
    score: float


def joined_to(region: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """The 8-connected components of ``region`` ``(H, W) bool`` that hold a pixel of ``seeds``
    ``(H, W) bool``."""
    count, labels = cv2.connectedComponents(region.astype(np.uint8), connectivity=8)
    keep = np.unique(labels[seeds & region])
    return np.isin(labels, keep[keep > 0])


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """``ndimage.binary_fill_holes(mask)`` of a 2-D mask ``(H, W)`` (bool, or 0 / non-zero),
    the same pixels, filled within the box of its set pixels widened by one: all outside that
    box is background joined to the image's border. An object's region is a small part of
    the frame."""
    mask = np.asarray(mask, bool)
    out = np.zeros(mask.shape, bool)
    box = mask_window(mask, 1)
    if box is not None:
        out[box] = ndimage.binary_fill_holes(mask[box])
    return out


def _closed(mask: np.ndarray, radius: int) -> np.ndarray:
    """``(H, W) bool`` closed with a disk of ``radius`` pixels and its holes filled, the same
    pixels, closed within the box of its set pixels widened by ``2 * radius + 1``: the
    dilation reaches ``radius`` past that box, and the erosion, from a pixel the dilation set,
    ``radius`` further, which stays inside it."""
    out = np.zeros(mask.shape, bool)
    box = mask_window(mask, 2 * radius + 1)
    if box is not None:
        out[box] = cv2.morphologyEx(np.asarray(mask[box], np.uint8), cv2.MORPH_CLOSE,
                                    _disk(radius)) > 0
    return fill_holes(out)


def _cut_window(region: np.ndarray, margin: int) -> tuple[slice, slice]:
    """:func:`mask_window` of a region ``(H, W) bool`` (not empty) widened by ``margin``
    pixels and, up and left, to even coordinates, where its cuts are worked out: nothing
    they are made of (distances to the region's edge or to seeds inside it, openings,
    watersheds) reaches past it, and cv2 numbers components in 2x2 blocks from the image's
    corner, so that a window whose blocks line up with the image's numbers them alike."""
    rows, cols = mask_window(region, margin)
    return (slice(rows.start - rows.start % 2, rows.stop),
            slice(cols.start - cols.start % 2, cols.stop))


def _embedded(window: np.ndarray, box: tuple[slice, slice], shape: tuple[int, int],
              beyond: bool = False) -> np.ndarray:
    """``(H, W) bool`` of ``shape``: ``window`` ``(h, w) bool`` at ``box``, ``beyond``
    elsewhere."""
    out = np.full(shape, beyond)
    out[box] = window
    return out


def _disk(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _near_border(stats: np.ndarray, shape: tuple[int, int], reach_x: int, reach_y: int
                 ) -> np.ndarray:
    """``(count,) bool``: which components' boxes (``cv2.connectedComponentsWithStats`` stats)
    come within ``reach_x`` pixels of the image's left or right side or ``reach_y`` of its top
    or bottom."""
    x, y, bw, bh = (stats[:, k] for k in range(4))
    return ((np.minimum(x, shape[1] - x - bw) <= reach_x)
            | (np.minimum(y, shape[0] - y - bh) <= reach_y))


def _border_artefacts(holes: np.ndarray, max_share: float) -> np.ndarray:
    """Hole components that touch the image border and are too big or too elongated to be an
    object (beyond the table's range, the stereo camera's invalid left band)."""
    h, w = holes.shape
    count, labels, stats, _ = cv2.connectedComponentsWithStats(holes.astype(np.uint8), 8)
    bw, bh, area = stats[:, 2], stats[:, 3], stats[:, 4]
    drop = _near_border(stats, holes.shape, 0, 0) & (
        (area > max_share * h * w) | (bh > 0.6 * h) | (bw > 0.6 * w))
    drop[0] = False
    return drop[labels]


def roughness(depth_m: np.ndarray) -> np.ndarray:
    """Local depth roughness ``(H, W) float32`` metres: mean absolute residual against a 5x5
    median over valid readings (a clean step survives a median filter; noise does not)."""
    valid = depth_m > 0
    d_mm = np.clip(depth_m * 1000, 0, 65535).astype(np.uint16)
    med = cv2.medianBlur(d_mm, 5).astype(np.float32) / 1000
    used = valid & (med > 0)
    resid = np.where(used, np.abs(depth_m - med), 0).astype(np.float32)
    return cv2.blur(resid, (5, 5)) / np.maximum(cv2.blur(used.astype(np.float32), (5, 5)), 1e-3)


def table_noise_model(rough: np.ndarray, depth_m: np.ndarray, on_table: np.ndarray,
                      floor: float = 0.0005) -> np.ndarray:
    """Expected roughness of an opaque surface at each pixel's depth, learnt from the table.

    The median roughness of table pixels in depth bins, interpolated over depth; this adapts to
    the sensor (stereo noise grows with depth squared) without a noise constant.
    """
    z = depth_m[on_table]
    r = rough[on_table]
    if z.size < 50:
        return np.full(depth_m.shape, max(floor, 0.002), np.float32)
    edges = np.quantile(z, np.linspace(0, 1, 9))
    centres, levels = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (z >= lo) & (z <= hi)
        if sel.sum() >= 10:
            centres.append(float(np.median(z[sel])))
            levels.append(float(np.median(r[sel])))
    levels = np.maximum(np.asarray(levels), floor)
    model = np.interp(depth_m, centres, levels)
    # beyond the table's depth range extrapolate with the z^2 law from the nearest bin
    far, near = depth_m > centres[-1], depth_m < centres[0]
    model[far] = levels[-1] * (depth_m[far] / centres[-1]) ** 2
    model[near] = np.maximum(levels[0] * (depth_m[near] / centres[0]) ** 2, floor)
    return model.astype(np.float32)


def table_footprint(on_table: np.ndarray, below: np.ndarray) -> np.ndarray:
    """``(H, W) bool``: the convex hull of the largest connected patch of table readings
    ``on_table (H, W) bool``, the image region where the table (and so anything standing on
    it) can be. Holes beyond it (a white wall, the floor, the far room) are sensor dropouts,
    not glass.

    A glass's column of dropouts can cut the table's readings in two (a frame whose lower
    border runs through the glass's foot shows only a band of table, split by it): each other
    patch of at least :data:`FOOTPRINT_PATCH` of the largest's pixels joins it, largest first,
    where the hull of the joined patches has at most :data:`FOOTPRINT_BELOW` of its pixels
    reading below the table (``below (H, W) bool``): the hull over two halves of one table
    covers the glass between them, the hull over a far desk at the table's height covers the
    floor beyond the table's edge."""
    patch = cv2.morphologyEx(on_table.astype(np.uint8), cv2.MORPH_OPEN, _disk(2))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(patch, 8)
    if count < 2:  # no table seen: no footprint to gate by
        return np.ones(on_table.shape, bool)
    area = stats[:, cv2.CC_STAT_AREA]
    order = 1 + np.argsort(-area[1:], kind="stable")
    joined = labels == order[0]
    footprint = convex_hull(joined)
    for k in order[1:]:
        if area[k] < FOOTPRINT_PATCH * area[order[0]]:
            break
        hull = convex_hull(joined | (labels == k))
        if (below & hull).sum() <= FOOTPRINT_BELOW * hull.sum():
            joined |= labels == k
            footprint = hull
    return footprint


def on_table_readings(depth_m: np.ndarray, K: np.ndarray, plane: Plane
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Heights above the table ``(H, W) float`` metres (0 where no reading) and the readings
    that lie on it ``(H, W) bool`` (within :func:`table_band`)."""
    valid = depth_m > 0
    height = np.where(valid, plane.height(depth_to_points(depth_m, K)), 0.0)
    on_table = valid & (np.abs(height) < table_band(depth_m))
    return height, on_table


def table_band(depth_m: np.ndarray) -> np.ndarray:
    """``(H, W)`` metres: how far from the table's plane a reading at ``depth_m (H, W)``
    metres still lies on it (the sensor's depth-squared noise)."""
    return 0.004 * np.maximum(depth_m, 0.3) ** 2 + 0.002


def colour_lab(rgb: np.ndarray) -> np.ndarray:
    """``(H, W, 3) float32``: the CIELAB colour of ``rgb`` ``(H, W, 3) uint8`` (OpenCV's 8-bit
    scale), smoothed over 3 px, as :func:`table_colour_departure` compares it."""
    return cv2.cvtColor(cv2.GaussianBlur(rgb, (3, 3), 0), cv2.COLOR_RGB2LAB).astype(np.float32)


def table_colour_departure(rgb: np.ndarray, on_table: np.ndarray, window: int = COLOUR_WINDOW,
                           surroundings: bool = False, lab: np.ndarray | None = None
                           ) -> np.ndarray:
    """How far each pixel's colour departs from the table's colour around it ``(H, W) float``,
    in units of the table's own spread (the 90th percentile of table pixels' departure, at
    least :data:`LEAST_SPREAD`), NaN where no table reading lies within ``window`` pixels;
    with ``surroundings``, the departure there from the mean colour of all the window's
    pixels instead (inside a dropout, a cloth the sensor returns nothing from, what an object
    stands on is known by its colour alone).

    The table's local colour is the mean CIELAB colour of the pixels whose readings lie on the
    table, within the window. A transparent object shows the table through itself, so over
    most of its mask it departs little (edges and highlights aside); an opaque object's own
    colour replaces the table's. ``lab``: :func:`colour_lab` of ``rgb`` where already made
    (a frame's rules compare its colour three ways).
    """
    lab = colour_lab(rgb) if lab is None else lab
    weight = on_table.astype(np.float32)
    share = cv2.blur(weight, (window, window))
    local = cv2.blur(lab * weight[..., None], (window, window)) / np.maximum(share, 1e-6)[..., None]
    departure = np.linalg.norm(lab - local, axis=2)
    spread = np.percentile(departure[on_table], 90) if on_table.any() else 0.0
    scale = max(float(spread), LEAST_SPREAD)
    out = departure / scale
    unknown = share <= 0.05
    if surroundings and unknown.any():
        around = cv2.blur(lab, (window, window))
        out[unknown] = np.linalg.norm(lab - around, axis=2)[unknown] / scale
    else:
        out[unknown] = np.nan
    return out


def looks_opaque(mask: np.ndarray, departure: np.ndarray, level: float | None = None) -> bool:
    """Whether an instance ``(H, W) bool`` is an opaque object by its colour: the median
    :func:`table_colour_departure` over its pixels with a table nearby is above ``level``
    (:data:`OPAQUE_COLOUR` unless given)."""
    known = departure[mask]
    known = known[np.isfinite(known)]
    return known.size > 0 and \
        float(np.median(known)) > (OPAQUE_COLOUR if level is None else level)


def outline_evidence(departure: np.ndarray, on_table: np.ndarray, level: float = OUTLINE_COLOUR
                     ) -> np.ndarray:
    """``(H, W) bool``: pixels whose colour departs from the table's around them by more than
    ``level`` (:func:`table_colour_departure`) and whose reading is not on the table: a glass's
    outline, rim and highlights, where a reading is missing or off the table; a shadow cast on
    the table departs in colour too, but reads the table."""
    return (np.nan_to_num(departure, nan=0.0) > level) & ~on_table


def shows_outline(mask: np.ndarray, departure: np.ndarray,
                  within: np.ndarray | None = None) -> bool:
    """Whether an instance ``(H, W) bool`` has a visible outline: at least :data:`FAINT_SHARE`
    of the band 3 px either side of its edge departs from the table's colour by over
    :data:`FAINT_COLOUR` (:func:`table_colour_departure`), counting only the band's pixels in
    ``within`` ``(H, W) bool`` where given (the rest of the band counts as not departing).
    A glass's rim, refraction edge or reflections always show somewhere around it; a sensor's
    dropout on a plain cloth or wall shows the surface's own colour all round (measured on the
    shared real and extsim frames: glass at least 0.05, dropouts at most 0.012; a lying glass
    on a generated wood texture 0.022). The band's pixels within its width of the image's
    border are left out: an instance the border cuts goes on beyond it, and the colour
    compared there is smoothed against the border (a patch of the table's holes at the
    bottom edge of a Tracebot view moved by a pixel: 0.024 with them, 0.0 without)."""
    width = 3
    inner = cv2.erode(mask.astype(np.uint8), _disk(width)) > 0
    band = (cv2.dilate(mask.astype(np.uint8), _disk(width)) > 0) & ~inner
    band[:width], band[-width:], band[:, :width], band[:, -width:] = False, False, False, False
    if not band.any():
        return False
    departs = np.nan_to_num(departure[band], nan=0.0) > FAINT_COLOUR
    if within is not None:
        departs &= within[band]
    return bool(departs.mean() >= FAINT_SHARE)


def opaque_objects(opaque: np.ndarray, departure: np.ndarray) -> np.ndarray:
    """The connected parts of opaque evidence ``(H, W) bool`` that are opaque by their colour
    too (the rule of :func:`looks_opaque`, per part). A real glass's front surface often returns smooth readings
    above the table, but shows the table's colour through itself."""
    count, labels = cv2.connectedComponents(opaque.astype(np.uint8), connectivity=8)
    if count < 2:
        return np.zeros(opaque.shape, bool)
    # each component's median over its pixels with a known departure (sorted by component,
    # then value; a frame's other pixels are never sorted); a component with none is not opaque
    known = (labels > 0) & np.isfinite(departure)
    value, label = departure[known], labels[known]
    order = np.lexsort((value, label))
    value, label = value[order], label[order]
    first = np.searchsorted(label, np.arange(1, count))
    size = np.searchsorted(label, np.arange(1, count), side="right") - first
    low = value[np.minimum(first + (size - 1) // 2, len(value) - 1)] if len(value) else 0.0
    high = value[np.minimum(first + size // 2, len(value) - 1)] if len(value) else 0.0
    median = np.where(size > 0, (low + high) / 2, 0.0)
    keep = np.concatenate([[False], median > OPAQUE_COLOUR])
    return keep[labels]


def _grown_once(mask: np.ndarray, outline: np.ndarray, close_radius: int,
                barred: np.ndarray | None, reach: int) -> np.ndarray:
    """One step of :func:`grow_to_outline`: ``mask`` ``(H, W) bool`` with the ``outline``
    pixels within ``reach`` of it, closed and filled, less ``barred``, the parts joined to it."""
    near = cv2.dilate(mask.astype(np.uint8), _disk(reach)) > 0
    grown = _closed(mask | (near & outline), close_radius)
    if barred is not None:
        grown &= ~barred
    return joined_to(grown, mask)


def grow_to_outline(mask: np.ndarray, outline: np.ndarray, *, close_radius: int,
                    barred: np.ndarray | None = None, reach: int = OUTLINE_REACH,
                    surfaces: np.ndarray | None = None) -> np.ndarray:
    """An instance ``(H, W) bool`` grown to the colour outline around it.

    The depth evidence of a real glass often covers only where the sensor failed (its rim, a
    band of holes); the rest of the object reads the table through itself. Its outline, rim
    and highlights still show (``outline``, :func:`outline_evidence`): the outline pixels
    within ``reach`` of the instance are added, the result closed and filled, and only the
    parts joined to the instance kept. ``barred`` ``(H, W) bool`` (other instances) is never
    taken.

    With ``surfaces`` ``(H, W) bool`` (smooth readings above the table, ``Evidence.opaque``)
    the outline is then followed further, step by step, until a step adds nothing: an open
    vessel seen from above (a bowl, a water glass) shows the table through its floor, and its
    evidence of holes covers an arc of the rim, the rim's ellipse more than ``reach`` from
    it. The further steps never take ``surfaces`` beyond the first step's growth (an opaque
    object beside the glass, whose face departs from the table's colour too, is read
    smoothly), and of what they add only what an opening by a disc of
    :data:`FOLLOWED_THICKNESS` px keeps (parts at least 7 px across), joined to the first
    step's growth: a rim followed round encloses the vessel's mouth, which fills; an outline
    followed along another object's edge stays a thin line.
    """
    grown = _grown_once(mask, outline, close_radius, barred, reach)
    if surfaces is None:
        return grown
    barred = surfaces & ~grown if barred is None else barred | (surfaces & ~grown)
    followed = grown
    while True:
        step = _grown_once(followed, outline, close_radius, barred, reach)
        if step.sum() == followed.sum():
            break
        followed = step
    if followed is grown:  # no step added anything
        return grown
    added = cv2.morphologyEx((followed & ~grown).astype(np.uint8), cv2.MORPH_OPEN,
                             _disk(FOLLOWED_THICKNESS)) > 0
    return joined_to(grown | added, grown)


@dataclass
class Evidence:
    """Per-pixel evidence of one frame, all ``(H, W)``.

    glass, opaque : bool, see :func:`evidence_maps`; footprint : bool, :func:`table_footprint`;
    on_table : bool, readings on the table; above : bool, readings clearly above the table
    (rough or smooth); height : float metres over the table (0 where no reading). stereo:
    whether the frame shows a stereo camera's shadows (:func:`casts_stereo_shadows`).
    """

    glass: np.ndarray
    opaque: np.ndarray
    footprint: np.ndarray
    on_table: np.ndarray
    above: np.ndarray
    height: np.ndarray
    stereo: bool = False


def evidence_maps(depth_m: np.ndarray, K: np.ndarray, plane: Plane, *, rough_factor: float,
                  max_object_share: float, stereo_baseline: float) -> Evidence:
    """Glass evidence, opaque evidence, the table's footprint, the readings on and above the
    table, and the heights (:class:`Evidence`).

    Glass: holes where the table should be seen, except a stereo camera's shadows beside
    nearer surfaces in a frame that shows them (:func:`stereo_shadow`, with ``stereo_baseline``
    metres; 0: none), and readings above the table that are ``rough_factor`` times rougher than
    the table at that depth. Opaque: smooth readings
    clearly above the table. Footprint: :func:`table_footprint`. On the table:
    :func:`on_table_readings`.
    """
    valid = depth_m > 0
    height, on_table = on_table_readings(depth_m, K, plane)
    rough = roughness(depth_m)
    footprint = table_footprint(on_table, valid & (height < -table_band(depth_m)))
    holes = ~valid & (plane.depth_image(depth_m.shape, K) > 0)
    artefact = _border_artefacts(holes, max_object_share)
    # a glass rising above the table's far edge joins its outline of holes to the room's: the
    # parts of an artefact well inside the table's footprint are kept if they reach down into
    # it (taller than wide, as an outline standing on the table is; the table's ragged far
    # edge runs across) and stay away from the image's sides (a stereo camera's invalid band)
    inner = artefact & (cv2.erode(footprint.astype(np.uint8), _disk(3)) > 0)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(inner.astype(np.uint8), 8)
    kept = ~_near_border(stats, holes.shape, int(BORDER_REACH * holes.shape[1]), 0)
    kept &= stats[:, cv2.CC_STAT_HEIGHT] >= stats[:, cv2.CC_STAT_WIDTH]
    kept[0] = False
    holes &= ~artefact | kept[labels]
    expected = table_noise_model(rough, depth_m, on_table)
    above = valid & (height > np.maximum(4 * expected, 0.004))
    is_rough = rough > rough_factor * expected
    shadow = stereo_shadow(depth_m, float(K[0, 0]), stereo_baseline) \
        if stereo_baseline > 0 else None
    if shadow is not None:
        holes &= ~shadow
    glass = holes | (above & is_rough)
    opaque = above & ~is_rough
    opaque = cv2.morphologyEx(opaque.astype(np.uint8), cv2.MORPH_OPEN, _disk(2)) > 0
    glass &= ~opaque_edges(glass, opaque)
    return Evidence(glass, opaque, footprint, on_table, above & footprint, height,
                    stereo=shadow is not None)


def _row_steps(depth_m: np.ndarray, fx: float, baseline: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along each row, every reading against the previous reading to its left across a run of
    holes (or none): ``(gap, step, nearer)`` ``(H, W)``: the holes between them (px), the
    disparity step ``fx * baseline * (1/z - 1/z_left)`` (px) and whether the reading is nearer
    than that on its left by :data:`SHADOW_STEP`. Pixels with no reading on their left, or
    none of their own, have ``nearer`` False."""
    H, W = depth_m.shape
    valid = depth_m > 0
    cols = np.broadcast_to(np.arange(W), (H, W))
    last = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)
    before = np.concatenate([np.full((H, 1), -1), last[:, :-1]], axis=1)
    rows = np.broadcast_to(np.arange(H)[:, None], (H, W))
    here = valid & (before >= 0)
    z = np.where(here, depth_m, 1.0)
    z_left = np.where(here, depth_m[rows, np.maximum(before, 0)], 1.0)
    step = fx * baseline * (1 / z - 1 / z_left)
    return cols - before - 1, step, here & (z < z_left - SHADOW_STEP)


def casts_stereo_shadows(gap: np.ndarray, step: np.ndarray, nearer: np.ndarray) -> bool:
    """Whether a depth image comes from a stereo camera that leaves shadows, by its
    :func:`_row_steps`: of the places where a reading lies nearer than the one to its left by a
    disparity step of :data:`SHADOW_MIN_STEP` px or more (at least :data:`SHADOW_MIN_EDGES` of
    them), :data:`SHADOW_SIGNATURE` have holes between them at least half that step wide. A
    stereo camera cannot see both sides of such a step (measured: 0.98-1.00 on every shared
    real D435/D415 frame); a renderer without that model, or a time-of-flight camera, reads
    straight across most of them (extsim at most 0.30, sr3d's own generator at most 0.44)."""
    edges = nearer & (step >= SHADOW_MIN_STEP)
    count = int(edges.sum())
    return count >= SHADOW_MIN_EDGES and \
        float((gap[edges] >= 0.5 * step[edges]).mean()) >= SHADOW_SIGNATURE


def stereo_shadow(depth_m: np.ndarray, fx: float, baseline: float) -> np.ndarray | None:
    """``(H, W) bool``: the holes a stereo depth camera leaves beside a nearer surface, in a
    frame that shows such shadows (:func:`casts_stereo_shadows`; else None).

    The depth image is the left imager's view: next to the left side of a surface, the
    left imager sees a strip of what lies behind it that the right imager does not, and no
    depth can be matched there. Along each row, a hole is in that shadow when the reading that
    ends its run on the right is nearer (by :data:`SHADOW_STEP`) than the one that starts it on
    the left and the hole lies within the disparity step ``fx * baseline * (1/z_right -
    1/z_left)`` (plus :data:`SHADOW_SLACK` px) of that reading. depth_m : (H, W) metres (0 =
    none); fx : pixels; baseline : metres. A glass's own holes run between the table's readings
    on both sides, so no step explains them: the cap of a container, a bottle's readable
    front or an opaque object stops only the strip beside it.
    """
    H, W = depth_m.shape
    gap, step, nearer = _row_steps(depth_m, fx, baseline)
    if not casts_stereo_shadows(gap, step, nearer):
        return None
    cols = np.broadcast_to(np.arange(W), (H, W))
    right = np.minimum.accumulate(np.where(depth_m > 0, cols, W)[:, ::-1], axis=1)[:, ::-1]
    rows = np.broadcast_to(np.arange(H)[:, None], (H, W))
    end = np.minimum(right, W - 1)  # the reading that ends each hole's run on the right
    return (depth_m <= 0) & (right < W) & nearer[rows, end] & \
        (right - cols <= step[rows, end] + SHADOW_SLACK)


def along_table_edge(footprint: np.ndarray, reach: int) -> np.ndarray:
    """``(H, W) bool``: pixels within ``reach`` px of the edge of the table's footprint
    ``(H, W) bool``, on either side."""
    inside = cv2.distanceTransform(footprint.astype(np.uint8), cv2.DIST_L2, 3)
    outside = cv2.distanceTransform((~footprint).astype(np.uint8), cv2.DIST_L2, 3)
    return np.where(footprint, inside, outside) <= reach


def in_seed_columns(readings: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """``(H, W) bool``: the ``readings`` ``(H, W) bool`` in an image column where their
    connected group of readings holds one of the ``seeds`` ``(H, W) bool``. A standing
    object's lower readings lie under its higher ones; a D4xx smooths its depth across the
    object's sides, and the readings it leaves there, falling to the table over 12-16 px at
    1280 px (Tracebot view 092: 19 mm high beside the container's edge, 7 mm 8 px further
    out), stand beside those columns."""
    count, labels = cv2.connectedComponents(readings.astype(np.uint8), connectivity=8)
    held = np.zeros((count, readings.shape[1]), bool)
    ys, xs = np.nonzero(seeds & readings)
    held[labels[ys, xs], xs] = True
    held[0] = False
    ys, xs = np.nonzero(readings)
    out = np.zeros_like(readings)
    out[ys, xs] = held[labels[ys, xs], xs]
    return out


def along_far_edge(footprint: np.ndarray, reach: int) -> np.ndarray:
    """``(H, W) bool``: pixels within ``reach`` rows of the top of the table's footprint
    ``(H, W) bool`` in their column: where the table meets the room beyond it (the camera
    looks down at the table, so its far edge is the footprint's top)."""
    h = footprint.shape[0]
    seen = footprint.any(axis=0)
    top = np.where(seen, footprint.argmax(axis=0), h)
    return seen[None, :] & (np.abs(np.arange(h)[:, None] - top[None, :]) <= reach)


def over_feet(readings: np.ndarray, seeds: np.ndarray, depth_m: np.ndarray, K: np.ndarray,
              plane: Plane, reach: float) -> np.ndarray:
    """``(H, W) bool``: the ``seeds`` and those of the ``readings`` whose foot on the table (the
    point dropped along the table's normal) lies within ``reach`` metres of the foot of a seed
    and that lie in a seed's column (:func:`in_seed_columns`; all ``(H, W) bool`` over
    ``depth_m (H, W)`` metres, K ``(3, 3)``)."""
    out = seeds.copy()
    low = in_seed_columns(readings, seeds) & ~seeds
    if not low.any() or not seeds.any():
        return out

    def feet(sel: np.ndarray) -> np.ndarray:
        ys, xs = np.nonzero(sel)
        p = unproject(np.column_stack([xs, ys]), depth_m[ys, xs], K)
        return p - plane.height(p)[:, None] * plane.normal

    dist, _ = cKDTree(feet(seeds)).query(feet(low), distance_upper_bound=reach)
    out[low] = np.isfinite(dist)
    return out


class BodyTests:
    """The tests of a standing body (:func:`standing_bodies`) on one frame: called on a mask
    ``(H, W) bool``, None where it fails one of size (``min_area`` pixels), holes
    (:data:`BODY_HOLES`) and height (:data:`BODY_HEIGHT`), else whether it shows the table
    (:data:`BODY_SEES_TABLE` of its pixels table-like in colour within
    :data:`SEE_THROUGH_WINDOW`, or like their surroundings where no table reading is near).
    ``lab``: :func:`colour_lab` of ``rgb`` where already made."""

    def __init__(self, rgb: np.ndarray, depth_m: np.ndarray, ev: Evidence, *, min_area: int,
                 lab: np.ndarray | None = None):
        self.valid, self.height, self.min_area = depth_m > 0, ev.height, min_area
        self.departure = table_colour_departure(rgb, ev.on_table, window=SEE_THROUGH_WINDOW,
                                                surroundings=True, lab=lab)

    def __call__(self, mask: np.ndarray) -> bool | None:
        area = int(mask.sum())
        read = mask & self.valid
        if area < self.min_area or not read.any() or (area - read.sum()) < BODY_HOLES * area:
            return None
        if np.percentile(self.height[read], 95) < BODY_HEIGHT:
            return None
        known = self.departure[mask]
        known = known[np.isfinite(known)]
        return bool(known.size and np.mean(known < TABLE_LIKE) >= BODY_SEES_TABLE)


def standing_bodies(depth_m: np.ndarray, ev: Evidence, K: np.ndarray, plane: Plane,
                    tests: BodyTests, *, close_radius: int) -> list[tuple[np.ndarray, bool]]:
    """Glass objects found by their readings over the table: ``(mask, sees_table)`` each,
    mask ``(H, W) bool``; ``sees_table`` is False for a body that passes every test but the
    see-through one (:func:`with_bodies` joins such a body only to an instance that already
    holds :data:`BODY_JOINED` of it).

    A real stereo camera often reads a glass's front surface smoothly, so a standing glass
    looks like an opaque object by its depth alone; what gives it away is that it shows the
    table's colour through itself (:data:`BODY_SEES_TABLE`) and that the sensor fails
    somewhere on it (:data:`BODY_HOLES`). Where no table reading lies within
    :data:`SEE_THROUGH_WINDOW` of it (a glass on a white cloth the sensor returns nothing
    from), it is the colour of its surroundings it must show. A body: the readings clearly
    above the table joined to one at least :data:`BODY_SEED_HEIGHT` high (the table's own
    bumps never reach that), closed and filled, that passes ``tests`` (:class:`BodyTests`: at
    least its ``min_area`` pixels and :data:`BODY_HEIGHT` tall); it is judged by all of them.

    Its mask keeps only the readings that stand over the object's own footprint: those at
    least :data:`BODY_SEED_HEIGHT` high and the lower ones whose foot on the table lies
    within :data:`BODY_FEET_REACH` of the foot of one of those, in their columns
    (:func:`over_feet`), closed and filled. A stereo camera's noise on a plain table leaves
    bumps a few millimetres high all over it; those beside the object join it through the
    closing, but stand on the table beside its base, not over it. Its smoothing leaves a
    ramp of readings beside the object's sides whose feet lie within that reach, but not
    under the object's higher readings.
    """
    high = ev.height > BODY_SEED_HEIGHT
    seeded = joined_to(ev.above, high)
    body = _closed(seeded, close_radius)
    count, labels = cv2.connectedComponents(body.astype(np.uint8), connectivity=8)
    if count < 2:
        return []
    own = _closed(over_feet(seeded, seeded & high, depth_m, K, plane, BODY_FEET_REACH),
                  close_radius)
    out = []
    for k in range(1, count):
        mask = labels == k
        sees_table = tests(mask)
        if sees_table is None:
            continue
        kept = mask & own
        out.append((kept if kept.sum() >= tests.min_area else mask, sees_table))
    return out


def with_bodies(found: list[Candidate], bodies: list[tuple[np.ndarray, bool]],
                evidence: np.ndarray, one_object, parted, tests=None) -> list[Candidate]:
    """Candidates with the :func:`standing_bodies` joined in.

    A body that does not show the table counts only where one candidate holds
    :data:`BODY_JOINED` of it: a glass whose top the sensor failed on (a candidate by its
    holes) and whose lower part it read smoothly, the table's colour there hidden by the
    walls and edges of a thick plastic; alone, or mostly beside a candidate, such a body is
    an opaque object. A body overlapping no candidate is new: it is cut by ``parted`` (a
    callable from an ``(H, W) bool`` mask to its parts: :func:`split_touching` with parts
    that both stand), each part a candidate scored by its share of ``evidence`` ``(H, W)
    bool`` (glass evidence or readings above the table). Two glasses a few millimetres apart
    that the sensor reads smoothly close into one body; a container whose readings are
    pinched where its glass fails across its middle cuts into parts that fit only lying (the
    shared Tracebot views copied beside themselves 100 px apart: one of them), so a body's
    cut holds only where both parts stand. A body mostly inside one candidate
    (:data:`BODY_INSIDE`) is a part of it and adds nothing. A body that one candidate overlaps
    less is joined to it: that candidate's glass evidence covered only the part of the object
    the sensor failed on, unless the join is no longer ``one_object`` (a callable on an
    ``(H, W) bool`` mask and the body: :func:`splits` finds no cut but through the body's
    own surface, as where a container's lid's holes join its read body, Tracebot views 053
    and 079 moved by a pixel). A joined body that shows the table and that ``parted`` cuts
    into standing parts is objects side by side whose holes the candidate joined across their
    tops (the shared Tracebot views copied beside themselves 40 px apart: 053, 066 and 092):
    the join goes to the parts, each pixel to the nearest (:func:`nearest_part`). Where the
    join is not one object, the body's part beyond that
    candidate is another object touching it, new like a body overlapping none where it
    passes ``tests`` itself (:class:`BodyTests`) and shows the table (a container read
    smoothly beside the holes on its lid; not a notebook that joined a glass's body, flat and
    fully read). A body that two candidates share
    (:data:`BODY_SHARED` of it each) is touching objects the candidates have already parted,
    and adds nothing.
    """
    out = list(found)
    for body, sees_table in bodies:
        area = int(body.sum())
        overlap = np.array([int((c.mask & body).sum()) for c in out])
        if not sees_table and (not overlap.size or overlap.max() < BODY_JOINED * area):
            continue
        if not overlap.size or overlap.max() == 0:
            out += [Candidate(part, float(evidence[part].mean())) for part in parted(body)]
            continue
        if (overlap >= BODY_SHARED * area).sum() > 1:
            continue
        j = int(np.argmax(overlap))
        if overlap[j] < BODY_INSIDE * area:
            others = [c.mask for i, c in enumerate(out) if i != j and overlap[i] > 0]
            free = body & ~np.any(others, axis=0) if others else body
            joined = out[j].mask | free
            if one_object(joined, body):
                pieces = nearest_part(joined, parted(body) if sees_table else [body])
                out += [Candidate(piece, out[j].score) for piece in pieces[1:]]
                out[j] = Candidate(pieces[0], out[j].score)
            elif tests is not None:
                rest = free & ~out[j].mask
                if tests(rest):
                    out += [Candidate(part, float(evidence[part].mean()))
                            for part in parted(rest)]
    return out


def nearest_part(mask: np.ndarray, parts: list[np.ndarray]) -> list[np.ndarray]:
    """``mask`` ``(H, W) bool`` divided among ``parts`` (``(H, W) bool`` each): each pixel
    goes to the part nearest to it (:func:`_nearest_seed`; where parts overlap, the later
    one). One part or none: ``[mask]``."""
    if len(parts) < 2:
        return [mask]
    seeds = np.zeros(mask.shape, np.int32)
    for k, part in enumerate(parts):
        seeds[part] = k + 1
    nearest = _nearest_seed(seeds)
    return [mask & (nearest == k + 1) for k in range(len(parts))]


def without_opaque_dropouts(found: list[Candidate], bodies: list[tuple[np.ndarray, bool]],
                            departure: np.ndarray) -> list[Candidate]:
    """``found`` less the candidates that are an opaque object's dropouts: at least
    :data:`OPAQUE_DROPOUTS` of the candidate lies in a :func:`standing_bodies` body that does
    not show the table and that it holds less than :data:`BODY_JOINED` of (an opaque object, by
    :func:`with_bodies`), and its own colour departs from the table's (median
    :func:`table_colour_departure` ``(H, W)`` over :data:`OUTLINE_COLOUR`). A dark opaque object
    drops out where it is darkest and is read smoothly elsewhere, so its holes are a candidate
    with its colour; a glass's holes show the table through it (the real holders' candidates
    that lie in such bodies depart 1.0-2.1)."""
    opaque = [(body, int(body.sum())) for body, sees_table in bodies if not sees_table]
    out = []
    for c in found:
        area = int(c.mask.sum())
        shared = [(int((c.mask & body).sum()), size) for body, size in opaque]
        if any(both >= OPAQUE_DROPOUTS * area and both < BODY_JOINED * size
               for both, size in shared) and looks_opaque(c.mask, departure, OUTLINE_COLOUR):
            continue
        out.append(c)
    return out


def opaque_edges(glass: np.ndarray, opaque: np.ndarray, *, reach: int = EDGE_REACH,
                 share: float = EDGE_SHARE, thin: float = EDGE_THIN) -> np.ndarray:
    """Glass evidence ``(H, W) bool`` that belongs to an opaque object's edge: the connected
    components at most ``2 * thin`` pixels thick, ``share`` of whose pixels lie within ``reach``
    pixels of opaque evidence. A stereo camera misses readings in a thin band along an opaque
    object's side (and the readings at its edge are rough); left as glass, the closing of
    :func:`find_candidates` bridges from a glass nearby to that band, and the table readings
    between them join the glass's mask. A glass's own evidence is thicker, or only touches
    the opaque object along part of its outline."""
    near = cv2.dilate(opaque.astype(np.uint8), _disk(reach)) > 0
    count, labels = cv2.connectedComponents(glass.astype(np.uint8), connectivity=8)
    size = np.bincount(labels.ravel(), minlength=count)
    close = np.bincount(labels[near].ravel(), minlength=count)
    edge = close >= share * size
    edge[0] = False
    if edge.any():  # half a component's thickness: its largest distance to its own edge
        near_band = edge[labels]
        inset = cv2.distanceTransform(near_band.astype(np.uint8), cv2.DIST_L2, 3)
        half = np.zeros(count)
        np.maximum.at(half, labels[near_band], inset[near_band])
        edge &= half <= thin
    return edge[labels]


def _enclosed(region: np.ndarray, reach: int, share: float = ENCLOSED_SHARE,
              far_edge: np.ndarray | None = None, on_table: np.ndarray | None = None
              ) -> np.ndarray:
    """``(H, W) bool``: gaps nearly closed in by ``region``: what its closing by a disc of
    radius ``reach`` adds or encloses, ``share`` of the pixels around which are the region's.
    An outline of holes with a narrow opening (where the evidence thins out, at the table's far
    edge or a bright reflection) has its inside filled; the table boxed in by two objects is
    open over more of its edge. (A slit narrower than the closing between two objects is
    filled, as :func:`merge_pieces` joins such pieces anyway; :func:`split_touching` parts
    them.) The band of dropouts along the table's ``far_edge`` ``(H, W) bool``
    (:func:`along_far_edge`) does not close in a gap that reads the table (:data:`TABLE_GAP`
    of its pixels ``on_table`` ``(H, W) bool``): it runs beside whatever stands near that edge,
    and the table between a glass and it is table (extsim scene 9: a pitcher 2 cm from the far
    edge, its instance 0.85 -> 0.98 IoU; Tracebot view 027 moved a pixel down and right 0.64
    -> 0.78)."""
    closed = cv2.morphologyEx(region.astype(np.uint8), cv2.MORPH_CLOSE, _disk(reach)) > 0
    gaps = ndimage.binary_fill_holes(closed) & ~region
    count, labels = cv2.connectedComponents(gaps.astype(np.uint8), connectivity=4)
    if count < 2:
        return gaps
    # the pixels just outside each gap, labelled with its number (with two gaps side by side,
    # the larger number's)
    ring = cv2.dilate(labels.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int32)
    ring[gaps] = 0
    held = np.bincount(ring[region].ravel(), minlength=count)
    around = np.bincount(ring.ravel(), minlength=count)
    if far_edge is not None and on_table is not None:
        table = np.bincount(labels[on_table], minlength=count) >= \
            TABLE_GAP * np.bincount(labels.ravel(), minlength=count)
        held = np.where(table, np.bincount(ring[region & ~far_edge].ravel(), minlength=count),
                        held)
    keep = held >= share * np.maximum(around, 1)
    keep[0] = False
    return keep[labels]


def find_candidates(glass: np.ndarray, opaque: np.ndarray, *, min_area: int,
                    close_radius: int, far_edge: np.ndarray | None = None,
                    on_table: np.ndarray | None = None) -> list[np.ndarray]:
    """Connected regions of glass evidence, closed and filled (holes and nearly closed gaps,
    :func:`_enclosed`, with ``far_edge`` and ``on_table``), without opaque parts."""
    region = cv2.morphologyEx(glass.astype(np.uint8), cv2.MORPH_CLOSE, _disk(close_radius)) > 0
    region = ndimage.binary_fill_holes(region | _enclosed(region, 2 * close_radius,
                                                          far_edge=far_edge,
                                                          on_table=on_table))
    veto = cv2.dilate(opaque.astype(np.uint8), _disk(2)) > 0
    region &= ~veto
    region = cv2.morphologyEx(region.astype(np.uint8), cv2.MORPH_OPEN, _disk(3)) > 0
    count, labels, stats, _ = cv2.connectedComponentsWithStats(region.astype(np.uint8), 8)
    return [labels == k for k in range(1, count) if stats[k, cv2.CC_STAT_AREA] >= min_area]


def grabcut_refine(rgb: np.ndarray, candidate: np.ndarray, opaque: np.ndarray, *,
                   iterations: int, margin: int = 20) -> np.ndarray:
    """Refine one candidate ``(H, W) bool`` with GrabCut in a window around it; the result
    holds the whole candidate (GrabCut only adds to it)."""
    h, w = candidate.shape
    ys, xs = np.nonzero(candidate)
    pad = max(margin, int(0.3 * max(np.ptp(ys), np.ptp(xs))))
    y0, y1 = max(0, ys.min() - pad), min(h, ys.max() + pad + 1)
    x0, x1 = max(0, xs.min() - pad), min(w, xs.max() + pad + 1)
    cand = candidate[y0:y1, x0:x1].astype(np.uint8)
    gc = np.full(cand.shape, cv2.GC_BGD, np.uint8)
    gc[cv2.dilate(cand, _disk(max(3, pad // 3))) > 0] = cv2.GC_PR_BGD
    gc[cand > 0] = cv2.GC_PR_FGD
    core = cv2.erode(cand, _disk(4)) > 0
    gc[core] = cv2.GC_FGD
    gc[opaque[y0:y1, x0:x1]] = cv2.GC_BGD
    if not (gc == cv2.GC_FGD).any() or not np.isin(gc, (cv2.GC_BGD, cv2.GC_PR_BGD)).any():
        return candidate
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    image = np.ascontiguousarray(rgb[y0:y1, x0:x1, ::-1])
    cv2.setRNGSeed(0)  # GrabCut seeds its colour models with k-means: same input, same mask
    cv2.grabCut(image, gc, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    # GrabCut may only add to the depth candidate (it is the high-precision part)
    fg = np.isin(gc, (cv2.GC_FGD, cv2.GC_PR_FGD)) | (cand > 0)
    fg = ndimage.binary_fill_holes(fg)
    fg = joined_to(fg, cand > 0)  # the component(s) overlapping the candidate
    out = np.zeros_like(candidate)
    out[y0:y1, x0:x1] = fg
    return out


def segment_training_free(rgb: np.ndarray, depth_m: np.ndarray, K: np.ndarray, plane: Plane, *,
                          rough_factor: float = 2.0, min_area: int = 150, close_radius: int = 6,
                          grabcut_iterations: int = 4, max_object_share: float = 0.25,
                          stereo_baseline: float = 0.05, min_score: float = 0.0
                          ) -> list[Candidate]:
    """Instance candidates of transparent objects in one RGB-D frame.

    rgb : (H, W, 3) uint8; depth_m : (H, W) metres (0 = none); K : (3, 3); plane : the table.
    A region scored below ``min_score`` (its share of glass evidence) is dropped as soon as
    it is scored, before the candidates grow and join: a frame's scattered holes on the
    table, closed into a network that encloses a wide patch of it, score low, and kept to
    the end they take the pixels of a glass beside them and both are lost.
    Returns candidates sorted by area (largest first); masks do not overlap.
    """
    ev = evidence_maps(depth_m, K, plane, rough_factor=rough_factor,
                       max_object_share=max_object_share, stereo_baseline=stereo_baseline)
    glass, opaque, footprint, on_table = ev.glass, ev.opaque, ev.footprint, ev.on_table
    pieces = find_candidates(glass, opaque, min_area=min_area // 4, close_radius=close_radius,
                             far_edge=along_far_edge(footprint, TABLE_EDGE_BAND),
                             on_table=on_table)
    size = depth_m.size
    # an object stands on the table: most of a candidate lies over the table's footprint (a
    # glass at the far edge may rise above it in the image, so not all of it); GrabCut only
    # adds to a candidate, so one already over MAX_IMAGE_SHARE is dropped before it (a frame's
    # dropouts joined into one candidate cost GrabCut over a second)
    pieces = [p for p in pieces if (p & footprint).sum() >= ON_TABLE_SHARE * p.sum() and
              p.sum() <= MAX_IMAGE_SHARE * size]
    if grabcut_iterations > 0:
        pieces = [grabcut_refine(rgb, p, opaque, iterations=grabcut_iterations) for p in pieces]
    lab = colour_lab(rgb)  # compared three ways: against the table, the surroundings, the room
    departure = table_colour_departure(rgb, on_table, lab=lab)
    kept = []
    least = max(min_area, int(MIN_IMAGE_SHARE * size))
    pieces = [p for p in pieces if p.sum() <= MAX_IMAGE_SHARE * size]

    def by_colour(mask: np.ndarray) -> bool:
        return looks_opaque(mask, departure)

    # the table's footprint less the band of dropouts along its edge, where the table meets
    # the room
    edge = along_table_edge(footprint, TABLE_EDGE_BAND)
    over_table = footprint & ~edge
    off_edge = footprint & ~along_table_edge(footprint, TABLE_EDGE_TRIM) if ev.stereo else \
        over_table
    fits = _PartFits(K, plane, depth_m)  # every revolution fit of the frame, made once
    apart = []  # the parts of the footprint cuts the outline alone took (lying_pieces_joined)
    for region in merge_pieces(pieces, depth_m.shape, radius=2 * close_radius):
        # beyond the table a region keeps only the columns its part over the table spans
        # before its cuts are judged: the room's dropouts joined to a glass at the far edge
        # make a whole that no cut parts (ClearGrasp 123: a wall's holes, the table they close
        # in beside a notebook, and a holder; once the wall is gone, the holder is cut from
        # the table, whose part then holds too little glass evidence to score)
        region = within_table_columns(region, over_table)
        if region.sum() < least:  # no part of it could be kept: judging its cuts spends fits
            continue
        # a region or part opaque by its colour as a whole is not split (the revolution fits
        # are most of segment's time), only dropped: on the shared real, extsim and generated
        # frames no part of one is ever kept, and a glass whose colour departs from the
        # table's is found by its readings instead (standing_bodies)
        # the outline is read over the table only: where the table meets the room the colour
        # departs along the whole edge, and a dropout beside it would show that as its own
        # (Tracebot view 027: a patch of holes under the robot at the table's far edge)
        for mask in split_touching(region, K, plane, depth=depth_m, glass=glass,
                                   close_radius=close_radius, min_area=min_area,
                                   opaque=by_colour, fits=fits, apart=apart):
            if least <= mask.sum() <= MAX_IMAGE_SHARE * size and not by_colour(mask) and \
                    shows_outline(mask, departure, over_table):
                kept.append(Candidate(mask, float(glass[mask].mean())))
    kept = [c for c in kept if c.score >= min_score]
    # never grown into: another instance, or an opaque object and the band of missing readings
    # a stereo camera leaves around it
    beside_opaque = cv2.dilate(opaque_objects(opaque, departure).astype(np.uint8),
                               _disk(OPAQUE_BAND)) > 0
    claimed = beside_opaque.copy()
    for c in kept:
        claimed |= c.mask
    # grown over the table's footprint only: beyond it every pixel of the room departs from
    # the table's colour, and the closing would join an instance to the room's edge and fill
    # the table between (extsim scene 9: a pitcher 2 cm from the table's far edge)
    outline = outline_evidence(departure, on_table) & footprint
    out = [Candidate(grow_to_outline(c.mask, outline, close_radius=5, barred=claimed & ~c.mask,
                                     surfaces=ev.opaque), c.score) for c in kept]
    # a region cut at a dent in its evidence that the growth filled is one object again
    out = rejoined(out, K, plane, depth_m, glass, fits)
    tests = BodyTests(rgb, depth_m, ev, min_area=least, lab=lab)
    bodies = standing_bodies(depth_m, ev, K, plane, tests, close_radius=close_radius)

    def one_object(mask: np.ndarray, body: np.ndarray) -> bool:
        return not splits(mask, K, plane, depth=depth_m, glass=glass,
                          close_radius=close_radius, min_area=min_area, fits=fits, body=body)

    def parted(mask: np.ndarray) -> list[np.ndarray]:
        return split_touching(mask, K, plane, depth=depth_m, glass=glass,
                              close_radius=close_radius, min_area=min_area, standing=True,
                              fits=fits)

    out = without_opaque_dropouts(out, bodies, departure)
    joined = with_bodies(out, bodies, glass | ev.above, one_object, parted, tests)
    # an object stands on the table; a band of dropouts along the table's edge, where the
    # table meets the room, is none: one lying mostly along the edge (with what lies beyond
    # the table above its whole span), or whose part over the table lies mostly in that band
    # (the room's dropouts beyond the far edge joined to it), is dropped, and beyond the table
    # or along its edge the others keep only the columns above their feet (the holes on the
    # table beside a glass at the far edge join the room's above them; the band a stereo
    # camera leaves along the edge reaches TABLE_EDGE_TRIM into the table)
    masks = [within_table_columns(c.mask, over_table) for c in joined]
    keep = [i for i, m in enumerate(masks) if not m.any() or (
        edge[m].mean() <= TABLE_EDGE_SHARE and
        (m & over_table).sum() >= TABLE_CLEAR_SHARE * (m & footprint).sum())]
    masks = [within_table_columns(masks[i], off_edge, feet=FEET_SHARE) for i in keep]
    joined = [joined[i] for i in keep]
    masks = [with_parts_on_axis(m, K, plane, depth_m, ev.height, fits) for m in masks]
    if ev.stereo:  # a stereo camera's holes and bumps beside a glass: within its outline
        seen = beside_room(rgb, depth_m, footprint, departure, lab)
        # where the table meets the room its colour gives way to the room's: that line is the
        # table's own outline, and an instance holding the table up to its far edge would keep
        # it all in its hull
        edges = outline_evidence(seen, on_table) & ~along_table_edge(footprint, TABLE_LINE)
        own = own_pixels(seen, ev.height)
        masks = [within_outline_hull(m, edges, own) for m in masks]
    found = [Candidate(m, c.score) for m, c in zip(masks, joined)]
    found = _without_overlaps(lying_pieces_joined(found, K, plane, depth_m, glass, fits=fits,
                                                  apart=apart))
    found = cuts_on_colour_edges(found, rgb, lab)
    found = found if ev.stereo else with_hull_gaps(found, ev, depth_m > 0, beside_opaque)
    return [c for c in found if placeable(c.mask, fits)]


def placeable(mask: np.ndarray, fits: "_PartFits") -> bool:
    """Whether an instance ``mask (H, W) bool`` can be a glass object on the table: its
    revolution fit (``fits``, :class:`_PartFits`) draws it at IoU :data:`MIN_FIT_IOU` or better
    and is :data:`MIN_OBJECT_SIZE` tall or wide. One that reaches the image's border is kept
    whatever its fit: the border may cut the object down to a sliver."""
    if on_image_border(mask):
        return True
    fit = fits(mask)
    if fit is None or fit.iou < MIN_FIT_IOU:
        return False
    width = 2.0 * float(fit.profile[:, 0].max()) * fit.height
    return max(fit.height, width) >= MIN_OBJECT_SIZE


def lying_pieces_joined(found: list[Candidate], K: np.ndarray, plane: Plane,
                        depth_m: np.ndarray, glass: np.ndarray, reach: int = OUTLINE_REACH,
                        fits: "_PartFits | None" = None,
                        apart: list[tuple[np.ndarray, np.ndarray]] = ()) -> list[Candidate]:
    """Candidates with the pieces of one lying object joined: two candidates (masks (H, W)
    bool) within ``reach`` pixels of each other, each fitted lying (a solid of revolution on
    ``plane``, camera ``K`` (3, 3), readings ``depth_m`` (H, W) metres), are one object when
    the convex hull of both, less the other candidates' pixels, is fitted lying too and draws
    it at least as well as the pieces' own fits draw them (their IoUs weighted by area). The
    joined candidate is that hull, scored by its share of ``glass`` (H, W) bool; the nearest
    pairs are judged first, and a joined candidate is judged again.

    A lying glass reads the table through its middle, where the sensor has nothing to fail
    on: its evidence comes in pieces along its axis (ClearGrasp 080's lying bottle, three
    pieces 22 and 1 px apart: the hull fits at 0.92 and 0.93, the pieces at 0.83 and 0.78 by
    area; extsim scene_0002's oil bottle: 0.78 against 0.76). Two lying objects side by side
    draw worse as one (extsim scene_0006: 0.89 against 0.92). ``fits``: the frame's fits
    (:class:`_PartFits`), made here when not given.

    ``apart``: the parts ``(a, b)`` of the footprint cuts the outline alone took
    (:func:`split_touching`): objects whose readings stand apart on the table. Two candidates
    that hold half of each of those parts are joined only where the hull draws them clearly
    better, by :data:`CLEAR_GAIN` times :data:`SPLIT_GAIN` (the gain a cut the readings
    refute needs): a lying fit draws any blob well, and extsim scene 0's glass bowl and wine
    glass draw 0.05 better as one (0.88 against 0.82), where the pieces of ClearGrasp 080's
    lying bottle draw 0.14 better."""
    fits = _PartFits(K, plane, depth_m) if fits is None else fits

    def kept_apart(a: np.ndarray, b: np.ndarray) -> bool:
        for parts in apart:
            held = [[int((m & p).sum()) for p in parts] for m in (a, b)]
            ia, ib = (int(np.argmax(h)) for h in held)
            if ia != ib and held[0][ia] >= 0.5 * parts[ia].sum() and \
                    held[1][ib] >= 0.5 * parts[ib].sum():
                return True
        return False

    def lying(mask: np.ndarray):
        fit = fits(mask)
        return fit if fit is not None and fit.resting == "lying" else None

    out = list(found)
    while True:
        gaps = []  # (gap px, i, j)
        for i, c in enumerate(out):
            dist = cv2.distanceTransform((~c.mask).astype(np.uint8), cv2.DIST_L2, 3)
            gaps += [(float(dist[d.mask].min()), i, j) for j, d in enumerate(out)
                     if j > i and d.mask.any()]
        for gap, i, j in sorted(gaps):
            if gap > reach:
                return out
            a, b = out[i].mask, out[j].mask
            fa, fb = lying(a), lying(b)
            if fa is None or fb is None:
                continue
            hull = convex_hull(a | b)
            for k, c in enumerate(out):
                if k not in (i, j):
                    hull &= ~c.mask
            whole = lying(hull)
            na, nb = int(a.sum()), int(b.sum())
            margin = CLEAR_GAIN * SPLIT_GAIN if kept_apart(a, b) else 0.0
            if whole is not None and \
                    whole.iou >= (fa.iou * na + fb.iou * nb) / (na + nb) + margin:
                out[i] = Candidate(hull, float(glass[hull].mean()))
                del out[j]
                break
        else:
            return out


def rejoined(found: list[Candidate], K: np.ndarray, plane: Plane, depth_m: np.ndarray,
             glass: np.ndarray, fits: "_PartFits | None" = None) -> list[Candidate]:
    """Candidates grown to their outlines (:func:`grow_to_outline`; masks (H, W) bool) with
    the touching ones that are one object joined again: two candidates whose masks touch are
    one when a solid of revolution fitted to their union (camera ``K`` (3, 3) above
    ``plane``) draws it at least as well as the parts' own fits (their IoU weighted by area)
    and its surface holds as many of the union's off-table readings ``depth_m (H, W)``
    metres as theirs (each part's counted where the other does not reach) and of each part's
    own (:func:`_apart_by_readings`). A joined candidate is scored by its share of ``glass``
    evidence (H, W) bool.

    :func:`split_touching` judges a region before it is grown: where an object's glass gave
    no evidence its region has a dent, and two fits of the parts either side of it draw the
    region better than one of the whole (extsim's lying bottle: parts 0.82 / 0.83, whole
    0.72). Grown to the outline, the dent is filled, and one fit of both draws them better
    (parts 0.92 / 0.87, union 0.95); touching objects still draw worse as one (extsim:
    0.76-0.93 as one against 0.86-0.96 as two). ``fits``: the frame's fits
    (:class:`_PartFits`), made here when not given."""
    fits = _PartFits(K, plane, depth_m) if fits is None else fits
    out = list(found)
    k = np.ones((3, 3), np.uint8)
    i = 0
    while i < len(out):
        near = cv2.dilate(out[i].mask.astype(np.uint8), k) > 0
        for j in range(i + 1, len(out)):
            a, b = out[i].mask, out[j].mask
            if not (near & b).any():
                continue
            union = a | b
            fa, fb, fu = fits(a), fits(b), fits(union)
            if fa is None or fb is None or fu is None:
                continue
            na, nb = int(a.sum()), int(b.sum())
            if fu.iou < (fa.iou * na + fb.iou * nb) / (na + nb):
                continue
            r = _RegionReadings.of(union, depth_m, K, plane)
            only_a, only_b = a & ~b, b & ~a  # grown candidates may overlap
            if r is not None and _apart_by_readings(r, fu, only_a | only_b,
                                                    ((fa, only_a), (fb, only_b))):
                continue
            out[i] = Candidate(union, float(glass[union].mean()))
            del out[j]
            break
        else:
            i += 1
    return out


def _apart_by_readings(r: _RegionReadings, whole, union: np.ndarray, parts) -> bool:
    """Whether the readings ``r`` in ``union`` (H, W) bool keep its ``parts`` ((fit, mask)
    pairs, masks not overlapping, together ``union``) apart from one fit ``whole`` of them:
    more of them lie on the parts' surfaces by the margin a split by the readings needs, or a
    part's fit holds :data:`OUTLINE_REFUTED` more of its own readings than the whole's fit
    does (a lying glass behind a standing one, generated seed 5100 frame 18: their union
    drawn at 0.86 against 0.81 / 0.89, but the lying glass's fit holds 18% of its readings,
    the union's none)."""
    one = _Whole(whole, r.on_surface(whole, union))
    return sum(r.on_surface(f, m) for f, m in parts) >= one.on + one.margin or \
        any(_holds_own(r, one, found, mask, OUTLINE_REFUTED) for found, mask in parts)


def with_parts_on_axis(mask: np.ndarray, K: np.ndarray, plane: Plane, depth_m: np.ndarray,
                       height: np.ndarray, fits: "_PartFits | None" = None) -> np.ndarray:
    """A standing glass's instance ``(H, W) bool`` with its opaque parts: the raw readings
    ``depth_m (H, W)`` metres above the table (``height (H, W)`` metres over it, 0 where no
    reading, :func:`on_table_readings`; over ``BODY_SEED_HEIGHT``) that lie within the
    radius of the instance's fitted solid of revolution (plus :data:`ON_AXIS_MARGIN`) around
    its axis, up to :data:`ON_AXIS_REACH` along it, joined to the instance in the image.

    A cap, lid or label reads well, so it gives no glass evidence and the instance stops below
    it (the real container's lid: a model 0.075-0.08 m tall for a 0.12 m container). Nothing
    else can hold readings inside the glass's own volume; an object beside or behind it lies
    farther from its axis. Lying or unfitted instances are returned unchanged. ``fits``: the
    frame's fits (:class:`_PartFits`), made here when not given."""
    box = mask_window(mask, 0)
    if box is None:
        return mask
    rows, cols = box
    tall = rows.stop - rows.start  # the window: the instance's box, as far again above
    y0, y1 = max(rows.start - tall, 0), rows.stop
    x0, x1 = max(cols.start - tall // 2, 0), min(cols.stop + tall // 2, mask.shape[1])
    own = mask[y0:y1, x0:x1]

    def joined(readings: np.ndarray) -> np.ndarray:  # the closing only joins, adds nothing
        both = cv2.morphologyEx((readings | own).astype(np.uint8), cv2.MORPH_CLOSE, _disk(2))
        return joined_to(both > 0, own) & readings & ~own

    above = height[y0:y1, x0:x1] > BODY_SEED_HEIGHT
    if not joined(above).any():  # nothing to take in: no fit needed
        return mask
    fit = (_PartFits(K, plane, depth_m) if fits is None else fits)(mask)
    if fit is None or fit.resting != "standing":
        return mask
    radius = float(fit.profile[:, 0].max()) * fit.height + ON_AXIS_MARGIN
    offset = depth_to_points(depth_m[y0:y1, x0:x1], window_K(K, x0, y0)) - fit.base
    along = offset @ fit.axis
    across = np.linalg.norm(offset - along[..., None] * fit.axis, axis=-1)
    added = joined(above & (across <= radius) & (along <= ON_AXIS_REACH))
    if not added.any():
        return mask
    out = mask.copy()
    out[y0:y1, x0:x1] |= added
    return fill_holes(out)


def within_outline_hull(mask: np.ndarray, outline: np.ndarray, own: np.ndarray,
                        band: int = 3) -> np.ndarray:
    """An instance ``(H, W) bool`` cut to the convex hull of its colour outline: the
    ``outline`` evidence ``(H, W) bool`` (:func:`outline_evidence`) within ``band`` pixels of
    it. What lies outside the hull stays where it is an object's ``own`` ``(H, W) bool``
    (:func:`own_pixels`: its own colour, or a reading clearly above the table); only the parts
    joined to the hull are kept. Unchanged where the cut would keep less than
    :data:`HULL_LEAST` of the instance (an outline seen in part).

    A stereo camera leaves holes beside an object that no step between readings explains
    where the glass's own edge is not read either (ClearGrasp's bottles against the far table:
    shadows up to 75 px wide), and reads bumps on a plain table around it; they join the
    glass's instance by its holes and readings, but show the table's plain colour outside its
    outline, rim and highlights."""
    near = cv2.dilate(mask.astype(np.uint8), _disk(band)) > 0
    points = outline & near
    if np.count_nonzero(points) < 3:
        return mask
    inside = mask & convex_hull(points)
    kept = joined_to(fill_holes(inside | (mask & own)) & mask, inside)
    return kept if kept.sum() >= HULL_LEAST * mask.sum() else mask


def beside_room(rgb: np.ndarray, depth_m: np.ndarray, footprint: np.ndarray,
                departure: np.ndarray, lab: np.ndarray | None = None) -> np.ndarray:
    """The colour departure ``departure`` ``(H, W)`` (:func:`table_colour_departure`) over the
    table's footprint ``(H, W) bool``, and beyond it the departure from the room's colour
    around each pixel: the same measure with the room's readings (``depth_m`` ``(H, W)``
    metres, valid beyond the footprint) in place of the table's, where the room reads within
    the window (a room out of the sensor's range gives nothing to compare: the table's
    departure stays there). Beyond the table a glass shows, and stands out from, the wall or
    the room behind it; against the table's colour every pixel of a wall departs, its holes (a
    stereo camera's shadows of the glass on it) too, and would count as a glass's outline.
    ``lab``: :func:`colour_lab` of ``rgb`` where already made."""
    room = table_colour_departure(rgb, (depth_m > 0) & ~footprint, lab=lab)
    return np.where(footprint | np.isnan(room), departure, room)


def own_pixels(departure: np.ndarray, height: np.ndarray) -> np.ndarray:
    """``(H, W) bool``: pixels that are an object's own, not the table's: colour departing from
    the table's (``departure`` ``(H, W)``, :func:`table_colour_departure`, over
    :data:`OUTLINE_COLOUR`) or a reading clearly above it (``height`` ``(H, W)`` metres over
    the table, over :data:`BODY_SEED_HEIGHT`)."""
    return (np.nan_to_num(departure, nan=0.0) > OUTLINE_COLOUR) | (height > BODY_SEED_HEIGHT)


def within_table_columns(mask: np.ndarray, footprint: np.ndarray,
                         margin: int = BEYOND_MARGIN, feet: float | None = None) -> np.ndarray:
    """An instance ``(H, W) bool`` without what lies beyond the table's footprint ``(H, W)
    bool`` outside the columns its part over the table spans (widened by ``margin`` pixels);
    with ``feet``, outside the columns where that part reaches down to within ``feet`` of its
    height (in rows) of its lowest row.

    An object standing on the table may rise above the table's far edge in the image, but only
    straight above its own base: the rest beyond the table is the room (a wall's or the floor's
    missing readings joined to the object's). The part over the table may hold more than the
    object (the holes on the table beside it, up to the edge), whose columns end higher up than
    the object's base does: ``feet`` keeps to the base's columns."""
    inside = mask & footprint
    if not inside.any() or inside.sum() == mask.sum():
        return mask
    columns = inside.any(axis=0)
    if feet is not None:
        rows = np.nonzero(inside.any(axis=1))[0]
        lowest = inside.shape[0] - 1 - np.argmax(inside[::-1], axis=0)  # (W,) per column
        columns &= lowest >= rows[-1] - feet * (rows[-1] - rows[0])
    columns = cv2.dilate(columns.astype(np.uint8)[None, :], np.ones((1, 2 * margin + 1), np.uint8)
                         )[0] > 0
    return joined_to(mask & (footprint | columns[None, :]), inside)


def _without_overlaps(found: list[Candidate]) -> list[Candidate]:
    """Candidates sorted by area (largest first), the pixels two of them claim (after
    :func:`grow_to_outline`) left to the larger."""
    out = []
    taken = np.zeros_like(found[0].mask) if found else None
    for c in sorted(found, key=lambda c: -int(c.mask.sum())):
        mask = c.mask & ~taken
        taken |= mask
        out.append(Candidate(mask, c.score))
    return out


def touching_groups(masks: list[np.ndarray]) -> list[list[int]]:
    """The groups of ``masks`` (each ``(H, W) bool``) that touch one another (8-connected),
    as lists of indices, each group of at least two."""
    near = [cv2.dilate(m.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0 for m in masks]
    links = [[j for j in range(len(masks)) if j != i and (near[i] & masks[j]).any()]
             for i in range(len(masks))]
    groups, seen = [], set()
    for first in range(len(masks)):
        if first in seen or not links[first]:
            continue
        group, stack = [], [first]
        while stack:
            i = stack.pop()
            if i not in seen:
                seen.add(i)
                group.append(i)
                stack.extend(links[i])
        groups.append(sorted(group))
    return groups


def colour_gradient(lab: np.ndarray) -> np.ndarray:
    """``(H, W) float32``: the magnitude of the colour gradient of ``lab`` ``(H, W, 3)``
    (:func:`colour_lab`), CIELAB units per pixel (3x3 Sobel, summed over the channels)."""
    gx = cv2.Sobel(lab, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(lab, cv2.CV_32F, 0, 1, ksize=3)
    return np.sqrt((gx ** 2 + gy ** 2).sum(axis=2))


def cut_contrast(parts: list[np.ndarray], gradient: np.ndarray) -> float:
    """The mean :func:`colour_gradient` ``(H, W)`` over the pixels of touching ``parts``
    (each ``(H, W) bool``) that have a pixel of another part beside them: how strongly the
    lines between them follow a colour edge."""
    values = []
    for i, part in enumerate(parts):
        others = np.zeros_like(part)
        for j, other in enumerate(parts):
            if j != i:
                others |= other
        beside = cv2.dilate(others.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        values.append(gradient[part & beside])
    values = np.concatenate(values)
    return float(values.mean()) if values.size else 0.0


def on_colour_edges(parts: list[np.ndarray], rgb: np.ndarray, reach: int = CUT_REACH
                    ) -> list[np.ndarray] | None:
    """Touching ``parts`` (each ``(H, W) bool``) with the lines between them moved onto the
    colour edges of ``rgb`` ``(H, W, 3) uint8`` within ``reach`` px of them: a watershed of the
    colour image in a window around them, seeded with each part less the band within
    ``reach`` of the others, flooding only their union (outside it is background). Each new
    part keeps what joins its seed; the watershed's own boundary pixels stay with their old
    part. None where a part lies all within that band (nothing to seed it)."""
    union = np.zeros_like(parts[0])
    for part in parts:
        union |= part
    box = mask_window(union, 2)
    u = union[box]
    markers = np.where(u, 0, len(parts) + 1).astype(np.int32)
    for i, part in enumerate(parts):
        own = part[box]
        others = (cv2.dilate((u & ~own).astype(np.uint8), _disk(reach)) > 0)
        seed = own & ~others
        if not seed.any():
            return None
        markers[seed] = i + 1
    cv2.watershed(np.ascontiguousarray(rgb[box][..., :3]), markers)
    out = []
    for i, part in enumerate(parts):
        own = part[box]
        moved = ((markers == i + 1) | ((markers == -1) & own)) & u
        new = np.zeros_like(part)
        new[box] = joined_to(moved, own & moved)
        out.append(new)
    return out


def cuts_on_colour_edges(found: list[Candidate], rgb: np.ndarray, lab: np.ndarray, *,
                         reach: int = CUT_REACH, gain: float = CUT_CONTRAST_GAIN
                         ) -> list[Candidate]:
    """``found`` with the lines between touching instances moved onto a colour edge
    (:func:`on_colour_edges`) where that raises the colour contrast along them
    (:func:`cut_contrast`) by ``gain`` of itself. A cut chosen by the shapes the parts draw
    runs where their silhouettes meet best, not where the glasses' edges are: where one glass
    stands in front of another, the nearer one's rim and outline show as a colour edge a few
    pixels away (extsim 0: a wine glass in front of a bowl, cut through its bowl). Where no
    edge stands out (a real frame's faint glass), the watershed wanders and is not kept.
    rgb ``(H, W, 3) uint8``; lab its :func:`colour_lab`."""
    groups = touching_groups([c.mask for c in found])
    if not groups:
        return found
    gradient = colour_gradient(lab)
    out = list(found)
    for group in groups:
        parts = [found[i].mask for i in group]
        moved = on_colour_edges(parts, rgb, reach)
        if moved is not None and \
                cut_contrast(moved, gradient) > (1 + gain) * cut_contrast(parts, gradient):
            for i, mask in zip(group, moved):
                out[i] = Candidate(mask, found[i].score)
    return out


def with_hull_gaps(found: list[Candidate], ev: "Evidence", valid: np.ndarray,
                   beside_opaque: np.ndarray) -> list[Candidate]:
    """``found`` with the gaps in each instance's convex hull that a glass seen through
    refracts: a connected gap (the hull less every instance, the band ``beside_opaque``
    ``(H, W) bool`` around opaque objects and what lies off the table's footprint) of at least
    :data:`HULL_GAP_LEAST` px is added when :data:`HULL_GAP_READ` of its pixels have a reading
    (``valid`` ``(H, W) bool``), under :data:`TABLE_GAP` of those read the table and their
    median height is under :data:`BODY_SEED_HEIGHT`. Through two walls of glass (an open
    pitcher's far rim seen over its near one) the table's readings are bent a few millimetres
    off its plane (extsim 13: 6 mm over, 34% on it; the mask took a bite out of the pitcher's
    top and it was fitted lying); an object beside a glass stands higher, the table beside
    it reads the table. Frames of a stereo camera are left as they are (the caller's rule):
    there the readings beside a glass that miss the table low are the sensor's smoothing
    ramp (a ClearGrasp holder's hull gaps: 5-6 mm over, 31-45% on the table)."""
    taken = np.zeros(valid.shape, bool)
    for c in found:
        taken |= c.mask
    free = ~taken & ~beside_opaque & ev.footprint
    out = []
    for c in found:
        count, labels = cv2.connectedComponents((convex_hull(c.mask) & free).astype(np.uint8))
        added = np.zeros_like(c.mask)
        for k in range(1, count):
            gap = labels == k
            read = gap & valid
            if gap.sum() < HULL_GAP_LEAST or read.sum() < HULL_GAP_READ * gap.sum():
                continue
            if ev.on_table[read].mean() < TABLE_GAP and \
                    np.median(ev.height[read]) < BODY_SEED_HEIGHT:
                added |= gap
        free &= ~added
        out.append(Candidate(c.mask | added, c.score))
    return out


def _pieces(mask: np.ndarray, max_pieces: int) -> tuple[np.ndarray, int, np.ndarray]:
    """Watershed of the distance to a region's edge, seeded at its maxima: labels (H, W) int
    (0 outside), the number of pieces and their shared boundary lengths (n+1, n+1). The
    smallest piece joins the neighbour it shares most boundary with until ``max_pieces`` are
    left (a goblet's foot or a bottle's neck is small; two touching objects are not)."""
    from skimage.feature import peak_local_max
    from skimage.segmentation import watershed

    dt = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5)
    top = float(dt.max())
    if top < 3:
        return mask.astype(np.int32), 1, np.zeros((2, 2))
    peaks = peak_local_max(dt, min_distance=max(3, int(top / 2)), threshold_abs=0.3 * top,
                           labels=mask.astype(np.int32), exclude_border=False)
    if len(peaks) < 2:
        return mask.astype(np.int32), 1, np.zeros((2, 2))
    markers = np.zeros(mask.shape, np.int32)
    markers[tuple(peaks.T)] = np.arange(1, len(peaks) + 1)
    labels = watershed(-dt, markers, mask=mask, watershed_line=False)
    n = len(peaks)
    length = np.zeros((n + 1, n + 1))
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1], labels[1:])):
        edge = (a != b) & (a > 0) & (b > 0)
        np.add.at(length, (a[edge], b[edge]), 1)
    length = length + length.T
    area = np.bincount(labels.ravel(), minlength=n + 1).astype(np.float64)
    area[0] = np.inf
    while n > max_pieces:
        small = int(np.argmin(area))
        into = int(np.argmax(length[small]))
        labels[labels == small] = into
        area[into] += area[small]
        length[into] += length[small]
        length[:, into] += length[:, small]
        length[into, into] = 0
        length[small], length[:, small], area[small] = 0, 0, np.inf
        n -= 1
    kept = np.unique(labels[mask])
    relabel = np.zeros(labels.max() + 1, np.int32)
    relabel[kept] = np.arange(1, len(kept) + 1)
    order = np.concatenate([[0], kept])
    return relabel[labels], len(kept), length[np.ix_(order, order)]


def _connected(group: list[int], length: np.ndarray) -> bool:
    """Whether pieces ``group`` (1-based) form one region through shared boundaries."""
    seen, todo = {group[0]}, [group[0]]
    while todo:
        i = todo.pop()
        for j in group:
            if j not in seen and length[i, j] > 0:
                seen.add(j)
                todo.append(j)
    return len(seen) == len(group)


def _attachments(region: np.ndarray, min_area: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """A region's body and the thin parts hanging off it: the body is what an opening by half
    its inscribed radius keeps, the parts are the components of what it removes that are more
    than slivers and at least ``min_area`` pixels (a vial beside or behind a glass; also a
    bottle's neck or a goblet's stem and foot, which :func:`split_touching` keeps by the
    readings on them). The watershed of :func:`_pieces` seeds only at wide places and gives
    such parts no piece of their own. What joins a part to the body (a bridge of fill between
    two objects) belongs to neither."""
    dt = cv2.distanceTransform(region.astype(np.uint8), cv2.DIST_L2, 5)
    radius = int(0.5 * float(dt.max()))
    if radius < 4:
        return region, []
    body = cv2.morphologyEx(region.astype(np.uint8), cv2.MORPH_OPEN, _disk(radius))
    body = region & (cv2.dilate(body, _disk(1)) > 0)
    rest = cv2.morphologyEx((region & ~body).astype(np.uint8), cv2.MORPH_OPEN, _disk(2))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(rest, 8)
    return body, [labels == k for k in range(1, count) if stats[k, 4] >= min_area]


def _bridge(region: np.ndarray, body: np.ndarray, thin: list[np.ndarray], part: np.ndarray
            ) -> np.ndarray:
    """The pixels that join a thin ``part`` to the ``body`` (see :func:`_attachments`): those of
    the region in neither the body nor a thin part, in pieces that touch ``part``. Cut off with
    the part, they go with neither side; the other thin parts (a bottle's neck beside a vial)
    stay with the body."""
    loose = region & ~body & ~np.any(thin, axis=0)
    count, labels = cv2.connectedComponents(loose.astype(np.uint8), connectivity=8)
    touching = np.unique(labels[(cv2.dilate(part.astype(np.uint8), _disk(1)) > 0) & loose])
    return np.isin(labels, touching[touching > 0])


def _nearest_seed(seeds: np.ndarray) -> np.ndarray:
    """Every pixel's nearest non-zero label of ``seeds`` (H, W)."""
    iy, ix = ndimage.distance_transform_edt(seeds == 0, return_distances=False,
                                            return_indices=True)
    return seeds[iy, ix]


def _evidence_cuts(region: np.ndarray, glass: np.ndarray, min_area: int, close_radius: int, *,
                   most: int = 3) -> tuple[list, list]:
    """Cuts of a region along its own glass evidence. Where that evidence comes in separate
    bodies of at least ``min_area`` pixels (the ``most`` largest), each body is closed by
    ``close_radius`` and filled, as a candidate is, and takes the region's pixels nearest to it
    within that outline; each body in turn is cut from the others. Two glasses side by side a
    few pixels apart leave two bodies of evidence, but the closing that made their candidate
    bridged the gap along its whole length, so the region has no neck to cut at; the gap's
    pixels go with neither part. Returns those cuts, and each body's part cut from all the rest
    of the region nearest the other bodies, gap and all (for where the others' evidence covers
    only some of their object: a vial beside a goblet)."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        (glass & region).astype(np.uint8), 8)
    big = [k for k in np.argsort(-stats[:, 4]) if k > 0 and stats[k, 4] >= min_area][:most]
    if len(big) < 2:
        return [], []
    nearest = _nearest_seed(np.where(np.isin(labels, big), labels, 0))
    parts = []
    for k in big:
        parts.append(region & (nearest == k) & _closed(labels == k, close_radius))
    rest = [(a, region & (nearest != k)) for a, k in zip(parts, big)]
    if len(parts) == 2:
        return [(parts[0], parts[1])], rest
    return [(a, np.any([b for b in parts if b is not a], axis=0)) for a in parts], rest


def _footprint_cut(region: np.ndarray, xs: np.ndarray, ys: np.ndarray, raw: np.ndarray,
                   K: np.ndarray, plane: Plane, min_apart: float, min_area: int
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """A cut of a region along where its off-table readings (pixels ``xs``, ``ys``, depth
    ``raw`` metres) stand on the table. Dropped straight onto the table, the readings on one
    solid gather around its axis; two objects that overlap in the image, one in front of the
    other, stand apart there though their outlines run into each other with no neck between
    them. The readings are grouped in two by 2-means, started at the 5th and 95th percentiles
    of the feet along their principal direction (a few stray readings far off do not take a
    group of their own); a cut is made when the groups' centres are ``min_apart`` metres
    apart, each pixel going with its nearest reading's group (each part at least ``min_area``
    pixels; the parts made within the region's :func:`_cut_window`). None otherwise."""
    if len(xs) < 2:
        return None
    pts = unproject(np.column_stack([xs, ys]).astype(np.float64), raw, K)
    foot = pts - plane.height(pts)[:, None] * plane.normal
    middle = foot.mean(0)
    along = np.linalg.eigh(np.cov((foot - middle).T))[1][:, -1]
    c = [middle + q * along for q in np.percentile((foot - middle) @ along, [5, 95])]
    for _ in range(10):
        side = np.linalg.norm(foot - c[0], axis=1) > np.linalg.norm(foot - c[1], axis=1)
        if side.all() or not side.any():
            return None
        c = [foot[~side].mean(0), foot[side].mean(0)]
    if np.linalg.norm(c[0] - c[1]) < min_apart:
        return None
    box = _cut_window(region, 1)
    inner = region[box]
    seeds = np.zeros(inner.shape, np.uint8)
    seeds[ys - box[0].start, xs - box[1].start] = np.where(side, 2, 1)
    first = inner & (_nearest_seed(seeds) == 1)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(first.astype(np.uint8), 8)
    if count < 2:
        return None
    a = labels == 1 + int(np.argmax(stats[1:, 4]))
    b = inner & ~a
    if min(a.sum(), b.sum()) < min_area:
        return None
    return _embedded(a, box, region.shape), _embedded(b, box, region.shape)


class _PartFits:
    """:func:`~sr3d_cli.shape.revolution_fit.fit_revolution` of a frame's regions and their
    parts (None for a part that cannot stand or lie on the table), with the near-square lying
    starts off: they cost a fifth of the segment time (one glass, one core: .52 -> .64 s per
    frame) and are for the chosen object's fit, not for a cut. A region the outline draws
    poorly is weighed by its outline, not fitted from its readings further off the axis
    (``poor_outline`` off): such a region is more often two objects than one that is no surface
    of revolution (a goblet and a beaker touching, IoU .71). Each fit is made once per
    frame, kept by the pixels of its mask and occluders: the cuts of a region and of its parts,
    and the later steps, ask for the same parts again (ClearGrasp 123: 12 of 92 fits)."""

    def __init__(self, K: np.ndarray, plane: Plane, depth: np.ndarray | None):
        self.K, self.plane, self.depth = K, plane, depth
        self.made: dict = {}  # _content of the mask and the occluders: the fit

    def __call__(self, mask: np.ndarray, occluders: np.ndarray | None = None):
        key = (_content(mask), None if occluders is None else _content(occluders))
        if key not in self.made:
            try:
                self.made[key] = fit_revolution(mask, self.K, self.plane, depth=self.depth,
                                                occluders=occluders,
                                                options=FitOptions(square_starts=False,
                                                                   poor_outline=0.0))
            except ValueError:  # a part that cannot stand or lie on the table
                self.made[key] = None
        return self.made[key]

    def has(self, mask: np.ndarray) -> bool:
        """Whether ``mask``'s fit without occluders is made."""
        return (_content(mask), None) in self.made


def _content(mask: np.ndarray) -> tuple:
    """A key equal for two ``(H, W)`` bool masks exactly when their pixels are: the image's
    shape, the set pixels' box and the box's bytes."""
    mask = np.ascontiguousarray(mask, dtype=bool)
    x, y, w, h = cv2.boundingRect(mask.view(np.uint8))
    return mask.shape, x, y, w, h, mask[y:y + h, x:x + w].tobytes()


@dataclass
class _RegionReadings:
    """A region's off-table raw readings, weighed against the fits of it and of its parts.

    every : (xs, ys, raw) all of them (pixels, metres); sample : (xs, ys, raw) at most
    ``DEPTH_SAMPLES`` of them spread evenly (as fit_revolution samples them); heights : (n,)
    metres above the table of the sample; shares : :meth:`own_share`'s answers for the cut being
    judged (cleared for each)."""
    every: tuple
    sample: tuple
    heights: np.ndarray
    K: np.ndarray
    plane: Plane
    shares: dict = field(default_factory=dict)

    @classmethod
    def of(cls, region: np.ndarray, depth: np.ndarray, K: np.ndarray,
           plane: Plane) -> "_RegionReadings | None":
        """The region's readings; None with fewer than ``DEPTH_MIN_POINTS`` in the sample."""
        every = off_table_readings(region, depth, K, plane, samples=int(region.sum()))
        sample = evenly(every, DEPTH_SAMPLES)
        heights = plane.height(unproject(np.column_stack(sample[:2]).astype(np.float64),
                                         sample[2], K))
        if len(sample[0]) < DEPTH_MIN_POINTS:
            return None
        return cls(every, sample, heights, K, plane)

    def on_surface(self, found, mask: np.ndarray) -> int:
        """How many of the region's readings in ``mask`` lie on the fit's surface."""
        xs, ys, raw = (r[mask[self.sample[1], self.sample[0]]] for r in self.sample)
        return 0 if found is None else raw_support(found, xs, ys, raw, self.K, mask.shape,
                                                   DEPTH_BAND)

    def count_in(self, mask: np.ndarray) -> int:
        """How many of the region's readings lie in ``mask``."""
        return int(mask[self.sample[1], self.sample[0]].sum())

    def above(self, found, mask: np.ndarray) -> int:
        """How many of the region's readings in ``mask`` stand above the fit (:func:`above_top`)."""
        return above_top(found, self.heights[mask[self.sample[1], self.sample[0]]], self.plane,
                         DEPTH_BAND)

    def own_share(self, found, mask: np.ndarray) -> float | None:
        """The share of the part's own readings (up to ``DEPTH_SAMPLES`` of them: a small
        object gets few of the region's sample) on the fit's surface; None with fewer than
        ``DEPTH_MIN_POINTS``. Each is computed once per cut: the rules ask for the same
        fit and part several times."""
        key = (id(found), id(mask))
        if key not in self.shares:  # the fit and the mask are kept with it: their ids stay theirs
            inside = mask[self.every[1], self.every[0]]
            xs, ys, raw = evenly(tuple(r[inside] for r in self.every), DEPTH_SAMPLES)
            share = None if len(xs) < DEPTH_MIN_POINTS else 0.0 if found is None else \
                raw_support(found, xs, ys, raw, self.K, mask.shape, DEPTH_BAND) / len(xs)
            self.shares[key] = (found, mask, share)
        return self.shares[key][2]


@dataclass
class _Whole:
    """The fit of the whole region a cut is judged against, and (with readings) how many of
    the region's readings lie on its surface."""
    fit: object
    on: int | None

    @property
    def margin(self) -> float:
        """Readings by which the parts must beat the whole (or lose to it to be refuted)."""
        return max(DEPTH_MIN_POINTS, SPLIT_READINGS * self.on)


@dataclass
class _Region:
    """A region being split: its mask (H, W) bool, the camera, the table, the image's "down"
    there, its parts' fits, its readings (None without enough) and the IoU gain a cut needs."""
    mask: np.ndarray
    K: np.ndarray
    plane: Plane
    down: np.ndarray
    fits: _PartFits
    readings: _RegionReadings | None
    gain: float


def _outline_cuts(region: np.ndarray, glass: np.ndarray | None, max_pieces: int,
                  min_share: float, min_area: int, close_radius: int
                  ) -> tuple[list[tuple[np.ndarray, np.ndarray]], range]:
    """The cuts the outline and the evidence make: every grouping of the watershed pieces into
    two connected parts, each at least ``min_share`` of the region, then the cuts between the
    ``glass`` evidence's bodies (:func:`_evidence_cuts`, parts at least ``min_area``). Returns
    the cuts and the range of their indices that cut one body from all the rest (ranked below
    the others). All are made within the region's :func:`_cut_window` widened by the reach of
    :func:`_closed` (``2 * close_radius + 1``), which closes the evidence's bodies."""
    box = _cut_window(region, 2 * close_radius + 1)
    inner = region[box]
    labels, n, length = _pieces(inner, max_pieces)
    # the watershed's label around the region, 0 or, where no seed reached a part of the
    # region, that part's piece (see _pieces), is the label of all beyond the window too
    around = labels[~inner][:1]
    area = float(region.sum())
    cuts = []
    for bits in range(1, 2 ** (n - 1)):  # piece n stays in the second part
        first = [k for k in range(1, n + 1) if bits >> (k - 1) & 1]
        second = [k for k in range(1, n + 1) if k not in first]
        if _connected(first, length) and _connected(second, length):
            a = _embedded(np.isin(labels, first), box, region.shape,
                          bool(np.isin(around, first).any()))
            if min(a.sum(), area - a.sum()) >= min_share * area:
                cuts.append((a, region & ~a))
    rests = range(0)
    if glass is not None:
        plain, rest = ([(_embedded(a, box, region.shape), _embedded(b, box, region.shape))
                        for a, b in found if min(a.sum(), b.sum()) >= min_area]
                       for found in _evidence_cuts(inner, glass[box], min_area, close_radius))
        cuts += plain
        rests = range(len(cuts), len(cuts) + len(rest))
        cuts += rest
    return cuts, rests


def _readings_cuts(region: np.ndarray, readings: _RegionReadings, K: np.ndarray, plane: Plane,
                   min_area: int) -> tuple[tuple[np.ndarray, np.ndarray] | None,
                                           list[tuple[np.ndarray, np.ndarray]]]:
    """The cuts only the readings can hold: the footprint cut (:func:`_footprint_cut`, or None)
    and each thin part hanging off the body (:func:`_attachments`) cut at its bridge, made
    within the region's :func:`_cut_window`."""
    footprint = _footprint_cut(region, *readings.every, K, plane, FOOTPRINT_APART, min_area)
    box = _cut_window(region, 1)
    inner = region[box]
    body, thin = _attachments(inner, min_area)
    attached = []
    if thin and cv2.connectedComponents(body.astype(np.uint8), connectivity=8)[0] == 2:
        attached = [(_embedded(a, box, region.shape),
                     _embedded(inner & ~a & ~_bridge(inner, body, thin, a), box, region.shape))
                    for a in thin]
    return footprint, attached


def _misses(r: _RegionReadings, whole: _Whole, mask: np.ndarray) -> bool:
    """Whether a fit of the part could hold :data:`OWN_READINGS` of its own readings
    more than the whole's fit does (see :func:`_holds_own`)."""
    on_whole = r.own_share(whole.fit, mask)
    return on_whole is not None and on_whole <= 1 - OWN_READINGS


def _holds_own(r: _RegionReadings, whole: _Whole, found, mask: np.ndarray,
               share: float = OWN_READINGS) -> bool:
    """Whether the part's fit holds ``share`` of the part's own readings more than the
    whole's fit does."""
    on_whole = r.own_share(whole.fit, mask)
    return on_whole is not None and r.own_share(found, mask) - on_whole >= share


def _refuted(r: _RegionReadings, whole: _Whole, fa, a: np.ndarray, fb, b: np.ndarray,
             on_parts: int) -> bool:
    """Whether the readings refute a cut into ``a`` and ``b`` (fits ``fa``, ``fb``; with
    ``on_parts`` readings on them): fewer on the parts than on the whole by the margin, or
    a part whose fit holds :data:`OUTLINE_REFUTED` fewer of its own readings than the
    whole's fit does."""
    if on_parts <= whole.on - whole.margin:
        return True
    for found, part in ((fa, a), (fb, b)):
        mine = r.own_share(found, part)
        if mine is not None and mine < r.own_share(whole.fit, part) - OUTLINE_REFUTED:
            return True
    return False


def _refutes_whole(r: _RegionReadings, whole: _Whole, part: np.ndarray) -> bool:
    """Whether the readings refute the whole's fit on ``part``: :data:`SPLIT_READINGS` of
    the part's readings (at least ``DEPTH_MIN_POINTS``) stand above it (a standing goblet
    and a glass beside it drew a lying goblet, 11 cm high, under readings up to 16 cm)."""
    return r.above(whole.fit, part) >= max(DEPTH_MIN_POINTS, SPLIT_READINGS * r.count_in(part))


def _could_hold(reg: _Region, whole: _Whole, outline_may_hold: bool, front: np.ndarray,
                f_front, back: np.ndarray) -> bool:
    """Whether a cut could hold with the best fit of ``back`` there can be (IoU 1, all
    its readings on it): if not, fitting it again with hidden pixels changes nothing.
    ``outline_may_hold``: the cut is one the outline may hold (not made by the readings)."""
    if f_front is None:
        return False
    r = reg.readings
    on_front, in_back = 0, 0
    if r is not None:
        on_front = r.on_surface(f_front, front)
        in_back = r.count_in(back)
    area = front.sum() + back.sum()
    by_outline = outline_may_hold and f_front.iou > whole.fit.iou and \
        (f_front.iou * front.sum() + back.sum()) / area >= whole.fit.iou + reg.gain and \
        (r is None or on_front + in_back > whole.on - whole.margin)
    return by_outline or (r is not None and f_front.iou >= SPLIT_PART_IOU and (
        min(on_front, in_back) >= DEPTH_MIN_POINTS and
        on_front + in_back >= whole.on + whole.margin or
        on_front >= (1 - SPLIT_READINGS) * r.on_surface(whole.fit, front) and
        _misses(r, whole, back)))


def _part_may_hold(found, whole: _Whole, outline_may_hold: bool) -> bool:
    """Whether a cut one of whose parts is fitted as ``found`` (None: no fit) may still hold
    (:func:`_judge_cut`): by the outline both parts' IoUs must exceed the whole's, by the
    readings both must reach :data:`SPLIT_PART_IOU`."""
    iou = found.iou if found is not None else -1.0
    return iou >= SPLIT_PART_IOU or (outline_may_hold and iou > whole.fit.iou)


def _fit_parts(reg: _Region, whole: _Whole, outline_may_hold: bool, a: np.ndarray,
               b: np.ndarray):
    """Both parts' fits, or None where the first part fitted rules the cut out
    (:func:`_part_may_hold`; the other part is then not fitted). A part behind the other
    (:func:`in_front`) is fitted with the other's pixels as hidden, if the cut could then
    hold, that fit lies behind the other's and its readings bear it out
    (:data:`HIDDEN_READINGS`); else alone."""
    r = reg.readings
    for front, back in ((a, b), (b, a)):
        if in_front(front, back, reg.down):
            f_front = reg.fits(front)
            if not _part_may_hold(f_front, whole, outline_may_hold):
                return None
            f_back = None  # the part behind fitted alone only where its hidden fit is not kept
            if _could_hold(reg, whole, outline_may_hold, front, f_front, back):
                hidden = reg.fits(back, front)
                if hidden is not None and (f_front is None or stands_behind(
                        hidden, f_front, front & fit_silhouette(hidden, reg.K, reg.mask.shape),
                        reg.K, reg.plane)) and (r is None or r.on_surface(hidden, back) >=
                                                HIDDEN_READINGS * r.count_in(back)):
                    f_back = hidden
            if f_back is None:
                f_back = reg.fits(back)
            return (f_front, f_back) if front is a else (f_back, f_front)
    # either part that may not hold rules the cut out: the one already fitted is asked
    # first, else the smaller (a small piece is the one no solid draws)
    first, second = (a, b) if reg.fits.has(a) or (not reg.fits.has(b) and
                                                  a.sum() <= b.sum()) else (b, a)
    f_first = reg.fits(first)
    if not _part_may_hold(f_first, whole, outline_may_hold):
        return None
    return (f_first, reg.fits(second)) if first is a else (reg.fits(second), f_first)


def _by_readings(r: _RegionReadings, whole: _Whole, gain: float, a, fa, ia: float, sa: int,
                 b, fb, ib: float, sb: int, mean: float, is_part: bool) -> tuple[bool, bool]:
    """Whether the readings hold the cut, and whether by the region's count (ranked above the
    rest); ``ia``, ``ib``: the parts' IoUs, ``sa``, ``sb``: readings on their surfaces,
    ``mean``: their area-weighted IoU."""
    w = whole.fit
    by_count = (min(ia, ib) >= SPLIT_PART_IOU and min(sa, sb) >= DEPTH_MIN_POINTS
                and sa + sb >= whole.on + whole.margin and (mean >= w.iou or not is_part))
    # a small part's own readings (ranked below a cut the region's count holds); fewer
    # of them where the outline gains too
    own = OWN_READINGS if mean < w.iou + gain else OUTLINE_OWN_READINGS
    by_readings = by_count or min(ia, ib) >= SPLIT_PART_IOU and mean >= w.iou and \
        any(_holds_own(r, whole, f, part, own) and s_other >= (1 - SPLIT_READINGS) *
            r.on_surface(w, other) for f, part, s_other, other in ((fa, a, sb, b), (fb, b, sa, a)))
    # readings above the whole's fit and above neither part's (the outline may be a
    # little worse: the whole's fit drew it with a shape the readings rule out)
    by_readings = by_readings or min(ia, ib) >= SPLIT_PART_IOU and \
        mean >= w.iou - gain and min(sa, sb) >= DEPTH_MIN_POINTS and \
        max(r.above(fa, a), r.above(fb, b)) < DEPTH_MIN_POINTS and \
        (_refutes_whole(r, whole, a) or _refutes_whole(r, whole, b))
    return by_readings, by_count


def _judge_cut(reg: _Region, whole: _Whole, a: np.ndarray, b: np.ndarray, *,
               outline_may_hold: bool, min_part: float, is_part: bool):
    """Whether the cut into ``a`` and ``b`` holds (see :func:`split_touching`): None if not,
    else (by the readings, by the region's count, score, fa, fb). ``outline_may_hold``: the
    cut is not one only the readings hold; ``min_part``: pixels below which a part of such a
    cut must fit to :data:`SPLIT_PART_IOU`."""
    gain, w = reg.gain, whole.fit
    if not outline_may_hold and not in_front(b, a, reg.down) and \
            (reg.fits(a) is None or reg.fits(a).iou < SPLIT_PART_IOU):
        return None  # a thin part that cannot hold by the readings (b need not be fitted)
    fitted = _fit_parts(reg, whole, outline_may_hold, a, b)
    if fitted is None:
        return None
    fa, fb = fitted
    if not outline_may_hold and (fa is None or fa.iou < SPLIT_PART_IOU):
        return None
    ia, ib = (f.iou if f is not None else -1.0 for f in (fa, fb))
    if outline_may_hold and min(a.sum(), b.sum()) < min_part and min(ia, ib) < SPLIT_PART_IOU:
        return None  # a small body of evidence no solid draws is a piece of an object
    mean = (ia * a.sum() + ib * b.sum()) / (a.sum() + b.sum())
    by_outline = outline_may_hold and min(ia, ib) > w.iou and mean >= w.iou + gain
    by_readings, by_count, score = False, False, mean
    r = reg.readings
    if r is not None:
        sa, sb = r.on_surface(fa, a), r.on_surface(fb, b)
        by_readings, by_count = _by_readings(r, whole, gain, a, fa, ia, sa, b, fb, ib, sb, mean,
                                             is_part)
        # no cut the readings refute holds by the outline (see :func:`_refuted`), unless
        # no solid draws the whole and the parts are drawn clearly better
        clear = w.iou < SPLIT_PART_IOU and mean >= w.iou + CLEAR_GAIN * gain
        by_outline = by_outline and (clear or not _refuted(r, whole, fa, a, fb, b, sa + sb))
        score = sa + sb if by_readings else mean
    if not (by_outline or by_readings):
        return None
    return by_readings, by_count, score, fa, fb


def split_touching(region: np.ndarray, K: np.ndarray, plane: Plane, *,
                   depth: np.ndarray | None = None, glass: np.ndarray | None = None,
                   close_radius: int = 6, max_pieces: int = SPLIT_PIECES,
                   gain: float = SPLIT_GAIN, min_share: float = SPLIT_SHARE, min_area: int = 150,
                   whole=None, rounds: int = 2, opaque=None,
                   standing: bool = False, fits: "_PartFits | None" = None,
                   apart: list | None = None) -> list[np.ndarray]:
    """Split a region made of touching objects where solids of revolution on the table explain
    the parts clearly better than one explains the whole.

    Four kinds of cut are tried. The region is cut into watershed pieces of the distance to its
    edge (at most ``max_pieces``), and every grouping of them into two connected parts, each at
    least ``min_share`` of the region (a sliver of background fits anything), is a candidate; so
    is, with the ``glass`` evidence map, the cut between its separate bodies of evidence
    (:func:`_evidence_cuts`, parts closed by ``close_radius``, held like a watershed cut; a
    part may be as small as ``min_area`` pixels, since a body of evidence is no sliver of
    background, but one under ``min_share`` must fit to :data:`SPLIT_PART_IOU`; a body cut
    from all the rest of the region ranks below a cut between bodies); so
    are every thin part hanging off the body (:func:`_attachments`, at least ``min_area``
    pixels) and, with raw ``depth``, the cut between two groups of readings that stand apart on
    the table (:func:`_footprint_cut`: one object behind another). A cut holds by the outline
    when both parts' silhouette IoUs exceed the whole's and their area-weighted mean gains
    ``gain`` on it (two glasses side by side split; a goblet's bowl and foot, a bottle's body
    and neck do not). With raw ``depth`` (metres), a cut also holds by the readings when more of
    the region's off-table readings lie on the parts' fitted surfaces than on the whole's, by
    :data:`SPLIT_READINGS` of the whole's count and at least ``DEPTH_MIN_POINTS``, with both
    parts fitting to :data:`SPLIT_PART_IOU` and holding that many readings each (a vial behind a
    glass draws a fine bottle: the bottle's neck misses the vial's readings; a part without
    readings of its own is no object), and, in a part of a region already cut, with the
    outline no worse (a lying beaker or a goblet cut in two holds more readings on two fits'
    surfaces that draw it worse). A small part gets few of the region's readings: a cut also
    holds by them (ranked below the above) when one part's fit holds
    :data:`OWN_READINGS` (:data:`OUTLINE_OWN_READINGS` where the outline also gains ``gain``:
    a bottle and a lying beaker whose glass gives few readings, a goblet and a beaker) of that
    part's own readings more than the whole's fit does, the other part's fit keeps all but
    :data:`SPLIT_READINGS` of the whole's readings on it, both fit to :data:`SPLIT_PART_IOU`
    and the outline gets no worse; and when the readings refute the
    whole's fit on one part (:data:`SPLIT_READINGS` of them above its top) and neither part's,
    both parts fitting to :data:`SPLIT_PART_IOU` and holding ``DEPTH_MIN_POINTS`` readings,
    with the outline at most ``gain`` worse. Only the readings hold a thin attachment's cut (it
    may be as small as a sliver). A footprint cut holds by the outline too, as a watershed cut
    does (extsim scene 0: a glass bowl, a wine glass and a lying cup, one region with no neck
    for the watershed, whose readings' feet stand apart: parts 0.82 / 0.72 against 0.70),
    except in a region the image's border cuts: no solid draws such a region well, and the
    parts of any cut draw it better (ClearGrasp 123 at 640x480: a holder the border cuts, its
    readings in two groups either side, parts 0.86 / 0.75 against 0.65). A cut the readings
    clearly refute (fewer on the parts by that much, or a part whose fit holds
    :data:`OUTLINE_REFUTED` fewer of its own than the whole's: a glass's top cut off where a
    lying glass behind it crosses) does not hold by the outline, unless no solid draws the
    whole (IoU under :data:`SPLIT_PART_IOU`) and the parts gain :data:`CLEAR_GAIN` times
    ``gain`` on it: a goblet and a lying beaker behind it; a standing
    bottle a lying one leans on, whose glass reads so noisily that a fit of the whole, a lying
    bottle too long to be one, holds more of its readings than its own fit. The best cut
    that holds wins (readings first; among those, a footprint cut only where no other holds,
    its edge being only as fine as the readings) and each part is split again, ``rounds``
    levels deep (``whole``: the region's fit, given with each part of a region already cut).
    A region or part for which ``opaque(mask)`` holds (a predicate on an (H, W) bool mask) is
    not split: an opaque object's parts are all dropped, and judging them only spends fits.
    With ``standing``, only cuts whose parts both fit standing hold (see :func:`with_bodies`).
    ``fits``: the frame's fits (:class:`_PartFits`), made here when not given. ``apart``: a
    list to which each footprint cut taken by the outline alone is added, as its two parts
    ``(a, b)`` (see :func:`lying_pieces_joined`).
    Where one part stands in front of the other (:func:`~sr3d_cli.geometry.occlusion.in_front`),
    the part behind is fitted with the front part's pixels as hidden, so that it may reach down
    behind it (:func:`~sr3d_cli.shape.revolution_fit.fit_revolution`'s ``occluders``),
    if that fit lies behind the front part's
    (:func:`~sr3d_cli.shape.revolution_fit.stands_behind`); alone otherwise. Fitted
    alone, a glass behind a glass stands where the front one's outline crosses it, and its
    readings miss it (seed 2700 frame 22: 24 of them on it, 56 when placed 4% nearer).
    """
    if rounds < 1 or (opaque is not None and opaque(region)):
        return [region]
    fits = _PartFits(K, plane, depth) if fits is None else fits
    best = None  # (key, parts with their fits)
    for key, parts in _held_cuts(region, K, plane, depth, glass, close_radius, max_pieces,
                                 gain, min_share, min_area, whole, fits):
        if standing and not all(f is not None and f.resting == "standing" for _, f in parts):
            continue
        if best is None or key > best[0]:
            best = (key, parts)
    if best is None:
        return [region]
    by_readings, _, not_footprint = best[0][:3]
    if apart is not None and not by_readings and not not_footprint:
        apart.append(tuple(mask for mask, _ in best[1]))
    return [part for mask, own in best[1]
            for part in split_touching(mask, K, plane, depth=depth, glass=glass,
                                       close_radius=close_radius, max_pieces=max_pieces,
                                       gain=gain, min_share=min_share, min_area=min_area,
                                       whole=own, rounds=rounds - 1, opaque=opaque,
                                       standing=standing, fits=fits, apart=apart)]


def splits(region: np.ndarray, K: np.ndarray, plane: Plane, *, depth: np.ndarray | None = None,
           glass: np.ndarray | None = None, close_radius: int = 6, min_area: int = 150,
           fits: "_PartFits | None" = None, body: np.ndarray | None = None) -> bool:
    """Whether :func:`split_touching` (default rules) cuts ``region`` ``(H, W) bool`` at all:
    true at the first cut that holds, without judging the rest or splitting the parts.
    ``fits``: the frame's fits (:class:`_PartFits`), made here when not given. ``body``:
    an ``(H, W) bool`` body of readings in the region (:func:`standing_bodies`); a cut that
    runs through it is passed over: each part holds :data:`BODY_CUT` of it and its readings
    are one surface across the cut (:func:`_one_surface`, with raw ``depth`` metres). A
    container read smoothly below the holes on its lid fits better as a lid and a body (lying
    0.90 and standing 0.89 against 0.85, Tracebot view 053 moved by a pixel); a glass and the
    notebook its body's readings reach hold the notebook on one side, and a bottle and the
    boxes its readings touch step in depth between them."""
    fits = _PartFits(K, plane, depth) if fits is None else fits
    for _, ((a, _), (b, _)) in _held_cuts(region, K, plane, depth, glass, close_radius,
                                          SPLIT_PIECES, SPLIT_GAIN, SPLIT_SHARE, min_area, None,
                                          fits):
        if body is None or depth is None or not _one_surface(a, b, body, depth):
            return True
    return False


def _one_surface(a: np.ndarray, b: np.ndarray, body: np.ndarray, depth: np.ndarray) -> bool:
    """Whether a cut into ``a`` and ``b`` ``(H, W) bool`` runs through the readings of one
    surface of ``body`` ``(H, W) bool``: each part holds :data:`BODY_CUT` of the body, the
    body's readings meet across the cut in :data:`SURFACE_ACROSS` pairs of neighbours per
    column of the body (at least 5), and the median step in ``depth`` ``(H, W)`` metres
    between them is under :data:`SURFACE_STEP`. Two objects touching meet at their contact
    only, where their surfaces are at one depth too."""
    size = body.sum()
    if min((a & body).sum(), (b & body).sum()) < BODY_CUT * size:
        return False
    read = body & (depth > 0)
    on_a, on_b = a & read, b & read
    steps = []
    for first, second in (((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
                          ((slice(None, -1), slice(None)), (slice(1, None), slice(None)))):
        for x, y in ((on_a, on_b), (on_b, on_a)):
            pair = x[first] & y[second]
            steps.append(np.abs(depth[first][pair] - depth[second][pair]))
    steps = np.concatenate(steps)
    across = max(5.0, SURFACE_ACROSS * float(body.any(axis=0).sum()))
    return len(steps) >= across and float(np.median(steps)) < SURFACE_STEP


def _held_cuts(region: np.ndarray, K: np.ndarray, plane: Plane, depth, glass, close_radius: int,
               max_pieces: int, gain: float, min_share: float, min_area: int, whole,
               fits: _PartFits):
    """The cuts of ``region`` that hold (:func:`split_touching`'s rules and arguments), as
    ``(key, ((a, fit_a), (b, fit_b)))`` in the order they are judged; the largest key is
    the best cut. Lazy: the whole is fitted once a cut turns up, and each cut is judged only
    when asked for."""
    is_part = whole is not None  # of a region already cut
    area = float(region.sum())
    cuts, rests = _outline_cuts(region, glass, max_pieces, min_share, min_area, close_radius)
    readings = None if depth is None else _RegionReadings.of(region, depth, K, plane)
    grouped = len(cuts)  # cuts past this one the readings made: only readings hold them
    # (but the footprint cut, see split_touching)
    footprint = None  # its index; it follows the readings, not the outline: ranked last
    on_border = on_image_border(region)
    if readings is not None:
        cut, attached = _readings_cuts(region, readings, K, plane, min_area)
        if cut is not None:
            footprint = len(cuts)
            cuts.append(cut)
        cuts += attached
    if not cuts:
        return
    reg = _Region(region, K, plane, down_direction(region, K, plane), fits, readings, gain)
    judged = None
    for i, (a, b) in enumerate(cuts):
        if readings is not None:
            readings.shares.clear()
        if whole is None:  # fitted once a cut turns up (most regions have none)
            whole = reg.fits(region)
        if whole is None:
            return
        if judged is None:
            judged = _Whole(whole, None if readings is None else
                            readings.on_surface(whole, region))
        held = _judge_cut(reg, judged, a, b, outline_may_hold=i < grouped or (
                              i == footprint and not on_border),
                          min_part=min_share * area, is_part=is_part)
        if held is None:
            continue
        by_readings, by_count, score, fa, fb = held
        yield (by_readings, by_count, i != footprint, i not in rests, score), ((a, fa), (b, fb))


def merge_pieces(pieces: list[np.ndarray], shape: tuple[int, int], *, radius: int
                 ) -> list[np.ndarray]:
    """Join pieces closer than ``radius`` pixels into one region each (closing, then filling),
    so that an object whose evidence came in several parts becomes one instance."""
    if not pieces:
        return []
    union = np.zeros(shape, np.uint8)
    for p in pieces:
        union |= p.astype(np.uint8)
    groups = cv2.dilate(union, _disk(radius // 2))
    count, labels = cv2.connectedComponents(groups, connectivity=8)
    out, taken = [], np.zeros(shape, bool)
    for k in range(1, count):
        region = _closed((union > 0) & (labels == k), radius) & ~taken
        taken |= region
        out.append(region)
    return out
