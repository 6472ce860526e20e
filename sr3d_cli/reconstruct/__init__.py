"""Meshes of segmented objects in sr3d's object frame (see :mod:`sr3d_cli.geometry.revolution`).

Backends: ``revolution`` (training-free surface of revolution fitted to the mask, the default),
``onnx`` (a single-image reconstruction model the user supplies) and ``library`` (a folder of
meshes). Every mesh is returned watertight, with outward normals, height 1 along +z and the
origin at the centre of its base.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import trimesh

from sr3d_cli.config import ReconstructConfig
from sr3d_cli.geometry.camera import project
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.revolution import open_vessel, revolve
from sr3d_cli.geometry.silhouette import mask_iou
from sr3d_cli.geometry.transforms import apply_T, place_points
from sr3d_cli.reconstruct.bowls import bowl_instead
from sr3d_cli.reconstruct.handles import handle_slab, split_handle
from sr3d_cli.reconstruct.lids import lid_read
from sr3d_cli.shape.revolution_fit import (DEPTH_BAND, DEPTH_MIN_POINTS, FitOptions,
                                           RevolutionFit, carved, fit_revolution, fit_silhouette,
                                           flat_ended, off_table_readings, raw_support, smoothed,
                                           straight_walls)

BASE_SHARE = 0.15  # of the height: the profile's lowest part, whose widest ring is the base
RIM_LOSS = 0.01  # outline IoU an open vessel's rim, widened to its widest level, may lose
MIN_AXIS_PX = 10  # pixels the projected axis must span for its upper half to be told apart


class ObjectError(ValueError):
    """One object cannot be reconstructed (the others go on)."""


@dataclass
class Reconstruction:
    """``mesh`` in the object frame; ``meta`` for meshes/<k>.json; ``open_alternative``: the
    same solid open at an end the readings did not show open (:func:`unseen_mouth`), in
    ``mesh``'s object frame, or None."""

    mesh: trimesh.Trimesh
    meta: dict = field(default_factory=dict)
    open_alternative: trimesh.Trimesh | None = None


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
    """Refuse masks no backend can use (empty, too small), with the reason."""
    area = int(mask.sum())
    if area == 0:
        raise ObjectError("empty mask")
    if area < cfg.min_pixels:
        raise ObjectError(f"mask has {area} px (< reconstruct.min_pixels {cfg.min_pixels})")


def border_pixels(mask: np.ndarray) -> np.ndarray:
    """(n, 2) pixels (x, y) of the mask on the image border."""
    edge = np.zeros_like(mask, dtype=bool)
    edge[[0, -1], :] = True
    edge[:, [0, -1]] = True
    ys, xs = np.nonzero(mask & edge)
    return np.column_stack([xs, ys]).astype(np.float64)


def cut_above_base(fit: RevolutionFit, edge: np.ndarray, shape: tuple[int, int],
                   K: np.ndarray) -> bool:
    """Whether the image (``shape``) border cuts only the upper half of a standing fit (all of
    the mask's border pixels ``edge``, from :func:`border_pixels`) and its base ring is in
    view: then the outline still gives the base, the width and the pose (the model runs on
    to the border, as the mask does), and only the unseen top is made up."""
    if fit.resting != "standing":
        return False
    h, w = shape
    z, r = fit.profile[:, 1], fit.profile[:, 0] * fit.height
    R = fit.T_cam_obj[:3, :3]
    turn = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = fit.base + r[z <= BASE_SHARE].max() * (np.cos(turn)[:, None] * R[:, 0]
                                                  + np.sin(turn)[:, None] * R[:, 1])
    if (ring[:, 2] <= 0).any():
        return False
    uv = project(ring, K)
    if not ((uv >= 1).all() and (uv[:, 0] <= w - 2).all() and (uv[:, 1] <= h - 2).all()):
        return False
    b, t = project(np.stack([fit.base, fit.top]), K)
    span = float((t - b) @ (t - b))
    if span < MIN_AXIS_PX ** 2:  # seen down its axis: no 'upper half' in the image
        return False
    return bool((((edge - b) @ (t - b)) / span >= 0.5).all())


