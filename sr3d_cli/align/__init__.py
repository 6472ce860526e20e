"""Placing a mesh in the scene: rotation by view matching, position and scale by keypoint
matching on the contact edge, then silhouette refinement on the support plane.

``mode: sr3d`` (default) uses the fitted table: resting orientations only, scale and translation
solved jointly by robust least squares over all contact-edge points (each must lie on its
pixel's ray; the object must rest on the plane), then a silhouette refinement that keeps the
object on the table. ``mode: paper`` reproduces the plain method for ablation: viewpoints on a
sphere with in-plane rolls, three contact representatives (left / middle / right) lifted with
single raw-depth pixels, no refinement.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np
import trimesh
from scipy.optimize import minimize
from scipy.spatial import ConvexHull, QhullError

from sr3d_cli.align.view_matching import (ViewMatcher, candidates_plane, candidates_sphere,
                                          icosphere_directions, is_axisymmetric,
                                          resting_directions)
from sr3d_cli.config import AlignConfig
from sr3d_cli.geometry.camera import unproject
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.simplify import clustered_stand_in, revolution_stand_in
from sr3d_cli.geometry.silhouette import (face_twins, fill_silhouette, mask_iou, project_mesh,
                                          surface_depth)
from sr3d_cli.geometry.transforms import make_T, rotation_about, unit


MIN_MASK_PX = 20  # pixels a mask needs before a mesh is placed on it
MIN_FACES = 4  # faces of the smallest closed mesh (a tetrahedron)
FLAT_EXTENT = 1e-9  # object-frame extent at or below which a mesh is flat along an axis
WINDOW_MARGIN = 0.35  # silhouette window margin, share of the mask box's larger side
WINDOW_PAD_PX = 4  # pixels added to that margin so that tiny masks keep a border
SOFT_SIGMA_PX = 1.5  # Gaussian blur of silhouettes in refinement: a smooth IoU to descend
CONTACT_BAND = 0.02  # unit-mesh heights above its lowest point that count as its contact region
SIZE_GUESS_ROUNDS = 2  # projections that rescale the size guess to the mask's extent
EDGE_OFFSET_PX = 0.5  # the contact edge lies half a pixel below the lowest mask pixel centres
KEYPOINT_ROUNDS = 4  # re-projections of the model's contact edge in the keypoint solve
PLANE_WEIGHT = 10.0  # weight of the rest-on-the-plane row against one contact-ray row
HUBER_ROUNDS = 5  # reweighting rounds of the robust (Huber IRLS) keypoint solve
HUBER_DELTA_M = 0.002  # residual (metres) above which a contact row is down-weighted
PAPER_BELOW_PX = 3  # paper mode: pixels below the contact edge where the table depth is read
PAPER_HALF_WINDOW_PX = 2  # paper mode: half side of the square of table readings (5 x 5)
REFINE_STEP = (0.004, 0.004, 0.05, np.radians(5))  # first simplex: metres, metres, log-scale, yaw
REFINE_RESTARTS = 2  # Nelder-Mead runs: a restart with a fresh simplex escapes early collapse
REFINE_STEP_SHRINK = 3  # the restart's simplex is this many times smaller
REFINE_XATOL = 1e-4  # Nelder-Mead stop: simplex size in the refined parameters
REFINE_FATOL = 1e-5  # Nelder-Mead stop: spread of soft-IoU errors over the simplex
REFINE_FIRST_RUNS = 1  # Nelder-Mead runs every seed gets before the seeds are compared
REFINE_KEEP_MARGIN = 0.02  # score (IoU + prior) below the leader within which a seed's
# refinement always goes on: a converged seed's restart gains ~0.01 IoU on extsim; a seed still
# descending goes on when its last run's second-half gain would close the gap (0.09 seen)
DEPTH_ROUNDS = 3  # inlier / median rounds of the depth-correction factor
DEPTH_VOTE_STEP = 0.005  # spacing of the depth factors that vote (0.5%)
UPRIGHT_COS = 0.999  # |cos| between the object's +z and the plane normal for "standing upright"
AXIS_PICK_COS = 0.9  # |n_x| below which x is far enough from the normal to span the plane
TINY = 1e-9  # guard against dividing by a zero extent or union
TINY_PX = 1e-6  # guard against dividing by a zero projected extent (pixels)
TINY_RES = 1e-12  # guard against dividing by a zero residual in the Huber weights
SCORE_DIGITS = 4  # decimals of the scores written to the pose files
ERROR_DIGITS = 5  # decimals of refinement errors and depth factors in the diagnostics
# sr3d mode draws the silhouettes of an axisymmetric mesh from a stand-in of revolution (fewer
# triangles along the outline, each filled on its own): on extsim meshes 0.992 mean IoU with
# the full mesh's silhouettes, area -0.2%, in 0.46 of the time; paper mode draws the mesh
STAND_IN_TOLERANCE = 0.002  # outer-profile simplification (object units): 0.2 px at 100 px tall
STAND_IN_SECTIONS = 24  # sections of the stand-in about its axis (written meshes have 48)
STAND_IN_MAX_POINTS = 600  # distinct (r, z) above which the profile is not extracted (its
# cost grows with points times edges; written meshes have 40-110)
CLUSTER_ABOVE = 20000  # triangles over which a mesh with no stand-in of revolution (a scan)
# draws its silhouettes from a clustered stand-in: sr3d's own meshes hold at most 12 000; a
# scanned container's 100 000 took 70 s to place, 8-9 s so, placed as well (2-8 mm off)
CLUSTER_CELLS = 64  # grid cubes to the largest extent of that stand-in (clustered_stand_in)


class AlignError(ValueError):
    """One object cannot be placed (its depth is left untouched)."""


@dataclass
class Placement:
    R: np.ndarray
    t: np.ndarray
    scale: float
    scores: dict = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)

    @property
    def T_cam_obj(self) -> np.ndarray:
        return make_T(self.R, self.t)


def _ray(uv, K):
    uv = np.atleast_2d(uv)
    return np.column_stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1],
                            np.ones(len(uv))])


class _Window:
    """Where silhouettes are drawn: the mask's box with a margin, at most ``size`` pixels;
    ``occluders``: the pixels of objects in front, where a silhouette is not compared."""

    def __init__(self, mask: np.ndarray, size: int, occluders: np.ndarray | None = None):
        ys, xs = np.nonzero(mask)
        h, w = np.ptp(ys) + 1, np.ptp(xs) + 1
        pad = int(WINDOW_MARGIN * max(h, w)) + WINDOW_PAD_PX
        self.origin = (float(xs.min() - pad), float(ys.min() - pad))
        extent = max(h, w) + 2 * pad
        self.zoom = min(1.0, size / extent)
        self.shape = (int(np.ceil((h + 2 * pad) * self.zoom)), int(np.ceil((w + 2 * pad)
                                                                            * self.zoom)))
        M = np.float32([[self.zoom, 0, -self.origin[0] * self.zoom],
                        [0, self.zoom, -self.origin[1] * self.zoom]])
        self.obs = cv2.warpAffine(mask.astype(np.float32), M, self.shape[::-1],
                                  flags=cv2.INTER_AREA) > 0.5
        self.occluders = None if occluders is None else \
            cv2.warpAffine(occluders.astype(np.float32), M, self.shape[::-1],
                           flags=cv2.INTER_AREA) > 0.5

    @property
    def spec(self):
        return self.origin, self.shape, self.zoom


def _soft(mask: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(mask.astype(np.float32), (0, 0), SOFT_SIGMA_PX)


@dataclass
class _Subject:
    """The arrays one placement works on.

    K : (3, 3) float intrinsics (pixels); verts : (V, 3) float64 mesh vertices, object frame
    (unit size: ``scale`` makes metres); faces : (F, 3) int; sil_verts : (S, 3) float64 and
    sil_faces : (G, 3) int, the mesh silhouettes are drawn from (the mesh itself, or for an
    axisymmetric one its stand-in of revolution, :func:`revolution_stand_in`); twins : (G, 3)
    int, the face across each edge of ``sil_faces`` (:func:`face_twins`); mask_px : (N, 2)
    float64 pixel (x, y) of every mask pixel."""
    K: np.ndarray
    verts: np.ndarray
    faces: np.ndarray
    sil_verts: np.ndarray
    sil_faces: np.ndarray
    twins: np.ndarray
    mask_px: np.ndarray

    @classmethod
    def of(cls, mesh: trimesh.Trimesh, mask: np.ndarray, K: np.ndarray, *,
           stand_in: bool) -> "_Subject":
        """The subject of ``mesh`` and ``mask (H, W) bool``; with ``stand_in`` (``mesh`` is
        axisymmetric) its silhouettes are drawn from :func:`revolution_stand_in` where there is
        one, else, for a mesh of over :data:`CLUSTER_ABOVE` triangles (a scan), from
        :func:`clustered_stand_in`; its surface is always read from the mesh itself."""
        ys, xs = np.nonzero(mask)
        stand_in = revolution_stand_in(mesh, STAND_IN_TOLERANCE, STAND_IN_SECTIONS,
                                       STAND_IN_MAX_POINTS) if stand_in else None
        if stand_in is None and len(mesh.faces) > CLUSTER_ABOVE:
            stand_in = clustered_stand_in(mesh, CLUSTER_CELLS)
        drawn = mesh if stand_in is None else stand_in
        sil_faces = np.asarray(drawn.faces)
        return cls(K, np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces),
                   np.asarray(drawn.vertices, dtype=np.float64), sil_faces,
                   face_twins(sil_faces), np.column_stack([xs, ys]).astype(np.float64))

    @cached_property
    def hull_verts(self) -> np.ndarray:
        """(H, 3) float64 the vertices on the convex hull of ``verts`` (all of them when qhull
        cannot build one). A projection's extremes lie among them: x / z and y / z over a convex
        polytope in front of the camera peak at its corners."""
        try:
            return self.verts[ConvexHull(self.verts).vertices]
        except (QhullError, ValueError):
            return self.verts


@dataclass
class _Placing:
    """Per-call state of one placement: the subject, the scene it is placed in, where it meets
    the table, and the counts reported in the diagnostics.

    mask : (H, W) bool; depth_m : (H, W) float raw depth (metres, 0 = none); anchor : (3,)
    metres, the plane point under the mask's lowest pixel; down : (2,) unit image direction of
    "down the plane" there; extent_px : the mask box's larger side (pixels)."""
    subject: _Subject
    mesh: trimesh.Trimesh
    mask: np.ndarray
    depth_m: np.ndarray
    plane: Plane
    window: _Window
    matcher: ViewMatcher
    anchor: np.ndarray
    down: np.ndarray
    symmetric: bool
    plain: bool
    extent_px: float
    renders: int = 0  # silhouettes drawn (see Aligner.render_bound)
    candidates: int = 0  # orientations view matching scored


