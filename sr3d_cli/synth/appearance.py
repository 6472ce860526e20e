"""Colour images of synthetic scenes: a textured table, opaque objects, and glass that looks like
glass (refraction-like distortion of what is behind, Fresnel brightening at grazing angles,
dark total-internal-reflection bands near silhouettes, specular highlights, a faint tint)."""

from __future__ import annotations

import cv2
import numpy as np

from sr3d_cli.geometry.camera import depth_to_points
from sr3d_cli.geometry.transforms import apply_T
from sr3d_cli.geometry.transforms import unit as _unit


def smooth_noise(rng: np.random.Generator, shape: tuple[int, int], cell: float) -> np.ndarray:
    """Value noise in [0, 1] with features about ``cell`` pixels wide, ``(H, W) float32``."""
    h, w = shape
    gh, gw = max(2, int(np.ceil(h / cell)) + 2), max(2, int(np.ceil(w / cell)) + 2)
    grid = rng.uniform(0, 1, (gh, gw)).astype(np.float32)
    big = cv2.resize(grid, (int(gw * cell), int(gh * cell)), interpolation=cv2.INTER_CUBIC)
    out = big[:h, :w]
    lo, hi = out.min(), out.max()
    return (out - lo) / max(hi - lo, 1e-6)


class TableTexture:
    """Procedural table top (wood grain or speckled laminate) as a function of world x, y."""

    def __init__(self, rng: np.random.Generator, extent: float = 1.2, res: int = 1024):
        self.extent, self.res = extent, res
        wood = rng.uniform() < 0.7
        noise = smooth_noise(rng, (res, res), res / 24)
        fine = smooth_noise(rng, (res, res), 3)
        y, x = np.mgrid[0:res, 0:res] / res
        if wood:
            base = np.array(rng.choice([[0.62, 0.45, 0.30], [0.45, 0.30, 0.18], [0.75, 0.60, 0.42]]))
            freq = rng.uniform(25, 60)
            grain = 0.5 + 0.5 * np.sin(2 * np.pi * (freq * y + 3.0 * noise))
            shade = 0.75 + 0.2 * grain + 0.1 * (fine - 0.5)
        else:
            base = np.array(rng.choice([[0.85, 0.85, 0.83], [0.55, 0.57, 0.6], [0.9, 0.88, 0.8]]))
            shade = 0.9 + 0.1 * noise + 0.15 * (fine - 0.5)
            speck = rng.uniform(0, 1, (res, res)) < 0.01
            shade = np.where(speck, shade * 0.6, shade)
        self.image = np.clip(shade[..., None] * base, 0, 1).astype(np.float32)

    def lookup(self, xy_world: np.ndarray) -> np.ndarray:
        """Colours ``(..., 3)`` in [0, 1] at world points ``(..., 2)`` (metres)."""
        pix = (xy_world / (2 * self.extent) + 0.5) * (self.res - 1)
        mx = pix[..., 0].astype(np.float32)
        my = pix[..., 1].astype(np.float32)
        return cv2.remap(self.image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _view_and_half(pts_cam: np.ndarray, light_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions ``(H, W, 3)`` towards the camera and halfway to the light (Blinn)."""
    view = _unit(-pts_cam)
    return view, _unit(view + light_cam)


def shade_background(render, T_world_cam, K, texture: TableTexture, colours: dict[int, tuple],
                     table_id: int, light_cam: np.ndarray, shadow: np.ndarray) -> np.ndarray:
    """Colour image ``(H, W, 3) float32`` in [0, 1] of the table and opaque objects."""
    h, w = render.depth.shape
    pts_cam = depth_to_points(render.depth, K)
    pts_world = apply_T(T_world_cam, pts_cam)
    lambert = np.clip(render.normals @ light_cam, 0, 1)
    ambient = 0.45
    image = np.empty((h, w, 3), np.float32)
    y = np.linspace(0, 1, h, dtype=np.float32)[:, None, None]
    image[:] = 0.55 + 0.25 * y  # wall / far background
    table = render.ids == table_id
    tex = texture.lookup(pts_world[..., :2])
    light = (ambient + 0.6 * lambert)[..., None] * shadow[..., None]
    image[table] = (tex * light)[table]
    _, half = _view_and_half(pts_cam, light_cam)
    spec = np.clip((render.normals * half).sum(-1), 0, 1) ** 40
    for obj_id, colour in colours.items():
        sel = render.ids == obj_id
        image[sel] = (np.asarray(colour, np.float32) * light[sel] + 0.3 * spec[sel, None])
    return np.clip(image, 0, 1)


def shade_glass(background: np.ndarray, render, glass_ids: list[int], K: np.ndarray,
                rng: np.random.Generator, light_cam: np.ndarray) -> np.ndarray:
    """Composite glass objects over ``background (H, W, 3)``, using the full render's normals."""
    h, w = render.depth.shape
    out = background.copy()
    view, half = _view_and_half(depth_to_points(render.depth, K), light_cam)
    n = render.normals
    cos = np.abs((n * view).sum(-1))
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    for obj_id in glass_ids:
        sel = render.ids == obj_id
        if not sel.any():
            continue
        ys, xs = np.nonzero(sel)
        size = max(np.ptp(xs), np.ptp(ys)) + 1
        strength = rng.uniform(0.08, 0.18) * size  # pixels of displacement at grazing normals
        mx = (u + strength * n[..., 0] * (1.2 - cos)).astype(np.float32)
        my = (v + strength * n[..., 1] * (1.2 - cos)).astype(np.float32)
        refracted = cv2.remap(background, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        tint = np.array(rng.choice([[0.97, 0.99, 0.98], [0.9, 0.97, 0.92], [0.93, 0.95, 0.99]]),
                        np.float32)
        refracted = refracted * tint * rng.uniform(0.9, 1.0)
        fresnel = 0.04 + 0.96 * (1 - cos) ** 5
        env = (0.85 + 0.1 * (1 - v / h))[..., None]  # bright room reflected at grazing angles
        colour = (1 - fresnel[..., None]) * refracted + fresnel[..., None] * env
        band = np.exp(-((cos - 0.22) / 0.08) ** 2)  # total internal reflection: dark band
        colour *= (1 - 0.55 * band)[..., None]
        spec = np.clip((n * half).sum(-1), 0, 1) ** rng.uniform(150, 500)
        colour += 1.2 * spec[..., None]
        out[sel] = colour[sel]
    return np.clip(out, 0, 1)


def contact_shadow(render_bg, T_world_cam, K, objects, table_id: int) -> np.ndarray:
    """Soft darkening of the table around each object's footprint, ``(H, W) float32`` factor."""
    pts_cam = depth_to_points(render_bg.depth, K)
    xy = apply_T(T_world_cam, pts_cam)[..., :2]
    factor = np.ones(render_bg.depth.shape, np.float32)
    for obj in objects:
        centre, radius = obj.footprint()
        d = np.maximum(np.linalg.norm(xy - centre, axis=-1) - 0.8 * radius, 0)
        dark = 0.12 if obj.transparent else 0.35
        factor *= 1 - dark * np.exp(-(d / (0.25 * radius + 0.005)) ** 2)
    return np.where(render_bg.ids == table_id, factor, 1.0).astype(np.float32)


def finish(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Camera look: slight blur, sensor noise, 8-bit RGB."""
    image = cv2.GaussianBlur(image, (0, 0), 0.6)
    image = image + rng.normal(0, 0.008, image.shape).astype(np.float32)
    return np.clip(image * 255 + 0.5, 0, 255).astype(np.uint8)
