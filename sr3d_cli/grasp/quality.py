"""Grasp quality against the truth: close the jaws on the true meshes, test force closure.

For each grasp: (1) the opening must fit the gripper; (2) the open gripper (fingers at the stated
width, palm) must not reach below the table nor hold points of the true scene (true meshes
sampled densely, plus the true depth); (3) each finger closes along the closing direction until it
first touches a true mesh (by one of the contact models below); both fingers must
touch the same object; (4) force closure of the two contacts with Coulomb friction: the line
between the contacts must lie inside both friction cones. The smallest friction coefficient for
which (4) holds is recorded, so success at any coefficient (GraspNet-1Billion uses 0.2 ... 1.2)
is read off without re-running.

Three contact models (``contacts``, :data:`CONTACTS`), as a pad's contact depends on how it is
found. ``grid`` (default): rays from 6 x 3 points on each pad, with the faces' normals. Its rows
lie 9.4 mm apart along the finger, so a feature narrower than that (a beaker's 3 mm lip) can
fall between them: the pad is judged to touch the wall below, where a whole flat pad would rest
on the lip. ``pads``: the whole flat pad's exact first touch (:func:`_pad_contact`), each
contact with the normal its kind has: a corner or edge of the mesh pressed by the pad's face
pushes along the pad's normal (a lip's top edge, a box's edge), the pad's edge on a face along
the face's (the fingertip on a cone's side). A lipped rim pinch then leans as the lip's top edge
stands above the inner wall's top (a 3 mm lip: friction .53 against .3 by the grid or 0 on a
plain rim), which the grid sees only where a row meets the lip. ``line``: one ray per jaw along
the closing line through the grasp centre, as GraspNet-1Billion's metric closes the jaws
(Dex-Net's line of action), which sees neither a lip nor a shoulder off that line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.raycast import first_hits
from sr3d_cli.grasp import GraspSet
from sr3d_cli.grasp.gripper import Gripper, count_inside, to_local

FRICTIONS = (0.2, 0.4, 0.5, 0.6, 0.8, 1.0, 1.2)
UNLABELLED = "unlabelled"  # the class of a true object without a label (reports by class)
MIDPOINTS = 400  # most midpoints of a patch's touches closure_angle(between=True) tries
CONTACTS = {  # contact models of close_jaws: what each finds, in words for reports
    "grid": "ray casting from a grid of 6 x 3 points on each finger pad",
    "pads": "each flat pad's exact first touch, with the normal of its kind of contact",
    "line": "one ray per jaw along the closing line through the grasp centre (GraspNet's)",
}


@dataclass
class TrueScene:
    """ids (n,), triangles: list of (m, 3, 3) camera-frame triangles per object, points: the
    collision cloud (n, 3), samples: per-object surface samples (for matching grasps to
    objects), plane: the true table; classes: id -> the object's class for reports (may be
    empty)."""

    ids: list[int]
    triangles: list[np.ndarray]
    points: np.ndarray
    samples: list[np.ndarray]
    plane: Plane
    classes: dict[int, str] = field(default_factory=dict)

    @classmethod
    def build(cls, objects: list[tuple[int, object]], depth_points: np.ndarray, plane: Plane,
              density: float = 2.5e5) -> "TrueScene":
        """objects: (id, camera-frame trimesh); depth_points: the true depth as points;
        density: surface samples per square metre for the collision cloud."""
        import trimesh

        tris, samples = [], []
        for i, (_, mesh) in enumerate(objects):
            tris.append(np.asarray(mesh.triangles))
            n = int(min(max(mesh.area * density, 2000), 60000))
            pts, _ = trimesh.sample.sample_surface(mesh, n, seed=i)
            samples.append(np.asarray(pts))
        points = np.concatenate([depth_points] + samples) if samples else depth_points
        return cls([k for k, _ in objects], tris, points, samples, plane)

    def nearest_object(self, point: np.ndarray, within: float) -> int | None:
        best, who = within, None
        for k, s in zip(self.ids, self.samples):
            d = float(np.min(np.linalg.norm(s - point, axis=1)))
            if d < best:
                best, who = d, k
        return who


def _jaw_origins(gripper: Gripper, width: float, depth: float, contacts: str = "grid",
                 nx: int = 6, nz: int = 3):
    """Ray origins on both finger pads (grasp frame): a grid of ``nx`` x ``nz`` points on each,
    or with ``contacts="line"`` the one point on the closing line through the grasp centre."""
    if contacts == "line":
        gx, gz = np.zeros(1), np.zeros(1)
    else:
        L, H = gripper.finger_length, gripper.finger_height
        xs = np.linspace(depth - L + 0.002, depth - 0.001, nx)
        zs = np.linspace(-H / 2 + 0.001, H / 2 - 0.001, nz)
        gx, gz = [a.ravel() for a in np.meshgrid(xs, zs)]
    left = np.stack([gx, np.full_like(gx, -width / 2), gz], 1)
    right = np.stack([gx, np.full_like(gx, width / 2), gz], 1)
    return left, right


def _facing(triangles: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Unit normals (p, 3) of ``triangles`` (p, 3, 3), each on the side facing a finger that
    closes along ``direction``."""
    n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return np.where((n @ direction < 0)[:, None], n, -n)


