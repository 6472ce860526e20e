"""Closed meshes lofted through stacked cross-sections, with swept handles joined into them.

A loft generalises :func:`sr3d_cli.geometry.revolution.revolve`: where a surface of revolution
has a circle at every height, a loft has any closed loop (a rounded square, an ellipse, a circle
pulled out into a spout). The loops are stacked in order along the surface, so a profile that
runs up an outer wall, over a rim and down an inner wall gives an open vessel with real wall
thickness, as :func:`sr3d_cli.geometry.revolution.open_vessel` does for profiles.

A handle is a tube swept along a centre line from one patch of the wall to another. The wall
faces inside each patch are removed and the tube's end rings are the patches' boundary
vertices, so the result is one watertight, consistently wound surface (a true union, without a
boolean engine) as long as the tube stays clear of the wall between its ends.

Vertex layout of a loft (used to name handle patches): point ``j`` of loop ``i`` is vertex
``i * n + j`` of the loop grid, loop points run counter-clockwise seen from +z.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

BLEND = 0.2  # share of the handle's length over which its section turns from the patch shape


def superellipse(n: int, a: float, b: float, p: float) -> np.ndarray:
    """``n`` points ``(n, 2)`` on ``|x / a|^p + |y / b|^p = 1``, counter-clockwise from +x.

    p = 2 is an ellipse (a circle with a == b); larger p squares it off (p ~ 5 is a rounded
    box). a, b: half-extents along x and y (any unit).
    """
    if n < 3 or a <= 0 or b <= 0 or p <= 0:
        raise ValueError("superellipse needs n >= 3 and positive a, b, p")
    theta = 2 * np.pi * np.arange(n) / n
    c, s = np.cos(theta), np.sin(theta)
    return np.column_stack([a * np.sign(c) * np.abs(c) ** (2 / p),
                            b * np.sign(s) * np.abs(s) ** (2 / p)])


@dataclass
class Handle:
    """A tube swept between two patches of a loft's wall.

    ends : the loop grid vertices ``((i_a, j_a), (i_b, j_b))`` at the centres of the two wall
    patches it joins; half_cells : ``(du, dv)`` half-size of each patch in grid cells along the
    loops and across them (the tube's section has ``4 (du + dv)`` vertices); path : ``(k, 3)``
    centre line from the centre vertex of patch a to that of patch b (same units as the loft),
    k >= 4; half_size : ``(hu, hv)`` half-extents of the tube's elliptic section away from the
    wall, ``hu`` along the direction of increasing loop point at patch a.
    """

    ends: tuple[tuple[int, int], tuple[int, int]]
    half_cells: tuple[int, int]
    path: np.ndarray
    half_size: tuple[float, float]


def loft(loops: np.ndarray, bottom: np.ndarray, top: np.ndarray,
         handles: tuple[Handle, ...] | list[Handle] = ()) -> trimesh.Trimesh:
    """A closed mesh through ``loops`` ``(m, n, 3)``: ``m >= 2`` closed loops of ``n`` points,
    consistently ordered, joined in sequence; the first loop is closed by a fan to ``bottom``
    ``(3,)`` and the last by a fan to ``top`` ``(3,)``. ``handles`` are joined into the wall
    (:class:`Handle`). Returns a mesh with outward normals (watertight when the loops do not
    cross each other).
    """
    loops = np.asarray(loops, dtype=np.float64)
    if loops.ndim != 3 or loops.shape[0] < 2 or loops.shape[1] < 3 or loops.shape[2] != 3:
        raise ValueError("loops must be (m >= 2, n >= 3, 3)")
    m, n, _ = loops.shape
    grid = np.arange(m * n).reshape(m, n)
    bottom_i, top_i = m * n, m * n + 1
    vertices = [loops.reshape(-1, 3), np.asarray(bottom, float)[None], np.asarray(top, float)[None]]
    j = np.arange(n)
    jn = (j + 1) % n
    cells = np.stack([  # (m - 1, n, 2, 3): two triangles per cell between loops i and i + 1
        np.stack([grid[:-1][:, j], grid[:-1][:, jn], grid[1:][:, jn]], -1),
        np.stack([grid[:-1][:, j], grid[1:][:, jn], grid[1:][:, j]], -1)], axis=2)
    caps = np.vstack([np.stack([np.full(n, bottom_i), grid[0, jn], grid[0, j]], 1),
                      np.stack([np.full(n, top_i), grid[-1, j], grid[-1, jn]], 1)])
    keep = np.ones((m - 1, n), bool)
    for handle in handles:
        for i, jc in handle.ends:
            du, dv = handle.half_cells
            if not dv <= i <= m - 1 - dv:
                raise ValueError(f"handle patch at loop {i} runs off the loft's {m} loops")
            rows = np.arange(i - dv, i + dv)
            cols = np.arange(jc - du, jc + du) % n
            if not keep[np.ix_(rows, cols)].all():
                raise ValueError("handle patches overlap")
            keep[np.ix_(rows, cols)] = False
    wall = np.vstack([cells[keep].reshape(-1, 3), caps])
    whole = trimesh.Trimesh(np.vstack(vertices), np.vstack([cells.reshape(-1, 3), caps]),
                            process=False)
    if whole.volume < 0:  # wind the wall outwards before it is cut open
        wall = wall[:, ::-1]
    faces = [wall]
    count = m * n + 2
    for handle in handles:
        tube_vertices, tube_faces = _tube(loops, grid, handle, count)
        vertices.append(tube_vertices)
        faces.append(tube_faces)
        count += len(tube_vertices)
    mesh = trimesh.Trimesh(np.vstack(vertices), np.vstack(faces), process=False)
    mesh.remove_unreferenced_vertices()
    return mesh


def _patch_ring(grid: np.ndarray, i: int, j: int, du: int, dv: int) -> np.ndarray:
    """Vertex ids ``(4 (du + dv),)`` around the patch centred on grid vertex (i, j), in order:
    along loop i - dv, up the side j + du, back along loop i + dv, down the side j - du."""
    n = grid.shape[1]
    steps = ([(i - dv, j + d) for d in range(-du, du)] + [(i + d, j + du) for d in range(-dv, dv)]
             + [(i + dv, j - d) for d in range(-du, du)]
             + [(i - d, j - du) for d in range(-dv, dv)])
    return np.array([grid[a, b % n] for a, b in steps])


def _area(points: np.ndarray) -> float:
    """Signed area of a closed 2D polygon ``(k, 2)`` (positive: counter-clockwise)."""
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(x @ np.roll(y, -1) - y @ np.roll(x, -1))


def _fade(x: float) -> float:
    """1 at x = 0 falling smoothly (smoothstep) to 0 at x >= 1."""
    x = min(max(x, 0.0), 1.0)
    return 1.0 - x * x * (3 - 2 * x)


def _tube(loops: np.ndarray, grid: np.ndarray, handle: Handle, first_id: int
          ) -> tuple[np.ndarray, np.ndarray]:
    """The vertices ``(v, 3)`` (ids from ``first_id``) and faces ``(f, 3)`` of a handle's tube,
    its end rings being the boundary vertices of its two wall patches."""
    flat = loops.reshape(-1, 3)
    path = np.asarray(handle.path, dtype=np.float64)
    if path.ndim != 2 or path.shape[1] != 3 or len(path) < 4:
        raise ValueError("a handle path must be (k >= 4, 3)")
    du, dv = handle.half_cells
    (ia, ja), (ib, jb) = handle.ends
    ring_a = _patch_ring(grid, ia, ja, du, dv)
    ring_b = _patch_ring(grid, ib, jb, du, dv)
    tangent = np.gradient(path, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    n = grid.shape[1]
    along = flat[grid[ia, (ja + 1) % n]] - flat[grid[ia, (ja - 1) % n]]
    start = along - (along @ tangent[0]) * tangent[0]
    u = [start / np.linalg.norm(start)]
    for t in tangent[1:]:  # parallel transport: the section turns with the path, no twist
        v = u[-1] - (u[-1] @ t) * t
        u.append(v / np.linalg.norm(v))
    u = np.asarray(u)
    w = np.cross(tangent, u)

    def offsets(ring: np.ndarray, k: int) -> np.ndarray:
        d = flat[ring] - path[k]
        return np.column_stack([d @ u[k], d @ w[k]])

    off_a, off_b = offsets(ring_a, 0), offsets(ring_b, -1)
    if np.sign(_area(off_a)) != np.sign(_area(off_b)):
        ring_b, off_b = ring_b[::-1], off_b[::-1]
    ang_a = np.arctan2(off_a[:, 1], off_a[:, 0])
    ang_b = np.arctan2(off_b[:, 1], off_b[:, 0])
    shift = int(np.argmin([np.abs(np.angle(np.exp(1j * (ang_a - np.roll(ang_b, -s))))).sum()
                           for s in range(len(ring_b))]))
    ring_b, off_b = np.roll(ring_b, -shift), np.roll(off_b, -shift, axis=0)
    ellipse = np.column_stack([handle.half_size[0] * np.cos(ang_a),
                               handle.half_size[1] * np.sin(ang_a)])
    length = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    t = length / length[-1]
    rings, vertices = [ring_a], []
    for k in range(1, len(path) - 1):
        wa, wb = _fade(t[k] / BLEND), _fade((1 - t[k]) / BLEND)
        off = wa * off_a + wb * off_b + (1 - wa - wb) * ellipse
        rings.append(first_id + len(vertices) * len(ring_a) + np.arange(len(ring_a)))
        vertices.append(path[k] + off[:, :1] * u[k] + off[:, 1:] * w[k])
    rings.append(ring_b)
    faces = []
    for r0, r1 in zip(rings[:-1], rings[1:]):
        r0n, r1n = np.roll(r0, -1), np.roll(r1, -1)
        faces += [np.stack([r0, r0n, r1n], 1), np.stack([r0, r1n, r1], 1)]
    faces = np.vstack(faces)
    vertices = np.vstack(vertices)
    # outward: the normal of a face in the middle of the tube points away from the centre line
    mid = len(path) // 2
    k0 = (mid - 1) * 2 * len(ring_a)
    tri = vertices[faces[k0] - first_id]
    normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    if normal @ (tri.mean(0) - path[mid]) < 0:
        faces = faces[:, ::-1]
    return vertices, faces
