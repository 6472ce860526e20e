"""Meshes of segmented objects in sr3d's object frame (see :mod:`sr3d_cli.geometry.revolution`).

Backends: ``revolution`` (training-free surface of revolution fitted to the mask, the default),
``onnx`` (a single-image reconstruction model the user supplies) and ``library`` (a folder of
meshes). Every mesh is returned watertight, with outward normals, height 1 along +z and the
origin at the centre of its base.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from sr3d_cli.config import ReconstructConfig
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.revolution import open_vessel, revolve
from sr3d_cli.reconstruct.revolution_fit import RevolutionFit, fit_revolution


class ObjectError(ValueError):
    """One object cannot be reconstructed (the others go on)."""


@dataclass
class Reconstruction:
    mesh: trimesh.Trimesh
    meta: dict = field(default_factory=dict)


def normalise_mesh(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Bring a mesh into the object frame: height (z extent) 1, origin at the base centre."""
    mesh = mesh.copy()
    lo, hi = mesh.bounds
    height = hi[2] - lo[2]
    if not height > 0:
        raise ObjectError("mesh is flat along z: cannot normalise its height")
    mesh.apply_translation([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    mesh.apply_scale(1.0 / height)
    if mesh.is_watertight and mesh.volume < 0:
        mesh.invert()
    return mesh


def check_mask(mask: np.ndarray, cfg: ReconstructConfig) -> None:
    """Refuse masks a silhouette fit cannot use, with the reason."""
    area = int(mask.sum())
    if area == 0:
        raise ObjectError("empty mask")
    if area < cfg.min_pixels:
        raise ObjectError(f"mask has {area} px (< reconstruct.min_pixels {cfg.min_pixels})")
    edge = mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any()
    if edge and not cfg.allow_border:
        raise ObjectError("object touches the image border, so its silhouette is cut "
                          "(set reconstruct.allow_border: true to try anyway)")


def configured_fit(mask: np.ndarray, K: np.ndarray, plane: Plane, cfg: ReconstructConfig,
                   depth: np.ndarray | None = None) -> RevolutionFit:
    """:func:`fit_revolution` with the ``reconstruct`` config's settings (the one place they
    are passed on); ``depth`` is used when ``use_depth`` is on."""
    return fit_revolution(mask, K, plane, levels=cfg.levels, iterations=cfg.iterations,
                          lying_margin=cfg.lying_margin,
                          depth=depth if cfg.use_depth else None, depth_vote=cfg.depth_vote,
                          axial_view=cfg.axial_view)


class Reconstructor:
    """One per batch: loads models or the library once; :meth:`__call__` per object."""

    def __init__(self, cfg: ReconstructConfig):
        self.cfg = cfg
        self.model = None
        self.library = None
        if cfg.backend == "onnx":
            from sr3d_cli.reconstruct.onnx_models import load_image_to_shape

            self.model = load_image_to_shape(cfg)
        elif cfg.backend == "library":
            from sr3d_cli.reconstruct.library import MeshLibrary

            self.library = MeshLibrary(cfg.library)

    def __call__(self, rgb: np.ndarray, mask: np.ndarray, K: np.ndarray, plane: Plane | None,
                 label: str = "", depth: np.ndarray | None = None) -> Reconstruction:
        """Mesh of the object under ``mask (H, W) bool`` in ``rgb (H, W, 3) uint8``; the raw
        ``depth (H, W)`` metres, when given, helps decide between standing and lying and, seen
        from above, gives a standing object's height and profile."""
        cfg = self.cfg
        check_mask(mask, cfg)
        if cfg.backend == "onnx":
            mesh = normalise_mesh(self.model(rgb, mask))
            return Reconstruction(mesh, {"backend": "onnx"})
        if plane is None:
            raise ObjectError("no support plane: the revolution fit needs the table")
        fit = configured_fit(mask, K, plane, cfg, depth)
        meta = {"backend": cfg.backend, "resting": fit.resting, "silhouette_iou": round(fit.iou, 4),
                "pose_hint": {"T_cam_obj": fit.T_cam_obj.tolist(), "scale": fit.height}}
        if cfg.backend == "library":
            name, mesh = self.library.pick(label, fit.profile)
            meta["library_mesh"] = name
            return Reconstruction(mesh, meta)
        profile = fit.profile
        if cfg.open_top_ratio > 0 and fit.resting == "standing" and \
                profile[-2, 0] >= cfg.open_top_ratio * profile[1:-1, 0].max():
            # a wide mouth: drinking glass, beaker, goblet. Model it open, with a wall and a
            # floor, so the depth inside the vessel is rendered, not a lid at the rim
            profile = open_vessel(profile[:-1], cfg.open_wall / fit.height,
                                  cfg.open_base / fit.height)
            meta["open_top"] = True
        return Reconstruction(revolve(profile, cfg.sections), meta)