def _contact(origins: np.ndarray, direction: np.ndarray, ids: list[int],
             triangles: list[np.ndarray], width: float, tie: float = 0.001):
    """Where a finger closing from ``origins`` along ``direction`` first touches one of the
    meshes (``triangles`` per object of ``ids``): (object id, contact points (p, 3), outward
    normals (p, 3)) or None. Every ray that touches within ``tie`` of the first belongs to the
    contact patch (a flat pad on a cylinder touches along a line)."""
    dirs = np.broadcast_to(direction, origins.shape)
    best = None
    for k, tri in zip(ids, triangles):
        dist, face = first_hits(origins, dirs, tri, max_distance=width)
        if np.isfinite(dist).any() and (best is None or dist.min() < best[1].min()):
            best = (k, dist, face, tri)
    if best is None:
        return None
    k, dist, face, tri = best
    patch = dist <= dist.min() + tie
    points = origins[patch] + dist[patch, None] * direction
    return k, points, _facing(tri[face[patch]], direction)


def _pad_contact(R: np.ndarray, t: np.ndarray, side: int, width: float, depth: float,
                 gripper: Gripper, ids: list[int], triangles: list[np.ndarray],
                 tie: float = 0.001, press: float = 1e-4):
    """Where the flat pad of one finger, closing from its open position, first touches one of
    the meshes (``triangles`` per object of ``ids``): (object id, contact points (p, 3),
    outward normals (p, 3)) or None. ``side`` +1: the finger at -width/2 closing along +y of
    the grasp frame (``R``, centre ``t``); -1: the other one.

    Exact for a flat rectangular pad: the first touch is the least sweep distance over each
    triangle clipped to the pad's footprint, found at one of the clipped polygon's corners
    (the triangle's corners inside the footprint, its edges crossing the footprint's sides, or
    the pad's corners hitting it). A grid of rays would step over a feature narrower than its
    spacing (a beaker's 3 mm lip between rows 9 mm apart) and report a contact elsewhere.
    Every touch within ``tie`` of the first belongs to the patch (a pad on a cylinder touches
    along a line). The touches within ``press`` of the first take the normal their kind of
    contact has: a corner of the mesh on the pad's face, the pad's normal (the pad's plane
    supports the object there: a lip's edge pushes along the pad's normal, not along the lip's
    sloped face); an edge of the mesh across the pad's edge, the normal to both edges (the
    fingertip across a cone's side: the cone's own normal); the pad's corner on a face, the
    face's normal. The rest of the patch keeps the touched faces' normals (see
    :func:`closure_angle`)."""
    L, H = gripper.finger_length, gripper.finger_height
    lo = np.array([depth - L, -H / 2])               # pad footprint in (x, z) of the grasp frame
    hi = np.array([depth, H / 2])
    direction = side * R[:, 1]
    corners = np.array([[x, -side * width / 2, z] for x in (lo[0], hi[0])
                        for z in (lo[1], hi[1])])
    best = None
    for k, tri in zip(ids, triangles):
        if not len(tri):
            continue
        local = (tri - t) @ R                          # (m, 3, 3) grasp frame
        sweep = side * local[..., 1] + width / 2       # distance the pad travels to reach it
        uv = local[..., [0, 2]]
        # candidate touches: (points, sweep distances, triangle indices, their own normals in
        # the grasp frame where the contact's kind sets one, else nan: the face's)
        # the triangle's corners inside the footprint
        inside = np.all((uv >= lo) & (uv <= hi), axis=-1) & (sweep >= 0) & (sweep <= width)
        f, c = np.nonzero(inside)
        own = np.full((len(f), 3), np.nan)
        own[np.all((uv[f, c] > lo) & (uv[f, c] < hi), axis=-1)] = [0.0, -side, 0.0]
        found = [(local[f, c], sweep[f, c], f, own)]
        # its edges crossing the footprint's four sides (the pad's edges, along z for the
        # sides at fixed x and along x for those at fixed z), or the pad's starting plane
        a, b = local, np.roll(local, -1, axis=1)
        sa, sb = sweep, np.roll(sweep, -1, axis=1)
        ends = [(a[..., 0], b[..., 0], v, (0.0, 0.0, 1.0)) for v in (lo[0], hi[0])] + \
               [(a[..., 2], b[..., 2], v, (1.0, 0.0, 0.0)) for v in (lo[1], hi[1])] + \
               [(sa, sb, 0.0, None)]
        for ea, eb, v, pad_edge in ends:
            with np.errstate(divide="ignore", invalid="ignore"):
                u = (v - ea) / (eb - ea)
            f, e = np.nonzero((u >= 0) & (u <= 1))
            if not len(f):
                continue
            edge = b[f, e] - a[f, e]
            p = a[f, e] + u[f, e, None] * edge
            sp = side * p[:, 1] + width / 2
            ok = np.all((p[:, [0, 2]] >= lo - 1e-9) & (p[:, [0, 2]] <= hi + 1e-9), axis=1) & \
                (sp >= -1e-9) & (sp <= width)
            own = np.full((int(ok.sum()), 3), np.nan)
            if pad_edge is not None:
                n = np.cross(pad_edge, edge[ok])
                size = np.linalg.norm(n, axis=1)
                crossing = size > 1e-6 * np.linalg.norm(edge[ok], axis=1)  # not along the edge
                n = n[crossing] / size[crossing, None]
                own[crossing] = np.where((n[:, 1] * side > 0)[:, None], -n, n)
            found.append((p[ok], sp[ok], f[ok], own))
        # the pad's corners hitting a face
        d_c, f_c = first_hits(corners, np.broadcast_to([0.0, side, 0.0], corners.shape), local,
                              max_distance=width)
        hit = np.isfinite(d_c)
        found.append((corners[hit] + d_c[hit, None] * [0.0, side, 0.0], d_c[hit], f_c[hit],
                      np.full((int(hit.sum()), 3), np.nan)))
        pts, dist, face, own = (np.concatenate(x) for x in zip(*found))
        if len(dist) and (best is None or dist.min() < best[1].min()):
            best = (k, dist, pts, face, own, tri)
    if best is None:
        return None
    k, dist, local_pts, face, own, tri = best
    patch = dist <= dist.min() + tie
    points = local_pts[patch] @ R.T + t
    normals = _facing(tri[face[patch]], direction)
    kind = ~np.isnan(own[patch, 0]) & (dist[patch] <= dist.min() + press)
    normals[kind] = own[patch][kind] @ R.T
    return k, points, normals


