"""Parallel-jaw gripper model in the grasp frame shared with graspnetAPI.

Grasp frame: origin at the grasp centre (between the finger pads), x = approach (from the palm
towards the object), y = closing direction, z = x cross y. The fingertips reach ``depth`` past the
centre along x; each finger is ``finger_length`` long, ``finger_thickness`` thick along y and
``finger_height`` tall along z; the palm sits behind the finger bases. Franka Emika hand sizes by
default (config ``grasp``, the one place the sizes are set), rounded: 0.08 m opening, 0.05 m
fingers, a 0.2 m wide palm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Gripper:
    max_width: float
    finger_length: float
    finger_thickness: float
    finger_height: float
    palm_width: float
    palm_height: float
    palm_depth: float

    @classmethod
    def from_config(cls, cfg) -> "Gripper":
        return cls(cfg.max_width, cfg.finger_length, cfg.finger_thickness, cfg.finger_height,
                   cfg.palm_width, cfg.palm_height, cfg.palm_depth)

    def boxes(self, width, depth) -> np.ndarray:
        """Axis-aligned boxes ``(..., 3, 2, 3)`` (left finger, right finger, palm; lower and
        upper corner) in the grasp frame for openings ``width`` and depths ``depth`` (arrays
        broadcast together)."""
        w, d = (a[..., None] for a in np.broadcast_arrays(np.asarray(width, dtype=np.float64),
                                                           np.asarray(depth, dtype=np.float64)))
        L, T, H = self.finger_length, self.finger_thickness, self.finger_height
        one = np.ones_like(w + d)
        left = np.stack([np.concatenate([d - L, -w / 2 - T, -H / 2 * one], -1),
                         np.concatenate([d, -w / 2, H / 2 * one], -1)], -2)
        right = np.stack([np.concatenate([d - L, w / 2, -H / 2 * one], -1),
                          np.concatenate([d, w / 2 + T, H / 2 * one], -1)], -2)
        palm = np.stack([np.concatenate([d - L - self.palm_depth, -self.palm_width / 2 * one,
                                         -self.palm_height / 2 * one], -1),
                         np.concatenate([d - L, self.palm_width / 2 * one,
                                         self.palm_height / 2 * one], -1)], -2)
        return np.stack([left, right, palm], -3)

    def corners(self, width, depth) -> np.ndarray:
        """The 8 corners of each box, ``(..., 24, 3)`` in the grasp frame."""
        b = self.boxes(width, depth)
        sel = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        c = np.stack([b[..., sel[:, 0], 0], b[..., sel[:, 1], 1], b[..., sel[:, 2], 2]], -1)
        return c.reshape(*c.shape[:-3], 24, 3)

    def lowest(self, R: np.ndarray, t: np.ndarray, width, depth, plane) -> np.ndarray:
        """Height above ``plane`` of the lowest corner of each gripper (rotation ``R (..., 3,
        3)``, centre ``t (..., 3)``, opening ``width``, ``depth``): ``(...)``."""
        up = np.einsum("...ij,i->...j", R, plane.normal)[..., None, None, :]  # grasp frame
        # a linear function's least over a box takes each coordinate at the end its sign picks
        low = np.min(self.boxes(width, depth) * up, axis=-2).sum(-1).min(-1)
        return low + plane.height(t)

    def finger_extent(self, R: np.ndarray, width, depth, direction: np.ndarray) -> np.ndarray:
        """How far the two fingers (of :meth:`boxes`) reach from each grasp centre along
        ``direction`` (camera frame), for rotations ``R (n, 3, 3)``, openings ``width`` and
        ``depth`` ``(n,)``: ``(n,)`` (as :meth:`lowest`, by the sign of each coordinate)."""
        a = np.einsum("nij,i->nj", R, direction)[:, None, None, :]   # (n, 1, 1, 3) grasp frame
        fingers = self.boxes(width, depth)[:, :2]                    # (n, 2, 2, 3)
        return np.max(fingers * a, axis=2).sum(-1).max(1)

    def reach(self) -> float:
        """Radius around the grasp centre that holds the whole gripper."""
        back = self.finger_length + self.palm_depth
        return float(np.sqrt(back ** 2 + (self.palm_width / 2) ** 2 + (self.palm_height / 2) ** 2))


def count_inside(local: np.ndarray, boxes: np.ndarray, shrink: float = 0.0) -> np.ndarray:
    """Points inside each box. local : (F, 3, M) grasp-frame coordinates, axis by axis (as
    :func:`to_local` gives them); boxes : (F, B, 2, 3), each shrunk by ``shrink`` on every side
    (negative: inflated). Returns (F, B) counts."""
    lo = (boxes[:, :, 0] + shrink).astype(local.dtype)[..., None]     # (F, B, 3, 1)
    hi = (boxes[:, :, 1] - shrink).astype(local.dtype)[..., None]
    x, y, z = local[:, 0], local[:, 1], local[:, 2]
    counts = np.zeros(boxes.shape[:2], dtype=np.int64)
    slabs: dict[bytes, np.ndarray] = {}  # the fingers share their x and z extents: test once
    for b in range(boxes.shape[1]):
        key = lo[:, b, ::2].tobytes() + hi[:, b, ::2].tobytes()
        if key not in slabs:
            slabs[key] = (x > lo[:, b, 0]) & (x < hi[:, b, 0]) & (z > lo[:, b, 2]) & \
                (z < hi[:, b, 2])
        inside = slabs[key] & (y > lo[:, b, 1]) & (y < hi[:, b, 1])
        counts[:, b] = inside.view(np.uint8).sum(axis=1, dtype=np.int64)
    return counts


def to_local(R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Camera-frame points ``(n, 3)`` in the frames of grasps ``R (F, 3, 3)``, ``t (F, 3)``,
    axis by axis: ``(F, 3, n)`` float32 (each axis's row contiguous: the box tests of
    :func:`count_inside` run along rows, several times faster than on (F, n, 3))."""
    R = np.asarray(R, dtype=np.float32)
    t = np.asarray(t, dtype=np.float32)
    F = len(R)
    rows = R.transpose(0, 2, 1).reshape(3 * F, 3)                   # frame axes as rows
    offset = (rows * np.repeat(t, 3, axis=0)).sum(axis=1)[:, None]  # each axis's value at t
    local = rows @ np.asarray(points, dtype=np.float32).T - offset
    return local.reshape(F, 3, -1)
