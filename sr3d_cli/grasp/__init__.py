"""6-DoF parallel-jaw grasps: the set of grasps of a frame and its file formats.

Every grasp is stored in graspnetAPI's layout: one row of 17 numbers, ``score, width, height,
depth, R (3x3, row-major), t (3), object id``, metres, camera frame, with the grasp frame of
:mod:`sr3d_cli.grasp.gripper` (x = approach, y = closing direction, t = grasp centre).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sr3d_cli.geometry.transforms import make_T


@dataclass
class GraspSet:
    """n grasps: scores (n,), widths (n,), heights (n,), depths (n,), R (n, 3, 3), t (n, 3),
    object_ids (n,) int."""

    scores: np.ndarray
    widths: np.ndarray
    heights: np.ndarray
    depths: np.ndarray
    R: np.ndarray
    t: np.ndarray
    object_ids: np.ndarray

    @classmethod
    def empty(cls) -> "GraspSet":
        return cls.from_array(np.zeros((0, 17)))

    def __len__(self) -> int:
        return len(self.scores)

    def take(self, index) -> "GraspSet":
        return GraspSet(self.scores[index], self.widths[index], self.heights[index],
                        self.depths[index], self.R[index], self.t[index], self.object_ids[index])

    @classmethod
    def concat(cls, sets: list["GraspSet"]) -> "GraspSet":
        if not sets:
            return cls.empty()
        return cls.from_array(np.concatenate([s.to_array() for s in sets]))

    def sorted(self) -> "GraspSet":
        """Best score first (stable, so equal scores keep their order)."""
        return self.take(np.argsort(-self.scores, kind="stable"))

    def to_array(self) -> np.ndarray:
        """graspnetAPI's ``(n, 17)`` float64 array."""
        n = len(self)
        return np.concatenate([self.scores[:, None], self.widths[:, None], self.heights[:, None],
                               self.depths[:, None], self.R.reshape(n, 9), self.t,
                               self.object_ids[:, None].astype(np.float64)], axis=1)

    @classmethod
    def from_array(cls, a: np.ndarray) -> "GraspSet":
        a = np.asarray(a, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 17:
            raise ValueError(f"expected an (n, 17) grasp array, got shape {a.shape}")
        return cls(a[:, 0].copy(), a[:, 1].copy(), a[:, 2].copy(), a[:, 3].copy(),
                   a[:, 4:13].reshape(-1, 3, 3).copy(), a[:, 13:16].copy(),
                   np.rint(a[:, 16]).astype(np.int64))

    def to_json(self) -> list[dict]:
        return [{"object": int(self.object_ids[i]), "score": float(self.scores[i]),
                 "position": self.t[i].tolist(), "rotation": self.R[i].tolist(),
                 "width": float(self.widths[i]), "height": float(self.heights[i]),
                 "depth": float(self.depths[i])} for i in range(len(self))]

    def hand_poses(self, base_to_tip: float) -> np.ndarray:
        """4x4 hand poses ``(n, 4, 4)`` in Contact-GraspNet's convention: z = approach,
        x = closing direction, origin at the hand's base, fingertips ``base_to_tip`` metres
        along z (0.1034 for the Franka hand)."""
        out = np.empty((len(self), 4, 4))
        for i in range(len(self)):
            a, c = self.R[i][:, 0], self.R[i][:, 1]
            R = np.stack([c, np.cross(a, c), a], axis=1)
            tip = self.t[i] + a * self.depths[i]
            out[i] = make_T(R, tip - a * base_to_tip)
        return out
