"""Coarser stand-ins of meshes for silhouettes drawn many times.

A silhouette's cost grows with the triangles along its outline (each is filled on its own,
:func:`sr3d_cli.geometry.silhouette.fill_silhouette`); a pose search draws hundreds of them. A
body of revolution casts the silhouette of the solid its outer profile bounds (a ray into a
vessel's opening meets its inner wall or base), so the stand-in is that outer profile, simplified,
revolved with fewer sections: no inner wall, fewer triangles along the outline. A mesh with
vertices off its rings (a handle) has no stand-in: turned about the axis, they would be a disc.
"""

from __future__ import annotations

import cv2
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from sr3d_cli.geometry.revolution import revolve


RZ_QUANTUM = 1e-5  # (r, z) rounding (object units) that merges a ring's vertices, whose radii
# differ by float32 rounding of the mesh file
MIN_RING = 8  # vertices at one (r, z) off the axis of a mesh of revolution: a ring (revolve
# draws 48, the synthetic shapes 64); a handle, or any mesh not revolved, has fewer


def outer_profile(vertices: np.ndarray, faces: np.ndarray, max_points: int) -> np.ndarray | None:
    """The outer profile ``(n, 2)`` (r, z) of a mesh of revolution about its z axis, from the
    base (r = 0) to the top (r = 0): at every height of a vertex, the largest radius of the
    mesh's edges there (each edge taken as the segment between its ends' (r, z), radii and
    heights rounded to ``RZ_QUANTUM``). None when a vertex off the axis is not on a ring (fewer
    than ``MIN_RING`` vertices within ``RZ_QUANTUM`` of its (r, z): a handle's, or a mesh not
    revolved), the mesh has more than ``max_points`` distinct (r, z), or the profile meets
    the axis between its ends, or a height between them has no edge (it cannot be revolved).

    vertices : (V, 3) float, faces : (F, 3) int, object frame."""
    rz = np.column_stack([np.hypot(vertices[:, 0], vertices[:, 1]), vertices[:, 2]])
    off_axis = rz[rz[:, 0] > RZ_QUANTUM]
    if len(off_axis) and cKDTree(off_axis).query_ball_point(
            off_axis, RZ_QUANTUM, p=np.inf, return_length=True).min() < MIN_RING:
        return None
    cells = np.round(rz / RZ_QUANTUM).astype(np.int64)  # (V, 2) (r, z) in quanta
    low = cells[:, 1].min()
    rows = cells[:, 1].max() - low + 1
    keys, index = np.unique(cells[:, 0] * rows + cells[:, 1] - low, return_inverse=True)
    if len(keys) > max_points:
        return None
    r_cell, z_cell = np.divmod(keys, rows)
    points = np.column_stack([r_cell, z_cell + low]) * RZ_QUANTUM  # (P, 2) distinct (r, z)
    pairs = np.sort(index.ravel()[np.asarray(faces)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)],
                    axis=1)
    edge_keys = np.unique(pairs[:, 0] * len(keys) + pairs[:, 1])
    edges = np.column_stack(np.divmod(edge_keys, len(keys)))
    a, b = points[edges[:, 0]], points[edges[:, 1]]  # (E, 2) (r, z) ends
    z = np.unique(points[:, 1])  # (Z,) heights of the vertices
    dz = b[:, 1] - a[:, 1]
    flat = dz == 0
    share = np.clip((z[:, None] - a[:, 1]) / np.where(flat, 1.0, dz), 0, 1)  # (Z, E)
    r_at = np.where(flat, np.maximum(a[:, 0], b[:, 0]), a[:, 0] + share * (b[:, 0] - a[:, 0]))
    spans = (z[:, None] >= np.minimum(a[:, 1], b[:, 1])) & \
        (z[:, None] <= np.maximum(a[:, 1], b[:, 1]))
    r = np.where(spans, r_at, -np.inf).max(axis=1)
    if len(z) < 2 or not np.all(r[1:-1] > 0):
        return None
    return np.vstack([[0.0, z[0]], np.column_stack([r, z])[r > 0], [0.0, z[-1]]])


def revolution_stand_in(mesh: trimesh.Trimesh, tolerance: float, sections: int,
                        max_points: int) -> trimesh.Trimesh | None:
    """A mesh of revolution with the silhouettes of ``mesh`` (object frame, symmetric about its
    z axis): its :func:`outer_profile` simplified to within ``tolerance`` (object units;
    Douglas-Peucker), revolved with ``sections``. None when there is no outer profile."""
    profile = outer_profile(np.asarray(mesh.vertices, dtype=np.float64),
                            np.asarray(mesh.faces), max_points)
    if profile is None:
        return None
    kept = cv2.approxPolyDP(profile.astype(np.float32)[:, None], tolerance, False)[:, 0]
    kept = kept.astype(np.float64)
    kept[:, 0] *= np.pi / (sections * np.sin(np.pi / sections))  # a polygon as wide as its
    # circle on average over the turns about the axis (the mean width of a regular polygon is
    # its perimeter over pi)
    return revolve(kept, sections)


def clustered_stand_in(mesh: trimesh.Trimesh, cells: int) -> trimesh.Trimesh:
    """A coarser stand-in of any mesh for silhouettes: its vertices merged on a grid of cubes
    ``cells`` to its largest extent (each cluster at its vertices' mean), the triangles that
    keep three corners kept as they wind, repeats dropped. The outline moves by at most a cube
    (with 64, about a pixel of a 160 px window): a finely subdivided mug of 141 000 triangles
    keeps 17 000 and draws its silhouettes at IoU 0.989 or more with the whole mesh's."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    low = vertices.min(axis=0)
    size = max(float(np.ptp(vertices, axis=0).max()) / cells, 1e-12)
    keys = np.floor((vertices - low) / size).astype(np.int64)
    _, cluster = np.unique(keys, axis=0, return_inverse=True)
    cluster = cluster.ravel()
    count = np.bincount(cluster)
    merged = np.stack([np.bincount(cluster, weights=vertices[:, j]) for j in range(3)], 1)
    faces = cluster[np.asarray(mesh.faces)]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) &
                  (faces[:, 2] != faces[:, 0])]
    # a triangle and its turns are one (same winding): keep each once
    turn = np.argmin(faces, axis=1)
    rolled = np.stack([faces[np.arange(len(faces)), (turn + k) % 3] for k in range(3)], 1)
    faces = np.unique(rolled, axis=0)
    return trimesh.Trimesh(merged / count[:, None], faces, process=False)