def close_jaws(R: np.ndarray, t: np.ndarray, width: float, depth: float, ids: list[int],
               triangles: list[np.ndarray], gripper: Gripper, shifts: np.ndarray | None = None,
               enough: float = math.inf, contacts: str = "grid",
               tilts: np.ndarray | None = None) -> tuple[str, int | None, float]:
    """Close both fingers of one grasp (rotation ``R``, centre ``t``, opening ``width``,
    ``depth``) onto the meshes (``triangles`` per object of ``ids``): (reason "ok", "no
    contact" or "two objects"; the object touched; the smallest friction coefficient giving
    force closure, inf unless "ok"). ``shifts (s, 3)``: the grasp is also closed moved by each
    (camera frame), and ``tilts (r, 3, 3)``: turned by each rotation (camera frame) about its
    centre; the worst outcome counts (the planner's margins for a model's height and slope
    errors); it stops at the first needing more than ``enough``. ``contacts``: the contact
    model (:data:`CONTACTS`): rays from each pad (:func:`_contact`) or the whole flat pads
    (:func:`_pad_contact`)."""
    if contacts not in CONTACTS:
        raise ValueError(f"contact model {contacts!r}: one of {', '.join(CONTACTS)}")
    moves = [(R, t)] + [(R, t + s) for s in ([] if shifts is None else shifts)] + \
        [(Q @ R, t) for Q in ([] if tilts is None else tilts)]
    # a finger's rays sweep only the box between the open pads: triangles outside it cannot
    # be hit (the test is exact, only fewer triangles are cast against); a tilt moves a point
    # of the box at most its distance from the centre times the angle
    eps = 1e-6
    lo = np.array([depth - gripper.finger_length, -width / 2, -gripper.finger_height / 2])
    hi = np.array([depth, width / 2, gripper.finger_height / 2])
    if tilts is not None and len(tilts):
        turn = max(math.acos(np.clip((np.trace(Q) - 1) / 2, -1, 1)) for Q in tilts)
        eps += turn * float(np.linalg.norm(np.maximum(np.abs(lo), np.abs(hi))))
    local_moves = (np.array([m[1] for m in moves]) - t) @ R
    lo = lo + local_moves.min(axis=0) - eps
    hi = hi + local_moves.max(axis=0) + eps
    near = []
    for tri in triangles:
        local = (tri - t) @ R
        near.append(tri[np.all(local.max(axis=1) >= lo, axis=1)
                        & np.all(local.min(axis=1) <= hi, axis=1)])
    worst: tuple[str, int | None, float] = ("ok", None, -1.0)
    for Rm, tm in moves:
        if contacts == "pads":
            touch = [_pad_contact(Rm, tm, side, width, depth, gripper, ids, near)
                     for side in (1, -1)]
        else:
            touch = [_contact(origins @ Rm.T + tm, direction, ids, near, width)
                     for origins, direction in zip(_jaw_origins(gripper, width, depth, contacts),
                                                   (Rm[:, 1], -Rm[:, 1]))]
        if any(c is None for c in touch):
            return "no contact", None, math.inf
        if touch[0][0] != touch[1][0]:
            return "two objects", None, math.inf
        (k, p_l, n_l), (_, p_r, n_r) = touch
        mu = math.tan(min(closure_angle(p_l, n_l, p_r, n_r, between=contacts == "pads"),
                          math.radians(89.99)))
        if mu > worst[2]:
            worst = ("ok", k, mu)
        if mu > enough:
            break
    return worst


