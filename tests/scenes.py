"""Small rendered scenes with known truth, shared by the segmentation and reconstruction tests."""

from __future__ import annotations

import numpy as np

from sr3d_cli.geometry.camera import Camera
from sr3d_cli.geometry.plane import Plane
from sr3d_cli.geometry.revolution import revolve
from sr3d_cli.render import RenderMesh, make_renderer

K_TABLE = np.array([[610.0, 0, 319.5], [0, 610, 239.5], [0, 0, 1]])
ELEVATION = 55.0  # degrees the camera looks down at the table
GLASS = np.array([[0, 0], [0.03, 0], [0.034, 0.1], [0, 0.1]])  # profile (r, z) m, 10 cm tall


def table() -> Plane:
    """The table 0.6 m along the optical axis, seen from :data:`ELEVATION` degrees."""
    e = np.radians(ELEVATION)
    up = np.array([0.0, -np.cos(e), -np.sin(e)])  # table normal, towards the camera
    return Plane(up, float(-up @ np.array([0, 0, 0.6])))


def table_point(plane: Plane, x: float, y: float) -> np.ndarray:
    """The table point ``x`` m right of and ``y`` m further than where the optical axis meets
    it (camera frame)."""
    x_dir = np.array([1.0, 0, 0])
    return plane.intersect(np.array([0.0, 0.0, 1.0])) + x * x_dir + y * np.cross(plane.normal,
                                                                                   x_dir)


def solids_on_table(placements):
    """Instance ids, K, the table and depth (metres, 0 off the objects) of solids of revolution
    on :func:`table`. placements: (profile, height m, x m, y m on the table), standing, or with
    a fifth item, lying with the axis turned that many degrees from the image's x direction
    (the base at x, y; the axis raised by the widest radius)."""
    plane = table()
    up = plane.normal
    x_dir = np.array([1.0, 0, 0])
    y_dir = np.cross(up, x_dir)
    meshes = []
    for k, (profile, height, x, y, *lying) in enumerate(placements, start=1):
        m = revolve(np.asarray(profile) / height)
        base = table_point(plane, x, y)
        if lying:
            yaw = np.radians(lying[0])
            axis = np.cos(yaw) * x_dir + np.sin(yaw) * y_dir
            R = np.stack([up, np.cross(axis, up), axis], 1)
            base = base + float(np.max(np.asarray(profile)[:, 0])) * up
        else:
            R = np.stack([x_dir, y_dir, up], 1)
        meshes.append(RenderMesh(m.vertices @ (height * R).T + base, np.asarray(m.faces), k))
    out = make_renderer("numpy").render(meshes, Camera(K_TABLE, 640, 480))
    return out.ids, K_TABLE, plane, out.depth.astype(np.float64)


def generated_frame(folder, seed: int, index: int, renderer: str = "numpy"):
    """Frame ``index`` of the synthetic generator's seed ``seed``, written under ``folder``:
    (its scene source, the loaded frame, the true instance ids)."""
    from sr3d_cli.config import IOConfig, SynthConfig
    from sr3d_cli.io.formats import discover_scenes
    from sr3d_cli.synth.generate import write_scene

    write_scene(folder / "scene_0000", index, SynthConfig(seed=seed, views=1),
                make_renderer(renderer))
    source = discover_scenes(folder, IOConfig(), None)[0]
    frame = source.load_frame("000000")
    return source, frame, source.load_mask(source.gt_mask_path("000000"), frame.depth_m.shape)
