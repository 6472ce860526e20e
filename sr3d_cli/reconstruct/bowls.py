"""Bowls told from domes by the readings.

Seen from above, a bowl (narrow foot, wide open rim) and a dome (wide base, narrowing upwards)
draw nearly the same outline: the rim's ellipse and the front of the body below it. The
outline fit settles on the dome (a glass bowl 61 mm tall came out a 42 mm dome, its base as
wide as the true rim), closed, and the depth it renders lies over the bowl's inside. The
readings tell them apart: looked into, a bowl returns its floor and inner wall, far below a
dome's surface. A standing fit that narrows upwards is refitted from its profile turned upside
down, opened at its top (:func:`sr3d_cli.reconstruct.mouths`), from several heights
(:data:`BOWL_STARTS`): the outline hardly sets a bowl's height, the readings on its inside do,
and of the bowls whose outline is about as good as the dome's the one most readings lie on is
kept when :data:`BOWL_VOTE` times as many lie on it as on the dome. Where neither holds that
many times the other's readings (a glass bowl's front and the table seen through it lie about
as well on a dome), a dome at least :data:`WIDE_LOW` times as wide as it is tall is taken for
a bowl: glassware that squat on a table is one (the bowls of sr3d's generator and of extsim
fitted as domes: 1.9-7.7 times as wide as tall; every bottle and flask whose fit narrows
upwards, on the shared and generated frames: at most 0.94). A dome whose readings lie on it
stays one.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from sr3d_cli.geometry.plane import Plane
from sr3d_cli.shape.revolution_fit import (DEPTH_BAND, DEPTH_MIN_POINTS, RevolutionFit, _fit,
                                           _Model, _result, off_table_readings, raw_support)

NARROW_TOP = 0.7  # a fit whose top radius is below this share of its widest narrows upwards
BOWL_VOTE = 2.0  # times as many readings on the opened bowl as on the dome (or the other way)
# that decide between them
BOWL_IOU_GAP = 0.03  # the bowl's outline IoU may fall this much short of the dome's
WIDE_LOW = 1.5  # a standing dome this many times as wide as tall is a bowl unless its readings
# hold BOWL_VOTE times as many on the dome
BOWL_STARTS = (0.5, 0.7, 1.0, 1.4)  # heights the upturned profile is refitted from, as shares
# of the dome's: from the dome's height alone an extsim glass bowl 61 mm tall came out 68 mm
# from one mask and 81 mm from another 2% different, the outline's IoU within 0.03 at every
# height from 23 to 85 mm; the readings on its inside tell them apart


def bowl_instead(fit: RevolutionFit, mask: np.ndarray, K: np.ndarray, plane: Plane,
                 depth: np.ndarray, iterations: int,
                 openings: Callable[[RevolutionFit], list[RevolutionFit]]
                 ) -> RevolutionFit | None:
    """The bowl (closed, as fitted; ``openings`` opens it) that explains ``mask (H, W) bool``
    and the raw ``depth (H, W)`` metres better than the standing dome ``fit``; None when
    the fit does not narrow upwards or the readings prefer the dome, and when neither is
    preferred, for a dome less than :data:`WIDE_LOW` times as wide as tall."""
    if fit.resting != "standing":
        return None
    r = fit.profile[1:-1, 0]
    if r[-1] >= NARROW_TOP * r.max() or np.argmax(r) > len(r) // 2:
        return None
    xs, ys, raw = off_table_readings(mask, depth, K, plane)
    best, most = None, -1
    for share in BOWL_STARTS:
        height = share * fit.height
        start = _Model(fit.base.copy(), fit.axis.copy(), height, r[::-1] * height)
        model, iou = _fit(start, mask, K, plane, "standing", iterations)
        bowl = _result(model, "standing", iou)
        opened = openings(bowl)
        if not opened or iou < fit.iou - BOWL_IOU_GAP:
            continue
        found = raw_support(opened[0], xs, ys, raw, K, mask.shape, DEPTH_BAND)
        if found > most:
            best, most = bowl, found
    if best is None:
        return None
    dome = raw_support(fit, xs, ys, raw, K, mask.shape, DEPTH_BAND)
    if most >= max(DEPTH_MIN_POINTS, BOWL_VOTE * dome):
        return best
    squat = 2.0 * r.max() >= WIDE_LOW  # the profile's radii are shares of the height
    return best if squat and dome < BOWL_VOTE * most else None