def closure_angle(p_l, n_l, p_r, n_r, between: bool = False) -> float:
    """The larger angle between a contact's inward normal and the line to the other contact
    (radians); force closure at friction mu iff tan(angle) <= mu. Best over pairs of contacts,
    where a contact is a patch point with its normal, or the patch's centroid with any of the
    patch's normals: a flat pad pressed on a concave surface (the inside of a glass's wall)
    touches along its two edges, whose forces meet between them, although neither edge alone
    faces the other finger's contact. ``between``: also the midpoint of any two patch points
    with the bisector of their normals (two equal forces: the pad's two edges on a concave
    wall push together at any height along them, not only at the centroid). The normals are
    the contact model's: the grid's are the surface's own, so an edge or a corner is not made
    any easier to hold.
    p_*, n_* : (p, 3) patch points and outward normals of the left and right finger."""
    def virtual(p, n):
        if between:  # a corner shared by several triangles is listed once for each
            p, n = np.split(np.unique(np.round(np.hstack([p, n]), 9), axis=0), 2, axis=1)
        centroid = np.broadcast_to(p.mean(0), p.shape)
        if between:
            i, j = np.triu_indices(len(p), 1)
            if len(i) > MIDPOINTS:  # many touches: every midpoint is too many pairs to test
                keep = np.linspace(0, len(i) - 1, MIDPOINTS).astype(np.int64)
                i, j = i[keep], j[keep]
            # two equal forces along their normals: the bisector, through the midpoint
            bisector = n[i] + n[j]
            bisector /= np.maximum(np.linalg.norm(bisector, axis=1, keepdims=True), 1e-12)
            return np.vstack([p, centroid, (p[i] + p[j]) / 2]), np.vstack([n, n, bisector])
        return np.vstack([p, centroid]), np.vstack([n, n])

    (p_l, n_l), (p_r, n_r) = virtual(p_l, n_l), virtual(p_r, n_r)
    line = p_r[None] - p_l[:, None]                               # (l, r, 3)
    norm = np.linalg.norm(line, axis=-1)
    line = line / np.maximum(norm, 1e-12)[..., None]
    a_l = np.arccos(np.clip(-np.einsum("lrk,lk->lr", line, n_l), -1, 1))
    a_r = np.arccos(np.clip(np.einsum("lrk,rk->lr", line, n_r), -1, 1))
    worst = np.where(norm > 1e-6, np.maximum(a_l, a_r), np.pi)
    return float(worst.min())


