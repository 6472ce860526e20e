"""Rotation by view matching: render candidate orientations, compare with the observed object.

Score of a candidate (the paper's three terms, weights in ``align``):
``alpha * patch SSIM + beta * Laplacian edge correlation + gamma * aspect-ratio similarity``,
computed between the observed mask and the candidate's silhouette, both cropped to their bounding
box and scaled into the same square. Glass shows the background's texture, so silhouettes are
compared, not colours.

Candidate orientations:

- plain (the paper): viewpoints spread evenly on a sphere (icosphere vertices, 162 by default)
  times in-plane rolls;
- plane prior (default): the object rests on the fitted table, so only resting orientations
  (faces of the mesh's convex hull turned onto the table) times yaw about the table normal are
  tried; an axially symmetric mesh needs one yaw when standing upright.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from sr3d_cli.geometry.silhouette import fill_silhouette, project_mesh
from sr3d_cli.geometry.transforms import rotation_about, rotation_between


@dataclass
class ViewScore:
    total: float
    ssim: float
    edges: float
    aspect: float


def crop_square(mask: np.ndarray, size: int) -> np.ndarray:
    """The mask's bounding box, centred in a ``size`` x ``size`` float32 image (aspect kept)."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return np.zeros((size, size), np.float32)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    crop = mask[y0:y1, x0:x1].astype(np.float32)
    side = max(y1 - y0, x1 - x0)
    canvas = np.zeros((side, side), np.float32)
    oy, ox = (side - (y1 - y0)) // 2, (side - (x1 - x0)) // 2
    canvas[oy:oy + y1 - y0, ox:ox + x1 - x0] = crop
    return cv2.resize(canvas, (size, size), interpolation=cv2.INTER_AREA)


def aspect(mask: np.ndarray) -> float:
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return 1.0
    return float((np.ptp(xs) + 1) / (np.ptp(ys) + 1))


def is_axisymmetric(mesh: trimesh.Trimesh, tol: float = 0.01) -> bool:
    """Whether the mesh maps onto itself when turned about its z axis (object-frame units)."""
    dense, _ = trimesh.sample.sample_surface(mesh, 30000, seed=0)
    pts = dense[:600]
    tree = cKDTree(np.vstack([mesh.vertices, dense]))
    for angle in (0.5, 1.9):
        turned = pts @ rotation_about(np.array([0, 0, 1.0]), angle).T
        if np.percentile(tree.query(turned)[0], 95) > tol * 2 or \
                np.median(tree.query(turned)[0]) > tol:
            return False
    return True


def resting_directions(mesh: trimesh.Trimesh, symmetric: bool, max_count: int = 6
                       ) -> list[np.ndarray]:
    """Object-frame directions that can face the table, most stable (largest hull area) first.

    Hull faces with normals within 8 degrees are merged; for an axially symmetric mesh the
    directions that differ only by a turn about the axis are one."""
    hull = mesh.convex_hull
    normals, areas = hull.face_normals, hull.area_faces
    if symmetric:  # only the tilt from the axis matters: turn every normal into the xz plane
        normals = np.column_stack([np.hypot(normals[:, 0], normals[:, 1]),
                                   np.zeros(len(normals)), normals[:, 2]])
    clusters: list[list] = []
    for i in np.argsort(-areas):
        for c in clusters:
            if c[0] @ normals[i] > np.cos(np.radians(8)):
                c[1] += areas[i]
                break
        else:
            clusters.append([normals[i] / np.linalg.norm(normals[i]), areas[i]])
    clusters.sort(key=lambda c: -c[1])
    return [c[0] for c in clusters[:max_count]]


def icosphere_directions(count: int) -> np.ndarray:
    """At least ``count`` unit vectors spread evenly (icosphere vertices: 12, 42, 162, 642)."""
    sub = 0
    while 10 * 4 ** sub + 2 < count:
        sub += 1
    return np.asarray(trimesh.creation.icosphere(subdivisions=sub).vertices)


