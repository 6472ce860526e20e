"""Exact ray-triangle intersection (Moller-Trumbore), vectorised over rays and triangles.

Used where a sampled approximation would blur the answer, e.g. where a closing gripper finger
first touches a mesh. No spatial index: callers pass the triangles near the rays.
"""

from __future__ import annotations

import numpy as np


def first_hits(origins: np.ndarray, directions: np.ndarray, triangles: np.ndarray,
               max_distance: float = np.inf, chunk: int = 4096
               ) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of every ray.

    origins, directions : (n, 3) rays (directions need not be unit; distances are in their units)
    triangles : (m, 3, 3) vertices
    Returns (distance (n,) with inf where nothing is hit within ``max_distance``,
    triangle index (n,) with -1 where nothing is hit). Both faces of a triangle count.
    """
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.float64)
    best = np.full(len(o), np.inf)
    index = np.full(len(o), -1, dtype=np.int64)
    for start in range(0, len(tri), chunk):
        t0 = tri[start:start + chunk, 0]
        e1 = tri[start:start + chunk, 1] - t0
        e2 = tri[start:start + chunk, 2] - t0
        p = np.cross(d[:, None, :], e2[None])                    # (n, m, 3)
        det = np.einsum("nmk,mk->nm", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o[:, None, :] - t0[None]
            u = np.einsum("nmk,nmk->nm", s, p) * inv
            q = np.cross(s, e1[None])
            v = np.einsum("nk,nmk->nm", d, q) * inv
            t = np.einsum("mk,nmk->nm", e2, q) * inv
            ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) \
                & (t <= max_distance)
        t = np.where(ok, t, np.inf)
        j = np.argmin(t, axis=1)
        tj = t[np.arange(len(o)), j]
        better = tj < best
        best[better] = tj[better]
        index[better] = start + j[better]
    return best, index
