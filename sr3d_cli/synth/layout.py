"""Random scene layouts: objects resting on a table (world z = 0, z up) and cameras looking at them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from sr3d_cli.geometry.camera import Camera, project
from sr3d_cli.geometry.revolution import resting_edge
from sr3d_cli.geometry.transforms import (apply_T, look_at, make_T, rotation_about,
                                          rotation_between)
from sr3d_cli.synth.shapes import KINDS, make_glassware


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


def sample_glass(rng: np.random.Generator, lying_fraction: float) -> Placed:
    kind = KINDS[rng.integers(len(KINDS))]
    glass = make_glassware(kind, rng)
    mesh = glass.unit_mesh()
    yaw = rotation_about([0, 0, 1], rng.uniform(0, 2 * np.pi))
    lying = kind != "flask" and rng.uniform() < lying_fraction
    R = yaw @ lying_rotation(glass.profile / glass.height, mesh.center_mass[2]) if lying \
        else yaw
    T = _rest(mesh, R, glass.height)
    return Placed(mesh, T, glass.height, kind, True, "lying" if lying else "standing")


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