def check_border(mask: np.ndarray, cfg: ReconstructConfig, K: np.ndarray,
                 fit: RevolutionFit | None = None) -> str | None:
    """Where the image border cuts the object: None where it does not, 'top' for a standing
    object cut above its base (see :func:`cut_above_base`; needs the ``fit``), else
    'base or side' with ``allow_border`` on (the default: its outline's foot or side is out of
    view, and the fit's size and place are a guess, better than the sensor's holes) and
    refused with it off."""
    edge = border_pixels(mask)
    if not len(edge):
        return None
    if fit is not None and cut_above_base(fit, edge, mask.shape, K):
        return "top"
    if cfg.allow_border:
        return "base or side"
    where = "" if fit is None else " lower than the upper half of a standing object"
    raise ObjectError(f"object touches the image border{where}, so its silhouette is cut "
                      "(set reconstruct.allow_border: true to try anyway)")


def configured_fit(mask: np.ndarray, K: np.ndarray, plane: Plane, cfg: ReconstructConfig,
                   depth: np.ndarray | None = None, occluders: np.ndarray | None = None
                   ) -> RevolutionFit:
    """:func:`fit_revolution` with the ``reconstruct`` config's settings (the one place they
    are passed on), a lying fit then started again from flat ends (:func:`flat_ended`);
    ``depth`` is used when ``use_depth`` is on; ``occluders``: the pixels of objects in front
    that may hide this one."""
    options = FitOptions(levels=cfg.levels, iterations=cfg.iterations,
                         lying_margin=cfg.lying_margin, depth_vote=cfg.depth_vote,
                         axial_view=cfg.axial_view)
    depth = depth if cfg.use_depth else None
    fit = fit_revolution(mask, K, plane, depth=depth, openings=lambda fit: mouths(fit, cfg),
                         occluders=occluders, options=options)
    return flat_ended(fit, mask, K, plane, depth, occluders, options)


def mouths(fit: RevolutionFit, cfg: ReconstructConfig) -> list[RevolutionFit]:
    """The fit opened at each end that can be a mouth (at least ``open_top_ratio`` of the
    widest radius): a wall and a floor inside instead of a lid, the mouth at the top of the
    object frame. Standing, only the top can be; lying, either end (the base end first: a lying
    fit's base is its wider end)."""
    if cfg.open_top_ratio <= 0:
        return []
    r = fit.profile[1:-1, 0]
    ends = [(fit, r[-1])] if fit.resting == "standing" else \
        [(fit.flipped(), r[0]), (fit, r[-1])]
    return [replace(f, profile=open_vessel(f.profile[:-1], cfg.open_wall / f.height,
                                           f.solid_below + cfg.open_base / f.height))
            for f, end in ends if end >= cfg.open_top_ratio * r.max()]


def open_mouth(fit: RevolutionFit, cfg: ReconstructConfig, mask: np.ndarray, K: np.ndarray,
               plane: Plane, depth: np.ndarray | None) -> RevolutionFit | None:
    """The fit as an open vessel (drinking glass, beaker, goblet; see :func:`mouths`), so the
    depth inside it is rendered rather than a lid; None for a closed solid. Standing, the top
    is the mouth when wide enough, unless the readings show a lid (below), and the vessel is
    opened with its rim widened (:func:`widened_rim`). Lying, an end is
    taken open only when the raw ``depth`` says so: of the off-table readings that miss the
    closed model's front surface, the open one takes in ``open_explains`` (and at least 5% of
    all), as when the camera sees into the mouth. A mouth turned away changes nothing the
    camera sees, and the model stays closed.
    A standing top stays shut where the readings on its lid are evidence of one: the closed
    model holds :data:`DEPTH_MIN_POINTS` readings more than the open one (a capped bottle or
    a container with a wide shoulder; an open glass's readings lie inside it, on the open
    model's floor and inner wall, never on a lid), or those within its rim lie at the rim's
    height over the table (:func:`~sr3d_cli.reconstruct.lids.lid_read`: a lid seen from low
    down). ``depth`` is used when ``use_depth`` is on."""
    opened = mouths(fit, cfg)
    if not opened:
        return None
    if depth is None or not cfg.use_depth:
        return mouths(widened_rim(fit, mask, K), cfg)[0] if fit.resting == "standing" else None
    xs, ys, raw = off_table_readings(mask, depth, K, plane)
    closed, *counts = [raw_support(f, xs, ys, raw, K, mask.shape, DEPTH_BAND)
                       for f in [fit] + opened]
    if fit.resting == "standing":
        shut = closed - counts[0] >= DEPTH_MIN_POINTS or lid_read(fit, mask, K, plane, depth)
        return None if shut else mouths(widened_rim(fit, mask, K), cfg)[0]
    best = int(np.argmax(counts))
    gained = counts[best] - closed
    return opened[best] if gained >= max(cfg.open_explains * (len(xs) - closed),
                                         0.05 * len(xs), 1) else None


