"""A standing top told shut by the height of the readings inside its rim.

:func:`sr3d_cli.reconstruct.open_mouth` keeps a standing top shut where more readings lie on
the closed model's surface than on the opened one's, each within ``DEPTH_BAND`` along its ray.
Looked at from low down, a lid's readings lie about as near the far inside wall of the opened
model, and a fit a few millimetres short or tall moves its lid by several times that along the
rays: the real containers of the Tracebot views, read on their lids, came out open. Their
height above the table tells a lid apart without the ray: within the image of the rim, a lid's
readings lie at the rim's height, while an open vessel shows its inside and the table through
its floor there, below it. That holds only where the line of sight falls steeply enough into
the mouth (:data:`LID_VIEW`): seen from nearly level, the far rim and the inside just below it
fill the rim's thin image, all at about the rim's height.
"""

from __future__ import annotations

import cv2
import numpy as np

from sr3d_cli.geometry.camera import project, unproject
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.transforms import perpendiculars
from sr3d_cli.shape.revolution_fit import DEPTH_BAND, DEPTH_MIN_POINTS, RevolutionFit

LID_SHARE = 0.75  # of the readings within the rim's image (those above the rim left out) at
# the rim's height that show a lid: Tracebot's lidded containers 0.87-1.00; the open glasses,
# bowls and pitchers of extsim and sr3d's generator at most 0.67
LID_VIEW = 0.3  # least cosine between the line of sight to the top's centre and the axis
# (17 deg above the rim's plane): a generated flute seen from 13 deg showed 0.95
RIM_POINTS = 48  # points round the rim's circle drawn as its image


def rim_image(fit: RevolutionFit, K: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Pixels ``(H, W) bool`` within the image of ``fit``'s top circle (camera ``K``, image
    ``shape``); none where the circle is behind the camera."""
    u, v = perpendiculars(fit.axis)
    turn = np.linspace(0.0, 2.0 * np.pi, RIM_POINTS, endpoint=False)
    ring = fit.top + fit.profile[-2, 0] * fit.height * (np.outer(np.cos(turn), u) +
                                                    np.outer(np.sin(turn), v))
    out = np.zeros(shape, np.uint8)
    if (ring[:, 2] > 0).all():
        cv2.fillPoly(out, [np.round(project(ring, K)).astype(np.int32)], 1)
    return out > 0


def lid_read(fit: RevolutionFit, mask: np.ndarray, K: np.ndarray, plane: Plane,
             depth: np.ndarray) -> bool:
    """Whether the raw ``depth (H, W)`` metres show a lid on the standing ``fit``'s top:
    seen steeply enough (:data:`LID_VIEW`), of the readings of ``mask (H, W) bool`` within
    the rim's image (:func:`rim_image`), at least :data:`DEPTH_MIN_POINTS` and
    :data:`LID_SHARE` of those not above it lie within ``DEPTH_BAND`` of the rim's height over
    the table (readings higher up are of something else)."""
    top = fit.top
    if abs(float(top @ fit.axis)) < LID_VIEW * float(np.linalg.norm(top)):
        return False
    ys, xs = np.nonzero(rim_image(fit, K, mask.shape) & mask & (depth > 0))
    if len(xs) < DEPTH_MIN_POINTS:
        return False
    heights = plane.height(unproject(np.column_stack([xs, ys]).astype(np.float64),
                                     depth[ys, xs].astype(np.float64), K))
    at_rim = int((np.abs(heights - fit.height) < DEPTH_BAND).sum())
    below = int((heights <= fit.height - DEPTH_BAND).sum())
    return at_rim >= DEPTH_MIN_POINTS and at_rim >= LID_SHARE * (at_rim + below)
