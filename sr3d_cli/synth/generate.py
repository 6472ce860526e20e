"""Generate synthetic scene folders in the native layout with full ground truth.

Each scene is one camera (one ``camera.json``) and ``views`` frames of the same arrangement.
Randomness comes from ``numpy.random.default_rng([seed, scene_index])``, so a scene does not
depend on how many others are generated, and output is byte-identical for a seed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sr3d_cli.config import SynthConfig
from sr3d_cli.geometry.camera import Camera
from sr3d_cli.geometry.transforms import apply_T
from sr3d_cli.io.atomic import write_bytes, write_json, write_png
from sr3d_cli.io.images import write_depth
from sr3d_cli.render import RenderMesh, Renderer
from sr3d_cli.synth import appearance, layout
from sr3d_cli.synth.families import DEFAULT_FAMILIES, kinds_for
from sr3d_cli.synth.shapes import KINDS
from sr3d_cli.synth.sensor import simulate_depth

TABLE_ID = 1000  # render ids: glass 1..n, distractors 1001.., table 1000
TABLE_HALF = 1.2  # metres


@dataclass
class SynthFrame:
    """rgb (H, W, 3) uint8; depth_m raw sensor; gt_depth_m all opaque; gt_mask (H, W) int32."""

    rgb: np.ndarray
    depth_m: np.ndarray
    gt_depth_m: np.ndarray
    gt_mask: np.ndarray
    objects: list[dict]


def _table_mesh() -> RenderMesh:
    s = TABLE_HALF
    v = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], dtype=np.float64)
    return RenderMesh(v, np.array([[0, 1, 2], [0, 2, 3]]), TABLE_ID,
                      np.tile([0.0, 0.0, 1.0], (4, 1)))


def _to_camera(mesh: RenderMesh, T_cam_world: np.ndarray) -> RenderMesh:
    normals = None if mesh.normals is None else mesh.normals @ T_cam_world[:3, :3].T
    return RenderMesh(apply_T(T_cam_world, mesh.vertices), mesh.faces, mesh.id, normals)


def _world_mesh(obj: layout.Placed, obj_id: int) -> RenderMesh:
    R = obj.T_world_obj[:3, :3]
    smooth = obj.label not in ("box",)
    normals = obj.mesh.vertex_normals @ R.T if smooth else None
    return RenderMesh(obj.world_vertices(), obj.mesh.faces, obj_id, normals)


def sample_layout(cfg: SynthConfig, rng: np.random.Generator,
                  kinds: tuple[str, ...] = KINDS) -> layout.Layout:
    """Objects (transparent ones of ``kinds``), the camera and its views of one scene."""
    camera = layout.sample_camera(rng, cfg.resolutions, cfg.depth_scale)
    n_glass = int(rng.integers(cfg.objects[0], cfg.objects[1] + 1))
    n_other = int(rng.integers(cfg.distractors[0], cfg.distractors[1] + 1))
    glass = [layout.sample_glass(rng, cfg.lying_fraction, kinds) for _ in range(n_glass)]
    others = [layout.sample_distractor(rng) for _ in range(n_other)]
    objects = layout.arrange(glass + others, rng)  # glass first: the first always fits
    glass_pts = np.vstack([o.world_vertices() for o in objects if o.transparent])
    target = (glass_pts.min(0) + glass_pts.max(0)) / 2
    target[2] = 0.3 * glass_pts[:, 2].max()
    elevation = layout.elevation_range(objects, tuple(cfg.elevation_deg))
    views = []
    for _ in range(cfg.views):
        for _attempt in range(100):
            T = layout.sample_view(rng, target, tuple(cfg.distance), elevation)
            if layout.in_view(glass_pts, T, camera):
                break
        views.append(T)
    return layout.Layout(objects, camera, views)


def render_frame(scene: layout.Layout, T_world_cam: np.ndarray, renderer: Renderer,
                 texture: appearance.TableTexture, cfg: SynthConfig,
                 rng: np.random.Generator) -> SynthFrame:
    camera = scene.camera
    K = camera.K
    T_cam_world = np.linalg.inv(T_world_cam)
    glass_ids, colours = [], {}
    world = [_table_mesh()]
    for obj in scene.objects:
        obj_id = (len(glass_ids) + 1) if obj.transparent else 1001 + len(colours)
        if obj.transparent:
            glass_ids.append(obj_id)
        else:
            colours[obj_id] = obj.colour
        world.append(_world_mesh(obj, obj_id))
    meshes = [_to_camera(m, T_cam_world) for m in world]
    full = renderer.render(meshes, camera)
    background = renderer.render([m for m in meshes if m.id not in glass_ids], camera)
    light_world = np.array([0.3, -0.4, 1.0])
    light_cam = T_cam_world[:3, :3] @ (light_world / np.linalg.norm(light_world))
    shadow = appearance.contact_shadow(background, T_world_cam, K, scene.objects, TABLE_ID)
    bg_rgb = appearance.shade_background(background, T_world_cam, K, texture, colours, TABLE_ID,
                                         light_cam, shadow)
    # opaque objects in front of glass appear in the full render: shade them from it too
    opaque_front = appearance.shade_background(full, T_world_cam, K, texture, colours, TABLE_ID,
                                               light_cam, shadow)
    base = np.where(np.isin(full.ids, glass_ids)[..., None], bg_rgb, opaque_front)
    rgb = appearance.finish(appearance.shade_glass(base, full, glass_ids, K, rng, light_cam), rng)
    far = full.depth > cfg.max_range * 1.5
    gt = np.where(far, 0, full.depth).astype(np.float32)
    raw = simulate_depth(gt, background.depth, full.ids, full.normals, K, glass_ids, rng,
                         hole_fraction=tuple(cfg.hole_fraction),
                         see_through_fraction=tuple(cfg.see_through_fraction),
                         noise_opaque=cfg.noise_opaque, noise_glass=cfg.noise_glass,
                         max_range=cfg.max_range)
    mask = np.where(np.isin(full.ids, glass_ids), full.ids, 0).astype(np.int32)
    objects = []
    for obj_id, obj in zip(glass_ids, [o for o in scene.objects if o.transparent]):
        T_cam_obj = T_cam_world @ obj.T_world_obj
        objects.append({"id": obj_id, "label": obj.label, "pose": obj.pose,
                        "T_cam_obj": T_cam_obj, "scale": obj.scale,
                        "visible_pixels": int((mask == obj_id).sum())})
    return SynthFrame(rgb, raw, gt, mask, objects)


def write_scene(out: Path, scene_index: int, cfg: SynthConfig, renderer: Renderer,
                families: Sequence[str] = DEFAULT_FAMILIES) -> list[str]:
    """Generate scene ``scene_index`` into folder ``out``; returns the frame ids written.

    families : the object families (or single kinds, or ``all``) its transparent objects are
    drawn from (:mod:`sr3d_cli.synth.families`); the default draws what it always drew.
    """
    rng = np.random.default_rng([cfg.seed, scene_index])
    scene = sample_layout(cfg, rng, kinds_for(families))
    texture = appearance.TableTexture(rng, extent=TABLE_HALF)
    camera: Camera = scene.camera
    mesh_names = {}
    for i, obj in enumerate(o for o in scene.objects if o.transparent):
        name = f"gt/meshes/{i + 1:02d}_{obj.label}.ply"
        write_bytes(out / name, obj.mesh.export(file_type="ply", encoding="binary"))
        mesh_names[i + 1] = name
    frame_ids = []
    for v, T_world_cam in enumerate(scene.T_world_cams):
        fid = f"{v:06d}"
        frame = render_frame(scene, T_world_cam, renderer, texture, cfg, rng)
        for obj in frame.objects:
            obj["mesh"] = mesh_names[obj["id"]]
        write_png(out / "rgb" / f"{fid}.png", frame.rgb)
        write_depth(out / "depth" / f"{fid}.png", frame.depth_m, camera.depth_scale)
        write_depth(out / "gt" / "depth" / f"{fid}.png", frame.gt_depth_m, camera.depth_scale)
        write_png(out / "gt" / "masks" / f"{fid}.png", frame.gt_mask.astype(np.uint8))
        write_json(out / "gt" / "objects" / f"{fid}.json", {"objects": frame.objects})
        frame_ids.append(fid)
    write_json(out / "camera.json", camera.to_json())
    return frame_ids