def widened_rim(fit: RevolutionFit, mask: np.ndarray, K: np.ndarray) -> RevolutionFit:
    """A standing ``fit`` that narrows above its widest level, with those levels as wide as it,
    where its silhouette draws ``mask (H, W) bool`` within :data:`RIM_LOSS` IoU of the fit's
    own; else ``fit``. Seen from above, an open vessel's rim is the upper edge of its outline,
    which the top levels draw about as well narrowed as straight: from their true masks the
    fits of extsim's water glasses and pitchers narrow by 1-10% over their top levels, and
    widened they draw those masks within 0.006 IoU; the rim then holds the readings along it
    (9's pitcher 112 inliers at its placing against 71; object MAE 16.2 -> 9.1 mm). A rim the
    outline shows drawn in (a tulip glass seen from the side) costs more than
    :data:`RIM_LOSS` and stays as fitted."""
    r = fit.profile[1:-1, 0]
    widest = int(np.argmax(r))
    if fit.resting != "standing" or r[-1] >= r[widest]:
        return fit
    profile = fit.profile.copy()
    profile[2 + widest:-1, 0] = r[widest]
    wide = replace(fit, profile=profile)
    drawn, widened = (mask_iou(fit_silhouette(f, K, mask.shape), mask) for f in (fit, wide))
    return replace(wide, iou=widened) if widened >= drawn - RIM_LOSS else fit


def unseen_mouth(fit: RevolutionFit, cfg: ReconstructConfig) -> trimesh.Trimesh | None:
    """A lying ``fit`` (kept closed) opened at its wider end, if that end can be a mouth
    (:func:`mouths`), as a mesh in ``fit``'s object frame; else None. A lying vessel's wider
    end is its mouth (a beaker's lip, a tumbler's taper), and a lying fit's base is its wider
    end (19 of 20 lying fits of glasses, beakers and goblets have their base at the true mouth).
    The readings seldom show whether an end is open, even one facing the camera
    (:func:`open_mouth` keeps most such mouths shut), so the end is taken whichever way it
    faces. A beaker lying there, wider than the gripper's opening, can only be held by its rim;
    the grasp stage plans on this model where the closed one gives no grasp."""
    if fit.resting != "lying":
        return None
    wider = [m for m in mouths(fit, cfg) if m.axis @ fit.axis < 0]  # opened at the base end
    if not wider:
        return None
    mouth = wider[0]
    mesh = revolve(mouth.profile, cfg.sections)
    cam = place_points(mesh.vertices, mouth.T_cam_obj, fit.height)
    mesh.vertices = apply_T(np.linalg.inv(fit.T_cam_obj), cam) / fit.height
    return mesh


class Reconstructor:
    """One per batch: builds the configured backend (:data:`sr3d_cli.backends.RECONSTRUCT`),
    which loads its models or library once; :meth:`__call__` per object."""

    def __init__(self, cfg: ReconstructConfig):
        from sr3d_cli.backends import RECONSTRUCT

        self.cfg = cfg
        self.backend = RECONSTRUCT.create(cfg.backend, cfg)

    @property
    def needs_plane(self) -> bool:
        """Whether the backend needs the support plane (all but a single-image model do)."""
        return self.backend.needs_plane

    def __call__(self, rgb: np.ndarray, mask: np.ndarray, K: np.ndarray, plane: Plane | None,
                 label: str = "", depth: np.ndarray | None = None,
                 occluders: np.ndarray | None = None) -> Reconstruction:
        """Mesh of the object under ``mask (H, W) bool`` in ``rgb (H, W, 3) uint8``; the raw
        ``depth (H, W)`` metres, when given, helps decide between standing and lying and, seen
        from above, gives a standing object's height and profile. ``occluders (H, W) bool``:
        pixels of objects in front that may hide this one (the fit ignores them)."""
        check_mask(mask, self.cfg)
        if plane is None and self.needs_plane:
            raise ObjectError("no support plane: the revolution fit needs the table")
        return self.backend(rgb, mask, K, plane, label, depth, occluders)