@dataclass
class _Seed:
    """One orientation carried on from view scoring: its score (view match plus upright
    prior), the prior alone, its resting-orientation group ("hint": the reconstruction's pose),
    its index among the candidates, and the start pose (R (3, 3), s0, t0 (3,) metres)."""
    total: float
    prior: float
    group: object
    index: int
    R: np.ndarray
    s0: float
    t0: np.ndarray
    view: object


@dataclass
class _Choice:
    """The best placed seed so far: its silhouette IoU plus its prior (what is compared)."""
    score: float
    iou: float
    index: int
    R: np.ndarray
    t: np.ndarray
    scale: float
    view: object
    diag: dict


@dataclass
class _Placed:
    """A seed placed so far: its choice (score, pose), the seed, its keypoint diagnostics,
    and its refinement when that can run on (None when it was not refined)."""
    choice: _Choice
    seed: _Seed
    diag: dict
    refinement: "_Refinement | None"


def _best(placed: list[_Placed]) -> _Choice | None:
    """The highest-scoring choice, the first among equals (None when there is none)."""
    best = None
    for one in placed:
        if best is None or one.choice.score > best.score:
            best = one.choice
    return best


class Aligner:
    """Places one mesh for one observed mask."""

    def __init__(self, cfg: AlignConfig):
        self.cfg = cfg

    # ---- shared pieces -------------------------------------------------------------------------
    @staticmethod
    def _footprint(sub: _Subject, R, normal) -> tuple[np.ndarray, float]:
        """Centre of the rotated unit mesh's contact region (points within ``CONTACT_BAND`` of
        its lowest point along ``normal``) and that lowest height."""
        pts = sub.verts @ R.T
        heights = pts @ normal
        low = heights.min()
        return pts[heights <= low + CONTACT_BAND].mean(0), float(low)

    def _rest_translation(self, sub: _Subject, R, scale, anchor, plane):
        """t such that the lowest point of the rotated mesh touches the plane under ``anchor``
        (a plane point), with the mesh's footprint centred there."""
        return anchor - scale * self._footprint(sub, R, plane.normal)[0]

    def _size_guess(self, sub: _Subject, R, anchor, plane, extent_px: float) -> float:
        """Scale making the projected mesh as large as the mask (larger bounding-box side; the
        box is that of the hull vertices' projections, the same as all vertices')."""
        s = float(anchor[2] * extent_px / sub.K[0, 0])  # metres spanned by the mask there
        for _ in range(SIZE_GUESS_ROUNDS):
            t = self._rest_translation(sub, R, s, anchor, plane)
            uv, _ = project_mesh(sub.hull_verts, R, t, s, sub.K)
            uv = uv[np.isfinite(uv).all(1)]
            if len(uv) == 0:
                break
            s *= extent_px / max(float(np.ptp(uv, axis=0).max()), TINY_PX)
        return s

    @staticmethod
    def _silhouette(sub: _Subject, R, t, scale, window: _Window) -> np.ndarray:
        uv, _ = project_mesh(sub.sil_verts, R, t, scale, sub.K)
        return fill_silhouette(uv, sub.sil_faces, window.shape, window.origin, window.zoom,
                               sub.twins)

    # ---- keypoint matching ---------------------------------------------------------------------
    @staticmethod
    def _contact_edge(points_uv: np.ndarray, down: np.ndarray, n: int):
        """Per horizontal bin (``n`` over the extent), the index of the lowest point."""
        across = np.array([-down[1], down[0]])
        h = points_uv @ across
        v = points_uv @ down
        finite = np.isfinite(h) & np.isfinite(v)
        if not finite.any():
            return np.full(n, -1)
        h = np.where(finite, h, np.nan)
        v = np.where(finite, v, -np.inf)
        lo, hi = np.nanmin(h), np.nanmax(h)
        h = np.nan_to_num(h, nan=lo)
        bins = np.clip(((h - lo) / max(hi - lo, TINY) * n).astype(int), 0, n - 1)
        best = np.full(n, -1)
        best_v = np.full(n, -np.inf)
        for i in np.argsort(v):  # ascending: later (lower) points overwrite
            best[bins[i]] = i
            best_v[bins[i]] = v[i]
        return best

    def _keypoints_sr3d(self, sub: _Subject, R, scale, t, plane, down):
        """Joint robust least squares for (scale, t) over the contact-edge points."""
        K, n = sub.K, self.cfg.contact_points
        obs_idx = self._contact_edge(sub.mask_px, down, n)
        ok = obs_idx >= 0
        obs_uv = sub.mask_px[obs_idx[ok]] + EDGE_OFFSET_PX * down
        rays = _ray(obs_uv, K)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        m_low = (sub.verts @ R.T @ plane.normal).min()
        residuals = np.zeros(0)
        for _ in range(KEYPOINT_ROUNDS):
            uv, _ = project_mesh(sub.verts, R, t, scale, K)
            model_idx = self._contact_edge(uv, down, n)[ok]
            good = model_idx >= 0
            a = sub.verts[model_idx[good]] @ R.T  # (m, 3) rotated object points
            A, b = _contact_rows(rays[good], a, m_low, plane)
            sol = _huber_solve(A, b)
            if not (sol[0] > 0):
                raise AlignError("keypoint matching gave a non-positive scale")
            scale, t = float(sol[0]), sol[1:]
            residuals = np.linalg.norm((A[:-1] @ sol - b[:-1]).reshape(-1, 3), axis=1)
        return scale, t, {"contact_points": obs_uv.round(1).tolist(),
                          "residual_median_m": float(np.median(residuals)) if residuals.size
                          else None}

    def _keypoints_paper(self, sub: _Subject, R, scale, t, down, depth_m):
        """The plain method: left / middle / right contact points lifted with raw depth just
        below the mask edge; scale from the left-right distance, translation from the middle."""
        K, n = sub.K, self.cfg.contact_points
        obs_idx = self._contact_edge(sub.mask_px, down, n)
        obs_idx = obs_idx[obs_idx >= 0]
        if len(obs_idx) < 3:
            raise AlignError("contact edge too short")
        reps = [obs_idx[0], obs_idx[len(obs_idx) // 2], obs_idx[-1]]
        lifted = []
        for i in reps:
            p = sub.mask_px[i] + PAPER_BELOW_PX * down
            x, y = int(round(p[0])), int(round(p[1]))
            r = PAPER_HALF_WINDOW_PX
            win = depth_m[max(0, y - r):y + r + 1, max(0, x - r):x + r + 1]
            z = float(np.median(win[win > 0])) if (win > 0).any() else 0.0
            if z <= 0:
                raise AlignError("no table depth below the contact edge")
            lifted.append(_ray(sub.mask_px[i], K)[0] * z)
        uv, _ = project_mesh(sub.verts, R, t, scale, K)
        model_idx = self._contact_edge(uv, down, n)
        model_idx = model_idx[model_idx >= 0]
        mreps = [model_idx[0], model_idx[len(model_idx) // 2], model_idx[-1]]
        a = sub.verts[mreps] @ R.T
        span = np.linalg.norm(a[0] - a[2])
        if span < TINY:
            raise AlignError("model contact edge is a point")
        scale = float(np.linalg.norm(lifted[0] - lifted[2]) / span)
        t = lifted[1] - scale * a[1]
        return scale, t, {"contact_points": [sub.mask_px[i].tolist() for i in reps]}

    # ---- refinement -----------------------------------------------------------------------------
    def _refine(self, sub: _Subject, R, t, scale, plane, window, yaw_free) -> "_Refinement":
        """Silhouette refinement on the plane (:class:`_Refinement`), not yet run."""
        return _Refinement(self, sub, R, t, scale, plane, window, yaw_free)

    def render_bound(self, mesh: trimesh.Trimesh | None = None) -> int:
        """The most silhouette renders one placement draws (its bounded cost): every candidate
        orientation once, the reconstruction's pose once, and each seed carried on (the best
        ``top_candidates`` and the hint) its refinement's ``refine_evals`` plus one IoU check.
        Without ``mesh`` the count of resting orientations is its largest, ``max_rests``."""
        cfg = self.cfg
        if cfg.mode == "paper":
            return len(icosphere_directions(cfg.views)) * cfg.rolls + 1
        rests = cfg.max_rests if mesh is None else \
            len(resting_directions(mesh, is_axisymmetric(mesh), cfg.max_rests))
        refined = cfg.refine_evals if cfg.refine else 0
        return rests * cfg.yaw_steps + 1 + (cfg.top_candidates + 1) * (refined + 1)

    # ---- raw depth on the object ----------------------------------------------------------------
    def _depth_correction(self, sub: _Subject, R, t, scale, mask, depth_m,
                          plane) -> tuple[float, dict]:
        """Factor ``f`` for a similarity about the camera centre (``t *= f``, ``scale *= f``),
        which leaves the silhouette unchanged, that brings the placed model's front surface onto
        the raw depth readings lying on it: readings within ``depth_inlier`` of the model,
        a robust median of their ratio, iterated; the surface is then set at the
        ``depth_quantile`` of the ratios in that band. A depth camera reads glass at or behind
        its front surface, seldom in front (the texture behind it, refracted; its back wall):
        the median sets the model too far (over the true surfaces of the real frames the
        readings within 3 cm lie a median 9 mm behind, extsim's 2 mm). Glass gives few such
        readings (most are holes or see-through); with fewer than ``depth_min_share`` of the
        mask, nothing changes.

        When the contact edge is wrong (hidden behind another object, or the height of a
        bottle seen from above), the model can be 10-20% too far; then no reading lies near it.
        So first the factors within ``depth_search`` vote (readings more than ``depth_inlier``
        above the table only: see-through readings on the table would vote for "farther"); a
        factor wins if ``depth_vote`` times more readings lie on its surface than on the
        placed one's, and they are at least ``depth_agree`` of the off-table readings (a mask
        of two merged objects, or a wrong shape, has readings that no one factor explains)."""
        cfg = self.cfg
        ys, xs = np.nonzero(mask & (depth_m > 0))
        info = {"raw_points": int(len(xs)), "raw_inliers": 0, "depth_factor": 1.0}
        need = max(cfg.depth_min_points, cfg.depth_min_share * int(mask.sum()))  # inliers
        if len(xs) < need:
            return 1.0, info
        sampled = np.linspace(0, len(xs) - 1, min(len(xs), cfg.depth_samples)).astype(np.int64)
        need *= len(sampled) / len(xs)  # in sampled readings
        ys, xs = ys[sampled], xs[sampled]
        uv, pts = project_mesh(sub.verts, R, t, scale, sub.K)
        z_model = surface_depth(uv, pts, sub.faces, sub.K, xs, ys, mask.shape)
        hit = np.isfinite(z_model)
        raw, z_model = depth_m[ys, xs].astype(np.float64)[hit], z_model[hit]
        start = self._depth_vote(sub, raw, z_model, np.column_stack([xs, ys])[hit], plane, need)
        lo, hi = start * (1 - cfg.depth_max_change), start * (1 + cfg.depth_max_change)
        factor, inliers = start, np.zeros(len(raw), bool)
        for last in [False] * (DEPTH_ROUNDS - 1) + [True]:  # the median centres the band
            inliers = np.abs(raw - factor * z_model) < cfg.depth_inlier
            if inliers.sum() < need:
                return 1.0, {**info, "raw_inliers": int(inliers.sum())}
            q = cfg.depth_quantile if last else 0.5
            factor = float(np.clip(np.quantile(raw[inliers] / z_model[inliers], q), lo, hi))
        return factor, {**info, "raw_inliers": int(inliers.sum()),
                        "depth_factor": round(factor, ERROR_DIGITS)}

    def _depth_vote(self, sub: _Subject, raw, z_model, px, plane, need) -> float:
        """The factor within ``depth_search`` on whose surface most off-table readings lie, if
        it beats the placed surface (factor 1) ``depth_vote`` times over and holds
        ``depth_agree`` of them; else 1."""
        cfg = self.cfg
        if cfg.depth_search <= cfg.depth_max_change:
            return 1.0
        off = plane.height(unproject(px.astype(np.float64), raw, sub.K)) > cfg.depth_inlier
        raw, z_model = raw[off], z_model[off]
        steps = int(np.ceil(cfg.depth_search / DEPTH_VOTE_STEP))
        factors = 1 + np.linspace(-cfg.depth_search, cfg.depth_search, 2 * steps + 1)
        votes = (np.abs(raw[:, None] - factors[None] * z_model[:, None])
                 < cfg.depth_inlier).sum(0)
        best = int(np.argmax(votes))
        if votes[best] >= need and votes[best] >= cfg.depth_vote * max(votes[steps], 1) and \
                votes[best] >= cfg.depth_agree * len(raw):
            return float(factors[best])
        return 1.0

    # ---- the whole placement ----------------------------------------------------------------
    def __call__(self, mesh: trimesh.Trimesh, mask: np.ndarray, K: np.ndarray,
                 plane: Plane | None, depth_m: np.ndarray,
                 hint: tuple[np.ndarray, float] | None = None,
                 occluders: np.ndarray | None = None) -> Placement:
        """Place ``mesh`` (object frame) so that it explains ``mask`` and rests on ``plane``.

        hint : (T_cam_obj, scale) from the reconstruction, if it fitted a pose (sr3d mode uses it
        as one more candidate, refined first; it is accepted at once when its silhouette IoU
        reaches ``align.hint_accept``).
        occluders : (H, W) bool pixels of objects in front that may hide this one: silhouettes
        are compared with the mask elsewhere (sr3d mode; view matching uses the whole mask)."""
        cfg = self.cfg
        _check_inputs(mesh, mask, plane)
        p = self._start(mesh, mask, K, plane, depth_m, occluders)
        placed: list[_Placed] = []
        for batch in (lambda: self._hint_seed(p, hint), lambda: self._candidates(p)):
            best = _best(placed)
            if best is not None and best.iou >= cfg.hint_accept:
                break  # the reconstruction's own pose explains the mask: no search needed
            for seed in batch():
                one = self._place_seed(p, seed)
                if one is not None:
                    placed.append(one)
        best = self._finish_refinements(p, placed)
        if best is None:
            raise AlignError("no candidate orientation could be matched to the contact edge")
        t, scale, diag = best.t, best.scale, best.diag
        if cfg.use_depth and not p.plain:
            factor, info = self._depth_correction(p.subject, best.R, t, scale, mask, depth_m,
                                                  plane)
            t, scale = np.asarray(t, dtype=np.float64) * factor, scale * factor
            diag = {**diag, **info}
        return self._placement(p, best, t, scale, diag)

    def _start(self, mesh, mask, K, plane, depth_m, occluders) -> _Placing:
        """The per-call state: silhouette window, view matcher, and where the object meets the
        table (the plane point under the mask's lowest pixel, and the image's "down" there)."""
        cfg = self.cfg
        symmetric = is_axisymmetric(mesh)
        plain = cfg.mode == "paper"
        sub = _Subject.of(seen_both_ways(mesh), mask, K, stand_in=symmetric and not plain)
        window = _Window(mask, cfg.window, None if plain else occluders)
        matcher = ViewMatcher(mask, alpha=cfg.alpha, beta=cfg.beta, gamma=cfg.gamma,
                              patches=cfg.patches)
        centre = sub.mask_px.mean(0)
        bottom = sub.mask_px[np.argmax(sub.mask_px @ plane.down_at(centre, K))]
        anchor = plane.intersect(_ray(bottom, K))[0]
        if not np.all(np.isfinite(anchor)):
            raise AlignError("the object's contact edge does not meet the support plane")
        ys, xs = np.nonzero(mask)
        return _Placing(sub, mesh, mask, depth_m, plane, window, matcher, anchor,
                        plane.down_at(bottom, K), symmetric, plain,
                        float(max(np.ptp(xs), np.ptp(ys)) + 1))

    def _candidates(self, p: _Placing) -> list[_Seed]:
        """View matching over the candidate orientations: the best view of each resting
        orientation (the best few) goes on to keypoints and refinement."""
        cfg = self.cfg
        if p.plain:
            rotations = candidates_sphere(cfg.views, cfg.rolls, -unit(p.anchor))
        else:
            rotations = candidates_plane(p.mesh, p.plane.normal, p.symmetric, cfg.yaw_steps,
                                         cfg.max_rests)
        p.candidates = len(rotations)
        p.renders += len(rotations)
        scored = [self._score_view(p, group, i, R) for i, (group, R) in enumerate(rotations)]
        scored.sort(key=lambda c: -c.total)
        carried, groups = [], set()
        for c in scored:
            if c.group not in groups:
                groups.add(c.group)
                carried.append(c)
        return carried[:1 if p.plain else cfg.top_candidates]

    def _score_view(self, p: _Placing, group, i: int, R: np.ndarray) -> _Seed:
        """One candidate orientation at its size guess, resting on the plane at the anchor,
        scored by view matching plus the upright prior."""
        sub = p.subject
        s0 = self._size_guess(sub, R, p.anchor, p.plane, p.extent_px)
        t0 = self._rest_translation(sub, R, s0, p.anchor, p.plane)
        view, _ = p.matcher.render_and_score(sub.sil_verts, sub.sil_faces, R, t0, s0, sub.K,
                                             p.window.spec, sub.twins)
        prior = 0.0 if p.plain else self._upright_prior(R, p.plane)
        return _Seed(view.total + prior, prior, group, i, R, s0, t0, view)

    def _upright_prior(self, R: np.ndarray, plane: Plane) -> float:
        """Objects stand the right way up more often than upside down (+z up)."""
        return self.cfg.upright_prior * max(0.0, float(R[:, 2] @ plane.normal))

    def _hint_seed(self, p: _Placing, hint) -> list[_Seed]:
        """The reconstruction's pose as one more seed (sr3d mode, when there is one)."""
        if hint is None or p.plain:
            return []
        T_h, s_h = np.asarray(hint[0], dtype=np.float64), float(hint[1])
        p.renders += 1
        sub = p.subject
        view, _ = p.matcher.render_and_score(sub.sil_verts, sub.sil_faces, T_h[:3, :3],
                                             T_h[:3, 3], s_h, sub.K, p.window.spec, sub.twins)
        return [_Seed(view.total, self._upright_prior(T_h[:3, :3], p.plane), "hint", -1,
                      T_h[:3, :3], s_h, T_h[:3, 3], view)]

    def _place_seed(self, p: _Placing, seed: _Seed) -> "_Placed | None":
        """Keypoint solve and the first ``REFINE_FIRST_RUNS`` refinement runs of one seed (all
        of them for the reconstruction's pose), or None when its contact edge cannot be matched
        (sr3d mode)."""
        cfg = self.cfg
        R = seed.R
        if seed.group == "hint":
            diag = {"seed": "reconstruction pose"}
            if cfg.refine_hint:
                return self._refine_seed(p, seed, R, seed.t0, seed.s0, diag, REFINE_RESTARTS)
            return self._chosen(p, seed, R, seed.t0, seed.s0, None, diag)
        if p.plain:
            scale, t, diag = self._keypoints_paper(p.subject, R, seed.s0, seed.t0, p.down,
                                                   p.depth_m)
            return self._chosen(p, seed, R, t, scale, None, diag)
        try:
            scale, t, diag = self._keypoints_sr3d(p.subject, R, seed.s0, seed.t0, p.plane,
                                                  p.down)
        except AlignError:
            return None
        return self._refine_seed(p, seed, R, t, scale, diag, REFINE_FIRST_RUNS)

    def _refine_seed(self, p: _Placing, seed: _Seed, R, t, scale, diag: dict,
                     runs: int) -> "_Placed":
        """The seed refined by ``runs`` Nelder-Mead runs (:class:`_Refinement`); yaw stays fixed
        for an axisymmetric mesh standing upright (turning it changes nothing)."""
        if not self.cfg.refine:
            return self._chosen(p, seed, R, t, scale, None, diag)
        refinement = self._refine(p.subject, R, t, scale, p.plane, p.window,
                                  yaw_free=not (p.symmetric and self._upright(R, p.plane)))
        return self._go_on(p, _Placed(None, seed, diag, refinement), runs)

    def _go_on(self, p: _Placing, placed: "_Placed", runs: int) -> "_Placed":
        """``placed`` after ``runs`` more runs of its refinement, scored again."""
        refinement = placed.refinement
        refinement.run(runs)
        p.renders += refinement.new_renders()
        R, t, scale, sil, info = refinement.result()
        return _Placed(self._chosen(p, placed.seed, R, t, scale, sil,
                                    {**placed.diag, **info}).choice,
                       placed.seed, placed.diag, refinement)

    def _chosen(self, p: _Placing, seed: _Seed, R, t, scale, sil, diag: dict) -> "_Placed":
        """A placed seed scored by its silhouette IoU (``sil`` drawn when None) plus prior."""
        if sil is None:
            sil = self._silhouette(p.subject, R, t, scale, p.window)
            p.renders += 1
        iou = mask_iou(sil, p.window.obs, p.window.occluders)
        return _Placed(_Choice(iou + seed.prior, iou, seed.index, R, t, scale, seed.view, diag),
                       seed, diag, None)

    def _finish_refinements(self, p: _Placing, placed: list["_Placed"]) -> _Choice | None:
        """The best placed seed once the refinement of every seed that may still catch up
        with the leader has run to its end: those within ``REFINE_KEEP_MARGIN`` of the
        leader's score, or within what their last run gained over its second half (still
        descending). The others lose to the leader by more than their remaining runs gain."""
        leader = _best(placed)
        for k, one in enumerate(placed):
            if one.refinement is not None and not one.refinement.done and \
                    one.choice.score + max(REFINE_KEEP_MARGIN, one.refinement.recent_gain) \
                    >= leader.score:
                placed[k] = self._go_on(p, one, REFINE_RESTARTS)
        return _best(placed)

    def _placement(self, p: _Placing, best: _Choice, t, scale, diag) -> Placement:
        """The chosen pose with its scores and diagnostics."""
        view = best.view
        scores = {"view": round(view.total, SCORE_DIGITS), "ssim": round(view.ssim, SCORE_DIGITS),
                  "edges": round(view.edges, SCORE_DIGITS),
                  "aspect": round(view.aspect, SCORE_DIGITS),
                  "silhouette_iou": round(best.iou, SCORE_DIGITS)}
        diagnostics = {"mode": self.cfg.mode, "best_view": int(best.index),
                       "candidates": p.candidates, "axisymmetric": bool(p.symmetric),
                       "renders": p.renders, **diag}
        return Placement(best.R, np.asarray(t, dtype=np.float64), float(scale), scores,
                         diagnostics)

    @staticmethod
    def _upright(R, plane) -> bool:
        return abs((R @ np.array([0, 0, 1.0])) @ plane.normal) > UPRIGHT_COS


class _Refinement:
    """Silhouette refinement on the plane (Nelder-Mead over shift, log-scale and, with
    ``yaw_free``, yaw), run in steps so that seeds can be compared between its runs: each
    :meth:`run` is one more Nelder-Mead run (``REFINE_RESTARTS`` in all, each restart with a
    fresh, ``REFINE_STEP_SHRINK`` times smaller simplex around the best pose so far). Bounded:
    at most ``refine_evals`` silhouette renders over all runs (a pose met again is not
    redrawn). Monotone: the pose kept is the lowest-error one evaluated, the start among them,
    so the error (1 - soft silhouette IoU) never ends above the start's."""

    def __init__(self, aligner: "Aligner", sub: _Subject, R, t, scale, plane, window: _Window,
                 yaw_free: bool):
        n = plane.normal
        self.aligner, self.sub, self.R, self.scale, self.plane = aligner, sub, R, scale, plane
        self.window, self.yaw_free = window, yaw_free
        self.e1 = unit(np.cross(n, [1.0, 0, 0]) if abs(n[0]) < AXIS_PICK_COS
                       else np.cross(n, [0, 1.0, 0]))
        self.e2 = np.cross(n, self.e1)
        self.shown = 1.0 if window.occluders is None else 1.0 - window.occluders
        self.obs = _soft(window.obs) * self.shown
        self.pivot = t + scale * aligner._footprint(sub, R, n)[0]  # contact centre
        self.errors: dict[bytes, float] = {}  # by pose parameters: not redrawn when met again
        self.history: list[float] = []  # best error after each render
        self.run_start = 0  # renders drawn before the last run
        self.best = {"error": np.inf}
        self.x = np.zeros(4 if yaw_free else 3)
        self.start = self.cost(self.x)
        self.step = np.array(REFINE_STEP)[:len(self.x)]
        self.runs = 0
        self.counted = 0  # renders already reported by new_renders

    def new_renders(self) -> int:
        """Silhouettes drawn since the last call (all of them at the first)."""
        new, self.counted = len(self.errors) - self.counted, len(self.errors)
        return new

    def pose(self, x):
        """(R (3, 3), t (3,) metres, scale) of parameters ``x``: shift (metres) along e1, e2,
        log-scale and yaw, resting on the plane."""
        n = self.plane.normal
        dx, dy, ls, yaw = x[0], x[1], x[2], x[3] if self.yaw_free else 0.0
        R1 = rotation_about(n, yaw) @ self.R
        s1 = self.scale * np.exp(ls)
        p1 = self.pivot + dx * self.e1 + dy * self.e2
        foot, low = self.aligner._footprint(self.sub, R1, n)
        t1 = p1 - s1 * foot
        t1 = t1 - (n @ t1 + s1 * low + self.plane.offset) * n  # rest on the plane
        return R1, t1, s1

    def cost(self, x) -> float:
        """1 - soft silhouette IoU of the pose ``x`` (memoised)."""
        key = np.asarray(x, dtype=np.float64).tobytes()
        if key not in self.errors:
            R1, t1, s1 = self.pose(x)
            sil = self.aligner._silhouette(self.sub, R1, t1, s1, self.window)
            ren = _soft(sil) * self.shown
            inter = np.minimum(self.obs, ren).sum()
            self.errors[key] = 1.0 - inter / max(np.maximum(self.obs, ren).sum(), TINY)
            if self.errors[key] < self.best["error"]:
                self.best.update(error=self.errors[key], x=np.array(x, dtype=np.float64),
                                 sil=sil)
            self.history.append(self.best["error"])
        return self.errors[key]

    @property
    def recent_gain(self) -> float:
        """How much the best error fell over the second half of the last run's renders."""
        drawn = self.history[self.run_start:]
        return float(drawn[len(drawn) // 2] - drawn[-1]) if drawn else 0.0

    @property
    def done(self) -> bool:
        return self.runs >= REFINE_RESTARTS

    def run(self, runs: int = REFINE_RESTARTS) -> None:
        """Up to ``runs`` more Nelder-Mead runs (none past ``REFINE_RESTARTS``)."""
        for _ in range(min(runs, REFINE_RESTARTS - self.runs)):
            x, step = self.x, self.step
            self.run_start = len(self.history)
            simplex = np.vstack([x] + [x + np.eye(len(x))[i] * step[i] for i in range(len(x))])
            # scipy stops a run at maxfev calls of cost, memoised ones included
            minimize(self.cost, x, method="Nelder-Mead",
                     options={"initial_simplex": simplex,
                              "maxfev": self.aligner.cfg.refine_evals // REFINE_RESTARTS,
                              "xatol": REFINE_XATOL, "fatol": REFINE_FATOL})
            self.x = self.best["x"]
            self.step = step / REFINE_STEP_SHRINK
            self.runs += 1

    def result(self):
        """(R, t, scale, silhouette (h, w) bool in the window of the best pose so far, info:
        the start's and the best error and the renders drawn)."""
        R1, t1, s1 = self.pose(self.best["x"])
        return R1, t1, s1, self.best["sil"], {
            "refine_error_start": round(float(self.start), ERROR_DIGITS),
            "refine_error": round(float(self.best["error"]), ERROR_DIGITS),
            "refine_renders": len(self.errors)}


def seen_both_ways(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` as the placing draws and reads it. Its silhouettes are drawn from the triangles
    facing away from the camera and its surface read from those facing it, which holds for a
    closed mesh wound outwards (sr3d's own: returned as it is). A closed mesh wound inwards is
    turned outwards; one that is not closed (a scan with holes, one sheet, an STL's unshared
    vertices) gets each triangle both ways, so that its silhouette is all of its triangles' and
    its surface the nearest of them whichever way they wind (a scanned container wound
    inwards was read from behind: the readings on its front voted it 6% nearer, 7-34 mm)."""
    if mesh.is_watertight:
        return mesh if mesh.volume >= 0 else \
            trimesh.Trimesh(mesh.vertices, np.asarray(mesh.faces)[:, ::-1], process=False)
    faces = np.asarray(mesh.faces)
    return trimesh.Trimesh(mesh.vertices, np.concatenate([faces, faces[:, ::-1]]), process=False)


def _check_inputs(mesh: trimesh.Trimesh, mask: np.ndarray, plane: Plane | None) -> None:
    """AlignError for a mask too small, a degenerate mesh, or no support plane."""
    if mask.sum() < MIN_MASK_PX:
        raise AlignError(f"mask has {int(mask.sum())} px: too small to place a mesh")
    if len(mesh.faces) < MIN_FACES or not np.isfinite(mesh.vertices).all() or \
            np.ptp(mesh.vertices, axis=0).min() <= FLAT_EXTENT:
        raise AlignError("degenerate mesh (fewer than 4 faces, not finite, or flat)")
    if plane is None:
        raise AlignError("no support plane visible: cannot place the object")


def _contact_rows(rays: np.ndarray, a: np.ndarray, m_low: float,
                  plane: Plane) -> tuple[np.ndarray, np.ndarray]:
    """Linear system in (scale, t): each rotated model point ``scale * a_i + t`` must lie on its
    contact ray (cross product with the ray is zero: three rows each), and the model's lowest
    point ``m_low`` (unit mesh, along the normal) must rest on the plane (the last row,
    weighted ``PLANE_WEIGHT``).

    rays : (m, 3) unit camera rays; a : (m, 3) rotated unit-mesh points. Returns A (3m + 1, 4),
    b (3m + 1,)."""
    rows, rhs = [], []
    for ri, ai in zip(rays, a):
        C = np.array([[0, -ri[2], ri[1]], [ri[2], 0, -ri[0]], [-ri[1], ri[0], 0]])
        rows.append(np.column_stack([C @ ai, C]))
        rhs.append(np.zeros(3))
    A = np.vstack(rows)
    b = np.concatenate(rhs)
    A = np.vstack([A, PLANE_WEIGHT * np.concatenate([[m_low], plane.normal])])
    b = np.concatenate([b, [-PLANE_WEIGHT * plane.offset]])
    return A, b


def _huber_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Robust least squares (Huber IRLS, ``HUBER_ROUNDS`` rounds, ``HUBER_DELTA_M``) of
    ``A x = b``; the last row (the plane) keeps full weight. Returns x (4,): scale, t."""
    weights = np.ones(len(A))
    for _ in range(HUBER_ROUNDS):
        sol, *_ = np.linalg.lstsq(A * weights[:, None], b * weights, rcond=None)
        res = np.abs(A @ sol - b)
        weights = np.where(res <= HUBER_DELTA_M, 1.0,
                           np.sqrt(HUBER_DELTA_M / np.maximum(res, TINY_RES)))
        weights[-1] = 1.0
    return sol
