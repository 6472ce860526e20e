"""Single-image reconstruction models through onnxruntime.

Two model shapes are accepted:

- **density grid**: one model, image ``(1, 3, S, S)`` -> density ``(1, R, R, R)`` over the cube
  ``[-radius, radius]^3`` (axes x, y, z; z up);
- **TripoSR-style** (two files): encoder image ``(1, 3, 512, 512)`` -> triplane
  ``(1, 3, C, P, P)`` (planes xy, xz, yz); decoder features ``(N, 3C)`` -> density ``(N, 1)``.
  Triplane features are sampled bilinearly in numpy (pixel centres as ``grid_sample`` with
  ``align_corners=False``), planes concatenated in that order.

Input preprocessing follows TripoSR: the object (cut out by its mask) is composited on 50% grey
and resized so that it fills ``foreground_ratio`` of a square image; values in [0, 1]. The
surface is the ``onnx_threshold`` iso-level, extracted by marching cubes (scikit-image).
"""

from __future__ import annotations

import cv2
import numpy as np
import trimesh

from sr3d_cli.config import ReconstructConfig
from sr3d_cli.onnx_model import OnnxModel


def model_image(rgb: np.ndarray, mask: np.ndarray, size: int, foreground_ratio: float
                ) -> np.ndarray:
    """The object on grey, centred, filling ``foreground_ratio``: ``(1, 3, size, size)`` float32."""
    ys, xs = np.nonzero(mask)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    alpha = mask[y0:y1, x0:x1, None].astype(np.float32)
    crop = rgb[y0:y1, x0:x1].astype(np.float32) / 255.0
    crop = crop * alpha + 0.5 * (1 - alpha)
    side = int(np.ceil(max(y1 - y0, x1 - x0) / foreground_ratio))
    canvas = np.full((side, side, 3), 0.5, np.float32)
    oy, ox = (side - (y1 - y0)) // 2, (side - (x1 - x0)) // 2
    canvas[oy:oy + y1 - y0, ox:ox + x1 - x0] = crop
    image = cv2.resize(canvas, (size, size), interpolation=cv2.INTER_AREA)
    return image.transpose(2, 0, 1)[None].astype(np.float32)


def surface_from_density(density: np.ndarray, level: float, radius: float) -> trimesh.Trimesh:
    """Marching cubes of ``density (R, R, R)`` (axes x, y, z over ``[-radius, radius]``)."""
    from skimage import measure

    lo, hi = float(np.nanmin(density)), float(np.nanmax(density))
    if not (lo < level < hi):
        raise ValueError(f"density ranges over [{lo:.3g}, {hi:.3g}] and never crosses the "
                         f"threshold {level:g} (reconstruct.onnx_threshold): no surface")
    res = density.shape[0]
    padded = np.pad(density, 1, constant_values=min(lo, level - 1.0))  # closes the surface
    verts, faces, _, _ = measure.marching_cubes(padded, level=level)
    verts = (verts - 1) / (res - 1) * 2 * radius - radius
    mesh = trimesh.Trimesh(verts, faces[:, ::-1], process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def sample_triplane(planes: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """Features ``(N, 3C)`` of ``points (N, 3)`` from ``planes (3, C, P, P)`` (xy, xz, yz)."""
    coords = np.clip(points / radius, -1, 1)
    pairs = ((0, 1), (0, 2), (1, 2))
    _, C, P, _ = planes.shape
    out = []
    for plane, (a, b) in zip(planes, pairs):
        x = ((coords[:, a] + 1) * P - 1) / 2  # width index
        y = ((coords[:, b] + 1) * P - 1) / 2  # height index
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]

        def tap(yy, xx):
            inside = (xx >= 0) & (xx < P) & (yy >= 0) & (yy < P)
            vals = plane[:, np.clip(yy, 0, P - 1), np.clip(xx, 0, P - 1)].T
            return vals * inside[:, None]

        out.append(tap(y0, x0) * (1 - fx) * (1 - fy) + tap(y0, x0 + 1) * fx * (1 - fy)
                   + tap(y0 + 1, x0) * (1 - fx) * fy + tap(y0 + 1, x0 + 1) * fx * fy)
    return np.concatenate(out, axis=1).astype(np.float32)


class DensityGridModel:
    def __init__(self, cfg: ReconstructConfig):
        self.cfg = cfg
        self.model = OnnxModel(cfg.onnx_model, "reconstruction",
                               {"*": (1, 3, None, None)}, {"*": (1, None, None, None)})
        shape = self.model.runtime.get_inputs()[0].shape
        self.size = shape[2] if isinstance(shape[2], int) else 256

    def __call__(self, rgb, mask) -> trimesh.Trimesh:
        image = model_image(rgb, mask, self.size, self.cfg.foreground_ratio)
        density = np.asarray(self.model.run({"*": image})["*"])[0]
        if density.ndim != 3 or len(set(density.shape)) != 1:
            raise ValueError(f"density grid has shape {density.shape}; expected (R, R, R)")
        return surface_from_density(density, self.cfg.onnx_threshold, self.cfg.onnx_radius)


class TriplaneModel:
    def __init__(self, cfg: ReconstructConfig):
        self.cfg = cfg
        self.encoder = OnnxModel(cfg.onnx_model, "TripoSR encoder",
                                 {"*": (1, 3, 512, 512)}, {"*": (1, 3, None, None, None)})
        self.decoder = OnnxModel(cfg.onnx_decoder, "TripoSR decoder",
                                 {"*": (None, None)}, {"*": (None, 1)})

    def __call__(self, rgb, mask) -> trimesh.Trimesh:
        image = model_image(rgb, mask, 512, self.cfg.foreground_ratio)
        planes = np.asarray(self.encoder.run({"*": image})["*"])[0]
        res, radius = self.cfg.onnx_resolution, self.cfg.onnx_radius
        axis = np.linspace(-radius, radius, res)
        grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
        density = np.empty(len(grid), np.float32)
        for start in range(0, len(grid), 65536):
            feats = sample_triplane(planes, grid[start:start + 65536], radius)
            density[start:start + 65536] = np.asarray(
                self.decoder.run({"*": feats})["*"]).reshape(-1)
        return surface_from_density(density.reshape(res, res, res), self.cfg.onnx_threshold,
                                    radius)


def load_image_to_shape(cfg: ReconstructConfig):
    """The density-grid model, or the TripoSR pair when ``onnx_decoder`` is set."""
    return TriplaneModel(cfg) if cfg.onnx_decoder else DensityGridModel(cfg)
