"""Training-free antipodal grasp planner on a scene point cloud.

For each object: seed points on its surface, as many on each slice along its length; across each
seed, along its normal, the farthest point of the same object within the gripper's opening (the
antipode), and the nearest too where it differs (across one wall); the closing direction is the
line between them (across a thin wall or stem, the two normals) and approach directions are
sampled around the table normal, perpendicular to it. Each candidate frame is tried at several depths
(deepest first): the object's cross-section between the fingers sets the opening and the centre,
the fingers and palm must hold no scene point and stay above the table, and the contact normals
must lie inside the friction cone. Score: friction margin, opening margin, approach from above and
a grasp centre near half the object's height (on a placed model, for jaws around its axis: pads
far from a change of its section), weighted (config), less where a finger reaches the object's
top end. Non-maximum suppression, then the
best K per object; where the object has a placed mesh, the best of the first 3K are scored again
with the friction their exact contacts on it need (the jaws closed onto its triangles, as the
evaluator closes them on a true mesh), the worst of the grasp as planned and moved
``height_tolerance`` either way along the mesh's height axis (and, for a pinch across one
wall, turned ``tilt_tolerance`` degrees against the wall's slope; for a lying vessel whose
mouth the image leaves open or shut, on its open form as well). An object where nothing holds
(with a placed mesh: whose best grasp's exact contacts do not hold) gets other seed points
(``redraws``). Where still nothing holds, the object goes down a ladder until something does:
an object given a fallback (a lying vessel's model opened at its wider end,
:func:`sr3d_cli.reconstruct.unseen_mouth`) is planned on it, without the object's own depth
(rendered from the closed model); then both with the margins narrowed (``tight_margins``,
:meth:`Planner.tightened`); then both accepting contacts up to ``fallback_friction``
(:meth:`Planner.relaxed`); an object that already has grasps, failing ones, gets a brief
look on the later rungs (:meth:`Planner.brief`). It keeps the grasps whose best needs the
least friction on the model, and a message says when even those need more than ``friction``.
Last, each grasp opens as wide as the gripper and the scene let it (``open_wide``,
:meth:`Planner._opened`): the jaws then close from farther out, so a model a few millimetres
narrower than its object, or off to one side, still leaves the fingers clear of it.

Objects that were placed (aligned meshes) contribute points sampled all over the mesh with the
mesh's normals, so the antipode behind the object is known (a wall an open mesh models by
one sheet gets its other side, :func:`mesh_cloud`); otherwise the cloud holds only what the
depth sees. A placed model can be wrong (a handle or a spout it lacks, a flat bottle fitted
round, a fit too thin or shifted); the sensor's own readings on the objects, which the repaired
depth replaces with the models, still show where surfaces are: a grasp whose fingers hold
readings no model accounts for is contradicted by the observation and dropped
(:meth:`Planner._observation_agrees`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sr3d_cli.geometry.camera import depth_normals, depth_to_points, project, unproject
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.raycast import first_hits
from sr3d_cli.geometry.transforms import place_points, rotation_about
from sr3d_cli.geometry.transforms import unit as _unit
from sr3d_cli.grasp import GraspSet
from sr3d_cli.grasp.gripper import Gripper, count_inside, to_local


@dataclass
class Cloud:
    """points (n, 3) metres, normals (n, 3) unit (0 = unknown), labels (n,) object id (0 = none)."""

    points: np.ndarray
    normals: np.ndarray
    labels: np.ndarray

    @classmethod
    def concat(cls, clouds: list["Cloud"]) -> "Cloud":
        return cls(np.concatenate([c.points for c in clouds]),
                   np.concatenate([c.normals for c in clouds]),
                   np.concatenate([c.labels for c in clouds]))

    def select(self, keep: np.ndarray) -> "Cloud":
        return Cloud(self.points[keep], self.normals[keep], self.labels[keep])


def depth_cloud(depth_m: np.ndarray, K: np.ndarray, ids: np.ndarray, stride: int = 1) -> Cloud:
    """Every ``stride``-th valid pixel of a depth map, normals from the depth, labels from ids."""
    pts = depth_to_points(np.where(np.isfinite(depth_m), depth_m, 0.0), K)
    nrm = depth_normals(pts, stride=stride)
    sl = (slice(None, None, stride), slice(None, None, stride))
    pts, lab = pts[sl], ids[sl]
    ok = pts[..., 2] > 0
    return Cloud(pts[ok], nrm[ok], lab[ok].astype(np.int64))


def observed_cloud(depth_m: np.ndarray, K: np.ndarray, ids: np.ndarray,
                   stride: int = 1) -> Cloud:
    """The sensor's valid readings (depth ``(H, W)`` metres, 0 or nan: none) on the objects'
    masks (``ids (H, W)`` int, 0 = none), every ``stride``-th pixel, back-projected, labelled by
    ``ids``; normals unknown (0). These are the readings a repaired depth replaces with the
    placed models: each is a surface, whatever the model says (a see-through reading: the
    surface behind). Each reading's depth is the median of the readings on its surface (within
    :data:`SAME_SURFACE` of it) in the window :data:`DENOISE_RADIUS` pixels around it: a
    glass's front-surface returns scatter by several millimetres along their rays, and one
    alone would put a surface inside a finger that the median of its neighbours puts on the
    object (see :meth:`Planner.plan`)."""
    depth = np.where(np.isfinite(depth_m), depth_m, 0.0).astype(np.float64)
    keep = np.zeros(depth.shape, bool)
    keep[::stride, ::stride] = True
    v, u = np.nonzero(keep & (depth > 0) & (ids > 0))
    r = DENOISE_RADIUS
    padded = np.pad(depth, r)
    z = depth[v, u]
    around = np.stack([padded[v + r + dv, u + r + du] for dv in range(-r, r + 1)
                       for du in range(-r, r + 1)], axis=1)          # (n, (2r + 1)^2)
    same = (around > 0) & (np.abs(around - z[:, None]) < SAME_SURFACE)  # the reading is one
    ranked = np.sort(np.where(same, around, np.inf), axis=1)
    count, rows = same.sum(axis=1), np.arange(len(z))
    z = (ranked[rows, (count - 1) // 2] + ranked[rows, count // 2]) / 2  # their median
    pts = unproject(np.column_stack([u, v]), z, K)
    return Cloud(pts, np.zeros_like(pts), ids[v, u].astype(np.int64))


def unexplained(observed: Cloud, models: list["Sections"]) -> Cloud:
    """The readings of ``observed`` that no placed model (``models``, their outer outlines)
    accounts for: every point of the reading's ray within :data:`RAY_NOISE` of it (a depth
    reading errs along its ray, a glass's front-surface return by several millimetres) lies
    farther than :data:`EXPLAINED` outside each model. A reading inside a model's outline may
    be its surface or one seen through it; one outside every model is a surface the models
    lack (a handle, a spout, a flat bottle's edge, an object wider than its fit)."""
    points = observed.points
    rays = _unit(points)
    keep = np.ones(len(points), bool)
    for step in np.linspace(-RAY_NOISE, RAY_NOISE, RAY_STEPS):
        for model in models:
            left = np.flatnonzero(keep)
            keep[left] = model.outside(points[left] + step * rays[left], EXPLAINED)
    return observed.select(keep)


def mesh_cloud(mesh, T_cam_obj: np.ndarray, scale: float, label: int, count: int,
               seed: int = 0) -> Cloud:
    """Points spread evenly over a placed mesh's surface, with its outward face normals.

    A mesh that is not closed may model a wall by one sheet (a scanned glass: its outer surface
    alone, open at the mouth), and a sheet has no antipode across the wall to pair a sample
    with: a glass wider than the opening, which only a pinch across its rim can hold, would get
    no grasp. Where nothing of such a mesh lies within :data:`SHEET_REACH` behind a sample
    (:func:`on_sheet`), the sheet's other side is added, :data:`SHEET_WALL` behind it with the
    opposite normal (so ``count`` and more points come back)."""
    import trimesh

    placed = trimesh.Trimesh(place_points(mesh.vertices, T_cam_obj, scale), mesh.faces,
                             process=False)
    pts, faces = trimesh.sample.sample_surface(placed, count, seed=seed)
    pts, nrm = np.asarray(pts), np.asarray(placed.face_normals[faces])
    if not placed.is_watertight:
        sheet = on_sheet(pts, nrm, np.asarray(placed.triangles))
        pts = np.vstack([pts, pts[sheet] - SHEET_WALL * nrm[sheet]])
        nrm = np.vstack([nrm, -nrm[sheet]])
    return Cloud(pts, nrm, np.full(len(pts), label, dtype=np.int64))


def on_sheet(points: np.ndarray, normals: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``(n,) bool``: the surface samples ``points (n, 3)`` (outward unit ``normals (n, 3)``)
    behind which no triangle of ``triangles (m, 3, 3)`` lies within :data:`SHEET_REACH`
    along the inward normal: a wall its mesh models by one sheet. The samples go in groups,
    one per cube of twice that reach, each against the triangles near its cube (a scan's tens
    of thousands of triangles against every sample at once would take gigabytes)."""
    out = np.zeros(len(points), bool)
    if not len(points) or not len(triangles):
        return out
    _, group = np.unique(np.floor(points / (2 * SHEET_REACH)).astype(np.int64), axis=0,
                         return_inverse=True)
    group = group.ravel()
    lo_tri, hi_tri = triangles.min(axis=1), triangles.max(axis=1)
    for idx in np.split(np.argsort(group, kind="stable"), np.cumsum(np.bincount(group))[:-1]):
        lo = points[idx].min(axis=0) - SHEET_REACH
        hi = points[idx].max(axis=0) + SHEET_REACH
        near = np.all((hi_tri >= lo) & (lo_tri <= hi), axis=1)
        dist, _ = first_hits(points[idx] - SHEET_START * normals[idx], -normals[idx],
                             triangles[near], max_distance=SHEET_REACH, chunk=1024)
        out[idx] = ~np.isfinite(dist)
    return out


def in_view(cloud: Cloud, K: np.ndarray, shape: tuple[int, int]) -> Cloud:
    """The points of ``cloud`` the camera sees the place of (in front of it, inside the image
    ``shape``): a placed mesh runs past the border where the image cuts its object, and a
    grasp there would rest on a made-up surface."""
    front = cloud.points[:, 2] > 0
    u, v = project(np.where(front[:, None], cloud.points, [0.0, 0.0, 1.0]), K).T
    return cloud.select(front & (u >= 0) & (u <= shape[1] - 1) & (v >= 0) & (v <= shape[0] - 1))


def rotation_distance(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle (radians) between grasp rotations ``(n, 3, 3)`` and one ``(3, 3)``, counting a
    turn of 180 deg about the approach as the same grasp (the jaws are symmetric)."""
    flip = np.diag([1.0, -1.0, -1.0])

    def angle(R):
        c = (np.einsum("nij,ij->n", Ra, R) - 1) / 2
        return np.arccos(np.clip(c, -1, 1))

    return np.minimum(angle(Rb), angle(Rb @ flip))


def nms(grasps: GraspSet, distance: float, angle_rad: float) -> GraspSet:
    """Greedy non-maximum suppression: best first; drop grasps near a kept one in both position
    and rotation."""
    g = grasps.sorted()
    keep: list[int] = []
    alive = np.ones(len(g), dtype=bool)
    for i in range(len(g)):
        if not alive[i]:
            continue
        keep.append(i)
        near = (np.linalg.norm(g.t - g.t[i], axis=1) < distance) & \
            (rotation_distance(g.R, g.R[i]) < angle_rad)
        alive &= ~near
    return g.take(np.array(keep, dtype=np.int64))


EXACT_MU_CAP = 2.0  # friction coefficient counted for exact contacts needing more (Planner._rescore)
EXACT_FIRST = 3  # best grasps per object always scored by exact contacts (Planner._rescore)
EXACT_POOL = 3   # times top_k grasps the rescoring may reach into (Planner._object)
THIN_PAIR = 3.0  # a pair shorter than this many pair radii spans a thin wall (Planner._frames)
LATE_REDRAWS = 1  # redraws of a later rung for an object with failing grasps (Planner.brief)
SURE = 1e-5  # m, kept from a box's faces where a test on other coordinates must agree
SHEET_WALL = 0.0025  # m: the wall one sheet of an open mesh stands for (glass: 1-4 mm)
SHEET_REACH = 0.01  # m: nothing of its mesh this near behind a sample: it lies on one sheet
SHEET_START = 1e-5  # m behind a sample its ray starts, so that its own triangle is not met
CHUNK = 96  # frames tried at once (Planner._try_frames): 48 is ~7% slower, 192 no faster
MIN_SECTION = 3  # target points under the pads that make a section (fewer: a stray sample)
OPENINGS = (1.0, 0.5, 0.25)  # shares of the spare opening tried in turn (Planner._opened)
MAX_CONTACT_ANGLE = np.radians(89.9)  # a contact's angle is capped here: tan stays finite
EXPLAINED = 0.003  # m, a reading this near a placed model's outline may be its surface
RAY_NOISE = 0.004  # m, a reading made a median (observed_cloud) errs up to this along its ray
RAY_STEPS = 5  # points tried along it, under EXPLAINED from the next (2 mm apart)
SAME_SURFACE = 0.012  # m, readings this near in depth lie on one surface: 3 sd of a glass return
DENOISE_RADIUS = 2  # px, the window (5 x 5) whose readings on one surface give its median


RUN_TOLERANCE = 0.001  # m: a section this near a run's line continues it (Sections.margin)
RUN_TAPER = 0.05       # m/m: and this much more per height away
RUN_SLOPE_SPAN = 0.003  # m: a run's slope is the section's this far up and down


@dataclass
class Sections:
    """A placed model's outer radius along its height axis ``along``: ``radius[i]`` at height
    ``h0 + i * step`` above ``origin`` (the mean of its vertices: on the axis of a revolved
    mesh), for :meth:`Planner.score`."""

    along: np.ndarray
    origin: np.ndarray
    h0: float
    step: float
    radius: np.ndarray

    @classmethod
    def of(cls, triangles: np.ndarray, along: np.ndarray, step: float = 0.001) -> "Sections":
        """From a model's triangles ``(m, 3, 3)``: the largest radius at each height, along
        every edge (between its ends' radii), so a vessel's inner surface never stands for the
        outer one between two of its rings."""
        origin = triangles.reshape(-1, 3).mean(axis=0)
        rel = triangles - origin
        h = rel @ along
        r = np.linalg.norm(rel - h[..., None] * along, axis=-1)
        h0 = float(h.min())
        radius = np.zeros(int(np.ceil((h.max() - h0) / step)) + 1)
        # each edge's heights on the grid, and its radius there
        ha, hb = h.ravel(), np.roll(h, -1, axis=1).ravel()
        ra, rb = r.ravel(), np.roll(r, -1, axis=1).ravel()
        first = np.ceil((np.minimum(ha, hb) - h0) / step - 1e-9).astype(np.int64)
        count = np.maximum(np.floor((np.maximum(ha, hb) - h0) / step + 1e-9).astype(np.int64)
                           - first + 1, 0)
        edge = np.repeat(np.arange(len(ha)), count)
        at = first[edge] + np.arange(len(edge)) - np.repeat(np.cumsum(count) - count, count)
        span = hb[edge] - ha[edge]
        frac = np.clip((h0 + at * step - ha[edge]) / np.where(span != 0, span, 1), 0, 1)
        np.maximum.at(radius, np.minimum(at, len(radius) - 1),
                      ra[edge] + frac * (rb[edge] - ra[edge]))
        return cls(along, origin, h0, step, radius)

    def height(self, points: np.ndarray) -> np.ndarray:
        return (points - self.origin) @ self.along

    def outside(self, points: np.ndarray, tolerance: float) -> np.ndarray:
        """Which ``points (n, 3)`` lie farther than ``tolerance`` (m) outside the model: past
        its outer radius at their height, or past either end. (n,) bool."""
        h = self.height(points)
        z = self.h0 + self.step * np.arange(len(self.radius))
        r = np.linalg.norm(points - self.origin - np.outer(h, self.along), axis=1)
        beyond = (h < z[0] - tolerance) | (h > z[-1] + tolerance)
        return beyond | (r > np.interp(h, z, self.radius) + tolerance)

    def margin(self, h: np.ndarray, below: np.ndarray, above: np.ndarray,
               end: float, drop: float = 0.0) -> np.ndarray:
        """How far pads from ``h - below`` to ``h + above`` (heights, clipped to the model)
        stay inside the straight run (a cylinder or a cone) around ``h``: the heights where the
        radius stays within :data:`RUN_TOLERANCE`, plus :data:`RUN_TAPER` per metre away, of
        the line through the section at ``h`` (its radius, and its slope over
        :data:`RUN_SLOPE_SPAN` either way), up to a kink (a stem's junction, a shoulder). A
        run reaching within ``end`` of the model's base has no edge there (the table keeps
        the fingers off it); the top end is one (a rim's lip, a neck's flare). A run that ends
        under a wider part (a stem under a bowl) ends ``drop`` lower (:meth:`Planner.score`)."""
        z = self.h0 + self.step * np.arange(len(self.radius))
        top = z[-1]
        ref = np.interp(h, z, self.radius)
        slope = (np.interp(h + RUN_SLOPE_SPAN, z, self.radius)
                 - np.interp(h - RUN_SLOPE_SPAN, z, self.radius)) / (2 * RUN_SLOPE_SPAN)
        dz = z[None] - h[:, None]
        off = np.abs(self.radius[None] - ref[:, None] - slope[:, None] * dz) > \
            RUN_TOLERANCE + RUN_TAPER * np.abs(dz)
        run_hi = np.where(off & (dz > 0), z[None], np.inf).min(axis=1)
        run_lo = np.where(off & (dz < 0), z[None], -np.inf).max(axis=1)
        if drop > 0:  # a run ending under a wider part (a stem under a bowl) ends lower
            i = np.minimum(np.searchsorted(z, run_hi), len(z) - 1)
            wider = self.radius[i] > ref + slope * (z[i] - h)
            run_hi = np.where(np.isfinite(run_hi) & wider, run_hi - drop, run_hi)
        run_hi = np.minimum(run_hi, top)
        run_lo = np.where(run_lo < self.h0 + end, -np.inf, run_lo)
        pad_hi = np.minimum(h + above, top)
        pad_lo = np.maximum(h - below, self.h0)
        return np.minimum(run_hi - pad_hi, pad_lo - run_lo)


def _across_wall(t: np.ndarray, width, along: np.ndarray, on_axis: np.ndarray):
    """Whether a grasp (centre ``t``, opening ``width``; or ``(n, 3)`` and ``(n,)``) pinches
    one wall of a solid of revolution (axis ``along`` through ``on_axis``): its centre lies
    farther from the axis than half the opening, so the jaws do not close around the axis (a
    rim pinch, one finger inside the vessel) as they do across a body, a neck or a stem."""
    off = t - on_axis
    return np.linalg.norm(off - np.multiply.outer(off @ along, along), axis=-1) > \
        np.asarray(width) / 2


class Planner:
    def __init__(self, cfg):
        self.cfg = cfg
        self.gripper = Gripper.from_config(cfg)

    def plan(self, scene: Cloud, targets: dict[int, Cloud], plane: Plane,
             surfaces: dict[int, np.ndarray] | None = None,
             fallbacks: dict[int, tuple[Cloud, Cloud, np.ndarray]] | None = None,
             axes: dict[int, np.ndarray] | None = None,
             observed: Cloud | None = None) -> tuple[GraspSet, list[str]]:
        """Grasps for every object in ``targets`` (contact points), checked against ``scene``
        (every point that can collide, targets included). ``surfaces``: the placed mesh's
        triangles (m, 3, 3) of objects that have one; their best grasps are scored again with
        the jaws closed exactly on it (:meth:`_rescore`). ``fallbacks``: (scene, target,
        triangles) to plan an object on where nothing on its own holds (a lying vessel opened
        at its wider end); its triangles also check the closed model's grasps. ``axes``: a
        placed mesh's height axis (camera frame), along which its fitted height may be off
        (default: the table normal). ``observed``:
        the sensor's readings where ``scene`` shows something else (:func:`observed_cloud`:
        the placed models rendered over the objects' masks); a grasp whose gripper holds
        some is contradicted by them (:meth:`_observation_agrees`). Returns (grasps, object
        messages)."""
        sets, messages = [], []
        surfaces, fallbacks, axes = surfaces or {}, fallbacks or {}, axes or {}
        if observed is not None:
            observed = unexplained(observed, [Sections.of(t, axes.get(k, plane.normal))
                                              for k, t in surfaces.items()])
        planners = [self] + ([self.tightened()] if self.cfg.tight_margins > 0 else [])
        if self.cfg.fallback_friction > self.cfg.friction:
            planners.append(self.relaxed())
        # each rung, and its brief look for an object that already has (failing) grasps
        ladder = [(p, p if p is self else p.brief()) for p in planners]
        for k in sorted(targets):
            axis = axes.get(k)
            # the closed model's exact contacts are also closed on its open form, which the
            # image leaves as likely (see _rescore); the open form itself is planned on alone
            opened = fallbacks[k][2] if k in fallbacks else None
            tries = [(targets[k], scene, surfaces.get(k), opened)]
            if k in fallbacks:
                other_scene, other_target, triangles = fallbacks[k]
                tries.append((other_target, other_scene, triangles, None))
            # down the ladder while nothing holds: the grasps whose best needs the least
            # friction on the model (exact contacts where it was placed), the first that hold
            found, why, need, exact = GraspSet.empty(), "", np.inf, True
            for full, short in ladder:
                planner = short if len(found) else full
                for target, cloud, triangles, other in tries:
                    grasps, reason, mu = planner._object(k, target, cloud, plane, triangles, axis,
                                                         observed, other)
                    why = why or reason
                    if triangles is None and planner.cfg.friction > self.cfg.friction:
                        mu = planner.cfg.friction  # sampled contacts held only at this one
                    if len(grasps) and mu < need:
                        found, need, exact = grasps, mu, triangles is not None
                    if need <= self.cfg.friction:
                        break
                if need <= self.cfg.friction:
                    break
            if len(found) == 0:
                messages.append(f"object {k}: no grasp ({why})")
            elif need > self.cfg.friction:
                messages.append(f"object {k}: nothing holds at friction {self.cfg.friction} on "
                                f"the model; the best grasp needs "
                                f"{'' if exact else 'up to '}{min(need, EXACT_MU_CAP):.2f}")
            sets.append(found)
        return GraspSet.concat(sets), messages

    def tightened(self) -> "Planner":
        """This planner with its opening and collision margins times ``tight_margins``, for
        an object where nothing holds with them: one nearly as wide as the opening (a lying
        beaker 75.5 mm across, in the 80 mm opening less 2 x 4 mm) is better tried tight than
        not at all."""
        f = self.cfg.tight_margins
        return Planner(replace(self.cfg, width_margin=f * self.cfg.width_margin,
                               collision_margin=f * self.cfg.collision_margin))

    def relaxed(self) -> "Planner":
        """This planner accepting contacts up to ``fallback_friction``, for an object nothing
        holds on at ``friction`` even with tight margins: the model's contacts are a few
        degrees off the true ones, and the best grasp there is beats none (a lying beaker
        wider than the opening, pinched at its mouth, can need 0.6-2 on the model's rim and
        under 0.3 on the true one)."""
        return Planner(replace(self.cfg, friction=self.cfg.fallback_friction))

    def brief(self) -> "Planner":
        """This planner with at most one redraw (``LATE_REDRAWS``), for the later rungs of the
        ladder where an object already has grasps that fail on its model: with all of them
        the ladder would double the grasp stage's time on frames with such objects."""
        return Planner(replace(self.cfg, redraws=min(self.cfg.redraws, LATE_REDRAWS)))

    # -- one object -----------------------------------------------------------------------------

    def _object(self, k: int, target: Cloud, scene: Cloud, plane: Plane,
                surface: np.ndarray | None = None, axis: np.ndarray | None = None,
                observed: Cloud | None = None, opened: np.ndarray | None = None
                ) -> tuple[GraspSet, str, float]:
        """Grasps for object ``k``, a reason where there are none, and the friction the best
        one's exact contacts on the placed model ``surface`` need (0 without one: its
        sampled contacts held); with ``opened`` (the triangles (m, 3, 3) of the same model
        open at one end), the worse of the two (:meth:`_rescore`)."""
        cfg, g = self.cfg, self.gripper
        has_normal = np.linalg.norm(target.normals, axis=1) > 0.5
        target = target.select(has_normal)
        if len(target.points) < 20:
            return GraspSet.empty(), f"{len(target.points)} surface points, too few", np.inf
        top = max(float(plane.height(target.points).max()), 1e-6)
        centre = target.points.mean(axis=0)
        radius = g.reach() + np.ptp(target.points, axis=0).max()

        def collides(points):
            # near enough to touch; the table is checked exactly by the plane test, and points
            # at its height cannot be hit by a gripper that passes it
            return (np.linalg.norm(points - centre, axis=1) < radius) & \
                (plane.height(points) >= cfg.clearance)

        scene = scene.select(collides(scene.points))
        solid = collides(target.points)  # the target's points among them (see _try_frames)
        if observed is not None:
            observed = observed.select(collides(observed.points))
        # an object with few holdable places (a goblet's stem, a wide beaker's rim) may get no
        # seed on them: draw other seeds, up to ``redraws`` times, while nothing holds (with a
        # placed mesh: while the best grasp's exact contacts do not hold)
        rng = np.random.default_rng([cfg.seed, k])
        along = plane.normal if axis is None else axis
        end = (along, float((target.points @ along).max()))  # the top end: rim, neck
        sections = None if surface is None else Sections.of(surface, along)
        grasps, pairs, mu = GraspSet.empty(), 0, np.inf
        for _ in range(1 + cfg.redraws):
            R, c, span = self._frames(target, plane, rng)
            pairs += len(R)
            found = [self._try_frames(k, R[s:s + CHUNK], c[s:s + CHUNK], span[s:s + CHUNK],
                                      target, scene, plane, top, end, sections, solid,
                                      observed)
                     for s in range(0, len(R), CHUNK)]
            grasps = GraspSet.concat([grasps] + [f for f in found if f is not None])
            if len(grasps) == 0:
                continue
            grasps = nms(grasps, cfg.nms_distance, np.radians(cfg.nms_angle))
            if surface is None:
                break
            # from a deeper pool: where the exact contacts fail the first ten, the next may hold
            grasps, mu = self._rescore(grasps.take(slice(0, EXACT_POOL * cfg.top_k)), k,
                                       surface, plane, top, end, sections, opened)
            if mu <= cfg.friction:
                break
        if pairs == 0:
            return grasps, "no antipodal pair within the gripper's opening", np.inf
        if len(grasps) == 0:
            return grasps, (f"no collision-free grasp inside the friction cone within the "
                            f"{g.max_width:.3f} m opening"), np.inf
        grasps = grasps.take(slice(0, cfg.top_k))
        if cfg.open_wide:
            grasps = self._opened(grasps, scene, observed, plane)
        return grasps, "", (0.0 if surface is None else mu)

    def _opened(self, grasps: GraspSet, scene: Cloud, observed: Cloud | None,
                plane: Plane) -> GraspSet:
        """The grasps with each opening widened to the widest of :data:`OPENINGS` (shares of
        what the gripper has to spare beyond it) whose fingers' path, from there in to the
        opening planned, holds fewer than ``collision_points`` of the ``scene`` points (the
        object's own included) and of the ``observed`` readings no model accounts for, both
        with the fingers inflated by ``collision_margin`` as in :meth:`_collision_free`, and
        keeps the gripper ``clearance`` above the table; the opening planned where none does.
        The grasp's contacts, centre and score stay: closed from farther out, the jaws meet
        the object where they would have from the planned opening, and the fingers start
        clear of an object a few millimetres wider than its model (measured on
        ../shared/extsim from sr3d's models of the true masks: most failed grasps are fingers
        set down on the object they hold)."""
        g, cfg = self.gripper, self.cfg
        w, d = grasps.widths, grasps.depths
        widths = w.copy()
        todo = g.max_width - w > 1e-6
        local = [to_local(grasps.R, grasps.t, c.points)  # (F, 3, n): every grasp's frame
                 for c in (scene, observed) if c is not None and len(c.points)]
        for share in OPENINGS:
            if not todo.any():
                break
            wide = w + share * (g.max_width - w)
            boxes = g.boxes(wide, d)[:, :2].copy()  # (F, 2, 2, 3): the two fingers
            boxes[:, 0, 1, 1] = -w / 2  # each finger's path: from the wide opening in
            boxes[:, 1, 0, 1] = w / 2
            ok = todo & (g.lowest(grasps.R, grasps.t, wide, d, plane) >= cfg.clearance)
            for pts in local:
                ok &= count_inside(pts, boxes, shrink=-cfg.collision_margin).max(axis=1) \
                    < cfg.collision_points
            widths[ok] = wide[ok]
            todo &= ~ok
        return replace(grasps, widths=widths)

    def score(self, mu: np.ndarray, width: np.ndarray, R: np.ndarray, centre: np.ndarray,
              plane: Plane, top: float, depth: float | np.ndarray,
              end: tuple[np.ndarray, float], sections: Sections | None = None) -> np.ndarray:
        """Grasp scores: friction margin (``mu``: the least coefficient that holds), opening
        margin, approach from above, and a centre near half the object's height (``top``: its
        height above the table), 1 there and 0 at the table and at the top: near the centre of
        mass, and away from rims and shoulders, where a model's small height error moves the
        surface the most; weighted (config). Less ``end_weight`` where a finger (at its
        ``depth``) reaches within ``end_band`` of the object's top end (``end``: the model's
        height axis, base to top, and the top's coordinate along it): a rim's lip or a neck's
        flare, a few millimetres the outline cannot show, stands there, and a pad on it
        slips.

        With the placed model's ``sections``, a grasp whose jaws close around its axis (not a
        pinch across one wall, :func:`_across_wall`) has for centre term how far its fingers
        stay from the ends of their straight run (:meth:`Sections.margin`), in ``run_scale``
        (1 from there on): half the height is the wrong place on a goblet, where it lies in
        the bowl and draws stem grasps to just under the junction, which a carved model often
        puts 10-55 mm too high. A run ending under a wider part counts as ending
        ``junction_drop`` lower, as the junction of a carved goblet errs upwards (its median
        error is 0, but about one in four sits 11-22 mm too high)."""
        cfg = self.cfg
        approach_up = np.clip(R[:, :, 0] @ -plane.normal, 0, 1)
        centred = 1 - 2 * np.abs(np.clip(plane.height(centre) / top, 0, 1) - 0.5)
        along, top_end = end
        up = self.gripper.finger_extent(R, width, depth, along)
        reach = up + centre @ along
        if sections is not None and cfg.run_scale > 0:
            down = self.gripper.finger_extent(R, width, depth, -along)
            run = np.clip(sections.margin(sections.height(centre), down, up, cfg.end_band,
                                          cfg.junction_drop) / cfg.run_scale, 0, 1)
            wall = _across_wall(centre, width, along, sections.origin)
            centred = np.where(wall, centred, run)
        at_end = reach > top_end - cfg.end_band
        return (cfg.friction_weight * (1 - mu / cfg.friction)
                + cfg.width_weight * (1 - width / self.gripper.max_width)
                + cfg.approach_weight * approach_up
                + cfg.centre_weight * centred
                - cfg.end_weight * at_end)

    def _rescore(self, grasps: GraspSet, k: int, surface: np.ndarray, plane: Plane,
                 top: float, end: tuple[np.ndarray, float], sections: Sections,
                 opened: np.ndarray | None = None) -> tuple[GraspSet, float]:
        """Score again with the friction the contacts need where the jaws, closed along the
        closing direction, first touch the placed mesh (``surface`` triangles), as the grasp
        evaluator closes them on a true mesh: the patch normals of :meth:`_try_frames` average
        over sampled points and pass grasps on a rim or a sloped wall whose exact contacts need
        far more. The contacts are also found with the grasp moved ``height_tolerance`` either
        way along the model's height axis (``end``'s, see :meth:`score`; default: the table
        normal), and the worst counts:
        a fitted model's height is off by a few millimetres, and a grasp that holds only at its
        exact height (fingertips on a flask's shoulder, a pad on a beaker's lip) fails on the
        true object. Of a pinch across one wall (jaws that do not close around the model's axis,
        through ``sections.origin``: :func:`_across_wall`), the contacts are also found with
        the grasp turned ``tilt_tolerance`` degrees either way (:meth:`_tilts`). A model with
        an ``opened`` form (triangles (m, 3, 3): a lying vessel whose wider end the image
        leaves open or shut, :func:`sr3d_cli.reconstruct.unseen_mouth`) has a grasp that holds
        on the closed one closed on the open one too, and the worse counts: jaws closing along
        a lying cup's axis hold on its lid and need 4-9 on the rim of its true, open mouth.
        Best first, until the best is one scored so (each costs up to three ray casts, five
        with the turns, twice that with an open form; most objects need one to three). A
        contact needing more than :data:`EXACT_MU_CAP` (or none) counts as that. Returns the
        grasps, sorted, and the friction the best one's exact contacts need."""
        from sr3d_cli.grasp.quality import close_jaws

        tol = self.cfg.height_tolerance
        along = end[0]
        shifts = np.outer([tol, -tol], along) if tol > 0 else None
        scores, checked = grasps.scores.copy(), np.zeros(len(grasps), bool)
        mu = np.full(len(grasps), np.inf)
        todo = list(np.argsort(-scores, kind="stable")[:EXACT_FIRST])
        while len(grasps):
            i = int(todo.pop(0)) if todo else int(np.argmax(scores))
            if checked[i]:
                break
            R, t, w = grasps.R[i], grasps.t[i], float(grasps.widths[i])
            wall = bool(_across_wall(t, w, along, sections.origin))
            tilts = self._tilts(R, along) if wall else None

            def needs(triangles: np.ndarray) -> float:
                return close_jaws(R, t, w, float(grasps.depths[i]), [k], [triangles],
                                  self.gripper, shifts, enough=EXACT_MU_CAP, tilts=tilts)[2]

            mu[i] = needs(surface)
            if opened is not None and mu[i] <= EXACT_MU_CAP:
                mu[i] = max(mu[i], needs(opened))
            scores[i] = self.score(np.array([min(mu[i], EXACT_MU_CAP)]), grasps.widths[i:i + 1],
                                   grasps.R[i:i + 1], grasps.t[i:i + 1], plane, top,
                                   grasps.depths[i:i + 1], end, sections)[0]
            checked[i] = True
        best = int(np.argmax(scores)) if len(grasps) else 0
        return replace(grasps, scores=scores).sorted(), float(mu[best]) if len(grasps) else np.inf

    def _tilts(self, R: np.ndarray, along: np.ndarray) -> np.ndarray | None:
        """The turns of one grasp (rotation ``R``) that :meth:`_rescore` also closes: by
        ``tilt_tolerance`` degrees either way about the line across both the closing direction
        and the model's height axis ``along``, as a fitted wall's slope is off by a degree or
        two and parallel pads on a thin wall so turned touch it at opposite ends. None where
        the jaws close along the axis (no wall's slope between them) or the tolerance is 0."""
        turn = np.radians(self.cfg.tilt_tolerance)
        about = np.cross(R[:, 1], along)
        size = float(np.linalg.norm(about))
        if turn <= 0 or size < 0.3:
            return None
        return np.stack([rotation_about(about / size, a) for a in (turn, -turn)])

    def _seed_points(self, points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Indices of ``seeds`` points spread evenly along the object's longest axis: the points
        are cut into ``seed_bins`` slices across it and each slice is equally likely, so a stem,
        a neck or a foot gets as many seeds as a cup or a body of far more area (0 bins: uniform
        over the surface)."""
        cfg = self.cfg
        size = min(cfg.seeds, len(points))
        if cfg.seed_bins < 2:
            return rng.choice(len(points), size=size, replace=False)
        centred = points - points.mean(axis=0)
        along = centred @ np.linalg.svd(centred, full_matrices=False)[2][0]
        span = max(float(np.ptp(along)), 1e-9)
        bins = np.minimum(((along - along.min()) / span * cfg.seed_bins).astype(np.int64),
                          cfg.seed_bins - 1)
        weight = 1.0 / np.bincount(bins, minlength=cfg.seed_bins)[bins]
        return rng.choice(len(points), size=size, replace=False, p=weight / weight.sum())

    def _frames(self, target: Cloud, plane: Plane, rng: np.random.Generator):
        """Candidate grasp frames from antipodal seed pairs: R (F, 3, 3), centre (F, 3), and the
        distance between the pair (F,)."""
        cfg, g = self.cfg, self.gripper
        seeds = self._seed_points(target.points, rng)
        s, n = target.points[seeds], target.normals[seeds]
        v = target.points[None] - s[:, None]                     # (S, M, 3)
        along = -np.einsum("smk,sk->sm", v, n)                   # distance into the object
        off_line = np.sqrt(np.maximum(np.einsum("smk,smk->sm", v, v) - along ** 2, 0))
        facing = np.einsum("mk,sk->sm", target.normals, n) < -0.3
        ok = (off_line < cfg.pair_radius) & (along > 0.0015) & (along < g.max_width) & facing
        # two partners per seed: the farthest (across the whole object) and the nearest (across
        # one wall, e.g. the rim of a glass); the same point for a convex solid
        far = np.where(ok, along, -np.inf)
        near = np.where(ok, along, np.inf)
        has = np.isfinite(far.max(axis=1))
        if not has.any():
            return np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0)
        j_far, j_near = np.argmax(far, axis=1)[has], np.argmin(near, axis=1)[has]
        distinct = j_near != j_far
        i_p = np.concatenate([seeds[has], seeds[has][distinct]])
        i_q = np.concatenate([j_far, j_near[distinct]])
        p, q = target.points[i_p], target.points[i_q]
        span = np.linalg.norm(p - q, axis=1)
        # across the whole object the pair's own line closes the jaws; across a thin wall the
        # pair is too close for its line (up to pair_radius off the normal) to mean anything,
        # so the jaws close along the two surfaces' normals. A wall is thin by the pair's
        # length, not by which partner it is: a wide vessel's wall has no far partner within
        # the opening, and its one pair is the near one
        y = _unit(p - q)
        thin = span < THIN_PAIR * cfg.pair_radius
        y[thin] = _unit(target.normals[i_p[thin]] - target.normals[i_q[thin]])
        mid = (p + q) / 2
        down = -plane.normal
        a0 = down - (y @ down)[:, None] * y
        steep = np.linalg.norm(a0, axis=1) < 0.3          # closing along the table normal
        view = _unit(mid) - np.einsum("fk,fk->f", _unit(mid), y)[:, None] * y
        a0 = _unit(np.where(steep[:, None], view, a0))
        b0 = np.cross(y, a0)
        angles = np.radians(np.linspace(-90, 90, cfg.approaches)) if cfg.approaches > 1 \
            else np.zeros(1)
        Rs, cs, spans = [], [], []
        for th in angles:
            a = np.cos(th) * a0 + np.sin(th) * b0
            R = np.stack([a, y, np.cross(a, y)], axis=2)
            up_ok = a @ down > -0.2        # never from below the table
            Rs.append(R[up_ok])
            cs.append(mid[up_ok])
            spans.append(span[up_ok])
        return np.concatenate(Rs), np.concatenate(cs), np.concatenate(spans)

    def _y_bins(self, y: np.ndarray, bin_size: float = 0.001):
        """Bins along the closing direction for :meth:`_between_jaws`, from the slab points'
        y (F, K), once per set of frames: (bin of each point, clipped to the jaws' reach;
        whether it is within reach; bins per frame)."""
        g = self.gripper
        reach = g.max_width + g.finger_thickness
        nb = int(np.ceil(2 * reach / bin_size))
        b = np.clip(((y + reach) / bin_size).astype(np.int64), 0, nb - 1)
        return b, np.abs(y) < reach, nb

    def _between_jaws(self, bins, slab: np.ndarray, span: np.ndarray,
                      bin_size: float = 0.001) -> np.ndarray:
        """Which slab points the jaws enclose: from the seed pair (+-span/2) outwards on each
        side, up to the first empty gap a finger fits in. bins: :meth:`_y_bins` of the points'
        y, of the same rows; slab : (F, K); span : (F,)."""
        g = self.gripper
        b, within, nb = bins
        F = len(slab)
        reach = g.max_width + g.finger_thickness
        occ = np.zeros(nb * F + 1, bool)
        occ[np.where(slab & within, b + nb * np.arange(F)[:, None], nb * F).ravel()] = True
        occ = occ[:-1].reshape(F, nb)
        gap = max(int(np.ceil(g.finger_thickness / bin_size)), 1)
        csum = np.concatenate([np.zeros((F, 1), np.int64), np.cumsum(occ, 1)], 1)
        empty = np.zeros_like(occ)
        empty[:, :nb - gap + 1] = (csum[:, gap:] - csum[:, :-gap]) == 0  # gap starts at bin
        idx = np.arange(nb)
        start_hi = ((span / 2 + reach) / bin_size).astype(np.int64)
        start_lo = ((-span / 2 + reach) / bin_size).astype(np.int64)
        hi_ok = empty & (idx[None] >= start_hi[:, None])
        edge_hi = np.where(hi_ok.any(1), np.argmax(hi_ok, 1), nb)
        # on the low side the gap must end at or below the pair: its last bin <= start_lo
        lo_ok = empty & (idx[None] + gap - 1 <= start_lo[:, None])
        edge_lo = np.where(lo_ok.any(1), nb - 1 - np.argmax(lo_ok[:, ::-1], 1) + gap - 1, -1)
        return (b > edge_lo[:, None]) & (b < edge_hi[:, None])

    def _try_frames(self, k, R, c, span, target: Cloud, scene: Cloud, plane: Plane, top: float,
                    end: tuple[np.ndarray, float], sections: Sections | None = None,
                    solid: np.ndarray | None = None,
                    observed: Cloud | None = None) -> GraspSet | None:
        """The best depth of each frame (rotations ``R (F, 3, 3)``, seed-pair midpoints ``c
        (F, 3)``, pair lengths ``span (F,)``) that holds, deepest first; at each depth, in
        turn: the palm keeps off the object (:meth:`_palm_clear`); the object's section
        between the jaws sets the opening and centre (:meth:`_sections`); both contacts lie
        inside the friction cone (:meth:`_contact_friction`); the gripper clears the table
        (:meth:`_clears_table`), holds no scene point (:meth:`_collision_free`) and no
        observed reading (:meth:`_observation_agrees`). ``solid``: which target points are
        also in ``scene`` (default all, as :meth:`plan` is given them; see
        :meth:`_palm_clear`). ``observed``: the sensor's own readings (see :meth:`plan`)."""
        g = self.gripper
        held = _HeldPoints.of(self, R, c, target, solid)
        scene_local = _LocalPoints(R, c, scene.points)
        observed_local = None if observed is None else _LocalPoints(R, c, observed.points)
        best = np.full(len(R), -1.0)
        out = np.zeros((len(R), 4))                               # width, depth, ymid, score
        for depth in sorted(self.cfg.depths, reverse=True):
            rows = np.flatnonzero(best < 0)
            rows = rows[self._palm_clear(held, rows, depth)]
            cand = self._sections(held, rows, depth, span)
            if cand is None:
                continue
            cand.mu = self._contact_friction(held, cand)
            cand = cand.keep(cand.mu <= self.cfg.friction)
            cand.centre = c[cand.rows] + R[cand.rows, :, 1] * cand.ymid[:, None]
            # the table first (cheap, and half the survivors fail it), then the scene points
            cand = cand.keep(self._clears_table(cand, R, depth, plane))
            cand = cand.keep(self._collision_free(cand, scene_local, depth))
            if observed_local is not None:
                cand = cand.keep(self._observation_agrees(cand, observed_local, depth))
            if len(cand.rows) == 0:
                continue
            best[cand.rows] = self.score(cand.mu, cand.width, R[cand.rows], cand.centre, plane,
                                         top, depth, end, sections)
            out[cand.rows] = np.stack([cand.width, np.full(len(cand.rows), depth), cand.ymid,
                                       best[cand.rows]], 1)
        keep = best >= 0
        if not keep.any():
            return None
        n = int(keep.sum())
        w, d, ymid, score = out[keep].T
        centre = c[keep] + R[keep][:, :, 1] * ymid[:, None]
        return GraspSet(score, w, np.full(n, g.finger_height), d, R[keep], centre,
                        np.full(n, k, np.int64))

    def _palm_clear(self, held: "_HeldPoints", rows: np.ndarray, depth: float) -> np.ndarray:
        """Which frames ``rows`` keep their palm, at ``depth``, off the object's own solid
        points (``held.behind``: inside the palm at any centring of the opening), a necessary
        condition of :meth:`_collision_free` that costs no section work: at the deeper depths
        most palms are inside the object. (f,) bool."""
        g, m = self.gripper, self.cfg.collision_margin
        x = held.local[rows, 0]
        palm = held.behind[rows] & (x > depth - g.finger_length - g.palm_depth - m + SURE) & \
            (x < depth - g.finger_length + m - SURE)
        return palm.sum(axis=1) < self.cfg.collision_points

    def _sections(self, held: "_HeldPoints", rows: np.ndarray, depth: float,
                  span: np.ndarray) -> "_Candidates | None":
        """The object's section under the (inflated) finger pads of frames ``rows`` at
        ``depth``: the target points the jaws enclose (:meth:`_between_jaws`) set the opening
        (their extent along the closing direction plus ``width_margin`` each side) and the
        centre (their middle). Frames whose section has fewer than :data:`MIN_SECTION` points,
        is too wide for the gripper, or whose centre lies farther than half the largest
        opening from the seed pair's midpoint are dropped; None where none is left."""
        if len(rows) == 0:
            return None
        cfg, g = self.cfg, self.gripper
        L, m = g.finger_length, cfg.collision_margin
        x, y = held.local[rows, 0], held.local[rows, 1]
        slab = held.can[rows] & (x > depth - L - m) & (x < depth + m)
        b, within, nb = held.bins
        slab &= self._between_jaws((b[rows], within[rows], nb), slab, span[rows])
        count = slab.sum(axis=1)
        y_lo = np.where(slab, y, np.inf).min(axis=1)
        y_hi = np.where(slab, y, -np.inf).max(axis=1)
        width = (y_hi - y_lo) + 2 * cfg.width_margin
        ymid = np.where(count > 0, (y_hi + y_lo) / 2, 0.0)
        ok = (count >= MIN_SECTION) & (width <= g.max_width) & (np.abs(ymid) <= g.max_width / 2)
        if not ok.any():
            return None
        return _Candidates(rows[ok], width[ok], ymid[ok], slab[ok], y_lo[ok], y_hi[ok])

    def _contact_friction(self, held: "_HeldPoints", cand: "_Candidates") -> np.ndarray:
        """The friction coefficient (f,) each candidate's two contacts need: each contact is
        the outermost ``contact_band`` of its section on that side, of the points whose
        normals face that finger (across a thin wall the inner surface's points lie in the
        band too, facing the other way); its normal the mean of theirs, and the closing line
        runs between the two patches' centroids (the larger of the two angles counts)."""
        band = self.cfg.contact_band
        local = held.local[cand.rows]
        y, ny = local[:, 1], local[:, 4]
        left = cand.slab & (y < cand.y_lo[:, None] + band) & (ny < 0)
        right = cand.slab & (y > cand.y_hi[:, None] - band) & (ny > 0)
        sums = local @ np.stack([left, right], 2).astype(np.float32)  # (f, 6, 2)
        n_left, n_right = _unit(sums[:, 3:, 0]), _unit(sums[:, 3:, 1])
        c_left = sums[:, :3, 0] / np.maximum(left.sum(1), 1)[:, None]
        c_right = sums[:, :3, 1] / np.maximum(right.sum(1), 1)[:, None]
        line = _unit(c_right - c_left)
        ang = np.maximum(np.arccos(np.clip(-np.sum(n_left * line, 1), -1, 1)),
                         np.arccos(np.clip(np.sum(n_right * line, 1), -1, 1)))
        return np.tan(np.minimum(ang, MAX_CONTACT_ANGLE))

    def _clears_table(self, cand: "_Candidates", R: np.ndarray, depth: float,
                      plane: Plane) -> np.ndarray:
        """Which candidates keep every corner of the gripper ``clearance`` above the table:
        (f,) bool."""
        return self.gripper.lowest(R[cand.rows], cand.centre, cand.width, depth, plane) >= \
            self.cfg.clearance

    def _boxes(self, cand: "_Candidates", depth: float) -> np.ndarray:
        """The fingers and palm of each candidate at ``depth``, centred between the jaws:
        (f, 3, 2, 3) in each frame's coordinates (see :meth:`Gripper.boxes`)."""
        boxes = self.gripper.boxes(cand.width, depth)
        boxes[..., 1] += cand.ymid[:, None, None]
        return boxes

    def _collision_free(self, cand: "_Candidates", scene: "_LocalPoints",
                        depth: float) -> np.ndarray:
        """Which candidates' fingers and palm, inflated by ``collision_margin`` (for the
        model's pose error), hold fewer than ``collision_points`` scene points: (f,) bool."""
        if len(cand.rows) == 0:
            return np.zeros(0, bool)
        hits = count_inside(scene.of(cand.rows), self._boxes(cand, depth),
                            shrink=-self.cfg.collision_margin)
        return hits.max(axis=1) < self.cfg.collision_points

    def _observation_agrees(self, cand: "_Candidates", observed: "_LocalPoints",
                            depth: float) -> np.ndarray:
        """Which candidates no sensor reading contradicts: each finger, inflated by
        ``collision_margin``, and the palm hold fewer than ``collision_points`` of the
        ``observed`` readings no placed model accounts for (:func:`unexplained`). Such a
        reading is a surface the model lacks (the object wider than its model, or elsewhere;
        a handle, a spout): a finger on it would close through it on the true object, and one
        just beside a finger (the pads pass ``width_margin`` from the model) tells of that
        surface reaching into it, as a glass's readings sample its surface a few pixels in
        ten. Only readings inside the palm count: it passes over a rim's readings, and
        inflated it rejects grasps that hold (on ../shared/extsim, two objects' best). (f,)
        bool."""
        if len(cand.rows) == 0:
            return np.zeros(0, bool)
        boxes = self._boxes(cand, depth)
        fingers = boxes[:, :2]
        fingers[:, :, 0] -= self.cfg.collision_margin
        fingers[:, :, 1] += self.cfg.collision_margin
        hits = count_inside(observed.of(cand.rows), np.concatenate([fingers, boxes[:, 2:]], 1))
        return hits.max(axis=1) < self.cfg.collision_points


@dataclass
class _HeldPoints:
    """The target's points that some depth's finger pads of a chunk of F frames can hold, K per
    frame (the rows padded): ``local (F, 6, K)`` float32, rows x y z of the points then of their
    normals in each frame's coordinates; ``can (F, K)``: a real point, not padding;
    ``behind (F, K)``: a solid point the palm holds at any centring of the opening (up to
    max_width / 2 either way) within its height (see :meth:`Planner._palm_clear`);
    ``bins``: :meth:`Planner._y_bins` of the points' y."""

    local: np.ndarray
    can: np.ndarray
    behind: np.ndarray
    bins: tuple

    @classmethod
    def of(cls, planner: "Planner", R: np.ndarray, c: np.ndarray, target: Cloud,
           solid: np.ndarray | None) -> "_HeldPoints":
        """From frames ``R (F, 3, 3)``, ``c (F, 3)``: the points a finger slab can hold at some
        depth, found from their approach (x) and height (z) coordinates, packed to the front
        of each row, the rows cut to the longest such list."""
        cfg, g = planner.cfg, planner.gripper
        L, m = g.finger_length, cfg.collision_margin
        local_t = to_local(R, c, target.points)                   # (F, 3, M)
        x, z = local_t[:, 0], local_t[:, 2]
        can = (np.abs(z) < g.finger_height / 2 + m) & (x > min(cfg.depths) - L - m) & \
            (x < max(cfg.depths) + m)
        keep = max(int(can.sum(axis=1).max()), 1)
        order = np.argsort(~can, axis=1, kind="stable")[:, :keep]  # (F, K)
        can = np.take_along_axis(can, order, 1)
        local = np.concatenate([np.take_along_axis(local_t, order[:, None], 2),
                                R.transpose(0, 2, 1).astype(np.float32) @
                                target.normals.astype(np.float32)[order].transpose(0, 2, 1)], 1)
        y, z = local[:, 1], local[:, 2]
        behind = can & (np.abs(y) < g.palm_width / 2 + m - g.max_width / 2 - SURE) & \
            (np.abs(z) < g.palm_height / 2 + m - SURE)
        if solid is not None:
            behind &= solid[order]
        return cls(local, can, behind, planner._y_bins(y))


class _LocalPoints:
    """Points ``(n, 3)`` in the coordinates of frames ``R (F, 3, 3)``, ``c (F, 3)``, each frame's
    turned once, when it first reaches a test that needs them (:func:`to_local`'s layout)."""

    def __init__(self, R: np.ndarray, c: np.ndarray, points: np.ndarray):
        self.R, self.c, self.points = R, c, points
        self.local = np.empty((len(R), 3, len(points)), np.float32)
        self.seen = np.zeros(len(R), bool)

    def of(self, rows: np.ndarray) -> np.ndarray:
        """``(f, 3, n)`` for frames ``rows``."""
        fresh = rows[~self.seen[rows]]
        if len(fresh):
            self.local[fresh] = to_local(self.R[fresh], self.c[fresh], self.points)
            self.seen[fresh] = True
        return self.local[rows]


@dataclass
class _Candidates:
    """The frames of a chunk still in the running at one depth: ``rows (f,)`` their indices,
    and for each the opening ``width (f,)`` m, the centre's offset ``ymid (f,)`` m along the
    closing direction from the seed pair's midpoint, the section's points ``slab (f, K)`` bool
    (of :class:`_HeldPoints`) and its extent ``y_lo``, ``y_hi (f,)`` m; filled in later: the
    friction ``mu (f,)`` the contacts need and the grasp ``centre (f, 3)``."""

    rows: np.ndarray
    width: np.ndarray
    ymid: np.ndarray
    slab: np.ndarray
    y_lo: np.ndarray
    y_hi: np.ndarray
    mu: np.ndarray | None = None
    centre: np.ndarray | None = None

    def keep(self, ok: np.ndarray) -> "_Candidates":
        """The candidates where ``ok (f,)`` holds."""
        return _Candidates(*(None if a is None else a[ok] for a in
                             (self.rows, self.width, self.ymid, self.slab, self.y_lo, self.y_hi,
                              self.mu, self.centre)))
