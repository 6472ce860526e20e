"""Random scene layouts: objects resting on a table (world z = 0, z up) and cameras looking at them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from sr3d_cli.geometry.camera import Camera, project
from sr3d_cli.geometry.revolution import resting_edge
from sr3d_cli.geometry.transforms import (apply_T, look_at, make_T, rotation_about,
                                          rotation_between)
from sr3d_cli.synth.families import FAMILIES, make_shape
from sr3d_cli.synth.shapes import KINDS

SIDE_TILT_DEG = 40.0  # a shape laid on its side keeps its axis within this of level (else it
# stands or stands on its head: not lying)
SIDE_STEP_DEG = (5.0, 0.5, 0.05)  # side_rotation's grids, each around the last one's best:
# the finest leaves the resting points within 0.001 of the object's height of the table
OPEN_MIN_ELEVATION_DEG = 56.0  # the inner floor of an open glass 1.5x as tall as wide shows
# from atan(1.5) = 56 degrees up: scenes holding one are seen from at least this high


@dataclass
class Placed:
    """An object in the world: ``p_world = T_world_obj @ (scale * p_obj)``."""

    mesh: trimesh.Trimesh  # object frame (glassware: unit height)
    T_world_obj: np.ndarray
    scale: float
    label: str
    transparent: bool
    pose: str = "standing"
    colour: tuple = (0.5, 0.5, 0.5)

    def world_vertices(self) -> np.ndarray:
        return apply_T(self.T_world_obj, self.scale * self.mesh.vertices)

    def footprint(self) -> tuple[np.ndarray, float]:
        """Centre (2,) and radius of a circle holding the object's outline on the table."""
        xy = self.world_vertices()[:, :2]
        centre = (xy.min(0) + xy.max(0)) / 2
        return centre, float(np.linalg.norm(xy - centre, axis=1).max())


@dataclass
class Layout:
    objects: list[Placed]
    camera: Camera
    T_world_cams: list[np.ndarray] = field(default_factory=list)


def lying_rotation(profile: np.ndarray, z_mass: float) -> np.ndarray:
    """Rotation (object -> world) that lays a body of revolution on its side: on the hull edge of
    its ``(r, z)`` profile under its centre of mass (at height ``z_mass`` on the axis, same units;
    :func:`resting_edge`), that edge's outward normal turned to face the table (world -z)."""
    a, b = resting_edge(profile[:, 1], profile[:, 0], z_mass)
    d = (b - a) / np.linalg.norm(b - a)  # (dz, dr) along the edge
    outward_obj = np.array([d[0], 0.0, -d[1]])  # (r, z) = (dz, -dr), away from the axis
    return rotation_between(outward_obj, np.array([0.0, 0.0, -1.0]))


def _rest(mesh: trimesh.Trimesh, R: np.ndarray, scale: float) -> np.ndarray:
    """Pose with rotation ``R`` whose lowest point touches the table (``arrange`` moves it)."""
    z = (scale * mesh.vertices @ R.T)[:, 2]
    return make_T(R, [0.0, 0.0, -z.min()])


def side_rotation(mesh: trimesh.Trimesh) -> np.ndarray:
    """Rotation (object -> world) that lays any closed mesh on its side as it comes to rest:
    of the orientations with the object's z axis within :data:`SIDE_TILT_DEG` of level, the one
    with its centre of mass lowest above its lowest point (least potential energy: a flat bottle
    on its broad face, a mug on its body and handle). Searched on a coarse grid of roll about
    the axis and tilt of the axis, then finer ones around the best."""
    hull = mesh.convex_hull.vertices  # (k, 3) the points that can touch a table
    com = mesh.center_mass

    def search(roll: np.ndarray, tilt: np.ndarray) -> tuple[float, float]:
        r, t = (a.ravel() for a in np.meshgrid(roll, tilt))
        rot = np.stack([rotation_about([1.0, 0, 0], np.pi / 2 + b) @ rotation_about([0, 0, 1.0], a)
                        for a, b in zip(r, t)])  # (g, 3, 3)
        height = rot[:, 2] @ com - (hull @ rot[:, 2].T).min(0)
        best = int(np.argmin(height))
        return r[best], t[best]

    steps = np.radians(SIDE_STEP_DEG)
    limit = np.radians(SIDE_TILT_DEG)
    roll, tilt = search(np.arange(0, 2 * np.pi, steps[0]),
                        np.arange(-limit, limit + 1e-9, steps[0]))
    for coarse, fine in zip(steps[:-1], steps[1:]):
        around = np.arange(-coarse, coarse + 1e-9, fine)
        roll, tilt = search(roll + around, np.clip(tilt + around, -limit, limit))
    return rotation_about([1.0, 0, 0], np.pi / 2 + tilt) @ rotation_about([0, 0, 1.0], roll)


