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

import cv2
import numpy as np
import trimesh
from scipy.optimize import minimize

from sr3d_cli.align.view_matching import (ViewMatcher, candidates_plane, candidates_sphere,
                                          icosphere_directions, is_axisymmetric,
                                          resting_directions)
from sr3d_cli.config import AlignConfig
from sr3d_cli.geometry.camera import unproject
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.silhouette import fill_silhouette, mask_iou, project_mesh, surface_depth
from sr3d_cli.geometry.transforms import make_T, rotation_about, unit


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
        pad = int(0.35 * max(h, w)) + 4
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
    return cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 1.5)


class Aligner:
    """Places one mesh for one observed mask."""

    def __init__(self, cfg: AlignConfig):
        self.cfg = cfg

    # ---- shared pieces -------------------------------------------------------------------------
    def _footprint(self, R, normal) -> tuple[np.ndarray, float]:
        """Centre of the rotated unit mesh's contact region (points within 0.02 of its lowest
        point along ``normal``) and that lowest height."""
        pts = self.verts @ R.T
        heights = pts @ normal
        low = heights.min()
        return pts[heights <= low + 0.02].mean(0), float(low)

    def _rest_translation(self, R, scale, anchor, plane):
        """t such that the lowest point of the rotated mesh touches the plane under ``anchor``
        (a plane point), with the mesh's footprint centred there."""
        return anchor - scale * self._footprint(R, plane.normal)[0]

    def _size_guess(self, R, anchor, plane, extent_px: float) -> float:
        """Scale making the projected mesh as large as the mask (larger bounding-box side)."""
        s = float(anchor[2] * extent_px / self.K[0, 0])  # metres spanned by the mask there
        for _ in range(2):
            t = self._rest_translation(R, s, anchor, plane)
            uv, _ = project_mesh(self.verts, R, t, s, self.K)
            uv = uv[np.isfinite(uv).all(1)]
            if len(uv) == 0:
                break
            s *= extent_px / max(float(np.ptp(uv, axis=0).max()), 1e-6)
        return s

    def _silhouette(self, R, t, scale, window: _Window) -> np.ndarray:
        uv, _ = project_mesh(self.verts, R, t, scale, self.K)
        return fill_silhouette(uv, self.faces, window.shape, window.origin, window.zoom)

    # ---- keypoint matching ---------------------------------------------------------------------
    def _contact_edge(self, points_uv: np.ndarray, down: np.ndarray, n: int):
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
        bins = np.clip(((h - lo) / max(hi - lo, 1e-9) * n).astype(int), 0, n - 1)
        best = np.full(n, -1)
        best_v = np.full(n, -np.inf)
        for i in np.argsort(v):  # ascending: later (lower) points overwrite
            best[bins[i]] = i
            best_v[bins[i]] = v[i]
        return best

    def _keypoints_sr3d(self, R, scale, t, plane, down):
        """Joint robust least squares for (scale, t) over the contact-edge points."""
        K, n = self.K, self.cfg.contact_points
        obs_idx = self._contact_edge(self.mask_px, down, n)
        ok = obs_idx >= 0
        obs_uv = self.mask_px[obs_idx[ok]] + 0.5 * down  # the edge is half a pixel lower
        rays = _ray(obs_uv, K)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        m_low = (self.verts @ R.T @ plane.normal).min()
        residuals = np.zeros(0)
        for _ in range(4):
            uv, _ = project_mesh(self.verts, R, t, scale, K)
            model_idx = self._contact_edge(uv, down, n)[ok]
            good = model_idx >= 0
            a = self.verts[model_idx[good]] @ R.T  # (m, 3) rotated object points
            r = rays[good]
            rows, rhs = [], []
            for ri, ai in zip(r, a):
                C = np.array([[0, -ri[2], ri[1]], [ri[2], 0, -ri[0]], [-ri[1], ri[0], 0]])
                rows.append(np.column_stack([C @ ai, C]))
                rhs.append(np.zeros(3))
            A = np.vstack(rows)
            b = np.concatenate(rhs)
            w_plane = 10.0
            A = np.vstack([A, w_plane * np.concatenate([[m_low], plane.normal])])
            b = np.concatenate([b, [-w_plane * plane.offset]])
            weights = np.ones(len(A))
            for _ in range(5):  # Huber IRLS
                sol, *_ = np.linalg.lstsq(A * weights[:, None], b * weights, rcond=None)
                res = np.abs(A @ sol - b)
                delta = 0.002
                weights = np.where(res <= delta, 1.0, np.sqrt(delta / np.maximum(res, 1e-12)))
                weights[-1] = 1.0
            if not (sol[0] > 0):
                raise AlignError("keypoint matching gave a non-positive scale")
            scale, t = float(sol[0]), sol[1:]
            residuals = np.linalg.norm((A[:-1] @ sol - b[:-1]).reshape(-1, 3), axis=1)
        return scale, t, {"contact_points": obs_uv.round(1).tolist(),
                          "residual_median_m": float(np.median(residuals)) if residuals.size
                          else None}

    def _keypoints_paper(self, R, scale, t, down, depth_m):
        """The plain method: left / middle / right contact points lifted with raw depth just
        below the mask edge; scale from the left-right distance, translation from the middle."""
        K, n = self.K, self.cfg.contact_points
        obs_idx = self._contact_edge(self.mask_px, down, n)
        obs_idx = obs_idx[obs_idx >= 0]
        if len(obs_idx) < 3:
            raise AlignError("contact edge too short")
        reps = [obs_idx[0], obs_idx[len(obs_idx) // 2], obs_idx[-1]]
        lifted = []
        for i in reps:
            p = self.mask_px[i] + 3 * down
            x, y = int(round(p[0])), int(round(p[1]))
            win = depth_m[max(0, y - 2):y + 3, max(0, x - 2):x + 3]
            z = float(np.median(win[win > 0])) if (win > 0).any() else 0.0
            if z <= 0:
                raise AlignError("no table depth below the contact edge")
            lifted.append(_ray(self.mask_px[i], K)[0] * z)
        uv, _ = project_mesh(self.verts, R, t, scale, K)
        model_idx = self._contact_edge(uv, down, n)
        model_idx = model_idx[model_idx >= 0]
        mreps = [model_idx[0], model_idx[len(model_idx) // 2], model_idx[-1]]
        a = self.verts[mreps] @ R.T
        span = np.linalg.norm(a[0] - a[2])
        if span < 1e-9:
            raise AlignError("model contact edge is a point")
        scale = float(np.linalg.norm(lifted[0] - lifted[2]) / span)
        t = lifted[1] - scale * a[1]
        return scale, t, {"contact_points": [self.mask_px[i].tolist() for i in reps]}

    # ---- refinement -----------------------------------------------------------------------------
    def _refine(self, R, t, scale, plane, window, yaw_free):
        """Silhouette refinement on the plane (Nelder-Mead over shift, log-scale and, with
        ``yaw_free``, yaw). Bounded: at most ``refine_evals`` silhouette renders (a pose met
        again is not redrawn). Monotone: the pose returned is the lowest-error one evaluated, the
        start among them, so the error (1 - soft silhouette IoU) never ends above the start's.
        Returns (R, t, scale, silhouette (h, w) bool in ``window`` of that pose, info: the
        start's and the end's error and the renders drawn)."""
        n = plane.normal
        e1 = unit(np.cross(n, [1.0, 0, 0]) if abs(n[0]) < 0.9 else np.cross(n, [0, 1.0, 0]))
        e2 = np.cross(n, e1)
        obs = _soft(window.obs)
        shown = 1.0 if window.occluders is None else 1.0 - window.occluders
        obs = obs * shown
        pivot = t + scale * self._footprint(R, n)[0]  # contact centre

        def pose(x):
            dx, dy, ls, yaw = x[0], x[1], x[2], x[3] if yaw_free else 0.0
            Ry = rotation_about(n, yaw)
            R1 = Ry @ R
            s1 = scale * np.exp(ls)
            p1 = pivot + dx * e1 + dy * e2
            foot, low = self._footprint(R1, n)
            t1 = p1 - s1 * foot
            t1 = t1 - (n @ t1 + s1 * low + plane.offset) * n  # rest on the plane
            return R1, t1, s1

        errors: dict[bytes, float] = {}  # by pose parameters: a vertex met again is not redrawn
        best = {"error": np.inf}

        def cost(x):
            key = np.asarray(x, dtype=np.float64).tobytes()
            if key not in errors:
                R1, t1, s1 = pose(x)
                sil = self._silhouette(R1, t1, s1, window)
                ren = _soft(sil) * shown
                inter = np.minimum(obs, ren).sum()
                errors[key] = 1.0 - inter / max(np.maximum(obs, ren).sum(), 1e-9)
                if errors[key] < best["error"]:
                    best.update(error=errors[key], x=np.array(x, dtype=np.float64), sil=sil)
            return errors[key]

        x = np.zeros(4 if yaw_free else 3)
        start = cost(x)
        step = np.array([0.004, 0.004, 0.05, np.radians(5)])[:len(x)]
        for _ in range(2):  # a restart with a fresh simplex escapes early collapse
            simplex = np.vstack([x] + [x + np.eye(len(x))[i] * step[i] for i in range(len(x))])
            # scipy stops a run at maxfev calls of cost, memoised ones included
            minimize(cost, x, method="Nelder-Mead",
                     options={"initial_simplex": simplex, "maxfev": self.cfg.refine_evals // 2,
                              "xatol": 1e-4, "fatol": 1e-5})
            x = best["x"]
            step = step / 3
        R1, t1, s1 = pose(best["x"])
        return R1, t1, s1, best["sil"], {"refine_error_start": round(float(start), 5),
                                         "refine_error": round(float(best["error"]), 5),
                                         "refine_renders": len(errors)}

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
    def _depth_correction(self, R, t, scale, mask, depth_m, plane) -> tuple[float, dict]:
        """Factor ``f`` for a similarity about the camera centre (``t *= f``, ``scale *= f``),
        which leaves the silhouette unchanged, that brings the placed model's front surface onto
        the raw depth readings lying on it: readings within ``depth_inlier`` of the model,
        a robust median of their ratio, iterated. Glass gives few such readings (most are holes
        or see-through); with fewer than ``depth_min_share`` of the mask, nothing changes.

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
        uv, pts = project_mesh(self.verts, R, t, scale, self.K)
        z_model = surface_depth(uv, pts, self.faces, self.K, xs, ys, mask.shape)
        hit = np.isfinite(z_model)
        raw, z_model = depth_m[ys, xs].astype(np.float64)[hit], z_model[hit]
        start = self._depth_vote(raw, z_model, np.column_stack([xs, ys])[hit], plane, need)
        lo, hi = start * (1 - cfg.depth_max_change), start * (1 + cfg.depth_max_change)
        factor, inliers = start, np.zeros(len(raw), bool)
        for _ in range(3):
            inliers = np.abs(raw - factor * z_model) < cfg.depth_inlier
            if inliers.sum() < need:
                return 1.0, {**info, "raw_inliers": int(inliers.sum())}
            factor = float(np.clip(np.median(raw[inliers] / z_model[inliers]), lo, hi))
        return factor, {**info, "raw_inliers": int(inliers.sum()), "depth_factor": round(factor, 5)}

    def _depth_vote(self, raw, z_model, px, plane, need) -> float:
        """The factor within ``depth_search`` on whose surface most off-table readings lie, if
        it beats the placed surface (factor 1) ``depth_vote`` times over and holds
        ``depth_agree`` of them; else 1."""
        cfg = self.cfg
        if cfg.depth_search <= cfg.depth_max_change:
            return 1.0
        off = plane.height(unproject(px.astype(np.float64), raw, self.K)) > cfg.depth_inlier
        raw, z_model = raw[off], z_model[off]
        steps = int(np.ceil(cfg.depth_search / 0.005))  # factors 0.5% apart
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
        if mask.sum() < 20:
            raise AlignError(f"mask has {int(mask.sum())} px: too small to place a mesh")
        if len(mesh.faces) < 4 or not np.isfinite(mesh.vertices).all() or \
                np.ptp(mesh.vertices, axis=0).min() <= 1e-9:
            raise AlignError("degenerate mesh (fewer than 4 faces, not finite, or flat)")
        if plane is None:
            raise AlignError("no support plane visible: cannot place the object")
        self.K = K
        self.verts = np.asarray(mesh.vertices, dtype=np.float64)
        self.faces = np.asarray(mesh.faces)
        ys, xs = np.nonzero(mask)
        self.mask_px = np.column_stack([xs, ys]).astype(np.float64)
        window = _Window(mask, cfg.window, None if cfg.mode == "paper" else occluders)
        matcher = ViewMatcher(mask, alpha=cfg.alpha, beta=cfg.beta, gamma=cfg.gamma,
                              patches=cfg.patches)
        # the object's place on the table and the image's "down" there
        centre = self.mask_px.mean(0)
        bottom = self.mask_px[np.argmax(self.mask_px @ plane.down_at(centre, K))]
        anchor = plane.intersect(_ray(bottom, K))[0]
        if not np.all(np.isfinite(anchor)):
            raise AlignError("the object's contact edge does not meet the support plane")
        down = plane.down_at(bottom, K)
        symmetric = is_axisymmetric(mesh)
        plain = cfg.mode == "paper"
        searched = {"candidates": 0}
        extent_px = float(max(np.ptp(xs), np.ptp(ys)) + 1)
        renders = [0]  # silhouettes drawn for this placement (see render_bound)

        def searched_candidates():
            """View matching over the candidate orientations: the best view of each resting
            orientation (the best few) goes on to keypoints and refinement."""
            if plain:
                rotations = candidates_sphere(cfg.views, cfg.rolls, -unit(anchor))
            else:
                rotations = candidates_plane(mesh, plane.normal, symmetric, cfg.yaw_steps,
                                             cfg.max_rests)
            searched["candidates"] = len(rotations)
            renders[0] += len(rotations)
            scored = []
            for i, (group, R) in enumerate(rotations):
                s0 = self._size_guess(R, anchor, plane, extent_px)
                t0 = self._rest_translation(R, s0, anchor, plane)
                view, _ = matcher.render_and_score(self.verts, self.faces, R, t0, s0, K,
                                                   window.spec)
                # objects stand the right way up more often than upside down (+z up)
                prior = 0.0 if plain else cfg.upright_prior * max(0.0, float(R[:, 2]
                                                                             @ plane.normal))
                scored.append((view.total + prior, prior, group, i, R, s0, t0, view))
            scored.sort(key=lambda c: -c[0])
            carried, groups = [], set()
            for c in scored:
                if c[2] not in groups:
                    groups.add(c[2])
                    carried.append(c)
            return carried[:1 if plain else cfg.top_candidates]

        def hinted():
            if hint is None or plain:
                return []
            T_h, s_h = np.asarray(hint[0], dtype=np.float64), float(hint[1])
            renders[0] += 1
            view, _ = matcher.render_and_score(self.verts, self.faces, T_h[:3, :3], T_h[:3, 3],
                                               s_h, K, window.spec)
            prior = cfg.upright_prior * max(0.0, float(T_h[:3, 2] @ plane.normal))
            return [(view.total, prior, "hint", -1, T_h[:3, :3], s_h, T_h[:3, 3], view)]

        def refine(R, t, scale):
            """(R, t, scale, its silhouette in ``window`` or None, refinement info)."""
            if not cfg.refine:
                return R, t, scale, None, {}
            R, t, scale, sil, info = self._refine(
                R, t, scale, plane, window, yaw_free=not (symmetric and self._upright(R, plane)))
            renders[0] += info["refine_renders"]
            return R, t, scale, sil, info

        best = None
        for batch in (hinted, searched_candidates):
            if best is not None and best[1] >= cfg.hint_accept:
                break  # the reconstruction's own pose explains the mask: no search needed
            for _total, prior, group, i, R, s0, t0, view in batch():
                sil = None
                if group == "hint":
                    diag = {"seed": "reconstruction pose"}
                    if cfg.refine_hint:
                        R, t, scale, sil, info = refine(R, t0, s0)
                        diag.update(info)
                    else:
                        t, scale = t0, s0
                elif plain:
                    scale, t, diag = self._keypoints_paper(R, s0, t0, down, depth_m)
                else:
                    try:
                        scale, t, diag = self._keypoints_sr3d(R, s0, t0, plane, down)
                    except AlignError:
                        continue
                    R, t, scale, sil, info = refine(R, t, scale)
                    diag = {**diag, **info}
                if sil is None:
                    sil = self._silhouette(R, t, scale, window)
                    renders[0] += 1
                iou = mask_iou(sil, window.obs, window.occluders)
                if best is None or iou + prior > best[0]:
                    best = (iou + prior, iou, i, R, t, scale, view, diag)
        if best is None:
            raise AlignError("no candidate orientation could be matched to the contact edge")
        _, iou, i, R, t, scale, view, diag = best
        if cfg.use_depth and not plain:
            factor, info = self._depth_correction(R, t, scale, mask, depth_m, plane)
            t, scale = np.asarray(t, dtype=np.float64) * factor, scale * factor
            diag = {**diag, **info}
        scores = {"view": round(view.total, 4), "ssim": round(view.ssim, 4),
                  "edges": round(view.edges, 4), "aspect": round(view.aspect, 4),
                  "silhouette_iou": round(iou, 4)}
        diagnostics = {"mode": cfg.mode, "best_view": int(i),
                       "candidates": searched["candidates"], "axisymmetric": bool(symmetric),
                       "renders": renders[0], **diag}
        return Placement(R, np.asarray(t, dtype=np.float64), float(scale), scores, diagnostics)

    @staticmethod
    def _upright(R, plane) -> bool:
        return abs((R @ np.array([0, 0, 1.0])) @ plane.normal) > 0.999
