"""Rendering placed meshes: depth, instance ids and normals, with two interchangeable backends.

- ``PyrenderRenderer``: offscreen OpenGL through pyrender (EGL headless, or OSMesa).
- ``NumpyRenderer``: a z-buffer rasteriser in numpy, always available.

``make_renderer("auto")`` tries pyrender and falls back to numpy with one notice when no GL
context can be made. Meshes are given in the OpenCV camera frame (metres); the one conversion to
OpenGL's camera convention is :func:`opencv_to_opengl`. Both backends agree on depth and
silhouettes (tested): identical silhouettes, depth within a few micrometres.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass

import numpy as np

from sr3d_cli.geometry.camera import Camera, mask_window

log = logging.getLogger("sr3d")

ZNEAR = 0.02  # metres
ZFAR = 50.0


@dataclass
class RenderMesh:
    """A mesh to draw.

    vertices : (n, 3) float, camera frame (OpenCV), metres.
    faces : (m, 3) int, counter-clockwise seen from outside.
    id : int > 0 written into the id image.
    normals : (n, 3) float vertex normals in the camera frame (None: face normals).
    """

    vertices: np.ndarray
    faces: np.ndarray
    id: int
    normals: np.ndarray | None = None


@dataclass
class RenderOutput:
    """depth : (H, W) float32 metres, 0 = empty; ids : (H, W) int32, 0 = empty;
    normals : (H, W, 3) float32 unit normals in the camera frame, 0 where empty (None where
    the render was asked for depth and ids only)."""

    depth: np.ndarray
    ids: np.ndarray
    normals: np.ndarray | None

    def grey(self, light_cam: np.ndarray = (0.0, 0.0, -1.0)) -> np.ndarray:
        """Shaded grey image ``(H, W) uint8``: two-sided Lambert, light from ``light_cam``."""
        light = np.asarray(light_cam, dtype=np.float64)
        light = light / np.linalg.norm(light)
        shade = np.abs(self.normals @ light) * 0.8 + 0.2
        return np.where(self.ids > 0, shade * 255, 0).astype(np.uint8)


def opencv_to_opengl(T_cv: np.ndarray) -> np.ndarray:
    """Re-express a pose whose frame is an OpenCV camera (x right, y down, z forward) for an
    OpenGL camera (x right, y up, z backward): flips the y and z axes of that frame."""
    return np.asarray(T_cv, dtype=np.float64) @ np.diag([1.0, -1.0, -1.0, 1.0])


class Renderer:
    name = "base"

    def render(self, meshes: list[RenderMesh], camera: Camera,
               normals: bool = True) -> RenderOutput:
        """The meshes' depth and ids as ``camera`` sees them, and with ``normals`` their
        normals (shading, simulated sensors); a repaired depth needs depth and ids only."""
        raise NotImplementedError


# ------------------------------------------------------------------------------------------------
# numpy backend

def _clip_near(tri: np.ndarray, near: float) -> list[np.ndarray]:
    """Clip one triangle (3, D) (columns 0..2 = xyz) against z >= near: 0, 1 or 2 triangles."""
    out = []
    poly = []
    for i in range(3):
        a, b = tri[i], tri[(i + 1) % 3]
        a_in, b_in = a[2] >= near, b[2] >= near
        if a_in:
            poly.append(a)
        if a_in != b_in:
            s = (near - a[2]) / (b[2] - a[2])
            poly.append(a + s * (b - a))
    for k in range(1, len(poly) - 1):
        out.append(np.stack([poly[0], poly[k], poly[k + 1]]))
    return out


class NumpyRenderer(Renderer):
    """Z-buffer rasteriser: pixel centres inside a triangle, perspective-correct interpolation."""

    name = "numpy"
    CHUNK = 200_000  # candidate pixels processed at once

    def render(self, meshes, camera, normals=True):
        want = normals  # the name is taken by the normal image below
        h, w = camera.height, camera.width
        K = camera.K
        all_pix, all_z, all_n, all_id = [], [], [], []
        for mesh in meshes:
            V = np.asarray(mesh.vertices, dtype=np.float64)
            F = np.asarray(mesh.faces, dtype=np.int64)
            if len(F) == 0:
                continue
            N = (np.asarray(mesh.normals, dtype=np.float64) if mesh.normals is not None
                 else None)
            tri = V[F]  # (m, 3, 3)
            if N is None:
                fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
                fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-12)
                tri_n = np.repeat(fn[:, None, :], 3, axis=1)
            else:
                tri_n = N[F]
            data = np.concatenate([tri, tri_n], axis=2)  # (m, 3, 6)
            data = data[data[:, :, 2].max(axis=1) > ZNEAR]
            straddle = data[:, :, 2].min(axis=1) < ZNEAR
            clipped = [t for d in data[straddle] for t in _clip_near(d, ZNEAR)]
            data = data[~straddle]
            if clipped:
                data = np.concatenate([data, np.stack(clipped)])
            pix, z, n = self._rasterise(data, K, h, w)
            all_pix.append(pix)
            all_z.append(z)
            all_n.append(n)
            all_id.append(np.full(len(pix), mesh.id, dtype=np.int32))
        depth = np.zeros((h, w), np.float32)
        ids = np.zeros((h, w), np.int32)
        normals = np.zeros((h, w, 3), np.float32)
        if all_pix:
            pix = np.concatenate(all_pix)
            z = np.concatenate(all_z)
            order = np.lexsort((z, pix))  # by pixel, nearest first
            pix, first = np.unique(pix[order], return_index=True)
            pick = order[first]
            depth.flat[pix] = np.concatenate(all_z)[pick]
            ids.flat[pix] = np.concatenate(all_id)[pick]
            nn = np.concatenate(all_n)[pick]
            nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-12)
            normals.reshape(-1, 3)[pix] = nn
        return RenderOutput(depth, ids, normals if want else None)

    def _rasterise(self, data: np.ndarray, K: np.ndarray, h: int, w: int):
        """Candidate fragments of triangles ``data (m, 3, 6)`` (xyz, normal per corner)."""
        z = data[:, :, 2]
        u = data[:, :, 0] / z * K[0, 0] + K[0, 2]
        v = data[:, :, 1] / z * K[1, 1] + K[1, 2]
        x0 = np.clip(np.ceil(u.min(1)), 0, w).astype(np.int64)
        x1 = np.clip(np.floor(u.max(1)), -1, w - 1).astype(np.int64)
        y0 = np.clip(np.ceil(v.min(1)), 0, h).astype(np.int64)
        y1 = np.clip(np.floor(v.max(1)), -1, h - 1).astype(np.int64)
        bw, bh = x1 - x0 + 1, y1 - y0 + 1
        keep = (bw > 0) & (bh > 0)
        area = (u[:, 1] - u[:, 0]) * (v[:, 2] - v[:, 0]) - (u[:, 2] - u[:, 0]) * (v[:, 1] - v[:, 0])
        keep &= np.abs(area) > 1e-12
        idx = np.flatnonzero(keep)
        pix_out, z_out, n_out = [], [], []
        counts = (bw * bh)[idx]
        start = 0
        while start < len(idx):
            stop = start + 1
            total = counts[start]
            while stop < len(idx) and total + counts[stop] <= self.CHUNK:
                total += counts[stop]
                stop += 1
            sel = idx[start:stop]
            start = stop
            n_per = bw[sel] * bh[sel]
            tri_of = np.repeat(np.arange(len(sel)), n_per)
            offs = np.arange(n_per.sum()) - np.repeat(np.cumsum(n_per) - n_per, n_per)
            px = x0[sel][tri_of] + offs % bw[sel][tri_of]
            py = y0[sel][tri_of] + offs // bw[sel][tri_of]
            t = sel[tri_of]
            uu, vv, a = u[t], v[t], area[t]
            l0 = ((uu[:, 1] - px) * (vv[:, 2] - py) - (uu[:, 2] - px) * (vv[:, 1] - py)) / a
            l1 = ((uu[:, 2] - px) * (vv[:, 0] - py) - (uu[:, 0] - px) * (vv[:, 2] - py)) / a
            l2 = 1.0 - l0 - l1
            lam = np.stack([l0, l1, l2], axis=1)
            inside = np.all(lam >= -1e-9, axis=1)
            lam, t, px, py = lam[inside], t[inside], px[inside], py[inside]
            inv_z = (lam / z[t]).sum(axis=1)
            zz = 1.0 / inv_z
            persp = lam / z[t] * zz[:, None]
            nrm = np.einsum("ki,kij->kj", persp, data[t][:, :, 3:6])
            pix_out.append(py * w + px)
            z_out.append(zz)
            n_out.append(nrm)
        if not pix_out:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3))
        return np.concatenate(pix_out), np.concatenate(z_out), np.concatenate(n_out)


# ------------------------------------------------------------------------------------------------
# pyrender backend

def import_pyrender():
    """Import pyrender headless. The one place that sets the GL platform and patches NumPy 2:
    pyrender 0.1.45 still refers to ``np.infty``, which NumPy 2 removed."""
    if "PYOPENGL_PLATFORM" not in os.environ and not os.environ.get("DISPLAY"):
        os.environ["PYOPENGL_PLATFORM"] = "egl"
    if not hasattr(np, "infty"):
        np.infty = np.inf  # noqa: NPY201 - compatibility shim for pyrender
    import pyrender

    return pyrender


def _fill_partial_normals(normals: np.ndarray, ids: np.ndarray, full: float = 0.9,
                          passes: int = 3) -> np.ndarray:
    """Unit normals from a multisampled normal image ``(H, W, 3)``.

    At silhouettes a pixel's value blends the object with the background (a zero vector), so it
    is short and its direction unreliable (it varies between identical runs).
    Such pixels take the normal of their best-covered 8-neighbour with the same id; only the
    box of the drawn pixels, widened by one, is searched (no other pixel has such a neighbour).
    """
    length = np.linalg.norm(normals, axis=-1)
    full_out = normals / np.maximum(length, 1e-6)[..., None]
    box = mask_window(ids > 0, 1)
    if box is None:
        return full_out
    out, length, ids = full_out[box], length[box], ids[box]  # ``out`` is a view: filled in place
    h, w = ids.shape
    for _ in range(passes):
        short = (length < full) & (ids > 0)
        if not short.any():
            break
        best_len = np.where(short, -1.0, length)
        best = out.copy()
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy == 0 and dx == 0:
                    continue
                ys = slice(max(dy, 0), h + min(dy, 0))
                yd = slice(max(-dy, 0), h + min(-dy, 0))
                xs = slice(max(dx, 0), w + min(dx, 0))
                xd = slice(max(-dx, 0), w + min(-dx, 0))
                cand_len = np.full((h, w), -1.0)
                cand_len[yd, xd] = np.where(ids[ys, xs] == ids[yd, xd], length[ys, xs], -1.0)
                cand = np.zeros_like(out)
                cand[yd, xd] = out[ys, xs]
                take = short & (cand_len > best_len)
                best_len = np.where(take, cand_len, best_len)
                best[take] = cand[take]
        fixed = short & (best_len >= full)
        out[fixed] = best[fixed]
        length = np.where(fixed, 1.0, length)
    return full_out


class PyrenderRenderer(Renderer):
    """Offscreen OpenGL. One renderer per image size is kept; the GL context is made on init."""

    name = "pyrender"

    def __init__(self):
        self.pyrender = import_pyrender()
        self._renderers: dict[tuple[int, int], object] = {}
        self._get(64, 48)  # fail now, not mid-batch, if no context can be made

    def _get(self, w: int, h: int):
        if (w, h) not in self._renderers:
            self._renderers[(w, h)] = self.pyrender.OffscreenRenderer(w, h)
        return self._renderers[(w, h)]

    def render(self, meshes, camera, normals=True):
        import trimesh

        want = normals  # the name is taken by each mesh's normals below
        pr = self.pyrender
        h, w = camera.height, camera.width
        scene = pr.Scene(bg_color=[0.5, 0.5, 0.5, 1.0], ambient_light=[1.0, 1.0, 1.0])
        # GL samples pixel i at window coordinate i + 0.5; OpenCV's pixel centres are integers
        cam = pr.IntrinsicsCamera(camera.fx, camera.fy, camera.cx + 0.5, camera.cy + 0.5,
                                  znear=ZNEAR, zfar=ZFAR)
        scene.add(cam, pose=opencv_to_opengl(np.eye(4)))
        seg_map = {}
        for mesh in meshes:
            if len(mesh.faces) == 0:
                continue
            tm = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False)
            normals = mesh.normals if mesh.normals is not None else None
            if normals is None:
                tm = tm.copy()
                tm.unmerge_vertices()
                normals = np.repeat(tm.face_normals, 3, axis=0)
            colours = np.clip((np.asarray(normals) + 1.0) * 0.5 * 255.0 + 0.5, 0, 255)
            colours = np.concatenate([colours, np.full((len(colours), 1), 255)], axis=1)
            # pyrender's SEG pass culls back faces whatever the flags say: draw both sides
            faces = np.concatenate([tm.faces, tm.faces[:, ::-1]])
            tm = trimesh.Trimesh(tm.vertices, faces, vertex_colors=colours.astype(np.uint8),
                                 process=False)
            node = scene.add(pr.Mesh.from_trimesh(tm, smooth=True))
            seg_map[node] = [mesh.id % 256, mesh.id // 256, 0]
        r = self._get(w, h)
        flags = pr.RenderFlags
        # The colour pass is multisampled, so its depth is resolved from sub-pixel samples;
        # the SEG pass is not: depth and ids come from it. Normals come from the colour pass;
        # its background 0.5 decodes to a zero normal, so partly covered silhouette pixels come
        # out short, and _fill_partial_normals replaces them.
        # (without normals the colour pass is left out: a repaired depth needs depth and ids)
        colour = r.render(scene, flags=flags.FLAT | flags.SKIP_CULL_FACES)[0] if want else None
        seg, depth = r.render(scene, flags=flags.SEG | flags.SKIP_CULL_FACES,
                              seg_node_map=seg_map)
        ids = seg[..., 0].astype(np.int32) + 256 * seg[..., 1].astype(np.int32)
        depth = np.asarray(depth, dtype=np.float32)
        empty = depth <= 0
        shade = None
        if colour is not None:
            shade = colour[..., :3].astype(np.float32) / 255.0 * 2.0 - 1.0
            shade = _fill_partial_normals(shade, ids)
            shade[empty] = 0
        ids[empty] = 0
        return RenderOutput(depth, ids, shade)


_CACHE: dict[str, Renderer] = {}


def auto_renderer() -> Renderer:
    """pyrender, else the numpy fallback with one notice (no GL context)."""
    try:
        return PyrenderRenderer()
    except Exception as exc:  # no GL context, no EGL/OSMesa library, broken driver...
        log.warning("notice: no OpenGL context (%s: %s); rendering with the numpy fallback",
                    type(exc).__name__, str(exc).splitlines()[0] if str(exc) else "")
        return NumpyRenderer()


def make_renderer(backend: str = "auto") -> Renderer:
    """The renderer registered as ``backend`` (:data:`sr3d_cli.backends.RENDER`: ``pyrender``,
    ``numpy`` or ``auto``), one per process."""
    from sr3d_cli.backends import RENDER

    if backend not in _CACHE:
        _CACHE[backend] = RENDER.create(backend)
    return _CACHE[backend]
