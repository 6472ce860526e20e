"""Training-free reconstruction: a surface of revolution fitted to one instance mask.

Most glassware is rotationally symmetric. Given the mask, the camera and the support plane, the
object is modelled as a solid of revolution standing on the plane (axis = plane normal) or lying
on it (resting on the hull of its profile, so a goblet's axis tilts). The fit runs in 3D, so the
camera's tilt and perspective are handled exactly: the silhouette of the current model is drawn
with :func:`sr3d_cli.geometry.revolution.silhouette` and compared with the mask row by row in an
image frame whose vertical is the projected axis; radii, the two ends and the lateral position
are updated from the differences (a damped fixed-point iteration). Both hypotheses are fitted;
the one whose silhouette matches the mask better wins (standing on ties). Raw depth, when
given, breaks ties the outline cannot (standing or lying, seen from above) and, for a camera
looking down a standing object's axis, supplies the height and profile the outline lacks.

The result is a profile in sr3d's object frame (base centre, +z up the axis, height 1) and the
fitted metric pose, kept as a hint for ``align``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import cv2
import numpy as np

from sr3d_cli.geometry.camera import project, unproject
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.revolution import hull_sides, revolved, silhouette
from sr3d_cli.geometry.silhouette import mask_iou, project_mesh, surface_depth
from sr3d_cli.geometry.transforms import cross3, make_T, perpendiculars, rotation_about, unit

DEPTH_BAND = 0.01  # metres: a raw reading this close to a model's front surface lies on it
DEPTH_MIN_POINTS = 30  # fewest readings on a surface that count as evidence
DEPTH_SAMPLES = 400  # readings of a mask weighed against fitted surfaces (evenly spread)
TOP_SHARE = 0.25  # a straight top's height: where the outline is this share of its widest
NEARER_REACH = 0.2  # share nearer than its outline says a solid whose foot is hidden may stand
FLAT_END_START = 0.8  # share of a lying fit's length and radii its flat-ended refit starts at
SQUARE_OUTLINE = 1.5  # below this elongation the outline's major axis is no lying solid's
SYMMETRY_STEPS = 60  # directions tried for an outline's line of mirror symmetry (3 degrees apart)
SYMMETRY_SAMPLES = 4000  # the outline's pixels reflected about each (evenly spread)
SYMMETRY_SHARE = 0.9  # least share of those pixels whose mirror image lies in the outline for
# it to be a solid of revolution's (lying cups 0.95-0.99, drawn solids 0.99; a lying pitcher with
# its handle and spout 0.82)
SYMMETRY_GAIN = 0.03  # IoU a lying fit started on that line must gain over the others' best


@dataclass
class RevolutionFit:
    """profile : (n, 2) (r, z) object frame, height 1, ends on the axis.
    base : (3,) base centre (camera frame, m); axis : (3,) unit; height : metres;
    resting : 'standing' or 'lying'; iou : silhouette IoU of the fit against the mask;
    solid_below : share of the height below which an opened model stays solid (the top of a
    stem, :func:`carved`)."""

    profile: np.ndarray
    base: np.ndarray
    axis: np.ndarray
    height: float
    resting: str
    iou: float
    solid_below: float = 0.0

    @property
    def top(self) -> np.ndarray:
        """The centre (3,) of the top end on the axis (camera frame, metres)."""
        return self.base + self.height * self.axis

    def flipped(self) -> "RevolutionFit":
        """The same solid described from its other end (base and top swapped)."""
        profile = np.column_stack([self.profile[::-1, 0], 1.0 - self.profile[::-1, 1]])
        return RevolutionFit(profile, self.top, -self.axis, self.height, self.resting,
                             self.iou)

    @property
    def T_cam_obj(self) -> np.ndarray:
        z = self.axis / np.linalg.norm(self.axis)
        helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
        x = cross3(helper, z)
        x /= np.linalg.norm(x)
        return make_T(np.stack([x, cross3(z, x), z], axis=1), self.base)


@dataclass
class _Model:
    base: np.ndarray
    axis: np.ndarray
    height: float
    radii: np.ndarray  # (L,) metres at z_k = height * k / (L - 1)

    def centres(self) -> np.ndarray:
        z = _linspace_to(self.height, len(self.radii))
        return self.base + z[:, None] * self.axis


@functools.lru_cache(maxsize=8)
def _steps(n: int) -> np.ndarray:
    """``np.arange(n)`` (n,) float64, read-only: shared by every :func:`_linspace_to` of
    ``n`` values."""
    out = np.arange(0, n, dtype=np.float64)
    out.flags.writeable = False
    return out


def _linspace_to(stop: float, n: int) -> np.ndarray:
    """``np.linspace(0, stop, n)`` (n,), the same values bit for bit: ``k * (stop / (n - 1))``
    with the last set to ``stop``, as NumPy works them out, without its argument handling
    (most of its cost on a few values). Other cases (``n < 2``, a step that is not positive,
    ``stop`` not a float) go to NumPy."""
    if n < 2 or not isinstance(stop, float):
        return np.linspace(0, stop, n)
    step = stop / (n - 1)
    if not step > 0:
        return np.linspace(0, stop, n)
    z = _steps(n) * step
    z[-1] = stop
    return z


def _projected(points: list, K: np.ndarray) -> list:
    """:func:`project` of a few camera-frame points (lists of three floats, metres): pixels
    [(u, v), ...], the same values, worked out on Python floats (NumPy's cost per call is
    most of it on a few points); NumPy's infinities where a point lies on the camera's
    plane."""
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    try:
        return [(x / z * fx + cx, y / z * fy + cy) for x, y, z in points]
    except ZeroDivisionError:
        return project(np.array(points, np.float64), K).tolist()


def _ray(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    return np.array([(uv[0] - K[0, 2]) / K[0, 0], (uv[1] - K[1, 2]) / K[1, 1], 1.0])


class _Frame:
    """An image window around the mask, rotated so that the projected axis points up. Pixels
    ``occluders`` (H, W) bool, when given, are where objects in front may hide the one fitted:
    whatever a model draws there neither matches nor misses the mask (:meth:`seen`,
    :meth:`iou`); the window then covers them too. ``drawn``: the silhouette (size, size) bool
    of the model the window was made with (:meth:`along`), where asked for, else None."""

    def __init__(self, mask: np.ndarray, centre_px: np.ndarray, up_px: np.ndarray, pad: int,
                 occluders: np.ndarray | None = None,
                 box: tuple[int, int, int, int] | None = None,
                 solid: tuple["_Model", np.ndarray] | None = None):
        # box: (x, y, w, h) of the set pixels of the mask and the occluders (:func:`_box`),
        # given where one fit makes many windows on the same mask; solid: (model, K) of a
        # model to draw in the window as it is made (:attr:`drawn`), warped with the mask
        bx, by, bw, bh = _box(mask, occluders) if box is None else box
        x0, y0 = self.x0, self.y0 = max(0, bx - pad), max(0, by - pad)
        x1, y1 = min(mask.shape[1], bx + bw + pad), min(mask.shape[0], by + bh + pad)
        self.shape = (y1 - y0, x1 - x0)
        angle = np.degrees(np.arctan2(up_px[0], -up_px[1]))  # rotate 'up' onto image -y
        c = (float(centre_px[0] - x0), float(centre_px[1] - y0))
        # the window's diagonal, whole pixels (integer sides: the root of a whole number is
        # one or lies far from one, so any hypot rounds it up alike)
        size = math.ceil(math.hypot(*self.shape)) + 2
        self.M = cv2.getRotationMatrix2D(c, angle, 1.0)
        self.M[0, 2] += size / 2 - c[0]
        self.M[1, 2] += size / 2 - c[1]
        self.size = size
        # :meth:`point`'s terms: the window's corner (2,), the rotation (2, 2) applied to
        # rows and the shift (2,)
        self._corner = np.array([x0, y0], np.float64)
        self._turn, self._shift = self.M[:, :2].T, self.M[:, 2]
        windows = [mask[y0:y1, x0:x1]]
        if occluders is not None:
            windows.append(occluders[y0:y1, x0:x1])
        if solid is not None:
            windows.append(self._silhouette(*solid, mask.shape))
        warped = self._warp_all(windows)
        self.obs = warped[0]
        self.occluders = None if occluders is None else warped[1]
        self.drawn = None if solid is None else warped[-1]

    @classmethod
    def along(cls, model: "_Model", mask: np.ndarray, K: np.ndarray,
              occluders: np.ndarray | None = None,
              box: tuple[int, int, int, int] | None = None, drawn: bool = False) -> "_Frame":
        """The window whose vertical is ``model``'s projected axis, centred between its ends
        (``box``: see :meth:`__init__`); with ``drawn``, ``model`` drawn in it
        (:attr:`drawn`, as :meth:`draw` draws it)."""
        base = model.base.tolist()
        (u0, v0), (u1, v1) = _projected([base, _moved(base, model.height,
                                                      model.axis.tolist())], K)
        d = np.array([u1 - u0, v1 - v0])
        length = math.sqrt(d.dot(d))  # np.linalg.norm(d): the same sum
        up = d / length if length > 1e-6 else np.array([0.0, -1.0])  # unit(d), one norm
        return cls(mask, ((u0 + u1) / 2, (v0 + v1) / 2), up, pad=8, occluders=occluders,
                   box=box, solid=(model, K) if drawn else None)

    def seen(self, ren: np.ndarray) -> np.ndarray:
        """The mask as a drawn silhouette ``ren`` should match it: what ``ren`` puts on the
        occluders' pixels taken as shown."""
        return self.obs if self.occluders is None else self.obs | (ren & self.occluders)

    def iou(self, ren: np.ndarray) -> float:
        """Silhouette IoU of ``ren`` against the mask, over the pixels no occluder covers."""
        return mask_iou(self.obs, ren, self.occluders)

    def warp(self, window: np.ndarray) -> np.ndarray:
        """``window`` (h, w), set where nonzero, rotated into this frame: (size, size) bool.
        A bool window is warped through its uint8 view (0 and 1), and nearest-pixel sampling
        with a zero border gives back only those values, read again as bool: no copies."""
        return self._warped(_set(window).view(np.uint8)).view(bool)

    def _warp_all(self, windows: list[np.ndarray]) -> list[np.ndarray]:
        """:meth:`warp` of each of ``windows`` (at most eight), the same pixels, in one warp:
        nearest-pixel sampling takes each pixel whole from one place (or the zero border), so
        window k goes as bit k of one uint8 image and comes back as that bit (the top one as
        the values at least its weight)."""
        if len(windows) == 1:
            return [self.warp(windows[0])]
        bits = [_set(window).view(np.uint8) for window in windows]
        top = len(bits) - 1
        packed = bits[top] * np.uint8(1 << top)
        for k, bit in enumerate(bits[:top]):
            packed |= bit * np.uint8(1 << k) if k else bit
        warped = self._warped(packed)
        return [(warped & 1).view(bool)] + [(warped & (1 << k)) != 0 for k in range(1, top)] \
            + [warped >= 1 << top]

    def _warped(self, window: np.ndarray) -> np.ndarray:
        """``window`` (h, w) uint8 rotated into this frame, nearest-pixel: (size, size) uint8."""
        return cv2.warpAffine(window, self.M, (self.size, self.size), flags=cv2.INTER_NEAREST)

    def draw(self, model: "_Model", K: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """The model's silhouette in the image ``shape``, as seen in this window."""
        return self.warp(self._silhouette(model, K, shape))

    def _silhouette(self, model: "_Model", K: np.ndarray, shape: tuple[int, int]
                    ) -> np.ndarray:
        """The model's silhouette (h, w) bool in the unrotated window of the image ``shape``."""
        window = (self.x0, self.y0, self.shape[1], self.shape[0])
        return silhouette(model.centres(), model.axis, model.radii, K, shape, window)

    def point(self, uv: np.ndarray) -> np.ndarray:
        """Image pixel(s) (n, 2) to rotated-window coordinates (n, 2)."""
        return (np.atleast_2d(uv) - self._corner) @ self._turn + self._shift


def _set(window: np.ndarray) -> np.ndarray:
    """``window`` (h, w) as bool: set where its value as a uint8 is nonzero; a bool window as
    it is."""
    return window if window.dtype == bool else window.astype(np.uint8) != 0


def _box(mask: np.ndarray, occluders: np.ndarray | None = None) -> tuple[int, int, int, int]:
    """(x, y, w, h): the box of the set pixels of ``mask`` (H, W) bool, and of ``occluders``
    where given. cv2 scans a uint8 view of the bool image without listing every pixel
    (np.nonzero on a full frame costs about 20 times more)."""
    return cv2.boundingRect((mask if occluders is None else mask | occluders).view(np.uint8))


def _pixels(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.nonzero(mask)`` of a 2-D mask, the same arrays, listed within the box of a bool
    mask's set pixels."""
    if mask.dtype != bool:
        return np.nonzero(mask)
    x, y, w, h = _box(mask)
    ys, xs = np.nonzero(mask[y:y + h, x:x + w])
    return ys + y, xs + x


def _extent(mask: np.ndarray, top_share: float = 0.0) -> tuple[float, float, float]:
    """(top row, bottom row, mean column) of a rotated mask; with ``top_share``, the top row
    is the first one at least that share of the widest row wide."""
    return _extent_of(_counts(mask, 1), _counts(mask, 0), top_share)


def _extent_of(widths: np.ndarray, columns: np.ndarray,
               top_share: float = 0.0) -> tuple[float, float, float]:
    """:func:`_extent` of a mask from its set pixels per row ``widths`` (h,) and per column
    ``columns`` (w,) (:func:`_counts`, int64), where they are counted already."""
    rows = np.nonzero(widths)[0]
    top = rows[0] if top_share <= 0 else np.nonzero(widths >= top_share * widths.max())[0][0]
    # the mean column from the columns' counts: integer sums, so exactly the mean of the
    # pixels' columns
    column_sum = int(columns @ np.arange(len(columns)))
    return float(top), float(rows[-1]), float(column_sum) / int(widths.sum())


def _counts(mask: np.ndarray, axis: int) -> np.ndarray:
    """``mask.sum(axis)`` of a 2-D bool mask as int64: the set pixels of each column (axis 0)
    or row (axis 1), counted by cv2 over the uint8 view (a fifth of NumPy's time on a bool
    array)."""
    return cv2.reduce(mask.view(np.uint8), axis, cv2.REDUCE_SUM, dtype=cv2.CV_32S
                      ).ravel().astype(np.int64)


def _moved(point: list, length: float, direction: list) -> list:
    """``point + length * direction`` of two 3-vectors given as lists of floats, the same
    values as NumPy's."""
    return [p + length * d for p, d in zip(point, direction)]


def _metres(gap_px: float, moved_px: float, eps: float) -> float:
    """Metres to move a parameter so that a feature that moved ``moved_px`` pixels for ``eps``
    metres closes a ``gap_px`` pixel gap (0 when the parameter does not move it)."""
    return gap_px / (moved_px / eps) if abs(moved_px) > 1e-9 else 0.0


def _orientation(mask: np.ndarray, box: tuple[int, int, int, int]) -> float:
    """Angle (radians, from the window's vertical, clockwise positive) of the major axis of a
    mask (h, w) bool whose set pixels lie in ``box`` (x, y, w, h)."""
    mu20, mu11, mu02 = _central_moments(mask, box)
    if mu20 is None:
        return 0.0
    angle = 0.5 * np.arctan2(2 * mu11, mu20 - mu02)  # from +x
    return float(angle + np.pi / 2 if angle < 0 else angle - np.pi / 2)


def _central_moments(mask: np.ndarray, box: tuple[int, int, int, int]
                     ) -> tuple[float | None, float | None, float | None]:
    """(mu20, mu11, mu02) of a mask (h, w) bool whose set pixels lie in ``box`` (x, y, w, h),
    the values ``cv2.moments`` gives for the whole mask, bit for bit; all None with fewer than
    3 set pixels. cv2 sums over the box only (the rotated window is mostly empty), the bool
    view's 0s and 1s as they are (its binary mode gives the same raw sums in twice the time);
    the raw moments, whole numbers, are moved to the window's origin exactly in integers, and
    the central ones then worked out as cv2 does (``mu20 = m20 - m10 * cx`` with
    ``cx = m10 * (1 / m00)``)."""
    x, y, w, h = box
    m = cv2.moments(mask.view(np.uint8)[y:y + h, x:x + w])
    m00 = int(m["m00"])
    if m00 < 3:
        return None, None, None
    m10, m01 = int(m["m10"]), int(m["m01"])
    m20, m11, m02 = int(m["m20"]), int(m["m11"]), int(m["m02"])
    # the raw moments about the window's origin: x -> x + x0, y -> y + y0 in each sum
    m20 += 2 * x * m10 + x * x * m00
    m11 += x * m01 + y * m10 + x * y * m00
    m02 += 2 * y * m01 + y * y * m00
    m10 += x * m00
    m01 += y * m00
    inv = 1.0 / m00
    cx, cy = m10 * inv, m01 * inv
    return float(m20) - m10 * cx, float(m11) - m10 * cy, float(m02) - m01 * cy


def _box_of(widths: np.ndarray, columns: np.ndarray) -> tuple[int, int, int, int]:
    """(x, y, w, h): the box of a mask's set pixels from their counts per row ``widths`` (h,)
    and per column ``columns`` (w,) (:func:`_counts`); at least one must be set."""
    rows, cols = np.flatnonzero(widths), np.flatnonzero(columns)
    return (int(cols[0]), int(rows[0]), int(cols[-1] - cols[0]) + 1,
            int(rows[-1] - rows[0]) + 1)


def _widths(mask: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Width (pixels) of the mask (h, w) on each of ``rows`` (:func:`_rows`)."""
    return _counts(mask, 1)[_rows(rows, len(mask))].astype(np.float64)


def _rows(rows: np.ndarray, h: int) -> np.ndarray:
    """Rows (n,) of an image ``h`` rows tall, rounded and clipped to it: (n,) int."""
    return _clip(np.rint(rows).astype(int), 0, h - 1)


def _clip(a, lo, hi):
    """``np.clip(a, lo, hi)``, the same values (``hi`` None: no upper bound), by the two ufuncs
    it applies: its argument handling costs more than the work on a few values."""
    a = np.maximum(a, lo)
    return a if hi is None else np.minimum(a, hi)


def _fit(model: _Model, mask: np.ndarray, K: np.ndarray, plane: Plane, resting: str,
         iterations: int, tilt: bool = False, keep_radii: bool = False,
         occluders: np.ndarray | None = None, turn: bool = True,
         box: tuple[int, int, int, int] | None = None) -> tuple[_Model, float]:
    """Refine ``model`` so that its silhouette matches ``mask``; returns (model, IoU). A lying
    model's axis stays parallel to the plane, or with ``tilt`` rests on its hull
    (:func:`_rest_on_hull`) and, with ``turn``, turns in the plane as the outline's orientation
    says. With ``keep_radii`` only the ends and the position move, and the
    top end is matched where the outline is ``TOP_SHARE`` of its widest (a row or two of
    segmentation spill above a rim would pull a straight top up). On the ``occluders``'
    pixels (see :class:`_Frame`) the mask takes whatever the model draws. ``box``: the
    :func:`_box` of ``mask`` and ``occluders``, where known (the fits of one mask share it)."""
    n = plane.normal
    box = _box(mask, occluders) if box is None else box
    # a lying axis's trial turn about the normal (0.05 rad), to see how its image turns
    probe = rotation_about(n, 0.05) if resting == "lying" and turn else None
    for it in range(iterations + 1):
        frame = _Frame.along(model, mask, K, occluders, box, drawn=True)
        ren = frame.drawn
        if it == iterations or not ren.any():
            break
        obs = frame.seen(ren)
        if not obs.any():
            # the rotated image, centred between the model's ends, holds the mask's window
            # only as far as its diagonal reaches: a model drawn far from a small mask can
            # leave none of it there, and then no gap to close
            break
        # set pixels per row and per column of each, read by the width update, the extents
        # and the orientations
        obs_widths, obs_columns = _counts(obs, 1), _counts(obs, 0)
        ren_widths, ren_columns = _counts(ren, 1), _counts(ren, 0)
        if not keep_radii:
            at = _rows(frame.point(project(model.centres(), K))[:, 1], frame.size)
            ratio = (obs_widths[at] + 0.5) / (ren_widths[at] + 0.5)
            model.radii = _clip(model.radii * _clip(ratio, 0.7, 1.4) ** 0.8,
                                0.002 * model.height, None)
        share = TOP_SHARE if keep_radii else 0.0
        t_obs, b_obs, x_obs = _extent_of(obs_widths, obs_columns, share)
        t_ren, b_ren, x_ren = _extent_of(ren_widths, ren_columns, share)
        eps = 0.005
        # pixels moved in the window per metre of each parameter (finite differences): the
        # base and the top, then the top moved along the axis and the base moved two ways
        base, axis = model.base.tolist(), model.axis.tolist()
        top = _moved(base, model.height, axis)
        if resting == "standing":
            away = unit(plane.project_direction(model.base))
            side = cross3(n, away)
            a0, b0, bt, a_away, a_side = frame.point(_projected([
                base, top, _moved(top, eps, axis), _moved(base, eps, away.tolist()),
                _moved(base, eps, side.tolist())], K)).tolist()
            # top: the height; bottom: the base moves towards / away from the camera
            dh = _metres(t_obs - t_ren, bt[1] - b0[1], eps)
            db = _metres(b_obs - b_ren, a_away[1] - a0[1], eps)
            ds = _metres(x_obs - x_ren, a_side[0] - a0[0], eps)
            step = _clip(0.8 * np.array([dh, db, ds]), -0.5 * model.height, 0.5 * model.height)
            model.base = model.base + step[1] * away + step[2] * side
            model.height = max(model.height + step[0], 1e-3)
        else:
            # lying: move each end along the axis, the axis sideways in the plane
            side = unit(cross3(n, model.axis))
            a0, b0, bt, a_b, a_side = frame.point(_projected([
                base, top, _moved(top, eps, axis), _moved(base, -eps, axis),
                _moved(base, eps, side.tolist())], K)).tolist()
            dt = _metres(t_obs - t_ren, bt[1] - b0[1], eps)
            db = _metres(b_obs - b_ren, a_b[1] - a0[1], eps)
            ds = _metres(x_obs - x_ren, a_side[0] - a0[0], eps)
            step = _clip(0.8 * np.array([dt, db, ds]), -0.5 * model.height, 0.5 * model.height)
            model.base = model.base - step[1] * model.axis + step[2] * side
            model.height = max(model.height + step[0] + step[1], 1e-3)
            # turn the axis in the plane until the silhouette's orientation matches
            d_img = (_orientation(obs, _box_of(obs_widths, obs_columns))
                     - _orientation(ren, _box_of(ren_widths, ren_columns))) if turn else 0.0
            if abs(d_img) > 1e-3:
                base = model.base.tolist()
                tip = _moved(base, model.height, (probe @ model.axis).tolist())
                p = frame.point(_projected([base, tip], K))
                gain = (np.arctan2(p[1, 0] - p[0, 0], p[0, 1] - p[1, 1])) / 0.05
                if abs(gain) > 1e-3:
                    mid = model.base + 0.5 * model.height * model.axis
                    model.axis = rotation_about(n, float(_clip(0.8 * d_img / gain, -0.3, 0.3))
                                                ) @ model.axis
                    model.base = mid - 0.5 * model.height * model.axis
            if tilt:
                _rest_on_hull(model, plane)
            else:  # the axis rests at the largest radius above the plane
                lift = model.radii.max() - plane.height(model.base[None])[0]
                model.base = model.base + lift * n
    if ren.any() and not keep_radii:
        hidden = _hidden(model, frame, ren, K)
        if hidden.any():
            radii = _fill_hidden(model.radii, hidden)
            if not np.array_equal(radii, model.radii):  # else the same silhouette
                model.radii = radii
                ren = frame.draw(model, K, mask.shape)
    return model, frame.iou(ren)


def straightened(fit: RevolutionFit, mask: np.ndarray, K: np.ndarray, rise: float = 0.35,
                 loss: float = 0.002, occluders: np.ndarray | None = None,
                 box: tuple[int, int, int, int] | None = None) -> RevolutionFit:
    """A standing ``fit`` whose profile only narrows upwards (nowhere wider, by ``rise`` of its
    largest radius, than at a level below) with its hidden levels between shown ones widened
    towards the straight line between those, as far as the outline keeps its IoU (within
    ``loss``): seen from above, a flask's base covers its cone, which the width update leaves
    dented (up to 12 mm narrow at mid-height; straightening cuts a standing flask's mean
    radius error by about a quarter). Applied to the chosen fit only: the raw readings that
    decide standing from lying are counted on the fitted, dented surface, where a straightened
    flask can lose its vote to a lying fit; lying fits are left as they are (straightening them
    loses grasps). ``occluders``: see :class:`_Frame`; ``box``: see :func:`_fit`."""
    if fit.resting != "standing":
        return fit
    radii = fit.profile[1:-1, 0] * fit.height
    model = _Model(fit.base.copy(), fit.axis.copy(), fit.height, radii.copy())
    frame = _Frame.along(model, mask, K, occluders, box, drawn=True)
    ren = frame.drawn
    hidden = _hidden(model, frame, ren, K)
    shown = np.nonzero(~hidden)[0]
    if len(shown) < 2 or (radii - np.minimum.accumulate(radii)).max() > rise * radii.max():
        return fit
    k = np.arange(len(radii))
    inside = hidden & (k > shown[0]) & (k < shown[-1])
    line = np.where(inside, np.maximum(np.interp(k, shown, radii[shown]), radii), radii)
    floor = frame.iou(ren) - loss
    for share in (1.0, 0.5, 0.25):
        model.radii = radii + share * (line - radii)
        iou = frame.iou(frame.draw(model, K, mask.shape))
        if iou >= floor:
            return _result(model, "standing", iou)
    return fit


def _hidden(model: _Model, frame: _Frame, ren: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(L,) bool: levels whose own width falls short of the drawn width on their row (by 2 px):
    another part of the model covers them there."""
    centres = model.centres()
    drawn = _widths(ren, frame.point(project(centres, K))[:, 1])
    return 2 * model.radii * K[0, 0] / centres[:, 2] < drawn - 2


def _straight_top(model: _Model, outline: "_Outline", K: np.ndarray, plane: Plane,
                  iterations: int) -> tuple[_Model, float] | None:
    """The standing ``model`` of ``outline`` with its top levels above the highest level the
    silhouette shows widened to that level's radius, its height refitted; None if the top
    level shows."""
    mask, occluders, box = outline.mask, outline.occluders, outline.box
    frame = _Frame.along(model, mask, K, occluders, box, drawn=True)
    hidden = _hidden(model, frame, frame.drawn, K)
    shown = np.nonzero(~hidden)[0]
    if not hidden[-1] or len(shown) == 0:
        return None
    top = shown[-1]
    radii = model.radii.copy()
    radii[top + 1:] = np.maximum(radii[top + 1:], radii[top])
    start = _Model(model.base.copy(), model.axis.copy(), model.height, radii)
    return _fit(start, mask, K, plane, "standing", iterations, keep_radii=True,
                occluders=occluders, box=box)


def _fill_hidden(radii: np.ndarray, hidden: np.ndarray) -> np.ndarray:
    """Radii with no ``hidden`` level (one narrower than the silhouette where it is drawn:
    another part covers it) pinched below the nearest shown levels on both sides of it. The
    outline says nothing about a hidden level, and the width-ratio update carries it along
    with whatever covers it (a flask's neck seen from above can pinch to a tenth of its
    width). A goblet's stem stays thin: a shown part of it is nearest."""
    shown = np.nonzero(~hidden)[0]
    if len(shown) == 0 or len(shown) == len(radii):
        return radii
    k = np.arange(len(radii))
    prev = np.searchsorted(shown, k, side="right") - 1  # nearest shown at or below
    inside = (prev >= 0) & (prev < len(shown) - 1)
    lo, hi = shown[np.clip(prev, 0, None)], shown[np.clip(prev + 1, None, len(shown) - 1)]
    floor = np.where(inside, np.minimum(radii[lo], radii[hi]), 0.0)
    return np.where(hidden, np.maximum(radii, floor), radii)


def _resting_tilt(z: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """How a body of revolution lies on a table: on the side of its profile's convex hull
    (:func:`hull_sides`) whose span along the axis holds the centre of mass (of the solid,
    weight r^2); a goblet rests on its foot's rim and its cup, tilted. On fitted, noisy
    profiles this places the object with less error than the exact rule of :func:`resting_edge`.
    z (L,) increasing along the axis from the base, r (L,) radii (metres). Returns the axis's
    rise towards +z (radians) and the axis's height at z = 0 above the table.
    """
    zc = float((z * r ** 2).sum() / max((r ** 2).sum(), 1e-12))
    for a, b in hull_sides(z, r):
        if a[0] - 1e-9 <= zc <= b[0] + 1e-9:
            theta = float(np.arctan2(b[1] - a[1], b[0] - a[0]))
            return theta, float(a[1] * np.cos(theta) - a[0] * np.sin(theta))
    return 0.0, float(r.max())


def _rest_on_hull(model: _Model, plane: Plane) -> None:
    """Tilt a lying model's axis about its middle and set its height so that it rests on the
    table as :func:`_resting_tilt` says."""
    n = plane.normal
    flat = unit(plane.project_direction(model.axis))
    theta, h0 = _resting_tilt(_linspace_to(model.height, len(model.radii)), model.radii)
    mid = model.base + 0.5 * model.height * model.axis
    model.axis = np.cos(theta) * flat + np.sin(theta) * n
    base = mid - 0.5 * model.height * model.axis
    model.base = base + (h0 - plane.height(base[None])[0]) * n


@dataclass(frozen=True)
class _Outline:
    """A mask ``(H, W) bool`` to fit, the pixels ``occluders`` (H, W) bool of objects in front
    that may hide it (see :class:`_Frame`; None: none), and what the fits read of them more
    than once, worked out once: ``box``, the :func:`_box` of both; the mask's set pixels
    ``ys``, ``xs`` (n,) (:func:`_pixels`) and their count ``area``; their centroid ``centre``
    (2,), unit major direction ``major`` (2,) and ``elongation`` (the square root of the
    ratio of their spreads along the major and minor directions); ``symmetry`` when first
    asked."""

    mask: np.ndarray
    occluders: np.ndarray | None
    box: tuple[int, int, int, int]
    ys: np.ndarray
    xs: np.ndarray
    area: int
    centre: np.ndarray
    major: np.ndarray
    elongation: float

    @classmethod
    def of(cls, mask: np.ndarray, occluders: np.ndarray | None = None) -> "_Outline":
        ys, xs = _pixels(mask)
        pts = np.column_stack([xs, ys]).astype(np.float64)
        centre = pts.mean(0)
        evals, evecs = np.linalg.eigh(np.cov((pts - centre).T))
        return cls(mask, occluders, _box(mask, occluders), ys, xs, len(xs), centre,
                   evecs[:, 1], float(np.sqrt(evals[1] / max(evals[0], 1e-9))))

    @functools.cached_property
    def symmetry(self) -> tuple[np.ndarray, float]:
        """:func:`symmetry_line` of the mask about its centroid."""
        return symmetry_line(self.mask, self.xs, self.ys, self.centre)


def _init_standing(outline: _Outline, K, plane, levels) -> _Model | None:
    centre = outline.centre
    p = plane.intersect(_ray(centre, K))
    if not np.all(np.isfinite(p)):
        return None
    n = plane.normal
    up = project(np.stack([p, p + 0.05 * n]), K)
    up = unit(up[1] - up[0])
    ys, xs = outline.ys, outline.xs
    along = xs * up[0] + ys * up[1]
    low = along <= along.min() + 1.5
    bottom = np.array([xs[low].mean(), ys[low].mean()])
    front = plane.intersect(_ray(bottom, K))
    if not np.all(np.isfinite(front)):
        return None
    z = front[2]
    width_px = outline.area / max(np.ptp(along), 1.0)
    r = 0.5 * width_px * z / K[0, 0]
    base = front + r * unit(plane.project_direction(front))
    top = np.array([xs[along >= along.max() - 1.5].mean(), ys[along >= along.max() - 1.5].mean()])
    s = np.linspace(0.005, 1.5, 300)
    px = project(base[None] + s[:, None] * n, K)
    height = float(s[np.argmin(np.linalg.norm(px - top, axis=1))])
    return _Model(base, n.copy(), height, np.full(levels, r))


def _init_lying(outline: _Outline, K, plane, levels, across_major: bool = False,
                symmetric: bool = False) -> _Model | None:
    """A lying cylinder along the outline's major axis (or, ``across_major``, its minor one:
    a lying vessel about as long as it is wide has no telling major axis; or, ``symmetric``,
    its line of mirror symmetry, :func:`symmetry_line`)."""
    centre, major = outline.centre, outline.major
    if symmetric:
        major = outline.symmetry[0]
    elif across_major:
        major = np.array([-major[1], major[0]])
    ys, xs = outline.ys, outline.xs
    along = (xs - centre[0]) * major[0] + (ys - centre[1]) * major[1]
    across = -(xs - centre[0]) * major[1] + (ys - centre[1]) * major[0]
    mid = plane.intersect(_ray(centre, K))
    if not np.all(np.isfinite(mid)):
        return None
    r = 0.5 * np.ptp(across) * mid[2] / K[0, 0]
    raised = Plane(plane.normal, plane.offset - r)  # the axis runs r above the table
    e1 = raised.intersect(_ray(centre + along.min() * major, K))
    e2 = raised.intersect(_ray(centre + along.max() * major, K))
    if not (np.all(np.isfinite(e1)) and np.all(np.isfinite(e2))):
        return None
    axis = unit(plane.project_direction(e2 - e1))
    length = float(np.linalg.norm(e2 - e1))
    return _Model(e1, axis, max(length, 1e-3), np.full(levels, r))


def symmetry_line(mask: np.ndarray, xs: np.ndarray, ys: np.ndarray, centre: np.ndarray
                  ) -> tuple[np.ndarray, float]:
    """The line through ``centre`` (2,) about which the ``mask`` (H, W) bool pixels ``xs``,
    ``ys`` (n,) are most nearly their own mirror image: its unit image direction (2,) and the
    share of the pixels whose mirror image lies in the mask. A solid of revolution's outline is
    symmetric about its projected axis (within a pixel or two under perspective), whatever
    way it points. :data:`SYMMETRY_SAMPLES` pixels are reflected about
    :data:`SYMMETRY_STEPS` directions over half a turn; the first best wins."""
    pick = evenly((xs, ys), SYMMETRY_SAMPLES)
    p = np.column_stack(pick).astype(np.float64) - centre
    h, w = mask.shape
    phi = np.linspace(0.0, np.pi, SYMMETRY_STEPS, endpoint=False)
    c2, s2 = np.cos(2 * phi)[:, None], np.sin(2 * phi)[:, None]
    x = np.rint(c2 * p[:, 0] + s2 * p[:, 1] + centre[0]).astype(np.int64)
    y = np.rint(s2 * p[:, 0] - c2 * p[:, 1] + centre[1]).astype(np.int64)
    inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    hits = np.where(inside, mask[np.clip(y, 0, h - 1), np.clip(x, 0, w - 1)], False).sum(1)
    best = int(np.argmax(hits))
    return np.array([np.cos(phi[best]), np.sin(phi[best])]), float(hits[best] / len(p))


def _result(model: _Model, resting: str, iou: float) -> RevolutionFit:
    radii, base, axis = model.radii, model.base, model.axis
    if resting == "lying":
        tail = max(2, len(radii) // 8)
        if radii[-tail:].mean() > radii[:tail].mean():  # the wider end is the base
            base, axis, radii = base + model.height * axis, -axis, radii[::-1]
    z = np.linspace(0, 1, len(radii))
    r = radii / model.height
    profile = np.vstack([[0.0, 0.0], np.column_stack([r, z]), [0.0, 1.0]])
    return RevolutionFit(profile, base, axis, model.height, resting, iou)


def smoothed(fit: RevolutionFit, sigma: float) -> RevolutionFit:
    """``fit`` with its radii smoothed along the axis by a Gaussian of ``sigma`` levels (the
    ends held). Each level's width is read on one image row, in whole pixels: where levels lie
    about a pixel apart, neighbouring radii zigzag by a pixel's worth, and the mesh's walls
    with them (a 10 cm beaker's rim wall sloped 50 degrees level to level)."""
    if sigma <= 0:
        return fit
    half = int(np.ceil(3 * sigma))
    kernel = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
    profile = fit.profile.copy()
    profile[1:-1, 0] = np.convolve(np.pad(profile[1:-1, 0], half, mode="edge"),
                                   kernel / kernel.sum(), mode="valid")
    return replace(fit, profile=profile)


STRAIGHT_SPAN = (0.1, 0.85)  # share of the height whose levels straight_walls may set upright
STRAIGHT_BEND = 0.001  # metres: the most those levels may stray from one line to be a wall


def straight_walls(fit: RevolutionFit, max_deg: float) -> RevolutionFit:
    """A ``fit`` whose levels within :data:`STRAIGHT_SPAN` of its height lie on one
    line (within :data:`STRAIGHT_BEND`) leaning less than ``max_deg`` from its axis, with
    those levels set to their median radius: a wall that upright (a beaker's) is read as
    upright. The fit leans such walls outwards by half a degree or more (up to about 3 deg
    from sr3d's own masks), and a pinch across a thin wall, whose pads span up to 40 mm of it,
    holds only within about 1.5 deg. Levels above
    the span wider than the wall, but the top one, are set to it too: a beaker's 3 mm lip is one
    level, which the fit and :func:`smoothed` spread over the levels below as a wall flaring
    outwards over its top 10-15 mm, and a pinch across the rim closed at that slant holds on
    the model but not on the true, upright wall (pinches slanted 7-9 deg by a lip spread
    1.7 mm wide can need friction 3 on the true beaker). The span ends at 85% of the height,
    as the lip's spread reaches down to 87-90% of it (a span to 90% leaves a third of the
    beakers unstraightened, 1-2 mm off their line there).
    The top level (the lip) and the base are left as fitted. A lying fit is read the same way
    over the middle 15-85% of its length, and either end may be its mouth: a lying beaker's lip
    is spread the same way.
    ``max_deg`` 0 returns the fit unchanged."""
    if max_deg <= 0:
        return fit
    inner = fit.profile[1:-1] * fit.height
    r, z = inner[:, 0], inner[:, 1]
    standing = fit.resting == "standing"
    lo = STRAIGHT_SPAN[0] if standing else 1 - STRAIGHT_SPAN[1]
    wall = (z >= lo * fit.height) & (z <= STRAIGHT_SPAN[1] * fit.height)
    if wall.sum() < 4:
        return fit
    slope, offset = np.polyfit(z[wall], r[wall], 1)
    if abs(slope) > np.tan(np.radians(max_deg)) or \
            np.abs(r[wall] - (slope * z[wall] + offset)).max() > STRAIGHT_BEND:
        return fit
    upright = np.median(r[wall])
    # above the wall, a level wider than it is the lip spread down by the fit and smoothing:
    # the wall goes up to the top level, which keeps the lip (lying: at either end)
    lip = (z > STRAIGHT_SPAN[1] * fit.height) | ((not standing) & (z < lo * fit.height))
    lip[-1] = lip[0] = False
    profile = fit.profile.copy()
    profile[1:-1, 0] = np.where(wall | (lip & (r > upright)), upright / fit.height,
                                profile[1:-1, 0])
    return replace(fit, profile=profile)


CARVE_SHARE = 0.05  # levels holding fewer of the readings that look at them are empty ...
CARVE_CONTRAST = 4.0  # ... where the object's other levels hold this many times as many
CARVE_READINGS = 60  # fewest readings (over CARVE_WINDOW levels) that can show a level empty
CARVE_WINDOW = 5  # levels pooled around each level to judge it
CARVE_SAMPLES = 3000  # the mask's readings weighed (evenly spread)
STEM_SHARE = 0.12  # radius of a carved level, as a share of the widest
BOWL_READINGS = 5  # fewest readings at a level that find the bowl there (carved)
STEM_SPAN = (0.15, 0.75)  # a carved run spans at least the first share of the height and ends
# below the second (a stem holds up a bowl)
FOOT_SPAN = 0.25  # share of the height under a carved run beyond which what stands there is a
# body, not a foot (a flat bottle carved above its shoulder), and is left as fitted


def carved(fit: RevolutionFit, mask: np.ndarray, depth: np.ndarray, K: np.ndarray,
           loss: float = 0.005) -> RevolutionFit:
    """A standing ``fit`` with a run of levels between its foot and its top that the raw
    ``depth`` (H, W) metres shows empty thinned to a stem (:data:`STEM_SHARE` of the widest
    radius). Seen steeply from above, a goblet's bowl covers its stem, and the outline (a bowl
    over a foot) is fitted as well by a cylinder as wide as the bowl, which the width update
    makes (10-21 mm too wide at the stem, where grasps planned on that wall or on the rim
    above it fail on the true goblet). The readings tell
    them apart: glass gives front-surface returns as well as see-through ones, and of the rays
    that meet a made-up wall, none returns from anywhere inside it. A level is empty when,
    pooled over :data:`CARVE_WINDOW` levels, at least :data:`CARVE_READINGS` readings' rays
    first meet the solid there, and fewer than :data:`CARVE_SHARE` as many readings lie at
    that height within its radius but off a stem's (front returns of the goblet's foot and of
    the inside of its bowl, looked into, mark where the stem ends), while the other levels hold
    :data:`CARVE_CONTRAST` times as many (a sensor returning too little from this glass
    judges nothing). Only a run between a foot and a top, spanning :data:`STEM_SPAN`, is
    carved, and only while the outline keeps its IoU (within ``loss``). The readings find the
    bowl only where its underside turns towards the camera (a flatter one, met at a grazing
    angle, returns nothing), often well above the stem's top: below the lowest level where
    :data:`BOWL_READINGS` of them find it, the bowl narrows into the stem at 45 degrees from
    their median radius there, not as a flat floor on the stem, which would put the stem's
    top too high (by 17 mm on average against 12 mm with the cone). The foot below the stem
    then ends at its readings' median level (:func:`foot_at_readings`), again only while the
    outline keeps its IoU within ``loss``."""
    if fit.resting != "standing":
        return fit
    xs, ys, raw = evenly(_read(mask, depth), CARVE_SAMPLES)
    front = fit_depth(fit, xs, ys, K, mask.shape)
    hit = np.isfinite(front)
    if hit.sum() < CARVE_READINGS:
        return fit
    radii = fit.profile[1:-1, 0]
    n = len(radii)

    def levels(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Level index (p,) of camera-frame points and their distance from the axis (m)."""
        along = (points - fit.base) @ fit.axis
        away = np.linalg.norm(points - fit.base - along[:, None] * fit.axis, axis=1)
        return np.rint(along / fit.height * (n - 1)).astype(np.int64), away

    looked, _ = levels(unproject(np.column_stack([xs[hit], ys[hit]]).astype(np.float64),
                                 front[hit], K))
    at, away = levels(unproject(np.column_stack([xs, ys]).astype(np.float64), raw, K))
    stem = STEM_SHARE * radii.max()
    within = (at >= 0) & (at < n) & (away > 2 * stem * fit.height)
    within[within] &= away[within] <= radii[at[within]] * fit.height + DEPTH_BAND
    window = np.ones(CARVE_WINDOW)
    count = np.convolve(np.bincount(np.clip(looked, 0, n - 1), minlength=n), window, "same")
    each = np.bincount(at[within], minlength=n)
    held = np.convolve(each, window, "same")
    empty = (count >= CARVE_READINGS) & (held < CARVE_SHARE * count)
    if not empty.any() or held[~empty].sum() < CARVE_CONTRAST * CARVE_SHARE * \
            count[~empty].sum():
        return fit
    # pooling widens the foot and the bowl by half a window: a run goes on level by level
    # while each level alone holds as few
    alone = each < CARVE_SHARE * count / CARVE_WINDOW
    z = fit.profile[1:-1, 1]
    inside = np.zeros(n, bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], empty.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):  # runs [a, b) of empty levels
        while a > 1 and alone[a - 1]:
            a -= 1
        while b < n - 1 and alone[b]:
            b += 1
        if a > 0 and b < n and z[b - 1] - z[a] >= STEM_SPAN[0] and z[b - 1] <= STEM_SPAN[1] \
                and np.median(radii[a:b]) > 2 * stem:  # not a stem the outline showed
            inside[a:b] = True
    if not inside.any():
        return fit
    # below the lowest level whose readings find the bowl, a 45-degree cone (see above)
    thin = np.minimum(radii, stem)
    for b in np.flatnonzero(np.diff(inside.astype(np.int8)) < 0) + 1:  # first level above a run
        found = np.flatnonzero(each[b:] >= BOWL_READINGS)
        if not len(found):
            continue
        j = b + found[0]
        seen = float(np.median(away[within & (at == j)])) / fit.height
        cone = seen - (z[j] - z)
        thin = np.where(inside & (z < z[j]), np.maximum(thin, np.minimum(cone, radii)), thin)
    profile = fit.profile.copy()
    profile[1:-1, 0] = np.where(inside, thin, radii)
    thinned = replace(fit, profile=profile, solid_below=float(z[inside].max()))
    fitted = mask_iou(mask, fit_silhouette(fit, K, mask.shape))
    iou = mask_iou(mask, fit_silhouette(thinned, K, mask.shape))
    if iou < fitted - loss:
        return fit
    thinned = replace(thinned, iou=iou)
    footed = foot_at_readings(thinned, each, int(np.argmax(inside)), stem)
    if footed is not thinned:
        iou = mask_iou(mask, fit_silhouette(footed, K, mask.shape))
        if iou >= fitted - loss:
            return replace(footed, iou=iou)
    return thinned


def foot_at_readings(fit: RevolutionFit, each: np.ndarray, first: int,
                     stem: float) -> RevolutionFit:
    """A carved ``fit`` (:func:`carved`) with its foot ended at the median level of the
    readings below its stem: ``each (n,)`` the readings found at each level off the stem,
    ``first`` the stem's lowest level, ``stem`` its radius (share of the height). The carve
    pools readings over :data:`CARVE_WINDOW` levels, so a foot's own readings keep up to two
    levels above it wide: left so, extsim's wine glass (a 3 mm foot) has a foot 17-21 mm tall,
    and the stem's lower part is drawn 15-20 mm nearer than it is. The sensor's noise spreads
    the readings of the foot's top evenly about it, so their median level is that top; the
    levels above it take the stem's radius. The lowest level's readings are left out: they
    are the table seen through the foot, and with them a foot 12 mm thick ends at the table.
    Returns ``fit`` itself where no level changes, or where the levels under the stem span
    more than :data:`FOOT_SPAN` of the height."""
    below = each[1:first]  # the lowest level's are the table's, seen through the foot
    if first < 3 or below.sum() == 0 or fit.profile[1 + first, 1] > FOOT_SPAN:
        return fit
    cum = np.cumsum(below)
    top = 1 + int(np.searchsorted(cum, cum[-1] / 2.0))
    if top + 1 >= first:
        return fit
    profile = fit.profile.copy()  # row i + 1 holds level i: levels top + 1 .. first - 1
    profile[2 + top:1 + first, 0] = np.minimum(profile[2 + top:1 + first, 0], stem)
    return replace(fit, profile=profile)


def off_table_readings(mask: np.ndarray, depth: np.ndarray, K: np.ndarray, plane: Plane,
                       band: float = DEPTH_BAND, samples: int = DEPTH_SAMPLES
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels (xs, ys) and raw depth of the mask's readings more than ``band`` above the table
    (those on it are see-through readings), at most ``samples`` of them, evenly spread."""
    xs, ys, z = _read(mask, depth)
    pts = unproject(np.column_stack([xs, ys]).astype(np.float64), z, K)
    keep = plane.height(pts) > band
    return evenly((xs[keep], ys[keep], z[keep]), samples)


def _read(mask: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels ``xs``, ``ys`` (n,) of ``mask`` (H, W) bool where ``depth`` (H, W) metres
    reads (> 0), in ``np.nonzero``'s order, and their depth (n,) float64: read at the mask's
    pixels only (comparing the whole frame's depth costs more than the rest)."""
    ys, xs = _pixels(mask)
    z = depth[ys, xs]
    keep = z > 0
    return xs[keep], ys[keep], z[keep].astype(np.float64)


def evenly(readings: tuple[np.ndarray, ...], samples: int) -> tuple[np.ndarray, ...]:
    """At most ``samples`` of ``readings`` (parallel arrays), evenly spread."""
    n = len(readings[0])
    pick = np.linspace(0, n - 1, min(n, samples)).astype(np.int64)
    return tuple(r[pick] for r in readings)


def fit_silhouette(fit: RevolutionFit, K: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The fitted solid's silhouette (H, W) bool in an image of ``shape``."""
    inner = fit.profile[1:-1] * fit.height
    return silhouette(fit.base + inner[:, 1:2] * fit.axis, fit.axis, inner[:, 0], K, shape)


def fit_depth(fit: RevolutionFit, xs: np.ndarray, ys: np.ndarray, K: np.ndarray,
              shape: tuple[int, int], far: bool = False) -> np.ndarray:
    """Depth (n,) of the fitted solid's front surface at pixels (xs, ys) (NaN: off it); with
    ``far``, of the surface where the rays leave it."""
    vertices, faces = revolved(fit.profile, 24)
    T = fit.T_cam_obj
    uv, pts = project_mesh(vertices, T[:3, :3], T[:3, 3], fit.height, K)
    return surface_depth(uv, pts, faces[:, ::-1] if far else faces, K, xs, ys, shape)


def raw_support(fit: RevolutionFit, xs: np.ndarray, ys: np.ndarray, raw: np.ndarray,
                K: np.ndarray, shape: tuple[int, int], band: float) -> int:
    """How many raw readings lie within ``band`` metres of the fitted solid's front surface."""
    if len(xs) == 0:
        return 0
    return int((np.abs(fit_depth(fit, xs, ys, K, shape) - raw) < band).sum())


def stands_behind(back: RevolutionFit, front: RevolutionFit, pixels: np.ndarray,
                  K: np.ndarray, plane: Plane, tolerance: float = DEPTH_BAND,
                  share: float = 0.8, samples: int = 200) -> bool:
    """Whether solid ``back`` lies behind solid ``front``: its base's foot on ``plane`` no
    nearer the camera's than ``front``'s (within ``tolerance`` metres), and where both cover
    ``pixels`` (H, W) bool, on (at least ``share`` of) the rays through both, its front
    surface no nearer than where they leave ``front``. Two solids cannot pass through each
    other, so one hidden behind another starts where the other ends."""
    n = plane.normal
    reach = [np.linalg.norm(f.base - plane.height(f.base[None])[0] * n + plane.offset * n)
             for f in (back, front)]  # from the camera's foot on the table
    if reach[0] < reach[1] - tolerance:
        return False
    ys, xs = _pixels(pixels)
    if len(xs) == 0:
        return True
    pick = np.linspace(0, len(xs) - 1, min(len(xs), samples)).astype(np.int64)
    xs, ys = xs[pick], ys[pick]
    near = fit_depth(back, xs, ys, K, pixels.shape)
    leave = fit_depth(front, xs, ys, K, pixels.shape, far=True)
    both = np.isfinite(near) & np.isfinite(leave)
    if not both.any():
        return True
    return bool((near[both] >= leave[both] - tolerance).mean() >= share)


def top_height(fit: RevolutionFit, plane: Plane) -> float:
    """Height (metres) of the fitted solid's highest point above ``plane``."""
    z = fit.profile[:, 1] * fit.height
    centres = plane.height(fit.base + z[:, None] * fit.axis)
    across = np.sqrt(max(0.0, 1.0 - float(fit.axis @ plane.normal) ** 2))
    return float((centres + fit.profile[:, 0] * fit.height * across).max())


def above_top(fit: RevolutionFit, heights: np.ndarray, plane: Plane, band: float) -> int:
    """How many readings (``heights`` above ``plane``, metres) stand more than ``band`` above
    the fit's highest point: with the camera above the table, none of them can lie on it."""
    return int((heights > top_height(fit, plane) + band).sum())


def axial_view_angle(mask: np.ndarray, K: np.ndarray, plane: Plane) -> float:
    """Degrees between the table normal and the camera ray to the mask's centroid: near 0,
    the camera looks down a standing object's axis and its outline says almost nothing about
    its height or profile (a bottle, a jar and a glass all draw a disc)."""
    return _view_angle(_Outline.of(mask).centre, K, plane)


def _view_angle(centre: np.ndarray, K: np.ndarray, plane: Plane) -> float:
    """:func:`axial_view_angle` from the mask's centroid ``centre`` (2,) pixels."""
    return float(np.degrees(np.arccos(np.clip(-unit(_ray(centre, K)) @ plane.normal, -1, 1))))


def _envelope(z: np.ndarray, r: np.ndarray, levels: np.ndarray, band: float,
              floor: int) -> np.ndarray:
    """Radius at each of ``levels``: a high percentile of r over the readings at or above it.
    From above the camera sees the upper envelope (a neck's top, the shoulder, the rim); a
    reading at (r, z) means the solid is at least r wide at z and at every height below."""
    order = np.argsort(-z)  # highest first: the readings at or above a level are a prefix
    zs, rs = z[order], r[order]
    n = np.searchsorted(-zs, -(levels - 0.5 * band), side="right")
    counts = [max(int(k), min(floor, len(rs))) for k in n]
    if not counts or min(counts) < 1 or rs.dtype != np.float64 or np.isnan(rs).any():
        return np.array([np.percentile(rs[:k], 90) for k in counts])
    return np.array([_percentile_90(np.sort(rs[:k])) for k in counts])


def _percentile_90(ordered: np.ndarray) -> float:
    """``np.percentile(values, 90)`` of values (m,) float64 (m >= 1, no NaN) given sorted, the
    same value bit for bit: the index ``(m - 1) * 0.9`` falls ``t`` of the way from one value
    to the next, and the two are interpolated as NumPy does (from the upper one where ``t``
    is at least a half); at the last value (m = 1) both are it. NumPy's argument handling
    costs most of its time on a few hundred values."""
    m = len(ordered)
    at = (m - 1) * 0.9
    below = math.floor(at) if at < m - 1 else -1
    above = below + 1 if at < m - 1 else -1
    t = at - below
    a, b = float(ordered[below]), float(ordered[above])
    return b - (b - a) * (1 - t) if t >= 0.5 else a + (b - a) * t


def _fit_axial(outline: _Outline, K: np.ndarray, plane: Plane, points: np.ndarray,
               levels: int, band: float, min_points: int, iterations: int = 8
               ) -> RevolutionFit | None:
    """A standing solid seen down its axis, from the readings on it (camera frame, metres).

    The height is a high percentile of the readings' heights above the table and the profile
    their upper envelope (:func:`_envelope`), scaled to the widest radius; that radius and the
    axis's place on the table are then moved until the silhouette's area and centroid match
    the mask's (the readings give the shape, the outline the size), and the outline places the
    ends (:func:`_fit` keeping the radii) within ``band`` of that height. None with fewer
    than ``min_points`` readings more than ``band`` above the table."""
    n = plane.normal
    above = plane.height(points)
    points, above = points[above > band], above[above > band]
    if len(points) < min_points:
        return None
    height = float(np.percentile(above, 98))
    mask, centre_px = outline.mask, outline.centre
    mid = Plane(n, plane.offset - 0.5 * height).intersect(_ray(centre_px, K))
    if not np.all(np.isfinite(mid)) or height <= band:
        return None
    base = mid - 0.5 * height * n
    widest = np.sqrt(outline.area / np.pi) * mid[2] / K[0, 0]
    e1 = unit(plane.project_direction(np.array([1.0, 0, 0])))
    e2 = np.cross(n, e1)
    zk = np.linspace(0.0, height, levels)
    area = float(outline.area)
    for it in range(iterations + 1):
        rel = points - base
        z = rel @ n
        r = np.linalg.norm(rel - z[:, None] * n, axis=1)
        keep = r < widest + band
        if keep.sum() < min_points:
            return None
        shape = _envelope(z[keep], r[keep], zk, band, max(5, min_points // 6))
        radii = np.maximum(shape * widest / max(shape.max(), 1e-6), 0.002 * height)
        sil = silhouette(base + zk[:, None] * n, n, radii, K, mask.shape)
        if not sil.any() or it == iterations:
            break
        widest *= float(np.clip(np.sqrt(area / sil.sum()), 0.8, 1.25))
        ys, xs = _pixels(sil)
        gap = centre_px - np.array([xs.mean(), ys.mean()])
        at = base + 0.5 * height * n  # the silhouette's centre lies between base and top
        J = np.column_stack([(project((at + 0.005 * e)[None], K)[0] - project(at[None], K)[0])
                             / 0.005 for e in (e1, e2)])
        step = np.linalg.lstsq(J, gap, rcond=None)[0]
        base = base + np.clip(step, -0.5 * widest, 0.5 * widest) @ np.stack([e1, e2])
    iou = mask_iou(sil, mask)
    # the readings' top lies above the rim by about twice their noise (glass readings scatter
    # a few mm along the ray). Looked straight down, the outline hardly moves with the
    # height: its ends are kept only within ``band`` of the readings' height.
    model = _Model(base.copy(), n.copy(), height, radii.copy())
    model, refit_iou = _fit(model, mask, K, plane, "standing", iterations, keep_radii=True)
    if abs(model.height - height) <= band:
        return _result(model, "standing", refit_iou)
    profile = np.vstack([[0.0, 0.0], np.column_stack([radii / height, zk / height]),
                         [0.0, 1.0]])
    return RevolutionFit(profile, base, n.copy(), height, "standing", iou)


def nearer_factors(fit: RevolutionFit, occluders: np.ndarray, K: np.ndarray, plane: Plane,
                   mask: np.ndarray, reach: float = NEARER_REACH, step: float = 0.01
                   ) -> np.ndarray:
    """Factors ``f <= 1`` (1 first) at which a standing ``fit`` of ``mask`` may stand nearer
    the camera, its foot hidden by objects in front (``occluders``, (H, W) bool).

    A standing solid's distance comes from the outline's lowest row, where it meets the table.
    Where an object in front hides that row, the solid may reach further down behind it and
    stand nearer: scaled by ``f`` about the camera (the outline is unchanged) and continued
    down to the table at its base radius (:func:`moved_nearer`). Its foot ring on the table
    must then project onto the occluders or the mask (within 2 px), its nearest point onto
    the occluders. Factors run from 1 down by ``step`` to the first that fails, at most
    ``reach`` below 1."""
    factors = [1.0]
    if fit.resting != "standing" or not occluders.any():
        return np.array(factors)
    n = plane.normal
    e1, e2 = perpendiculars(n)
    turn = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.cos(turn)[:, None] * e1 + np.sin(turn)[:, None] * e2
    radius = float(fit.profile[1, 0] * fit.height)
    front = cv2.dilate(occluders.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    either = front | (cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)
    h, w = mask.shape
    for f in np.arange(1.0 - step, 1.0 - reach - 1e-9, -step):
        base = f * fit.base
        foot = base - plane.height(base[None])[0] * n + f * radius * ring
        if (foot[:, 2] <= 0).any():
            break
        uv = np.rint(project(foot, K)).astype(int)
        if (uv < 0).any() or (uv[:, 0] >= w).any() or (uv[:, 1] >= h).any():
            break
        nearest = int(np.argmin(np.linalg.norm(foot, axis=1)))
        if not front[uv[nearest, 1], uv[nearest, 0]] or not either[uv[:, 1], uv[:, 0]].all():
            break
        factors.append(float(f))
    return np.array(factors)


def moved_nearer(fit: RevolutionFit, factor: float, plane: Plane) -> RevolutionFit:
    """A standing ``fit`` scaled by ``factor`` about the camera (its outline unchanged) and
    continued down to the table at its lowest radius (see :func:`nearer_factors`)."""
    if factor == 1.0:
        return fit
    base = factor * fit.base
    lift = float(plane.height(base[None])[0])
    height = factor * fit.height + lift
    z_old = lift + fit.profile[1:-1, 1] * factor * fit.height  # metres above the table
    r_old = fit.profile[1:-1, 0] * factor * fit.height
    z = np.linspace(0.0, height, len(r_old))
    r = np.interp(z, z_old, r_old)  # below the old base: its lowest radius
    profile = np.vstack([[0.0, 0.0], np.column_stack([r / height, z / height]), [0.0, 1.0]])
    return RevolutionFit(profile, base - lift * plane.normal, plane.normal.copy(), height,
                         "standing", fit.iou)


def _nearer(fit: RevolutionFit, outline: _Outline, K: np.ndarray, plane: Plane,
            iterations: int, on_surface: Callable[[RevolutionFit], int], need: int,
            iou_gap: float, every: int = 2) -> RevolutionFit:
    """``fit`` of ``outline`` (with occluders) refitted standing nearer, at every
    ``every``-th of :func:`nearer_factors` (from :func:`moved_nearer` there), where most
    readings lie on its surface, if at least ``need`` do and its IoU is within ``iou_gap`` of
    the fit's; else ``fit``. The outline above a hidden foot fits a short solid standing where
    the occluder's outline crosses it; started further down, the fit keeps its foot there
    behind the occluder, and the readings on what shows tell how far down it stands."""
    mask, occluders = outline.mask, outline.occluders
    best, most = fit, need - 1
    for f in nearer_factors(fit, occluders, K, plane, mask)[every::every]:
        start = moved_nearer(fit, f, plane)  # levels evenly spaced, as many as the fit's
        model = _Model(start.base.copy(), start.axis.copy(), start.height,
                       start.profile[1:-1, 0] * start.height)
        model, iou = _fit(model, mask, K, plane, "standing", iterations, occluders=occluders,
                          box=outline.box)
        found = _result(model, "standing", iou)
        count = on_surface(found)
        if count > most and iou >= fit.iou - iou_gap:
            best, most = found, count
    return best


@dataclass(frozen=True)
class FitOptions:
    """The settings of :func:`fit_revolution` (what each rule is, in its docstring).

    levels : radii along the axis; iterations : fixed-point rounds of each silhouette fit;
    lying_margin : IoU a lying fit must beat a standing one by; allow_lying : fit lying at all;
    depth_band : metres within which a reading lies on a surface; depth_min_points : fewest
    readings that count as evidence; depth_vote : times more readings a hypothesis needs to win
    by them; vote_iou_gap : IoU within which the readings decide; axial_view : degrees from the
    axis within which a standing solid is also fitted from the readings; axial_iou_gap : IoU
    within which that fit is kept; poor_outline : outline IoU under which a standing fit is no
    surface of revolution; poor_outline_view : ``axial_view`` for such a fit; refute_share :
    share of the readings above a lying fit's top that refutes it; tilt_tolerance : IoU a tilted
    lying refit may lose; straight_top_gap : IoU a straight-topped refit may lose;
    square_starts : also start a near-square outline's lying fit across it; flat_end_gain :
    IoU a lying fit started again with flat ends must gain (:func:`flat_ended`)."""

    levels: int = 40
    iterations: int = 12
    lying_margin: float = 0.03
    allow_lying: bool = True
    depth_band: float = DEPTH_BAND
    depth_min_points: int = DEPTH_MIN_POINTS
    depth_vote: float = 2.0
    vote_iou_gap: float = 0.06
    axial_view: float = 25.0
    axial_iou_gap: float = 0.03
    poor_outline: float = 0.9
    poor_outline_view: float = 40.0
    refute_share: float = 0.25
    tilt_tolerance: float = 0.01
    straight_top_gap: float = 0.005
    square_starts: bool = True
    flat_end_gain: float = 0.03


# (across the outline's major axis, turned by its orientation, along its line of symmetry)
LyingStart = tuple[bool, bool, bool]


@dataclass
class _Readings:
    """The off-table raw readings of a mask, weighed against fits.

    xs, ys : (N,) int pixels; raw : (N,) metres; points : (N, 3) camera frame, metres;
    heights : (N,) metres above the plane; openings : the open vessels a fit may be rendered
    as (see :func:`fit_revolution`)."""
    xs: np.ndarray
    ys: np.ndarray
    raw: np.ndarray
    points: np.ndarray
    heights: np.ndarray
    shape: tuple[int, int]
    K: np.ndarray
    plane: Plane
    openings: Callable[[RevolutionFit], list[RevolutionFit]] | None

    @classmethod
    def of(cls, mask, depth, K, plane, band, openings) -> "_Readings":
        xs, ys, raw = off_table_readings(mask, depth, K, plane, band)
        points = unproject(np.column_stack([xs, ys]).astype(np.float64), raw, K)
        return cls(xs, ys, raw, points, plane.height(points), mask.shape, K, plane, openings)

    def on_surface(self, fit: RevolutionFit, band: float) -> int:
        """Readings on the surface of the fit or of any of its open forms, the most of them."""
        forms = [fit, *(self.openings(fit) if self.openings is not None else [])]
        return max(raw_support(f, self.xs, self.ys, self.raw, self.K, self.shape, band)
                   for f in forms)

    def refutes(self, fit: RevolutionFit, opts: FitOptions) -> bool:
        """Enough readings lie above the fit's highest point to rule it out."""
        return above_top(fit, self.heights, self.plane, opts.depth_band) >= \
            max(opts.depth_min_points, opts.refute_share * len(self.points))


def _refuted(readings: _Readings | None, fit: RevolutionFit, opts: FitOptions) -> bool:
    """:meth:`_Readings.refutes`, never without readings."""
    return readings is not None and readings.refutes(fit, opts)


def _lying_starts(outline: _Outline, opts: FitOptions) -> list[LyingStart]:
    """The lying fit's starts: along the major axis, turning. A near-square outline's major axis
    and orientation say nothing of a lying solid's axis (a beaker as long as it is wide), so
    there it starts both ways, turned or not, and unturned along its line of mirror symmetry
    where :data:`SYMMETRY_SHARE` of it is symmetric (a lying cup pointed obliquely at the
    camera: extsim 0003's axis is 30-70 degrees off the fits from both axes, IoU 0.83, and
    0.3 degrees off the one from that line, 0.94); not where an object in front may cut the
    outline (the top of a glass behind another, a near-square that a lying fit drew better
    than the standing one, which the readings then chose)."""
    square = opts.square_starts and outline.elongation < SQUARE_OUTLINE and \
        (outline.occluders is None or not outline.occluders.any())
    if not square:
        return [(False, True, False)]
    starts = [(False, True, False), (True, True, False), (True, False, False),
              (False, False, False)]
    return starts + [(False, False, True)] if outline.symmetry[1] >= SYMMETRY_SHARE else starts


def _outline_fit(resting: str, starts: list[LyingStart], outline: _Outline, K, plane,
                 opts: FitOptions) -> tuple[_Model, float, LyingStart] | None:
    """The best silhouette fit of one resting hypothesis over its starts: (model, IoU, the
    start it won from), or None when no start can be set up. The start along the line of
    symmetry wins only by :data:`SYMMETRY_GAIN` over the best of the others: one start more
    also draws the outline's noise better (taken at any gain, ClearGrasp 123 from its true
    masks went 8.2 -> 9.3 mm)."""
    tried = []
    for across, turn, symmetric in starts:
        model = _init_lying(outline, K, plane, opts.levels, across, symmetric) \
            if resting == "lying" else _init_standing(outline, K, plane, opts.levels)
        if model is not None:
            tried.append((*_fit(model, outline.mask, K, plane, resting, opts.iterations,
                                occluders=outline.occluders, turn=turn, box=outline.box),
                          (across, turn, symmetric)))
    if not tried:
        return None
    best = max(tried, key=lambda t: t[1])
    others = [t for t in tried if not t[2][2]]
    if not others or not best[2][2]:
        return best
    plain = max(others, key=lambda t: t[1])
    return best if best[1] > plain[1] + SYMMETRY_GAIN else plain


def _straight_top_kept(fit: RevolutionFit, model: _Model, outline: _Outline, K, plane,
                       readings: _Readings | None, opts: FitOptions) -> RevolutionFit:
    """The standing fit refitted with its hidden top levels straight
    (:func:`_straight_top`) if within ``straight_top_gap`` IoU and not refuted; else ``fit``."""
    straight = _straight_top(model, outline, K, plane, opts.iterations)
    if straight is not None and straight[1] >= fit.iou - opts.straight_top_gap:
        candidate = _result(straight[0], "standing", straight[1])
        if not _refuted(readings, candidate, opts):
            return candidate
    return fit


def _axial_kept(fit: RevolutionFit, outline: _Outline, K, plane, readings: _Readings,
                opts: FitOptions) -> tuple[RevolutionFit, int, RevolutionFit | None]:
    """The readings' fit (:func:`_fit_axial`) replaces the outline's if more readings lie on its
    surface and it is within ``axial_iou_gap`` IoU (off the axis, a flask's neck shifts against
    its body and the outline fit wins). Returns the fit, the readings on its surface and the
    readings' fit where it was made and not kept (else None)."""
    count = readings.on_surface(fit, opts.depth_band)
    down = _fit_axial(outline, K, plane, readings.points, opts.levels, opts.depth_band,
                      opts.depth_min_points)
    down_count = readings.on_surface(down, opts.depth_band) if down is not None else -1
    if down_count > count and down.iou >= fit.iou - opts.axial_iou_gap:
        return down, down_count, None
    return fit, count, down


def _by_readings(fits: list[tuple[float, RevolutionFit, int | None]], readings: _Readings,
                 opts: FitOptions, down: RevolutionFit | None = None) -> RevolutionFit | None:
    """Standing (fits[0]) against lying (fits[1]) by the readings: a refuted lying fit loses to
    an unrefuted standing one, the readings' fit ``down`` not kept for the standing one's
    outline if that one is refuted too; else, with the IoUs within ``vote_iou_gap``, the one
    with ``depth_vote`` times more readings on its surface (at least ``depth_min_points``)
    wins. None when the readings do not decide. The readings on the surfaces are counted only
    where they are asked (IoUs that close)."""
    if readings.refutes(fits[1][1], opts):
        for standing in (fits[0][1], down):
            if standing is not None and not readings.refutes(standing, opts):
                return standing  # readings high above a lying fit: it stands
    close = abs(fits[0][1].iou - fits[1][1].iou) <= opts.vote_iou_gap
    if not close:
        return None
    support = [readings.on_surface(f, opts.depth_band) if count is None else count
               for _, f, count in fits]
    lo, hi = sorted(support)
    if hi >= opts.depth_min_points and hi >= opts.depth_vote * lo:
        return fits[int(np.argmax(support))][1]
    return None


def _tilted(best: RevolutionFit, start: LyingStart, outline: _Outline, K, plane,
            opts: FitOptions) -> RevolutionFit:
    """A lying winner refitted resting on its hull, tilted, from its own start (the flat fit's
    radii hold the tilt as a taper), kept if within ``tilt_tolerance`` IoU. Decided flat: a
    tilt would let the lying fit take short standing vessels."""
    model = _init_lying(outline, K, plane, opts.levels, start[0], start[2])
    if model is None:
        return best
    model, iou = _fit(model, outline.mask, K, plane, "lying", opts.iterations, tilt=True,
                      occluders=outline.occluders, turn=start[1], box=outline.box)
    return _result(model, "lying", iou) if iou >= best.iou - opts.tilt_tolerance else best


def flat_ended(fit: RevolutionFit, mask: np.ndarray, K: np.ndarray, plane: Plane,
               depth: np.ndarray | None = None, occluders: np.ndarray | None = None,
               options: FitOptions = FitOptions()) -> RevolutionFit:
    """A lying ``fit`` of ``mask (H, W) bool`` fitted again from flat ends, kept where its
    silhouette IoU is ``flat_end_gain`` better and the raw ``depth (H, W)`` metres, when given,
    do not refute it (:meth:`_Readings.refutes`); else ``fit``. Seen obliquely, a lying
    vessel's ends draw half ellipses beyond them, and the outline fit, started as long as the
    outline, narrows its ends to follow those and can stop in a poor optimum: extsim 6's lying
    water glass (125 mm long, 40 mm in radius, its mouth towards the camera, 40 degrees off
    its axis) comes out 148 mm long with a 48 mm bulge near one end at IoU 0.90. The refit
    starts from the fit with every radius as wide as the widest between it and its end,
    scaled by :data:`FLAT_END_START` (length and radii) about its middle: IoU 0.97 with the
    glass's radius (40 mm), though still too long (162 mm) with narrowing ends.
    ``occluders``: see :class:`_Frame`."""
    if fit.resting != "lying":
        return fit
    radii = fit.profile[1:-1, 0] * fit.height
    half = len(radii) // 2
    flat = np.r_[np.maximum.accumulate(radii[:half]),
                 np.maximum.accumulate(radii[half:][::-1])[::-1]]
    share = FLAT_END_START
    start = _Model(fit.base + 0.5 * (1 - share) * fit.height * fit.axis, fit.axis.copy(),
                   share * fit.height, share * flat)
    outline = _Outline.of(mask, occluders)
    model, iou = _fit(start, mask, K, plane, "lying", options.iterations, tilt=True,
                      occluders=occluders, box=outline.box)
    if iou < fit.iou + options.flat_end_gain:
        return fit
    refit = _result(model, "lying", iou)
    readings = None if depth is None else \
        _Readings.of(mask, depth, K, plane, options.depth_band, None)
    return fit if _refuted(readings, refit, options) else refit


def fit_revolution(mask: np.ndarray, K: np.ndarray, plane: Plane, *,
                   depth: np.ndarray | None = None,
                   openings: Callable[[RevolutionFit], list[RevolutionFit]] | None = None,
                   occluders: np.ndarray | None = None,
                   options: FitOptions = FitOptions()) -> RevolutionFit:
    """Fit a solid of revolution to ``mask (H, W) bool`` seen by a camera ``K`` above ``plane``;
    the settings named below are the fields of ``options`` (:class:`FitOptions`).

    Standing and lying are both fitted; the better silhouette wins, lying only by
    ``lying_margin`` IoU. Seen from above, a tall standing bottle and a short lying one can draw
    nearly the same outline; with raw ``depth (H, W)`` metres given, the hypothesis on whose
    front surface ``depth_vote`` times more off-table readings lie (within ``depth_band``, at
    least ``depth_min_points``) wins instead, if its silhouette IoU is within ``vote_iou_gap`` of
    the other's (a mask of two merged objects fits neither well; there the outline decides).
    A standing solid seen within ``axial_view`` degrees of its axis is also fitted from the
    readings (:func:`_fit_axial`); that fit is kept if more readings lie on its surface and its
    silhouette IoU is within ``axial_iou_gap`` of the outline fit's (a flask's thin neck leaves
    few readings: the readings' height falls short where the outline has it right). An outline
    fit under ``poor_outline`` IoU is no surface of revolution (a square or flat bottle): its
    height is a guess (a square oil bottle seen 26 degrees off its axis came out 40% too tall),
    so the readings' fit is tried up to ``poor_outline_view`` degrees off the axis.
    Readings more than ``depth_band`` above a fit's highest point refute it: with the camera
    above the table, a ray meets the object's surface before anything lower behind it, so they
    can only be noise in front of it. A lying fit that ``refute_share`` of the readings (at least
    ``depth_min_points``) refute loses to a standing one they do not, whatever the outline says
    (a tall goblet seen steeply from above draws the outline of a short lying one); where they
    refute the standing outline fit too, to the readings' fit if they do not refute that (a
    flat bottle seen down its axis: the outline leaves a standing fit's height open).
    Standing and lying are weighed with the lying axis parallel to the table; a lying winner is
    then fitted again resting on its hull, tilted (:func:`_resting_tilt`), and that fit is kept
    if its IoU is within ``tilt_tolerance`` of the flat one's.
    Seen from above, an open vessel's rim ellipse covers its upper levels, and the outline fits
    a taller vessel curling inward at the top about as well as the true straight one (a 7 cm
    beaker looked down on from 56 degrees above the table can come out 30% too tall). A standing
    fit whose top levels are hidden is refitted with them as wide as the highest level shown
    (:func:`_straight_top`); that fit is kept if its IoU is within ``straight_top_gap`` of
    the free one's (a 10% lip makes the curled fit draw the outline up to 0.5% better) and
    the readings do not refute it (a squat box with a lid, not a solid of
    revolution, would come out 2.3 cm tall under readings up to 8 cm).
    ``openings`` gives the open vessels a fit may be rendered as (its mouth ends opened); the
    readings a hypothesis explains are then the most any of its closed and open forms does:
    looked down into, an open beaker shows its floor and inner wall, which a closed model's lid
    hides, and a short lying solid in front of them can take more of its readings than the
    lidded standing one (a 12.6 cm beaker: 29 readings on the lidded model, 70 on a lying fit,
    214 opened). A standing winner's hidden levels are then straightened where its
    profile only narrows upwards (:func:`straightened`).
    A lying fit starts along the outline's major axis, turning as its orientation says; with
    ``square_starts``, a near-square outline (elongation below :data:`SQUARE_OUTLINE`) that no
    ``occluders`` touch also starts across it, and both without turning: the best IoU wins.
    ``occluders`` (H, W) bool are the pixels of objects in front that may hide this one: the
    outline is compared with the fits elsewhere only (see :class:`_Frame`). A standing winner
    whose foot they hide is then moved nearer (:func:`nearer_factors`) where ``depth_vote``
    times more readings (at least ``depth_min_points``) lie on its surface there.

    Raises ValueError when neither hypothesis can be set up (e.g. the mask is above the horizon).
    """
    opts = options
    readings = None if depth is None else \
        _Readings.of(mask, depth, K, plane, opts.depth_band, openings)
    outline = _Outline.of(mask, occluders)
    # degrees off the axis; without readings, no readings' fit
    view = _view_angle(outline.centre, K, plane) if readings is not None else 180.0
    lying_starts = _lying_starts(outline, opts)
    lying_start = lying_starts[0]  # the one the lying fit won from (its tilted refit's too)
    fits = []  # (score, fit, readings on its surface when already counted)
    down = None  # the standing readings' fit the outline's was kept over
    for resting in ("standing", "lying") if opts.allow_lying else ("standing",):
        starts = lying_starts if resting == "lying" else [(False, True, False)]
        found = _outline_fit(resting, starts, outline, K, plane, opts)
        if found is None:
            continue
        model, iou, start = found
        fit, count = _result(model, resting, iou), None
        if resting == "lying":
            lying_start = start
        else:
            fit = _straight_top_kept(fit, model, outline, K, plane, readings, opts)
            if view < (opts.poor_outline_view if fit.iou < opts.poor_outline
                       else opts.axial_view):
                fit, count, down = _axial_kept(fit, outline, K, plane, readings, opts)
        fits.append((fit.iou + (opts.lying_margin if resting == "standing" else 0.0), fit,
                     count))
    if not fits:
        raise ValueError("the mask does not meet the support plane: cannot place an object")
    best = max(fits, key=lambda f: f[0])[1]
    if readings is not None and len(fits) == 2:
        decided = _by_readings(fits, readings, opts, down)
        best = best if decided is None else decided
    if best.resting == "lying":
        best = _tilted(best, lying_start, outline, K, plane, opts)
    if readings is not None and occluders is not None and best.resting == "standing":
        def on_surface(fit: RevolutionFit) -> int:
            return readings.on_surface(fit, opts.depth_band)
        best = _nearer(best, outline, K, plane, opts.iterations, on_surface,
                       max(opts.depth_min_points, opts.depth_vote * on_surface(best)),
                       opts.vote_iou_gap)
    return straightened(best, mask, K, occluders=occluders, box=outline.box)
