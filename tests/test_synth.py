"""Synthetic scenes: contract of every file, truth that is self-consistent, glass that fails
like glass. Seeds here (100+) are not the ones the benchmark uses."""

import hashlib

import numpy as np
import pytest

from sr3d_cli.config import SynthConfig
from sr3d_cli.geometry.revolution import revolve
from sr3d_cli.io.contract import check_frame
from sr3d_cli.io.scene import SceneSource
from sr3d_cli.render import NumpyRenderer, make_renderer
from sr3d_cli.synth.generate import write_scene
from sr3d_cli.synth.layout import lying_rotation
from sr3d_cli.synth.shapes import KINDS, make_glassware


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("synth")
    cfg = SynthConfig(seed=101, views=2)
    renderer = make_renderer("auto")
    return [root / f"s{i}" for i in range(4) if write_scene(root / f"s{i}", i, cfg, renderer)]


def test_every_kind_is_watertight_with_outward_normals():
    rng = np.random.default_rng(3)
    for kind in KINDS:
        for _ in range(10):
            mesh = make_glassware(kind, rng).unit_mesh()
            assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
            assert mesh.bounds[0, 2] == pytest.approx(0) and mesh.bounds[1, 2] == pytest.approx(1)


def _lie(profile: np.ndarray, mesh) -> tuple[np.ndarray, np.ndarray]:
    """World vertices of a unit mesh laid down by the generator, and its centre of mass."""
    R = lying_rotation(profile, mesh.center_mass[2])
    return mesh.vertices @ R.T, R @ mesh.center_mass


def test_lying_glassware_rests_with_its_centre_of_mass_over_the_contact():
    """Laid on its side, every object touches the table along a line (two rings' lowest points)
    and its centre of mass is above that line, so it would not roll: stable, as a real object
    comes to rest."""
    rng = np.random.default_rng(5)
    for kind in KINDS:
        for _ in range(10):
            glass = make_glassware(kind, rng)
            v, com = _lie(glass.profile / glass.height, glass.unit_mesh())
            low = v[v[:, 2] < v[:, 2].min() + 1e-9]
            d = (low[-1] - low[0])[:2]
            assert len(low) >= 2 and np.linalg.norm(d) > 0.05  # a line, not a point
            d /= np.linalg.norm(d)
            along = (low[:, :2] - low[0, :2]) @ d
            c = (com[:2] - low[0, :2]) @ d
            assert along.min() - 1e-9 <= c <= along.max() + 1e-9, kind
            off = com[:2] - low[0, :2]
            assert abs(d[0] * off[1] - d[1] * off[0]) < 1e-9  # above the line, by symmetry


def test_a_bottle_with_a_long_shoulder_lies_on_its_body():
    """The longest side of this bottle's outline runs from its shoulder to its lip, but its
    weight sits over the body: it lies with its axis level, not propped up on the neck."""
    prof = np.array([[0, 0], [0.03, 0], [0.03, 0.08], [0.01, 0.2], [0.008, 0.22], [0, 0.22]])
    v, _ = _lie(prof / 0.22, revolve(prof / 0.22))
    axis = v[-1] - v[-2]  # top centre minus base centre (revolve's last two vertices)
    assert abs(axis[2]) < 1e-9


def test_contract_of_every_file(scenes):
    renderer = NumpyRenderer()  # independent of the renderer that made the scenes
    all_ious = []
    for folder in scenes:
        source = SceneSource(folder)
        assert source.frame_ids() == ["000000", "000001"]
        for fid in source.frame_ids():
            problems, ious = check_frame(source, fid, renderer)
            assert problems == []
            all_ious += ious.values()
            frame = source.load_frame(fid)
            assert frame.rgb.dtype == np.uint8 and frame.rgb.shape[2] == 3
            assert frame.rgb.shape[:2] in ((480, 640), (480, 848))
    assert len(all_ious) >= 8 and min(all_ious) > 0.9 and np.median(all_ious) > 0.97


def test_scene_parameters_within_the_specified_ranges(scenes):
    for folder in scenes:
        source = SceneSource(folder)
        for fid in source.frame_ids():
            objects = source.load_gt_objects(fid)["objects"]
            assert 1 <= len(objects) <= 3
            for obj in objects:
                T = np.asarray(obj["T_cam_obj"])
                assert 0.2 < np.linalg.norm(T[:3, 3]) < 1.2
                assert obj["label"] in KINDS and obj["pose"] in ("standing", "lying")
                assert 0.03 < obj["scale"] < 0.35  # heights of real glassware, metres