# Backends: built with the reconstruct config; called per object with the arguments of
# Reconstructor.__call__ (the mask already checked, the plane there where they need it).

class RevolutionBackend:
    """``revolution``: the training-free surface of revolution fitted to the silhouette and
    the readings."""

    needs_plane = True

    def __init__(self, cfg: ReconstructConfig):
        self.cfg = cfg

    def fitted(self, mask, K, plane, depth, occluders) -> tuple[RevolutionFit, dict]:
        """The revolution fit of the object and the meta data of its mesh."""
        cfg = self.cfg
        fit = configured_fit(mask, K, plane, cfg, depth, occluders)
        cut = check_border(mask, cfg, K, fit)
        meta = {"backend": cfg.backend, "resting": fit.resting, "silhouette_iou": round(fit.iou, 4),
                "pose_hint": {"T_cam_obj": fit.T_cam_obj.tolist(), "scale": fit.height}}
        if cut:
            meta["cut_by_border"] = cut  # 'top': its height is a guess; else its size and place
        return fit, meta

    def __call__(self, rgb, mask, K, plane, label, depth, occluders) -> Reconstruction:
        cfg = self.cfg
        body, handle = split_handle(mask, K, plane)  # the body is fitted without its handle
        fit, meta = self.fitted(body, K, plane, depth, occluders)
        if depth is not None and cfg.use_depth:
            bowl = bowl_instead(fit, body, K, plane, depth, cfg.iterations,
                                lambda f: mouths(f, cfg))
            if bowl is not None:
                fit = bowl
                meta["pose_hint"]["scale"] = bowl.height
                meta["silhouette_iou"] = round(bowl.iou, 4)
            fit = carved(fit, body, depth, K)
        fit = straight_walls(smoothed(fit, cfg.smooth), cfg.straight_wall)
        mouth = open_mouth(fit, cfg, body, K, plane, depth)
        if mouth is not None:
            meta["open_top"] = True
            meta["pose_hint"]["T_cam_obj"] = mouth.T_cam_obj.tolist()  # the mouth is the top
            built = Reconstruction(revolve(mouth.profile, cfg.sections), meta)
        else:
            built = Reconstruction(revolve(fit.profile, cfg.sections), meta,
                                   unseen_mouth(fit, cfg))
        return with_handle(built, handle, int(mask.sum()), K)


def with_handle(built: Reconstruction, handle: np.ndarray, mask_pixels: int, K: np.ndarray
                ) -> Reconstruction:
    """``built`` with a slab over the ``handle (H, W) bool`` pixels split off its mask of
    ``mask_pixels`` pixels (:func:`sr3d_cli.reconstruct.handles.handle_slab`) unioned to its
    mesh as a closed component of its own; ``built`` as it is when there is none."""
    hint = built.meta["pose_hint"]
    slab = handle_slab(handle, mask_pixels, np.asarray(hint["T_cam_obj"]),
                       float(hint["scale"]), K)
    if slab is None:
        return built
    built.meta["handle_pixels"] = int(handle.sum())
    mesh = trimesh.util.concatenate([built.mesh, slab])
    return replace(built, mesh=mesh)


class LibraryBackend(RevolutionBackend):
    """``library``: the library mesh that the label names or that best fits the revolution
    fit's profile."""

    def __init__(self, cfg: ReconstructConfig):
        from sr3d_cli.reconstruct.library import MeshLibrary

        super().__init__(cfg)
        self.library = MeshLibrary(cfg.library)

    def __call__(self, rgb, mask, K, plane, label, depth, occluders) -> Reconstruction:
        fit, meta = self.fitted(mask, K, plane, depth, occluders)
        name, mesh = self.library.pick(label, fit.profile)
        meta["library_mesh"] = name
        return Reconstruction(mesh, meta)


class OnnxBackend:
    """``onnx``: a single-image reconstruction model the user supplies (no plane needed)."""

    needs_plane = False

    def __init__(self, cfg: ReconstructConfig):
        from sr3d_cli.reconstruct.onnx_models import load_image_to_shape

        self.cfg = cfg
        self.model = load_image_to_shape(cfg)

    def __call__(self, rgb, mask, K, plane, label, depth, occluders) -> Reconstruction:
        check_border(mask, self.cfg, K)
        mesh = normalise_mesh(self.model(rgb, mask))
        return Reconstruction(mesh, {"backend": "onnx"})
