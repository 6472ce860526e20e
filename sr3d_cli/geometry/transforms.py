"""Rigid transforms. ``T_a_b`` maps points from frame b into frame a: ``p_a = T_a_b @ p_b``."""

from __future__ import annotations

import numpy as np


def make_T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def apply_T(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to points ``(n, 3)``."""
    return np.asarray(points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]


def place_points(points_obj: np.ndarray, T_cam_obj: np.ndarray, scale: float) -> np.ndarray:
    """Object-frame (unit-free) points to the camera frame: ``R @ (scale * p) + t``."""
    return apply_T(T_cam_obj, scale * np.asarray(points_obj, dtype=np.float64))


def unit(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis of ``v (..., n)``, same dtype; a zero vector stays
    zero. One vector's norm is NumPy's vector norm (a dot product), a stack's a sum along the
    last axis: the two round differently in the last bit, and the pose and shape searches are
    set on the first."""
    v = np.asarray(v)
    norm = np.linalg.norm(v) if v.ndim == 1 else np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 0, norm, 1)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product ``(3,)`` of two 3-vectors ``(3,)``, rounded as ``np.cross`` rounds it
    (the same products and differences) at a tenth of its cost for a single pair."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross products ``(n, 3)`` of the rows of ``a``, ``b`` ``(n, 3)`` float64, rounded
    as ``np.cross`` rounds them (the same products and differences, into a C-ordered array)
    at a third of its cost on a few thousand rows."""
    out = np.empty((len(a), 3))
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        np.multiply(a[:, i], b[:, j], out=out[:, k])
        out[:, k] -= a[:, j] * b[:, i]
    return out


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` radians about ``axis`` (Rodrigues)."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def perpendiculars(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors at right angles to the unit ``axis`` and to each other, ``(e1, e2)``
    with ``e2 = axis x e1``: a frame for rings and sections about the axis."""
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 = e1 / np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``T_world_cam`` of an OpenCV camera at ``eye`` looking at ``target`` (image up ~ ``up``)."""
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)  # right = forward x up (with y pointing down)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_T(np.stack([x, y, z], axis=1), eye)


def is_rigid(T: np.ndarray, tol: float = 1e-6) -> bool:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return False
    R = T[:3, :3]
    return (np.allclose(R @ R.T, np.eye(3), atol=tol) and abs(np.linalg.det(R) - 1) < tol
            and np.allclose(T[3], [0, 0, 0, 1], atol=tol))


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation taking direction ``a`` to direction ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
        return rotation_about(perp, np.pi)
    return rotation_about(axis, np.arctan2(s, c))