def test_raw_depth_fails_like_a_sensor_on_glass(scenes):
    holes = through = front = total = 0
    opaque_err = []
    for folder in scenes:
        source = SceneSource(folder)
        for fid in source.frame_ids():
            frame = source.load_frame(fid)
            gt = source.load_gt_depth(fid, frame.depth_m.shape)
            mask = source.load_mask(source.gt_mask_path(fid), gt.shape) > 0
            raw = frame.depth_m
            total += mask.sum()
            holes += (mask & (raw == 0)).sum()
            through += (mask & (raw > gt + 0.01)).sum()
            front += (mask & (np.abs(raw - gt) < 0.01)).sum()
            opaque = ~mask & (raw > 0) & (gt > 0) & (gt < 1.5)
            opaque_err.append(np.median(np.abs(raw - gt)[opaque]))
    assert 0.1 < holes / total < 0.8  # clustered holes
    assert through / total > 0.05  # see-through readings of the table behind
    assert front / total > 0.05  # some true front-surface returns
    assert np.median(opaque_err) < 0.002  # opaque surfaces: millimetre noise


def test_glass_looks_like_glass_not_grey_plastic(scenes):
    """Glass shows what is behind it (on a wood table it takes the wood's hue, and its pixels
    vary like the texture seen through it) and brightens towards the silhouette (Fresnel),
    unlike a uniform grey object."""
    import cv2

    checked_hue, rim_brighter = 0, []
    for folder in scenes:
        source = SceneSource(folder)
        frame = source.load_frame("000000")
        mask = source.load_mask(source.gt_mask_path("000000"), frame.depth_m.shape) > 0
        rgb = frame.rgb.astype(float)
        inner = cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
        t_chroma = (rgb[~mask][:, 0] - rgb[~mask][:, 2]).mean()
        g_chroma = (rgb[inner][:, 0] - rgb[inner][:, 2]).mean()
        if abs(t_chroma) > 20:  # wood: strongly coloured table behind the glass
            assert np.sign(g_chroma) == np.sign(t_chroma) and abs(g_chroma) > 0.4 * abs(t_chroma)
            checked_hue += 1
        ring = (cv2.dilate(mask.astype(np.uint8), np.ones((31, 31), np.uint8)) > 0) & ~mask
        # not a flat fill: at least half the variation of the table around it
        assert rgb[inner].mean(1).std() > 0.5 * rgb[ring].mean(1).std()
        rim = mask & ~inner
        rim_brighter.append(np.percentile(rgb[rim].mean(1), 95) > np.median(rgb[inner].mean(1)))
    assert checked_hue >= 1
    assert sum(rim_brighter) >= len(rim_brighter) - 1


def test_deterministic_for_a_seed(tmp_path):
    cfg = SynthConfig(seed=123, views=1)
    renderer = make_renderer("auto")
    digests = []
    for run in ("a", "b"):
        write_scene(tmp_path / run, 0, cfg, renderer)
        files = sorted(p for p in (tmp_path / run).rglob("*") if p.is_file())
        digests.append({p.relative_to(tmp_path / run).as_posix():
                        hashlib.sha256(p.read_bytes()).hexdigest() for p in files})
    assert digests[0] == digests[1] and len(digests[0]) >= 7


def test_numpy_fallback_generates_an_equivalent_scene(tmp_path):
    cfg = SynthConfig(seed=7, views=1, resolutions=["640x480"])
    write_scene(tmp_path / "np", 0, cfg, NumpyRenderer())
    write_scene(tmp_path / "gl", 0, cfg, make_renderer("auto"))
    a, b = SceneSource(tmp_path / "np"), SceneSource(tmp_path / "gl")
    ma = a.load_mask(a.gt_mask_path("000000"), (480, 640))
    mb = b.load_mask(b.gt_mask_path("000000"), (480, 640))
    assert (ma > 0).sum() > 500
    inter, union = ((ma > 0) & (mb > 0)).sum(), ((ma > 0) | (mb > 0)).sum()
    assert inter / union > 0.99
    ga, gb = a.load_gt_depth("000000", (480, 640)), b.load_gt_depth("000000", (480, 640))
    assert np.median(np.abs(ga - gb)[(ga > 0) & (gb > 0)]) <= 0.001