def judge(grasps: GraspSet, truth: TrueScene, gripper: Gripper, *, tolerance: float = 0.001,
          collision_points: int = 2, contacts: str = "grid") -> list[dict]:
    """One record per grasp: ``object`` (true id it is matched to, or None), ``reason``
    ("ok", "too wide", "collision", "below table", "no contact", "two objects"), ``mu`` (smallest
    friction coefficient giving force closure; inf when it fails before the friction test).
    ``contacts``: the contact model (:data:`CONTACTS`)."""
    out = []
    for i in range(len(grasps)):
        R, t = grasps.R[i], grasps.t[i]
        w, d = float(grasps.widths[i]), float(grasps.depths[i])
        rec = {"object": truth.nearest_object(t, 0.03), "mu": math.inf}
        out.append(rec)
        if w > gripper.max_width + 1e-9:
            rec["reason"] = "too wide"
            continue
        if gripper.lowest(R, t, w, d, truth.plane) < -tolerance:
            rec["reason"] = "below table"
            continue
        boxes = gripper.boxes(w, d)[None]
        local = to_local(R[None], t[None], truth.points)
        if count_inside(local, boxes, shrink=tolerance).max() >= collision_points:
            rec["reason"] = "collision"
            continue
        reason, k, mu = close_jaws(R, t, w, d, truth.ids, truth.triangles, gripper,
                                   contacts=contacts)
        rec["reason"], rec["mu"] = reason, mu
        if k is not None:
            rec["object"] = k
    return out


def summarise(grasps: GraspSet, records: list[dict], object_ids: list[int], friction: float,
              top: int = 10, classes: dict[int, str] | None = None) -> dict:
    """Per-frame numbers: top-1 success per true object, mean success of the best ``top``
    grasps, success at each coefficient of :data:`FRICTIONS`; with ``classes`` (id -> class),
    top-1 by class too: {class: {"objects", "held"}}."""
    success = np.array([r["reason"] == "ok" and r["mu"] <= friction for r in records], bool)
    order = np.argsort(-grasps.scores, kind="stable")
    top1 = {}
    for k in object_ids:
        mine = [i for i in order if records[i]["object"] == k]
        top1[str(k)] = bool(success[mine[0]]) if mine else None
    best = order[:top]
    reasons: dict[str, int] = {}
    for r in records:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    by_class: dict[str, dict[str, int]] = {}
    for k in object_ids if classes else ():
        tally = by_class.setdefault(classes.get(k) or UNLABELLED, {"objects": 0, "held": 0})
        tally["objects"] += 1
        tally["held"] += bool(top1[str(k)])
    return {
        "grasps": len(grasps),
        "objects": len(object_ids),
        "objects_with_grasps": sum(v is not None for v in top1.values()),
        "top1": top1,
        "top1_success": (sum(bool(v) for v in top1.values()) / len(object_ids)
                         if object_ids else math.nan),
        f"top{top}_success": float(success[best].mean()) if len(best) else 0.0,
        "success_by_friction": {f"{mu:.1f}": float(np.mean([r["reason"] == "ok" and r["mu"] <= mu
                                                            for r in records]))
                                if records else math.nan for mu in FRICTIONS},
        "reasons": reasons,
        "top1_by_class": by_class,
    }


def overall(frames: list[dict]) -> dict:
    """Numbers over frames: top-1 success over all true objects (and by class, where the
    frames give classes), the other rates averaged over frames."""
    objects = sum(f["objects"] for f in frames)
    wins = sum(sum(bool(v) for v in f["top1"].values()) for f in frames)
    tally: dict[str, list[int]] = {}
    for f in frames:
        for name, t in f.get("top1_by_class", {}).items():
            counts = tally.setdefault(name, [0, 0])
            counts[0] += t["objects"]
            counts[1] += t["held"]

    def mean(key, sub=None):
        vals = [f[key] if sub is None else f[key][sub] for f in frames]
        vals = [v for v in vals if not (isinstance(v, float) and math.isnan(v))]
        return float(np.mean(vals)) if vals else math.nan

    return {"frames": len(frames), "objects": objects,
            "objects_with_grasps": sum(f["objects_with_grasps"] for f in frames),
            "top1_success": wins / objects if objects else math.nan,
            "top10_success": mean("top10_success"),
            "top1_by_class": {name: {"objects": n, "top1_success": held / n}
                              for name, (n, held) in sorted(tally.items())},
            "success_by_friction": {mu: mean("success_by_friction", mu)
                                    for mu in (frames[0]["success_by_friction"] if frames else {})}}