def sample_glass(rng: np.random.Generator, lying_fraction: float,
                 kinds: tuple[str, ...] = KINDS) -> Placed:
    """A transparent object of one of ``kinds`` (equally likely), at a random yaw, lying on its
    side with probability ``lying_fraction`` where its kind can lie."""
    kind = kinds[rng.integers(len(kinds))]
    shape = make_shape(kind, rng)
    mesh = shape.mesh
    yaw = rotation_about([0, 0, 1], rng.uniform(0, 2 * np.pi))
    lying = shape.can_lie and rng.uniform() < lying_fraction
    if not lying:
        R = yaw
    elif shape.profile is not None:
        R = yaw @ lying_rotation(shape.profile, mesh.center_mass[2])
    else:
        R = yaw @ side_rotation(mesh)
    T = _rest(mesh, R, shape.height)
    return Placed(mesh, T, shape.height, kind, True, "lying" if lying else "standing")


def elevation_range(objects: list[Placed], elevation_deg: tuple[float, float]
                    ) -> tuple[float, float]:
    """Camera elevations (degrees) for a scene: ``elevation_deg``, raised to at least
    :data:`OPEN_MIN_ELEVATION_DEG` where the scene holds an open vessel to be seen into."""
    if any(o.transparent and o.label in FAMILIES["open"] for o in objects):
        return (max(elevation_deg[0], OPEN_MIN_ELEVATION_DEG),
                max(elevation_deg[1], OPEN_MIN_ELEVATION_DEG))
    return elevation_deg


def sample_distractor(rng: np.random.Generator) -> Placed:
    colour = tuple(float(c) for c in rng.uniform(0.1, 0.9, 3))
    yaw = rotation_about([0, 0, 1], rng.uniform(0, 2 * np.pi))
    if rng.uniform() < 0.5:
        mesh = trimesh.creation.box(rng.uniform([0.03, 0.03, 0.02], [0.12, 0.10, 0.12]))
        mesh.unmerge_vertices()  # flat shading
        label = "box"
    else:
        mesh = trimesh.creation.cylinder(radius=rng.uniform(0.02, 0.045),
                                         height=rng.uniform(0.05, 0.14), sections=40)
        label = "can"
    return Placed(mesh, _rest(mesh, yaw, 1.0), 1.0, label, False, colour=colour)


def arrange(objects: list[Placed], rng: np.random.Generator, spread: float = 0.16,
            gap: float = 0.01, tries: int = 200) -> list[Placed]:
    """Move objects to random table positions without overlapping footprints (drops misfits)."""
    placed: list[tuple[Placed, np.ndarray, float]] = []
    for obj in objects:
        centre0, radius = obj.footprint()
        for _ in range(tries):
            xy = rng.uniform(-spread, spread, 2)
            if all(np.linalg.norm(xy - c) > radius + r + gap for _, c, r in placed):
                obj.T_world_obj = obj.T_world_obj.copy()
                obj.T_world_obj[:2, 3] += xy - centre0
                placed.append((obj, xy, radius))
                break
    return [p for p, _, _ in placed]


def sample_camera(rng: np.random.Generator, resolutions: list[str], depth_scale: float) -> Camera:
    """RealSense-like colour intrinsics (D435/D415 at 640x480 or 848x480)."""
    res = resolutions[rng.integers(len(resolutions))]
    w, h = (int(v) for v in res.lower().split("x"))
    f = rng.uniform(600.0, 625.0) * (h / 480.0)
    K = np.array([[f, 0, (w - 1) / 2 + rng.uniform(-6, 6)],
                  [0, f * rng.uniform(0.998, 1.002), (h - 1) / 2 + rng.uniform(-6, 6)],
                  [0, 0, 1]])
    return Camera(K, w, h, depth_scale)


def sample_view(rng: np.random.Generator, target: np.ndarray, distance: tuple[float, float],
                elevation_deg: tuple[float, float]) -> np.ndarray:
    """``T_world_cam`` at a random distance, elevation and azimuth, looking near ``target``."""
    d = rng.uniform(*distance)
    el = np.radians(rng.uniform(*elevation_deg))
    az = rng.uniform(0, 2 * np.pi)
    eye = target + d * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    aim = target + rng.normal(0, 0.01, 3) * np.array([1, 1, 0])
    return look_at(eye, aim, np.array([0.0, 0.0, 1.0]))


def in_view(points_world: np.ndarray, T_world_cam: np.ndarray, camera: Camera,
            margin: float = 8) -> bool:
    T_cam_world = np.linalg.inv(T_world_cam)
    p = apply_T(T_cam_world, points_world)
    if np.any(p[:, 2] < 0.1):
        return False
    u, v = project(p, camera.K).T
    return bool(u.min() >= margin and v.min() >= margin and u.max() <= camera.width - 1 - margin
                and v.max() <= camera.height - 1 - margin)