def candidates_plane(mesh: trimesh.Trimesh, up_cam: np.ndarray, symmetric: bool,
                     yaw_steps: int, max_rests: int) -> list[tuple[int, np.ndarray]]:
    """(resting-direction index, rotation R object -> camera) putting a resting direction of
    the mesh onto the table, turned about the table normal."""
    out = []
    for g, d in enumerate(resting_directions(mesh, symmetric, max_rests)):
        R_rest = rotation_between(d, -up_cam)  # this object direction points down
        upright = symmetric and abs(d[2]) > 0.999  # standing on its base (or top)
        steps = 1 if upright else yaw_steps
        for k in range(steps):
            out.append((g, rotation_about(up_cam, 2 * np.pi * k / steps) @ R_rest))
    return out


def candidates_sphere(view_count: int, roll_steps: int, towards_camera: np.ndarray
                      ) -> list[tuple[int, np.ndarray]]:
    """Rotations seeing the object from every icosphere viewpoint, times in-plane rolls."""
    out = []
    for v in icosphere_directions(view_count):
        R_view = rotation_between(v, towards_camera)  # object's v looks at the camera
        for k in range(roll_steps):
            out.append((len(out), rotation_about(towards_camera, 2 * np.pi * k / roll_steps)
                        @ R_view))
    return out


def _ssim_patches(a: np.ndarray, b: np.ndarray, grid: int) -> float:
    """Mean SSIM over a ``grid`` x ``grid`` tiling of two images ``(n, n)`` in [0, 1] (square
    patches of side ``n // grid``; rows and columns past ``grid`` patches are left out)."""
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    h = a.shape[0] // grid

    def tiles(img):  # (grid, grid, h * h): one row of pixels per patch
        img = np.asarray(img)[:grid * h, :grid * h]
        return img.reshape(grid, h, grid, h).transpose(0, 2, 1, 3).reshape(grid, grid, h * h)

    pa, pb = tiles(a), tiles(b)
    ma, mb = pa.mean(-1), pb.mean(-1)
    va, vb = pa.var(-1), pb.var(-1)
    cov = ((pa - ma[..., None]) * (pb - mb[..., None])).mean(-1)
    vals = ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
    return float(vals.mean())


def _edge_correlation(a: np.ndarray, b: np.ndarray) -> float:
    la = np.abs(cv2.Laplacian(cv2.GaussianBlur(a, (5, 5), 1.0), cv2.CV_32F))
    lb = np.abs(cv2.Laplacian(cv2.GaussianBlur(b, (5, 5), 1.0), cv2.CV_32F))
    la, lb = la - la.mean(), lb - lb.mean()
    denom = np.sqrt((la * la).sum() * (lb * lb).sum())
    return float((la * lb).sum() / denom) if denom > 0 else 0.0


class ViewMatcher:
    """Scores rendered silhouettes against one observed mask."""

    def __init__(self, mask: np.ndarray, *, alpha: float, beta: float, gamma: float,
                 patches: int, size: int = 64):
        self.size = size - size % patches
        self.weights = (alpha, beta, gamma)
        self.patches = patches
        self.obs = crop_square(mask, self.size)
        self.obs_aspect = aspect(mask)

    def score(self, sil: np.ndarray) -> ViewScore:
        ren = crop_square(sil, self.size)
        ssim = _ssim_patches(self.obs, ren, self.patches)
        edges = _edge_correlation(self.obs, ren)
        a = aspect(sil)
        asp = min(a, self.obs_aspect) / max(a, self.obs_aspect)
        alpha, beta, gamma = self.weights
        return ViewScore(alpha * ssim + beta * edges + gamma * asp, ssim, edges, asp)

    def render_and_score(self, vertices, faces, R, t, scale, K, window,
                         twins=None) -> tuple[ViewScore, np.ndarray]:
        """Score of the silhouette of ``vertices (V, 3)`` (object frame), ``faces (F, 3)``
        placed by ``R, t, scale`` and drawn in ``window`` (origin, shape, zoom), and that
        silhouette ``(h, w) bool``; ``twins``: :func:`face_twins` of ``faces``, if known."""
        uv, _ = project_mesh(vertices, R, t, scale, K)
        (x0, y0), shape, zoom = window
        sil = fill_silhouette(uv, faces, shape, (x0, y0), zoom, twins)
        return self.score(sil), sil
