"""Shared fixtures: tiny hand-made scene folders and the path to the shared real frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sr3d_cli.io.atomic import write_json, write_png
from sr3d_cli.io.images import write_depth

REALDATA = Path(__file__).resolve().parents[1].parent / "shared" / "realdata" / "cleargrasp-real"
EXTSIM = Path(__file__).resolve().parents[1].parent / "shared" / "extsim"

K_SMALL = [[50.0, 0.0, 15.5], [0.0, 50.0, 11.5], [0.0, 0.0, 1.0]]


def make_native_scene(root: Path, n_frames: int = 2, *, h: int = 24, w: int = 32,
                      depth_scale: float = 0.001) -> Path:
    """A scene with a flat 0.5 m table and one 6x8-pixel 'object' at 0.45 m.

    Raw depth has holes on the object's left half and reads the table (0.5 m) on the right half;
    the ground truth says 0.45 m on the object.
    """
    write_json(root / "camera.json", {"K": K_SMALL, "width": w, "height": h,
                                      "depth_scale": depth_scale})
    for i in range(n_frames):
        fid = f"{i:06d}"
        rgb = np.full((h, w, 3), 120, np.uint8)
        gt = np.full((h, w), 0.5, np.float32)
        mask = np.zeros((h, w), np.uint8)
        mask[8:14, 10:18] = 1
        gt[mask > 0] = 0.45
        raw = gt.copy()
        raw[8:14, 10:14] = 0.0
        raw[8:14, 14:18] = 0.5
        write_png(root / "rgb" / f"{fid}.png", rgb)
        write_depth(root / "depth" / f"{fid}.png", raw, depth_scale)
        write_depth(root / "gt" / "depth" / f"{fid}.png", gt, depth_scale)
        write_png(root / "gt" / "masks" / f"{fid}.png", mask)
    return root


@pytest.fixture
def native_scene(tmp_path) -> Path:
    return make_native_scene(tmp_path / "scene")


@pytest.fixture
def realdata() -> Path:
    if not REALDATA.is_dir():
        pytest.skip(f"shared real frames not present at {REALDATA} (they live outside the repo)")
    return REALDATA


@pytest.fixture
def extsim() -> Path:
    if not EXTSIM.is_dir():
        pytest.skip(f"the independent renderer's frames not present at {EXTSIM} (they live "
                    f"outside the repo)")
    return EXTSIM


@pytest.fixture(scope="package")
def synth_set(tmp_path_factory) -> Path:
    """Six synthetic scenes (seed 303, used only by the stage tests), made once per test run
    (once per xdist worker) and only read."""
    from sr3d_cli.config import SynthConfig
    from sr3d_cli.render import make_renderer
    from sr3d_cli.synth.generate import write_scene

    root = tmp_path_factory.mktemp("synth303")
    cfg = SynthConfig(seed=303, views=1)
    renderer = make_renderer("auto")
    for i in range(6):
        write_scene(root / f"scene_{i:04d}", i, cfg, renderer)
    return root
