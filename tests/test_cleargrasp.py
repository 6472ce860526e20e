"""ClearGrasp layout read in place: a fixture in its exact layout, and the shared real frames."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.config import IOConfig
from sr3d_cli.io.atomic import write_png
from sr3d_cli.io.exr import write_exr
from sr3d_cli.io.formats import detect_layout, discover_scenes


def make_cleargrasp(folder, fid="000000007"):
    folder.mkdir(parents=True)
    (folder / "camera_intrinsics.yaml").write_text(
        "camera_name: 'D435'\nxres: 64\nyres: 36\nfx: 46\nfy: 46\ncx: 32\ncy: 18\n")
    # PNG bytes under ClearGrasp's .jpg name: decoders go by content
    write_png(folder / f"{fid}-transparent-rgb-img.jpg", np.zeros((36, 64, 3), np.uint8))
    gt = np.full((36, 64), 0.6, np.float32)
    mask = np.zeros((36, 64), np.uint8)
    mask[5:10, 5:12] = 255  # two objects in one binary mask
    mask[20:30, 40:50] = 255
    gt[mask > 0] = 0.55
    gt[0, 0] = np.nan  # holes of the ground truth itself
    raw = gt.copy()
    raw[5:10, 5:12] = 0.0  # object 1: holes
    raw[20:30, 40:50] = 0.6  # object 2: reads the table through the glass
    write_exr(folder / f"{fid}-transparent-depth-img.exr", raw)
    write_exr(folder / f"{fid}-opaque-depth-img.exr", gt)
    write_png(folder / f"{fid}-mask.png", mask)
    return folder


def test_adapter_reads_the_layout_in_place(tmp_path):
    folder = make_cleargrasp(tmp_path / "cg")
    assert detect_layout(folder) == "cleargrasp"
    (source,) = discover_scenes(folder, IOConfig())
    assert source.frame_ids() == ["000000007"]
    frame = source.load_frame("000000007")
    assert frame.rgb.shape == (36, 64, 3) and frame.camera.fx == 46.0
    assert frame.depth_m[7, 7] == 0 and frame.depth_m[25, 45] == pytest.approx(0.6, abs=1e-3)
    ids = source.load_mask(source.gt_mask_path("000000007"), (36, 64))
    assert sorted(np.unique(ids)) == [0, 1, 2]  # binary mask split into instances
    gt = source.load_gt_depth("000000007", (36, 64))
    assert gt[0, 0] == 0  # NaN in EXR = no value
    assert source.output_path("repaired", "000000007").parent == folder / "repaired"


def test_evaluate_on_the_fixture_counts_holes_as_full_error(tmp_path):
    folder = make_cleargrasp(tmp_path / "cg")
    result = CliRunner().invoke(cli, ["evaluate", str(folder), "--pred", "depth", "-q",
                                      "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.stderr
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())["means"]["depth"]
    n1, n2 = 35, 100
    # float16 is not involved here (EXR written as float32): exact expectations
    assert m["pixels"] == n1 + n2
    assert m["mae"] == pytest.approx((n1 * 0.55 + n2 * 0.05) / (n1 + n2), abs=1e-6)
    assert m["coverage"] == pytest.approx(n2 / (n1 + n2))


def test_missing_openexr_gives_the_install_hint(tmp_path, monkeypatch):
    import builtins

    folder = make_cleargrasp(tmp_path / "cg")
    real_import = builtins.__import__

    def no_openexr(name, *args, **kwargs):
        if name == "OpenEXR":
            raise ImportError("No module named 'OpenEXR'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_openexr)
    result = CliRunner().invoke(cli, ["evaluate", str(folder), "--pred", "depth", "-q",
                                      "--out", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert "pip install 'sr3d-cli[exr]'" in result.stderr


# The figures published with the shared frames (../shared/realdata/README.md).
PUBLISHED = {
    "d435/000000123": {"pixels": 24846, "coverage": 0.777, "full": (0.3160, 0.2418, 0.1610),
                       "valid": (0.0217, 0.0241, 0.0161)},
    "d415/000000000": {"pixels": 5371, "coverage": 0.879, "full": (0.2805, 0.1570, 0.1248),
                       "valid": (0.0400, 0.0410, 0.0320)},
}


@pytest.mark.parametrize("mode, flag", [("full", []), ("valid", ["--only-valid"])])
def test_real_frames_reproduce_the_published_raw_depth_figures(realdata, tmp_path, mode, flag):
    result = CliRunner().invoke(cli, ["evaluate", str(realdata), "--pred", "depth", "-q",
                                      "--out", str(tmp_path), *flag])
    assert result.exit_code == 0, result.stderr
    frames = json.loads((tmp_path / "metrics.json").read_text())["frames"]
    assert sorted(frames) == sorted(PUBLISHED)
    for key, published in PUBLISHED.items():
        m = frames[key]["depth"]
        assert round(m["coverage"], 3) == published["coverage"]
        if mode == "full":
            assert m["pixels"] == published["pixels"]
        for name, value in zip(("rmse", "rel", "mae"), published[mode]):
            assert round(m[name], 4) == value, (key, name, m[name])


# At the frames' own size, every protocol counts the object pixels the README's figures count.
@pytest.mark.parametrize("protocol", ["native", "transcg", "cleargrasp"])
def test_each_protocol_at_native_size_reproduces_the_published_figures(realdata, tmp_path,
                                                                       protocol):
    result = CliRunner().invoke(cli, ["evaluate", str(realdata), "--pred", "depth", "-q",
                                      "--out", str(tmp_path), "--protocol", protocol,
                                      "--resolution", "native"])
    assert result.exit_code == 0, result.stderr
    assert f"# protocol {protocol}: native" in result.stdout
    document = json.loads((tmp_path / "metrics.json").read_text())
    assert document["protocol"]["name"] == protocol
    for key, published in PUBLISHED.items():
        m = document["frames"][key]["depth"]
        assert m["pixels"] == published["pixels"]
        for name, value in zip(("rmse", "rel", "mae"), published["full"]):
            assert round(m[name], 4) == value, (protocol, key, name, m[name])


# Measured at each protocol's table resolution (nearest-neighbour resize of every image)
AT_TABLE_SIZE = {
    ("transcg", "320x240"): {
        "d435/000000123": {"depth": (2065, 0.3166, 0.2430, 0.1617),
                           "depth:all": (61613, 0.1785, 0.0829, 0.0508)},
        "d415/000000000": {"depth": (449, 0.2807, 0.1582, 0.1252),
                           "depth:all": (71942, 0.0826, 0.0091, 0.0090)}},
    ("cleargrasp", None): {
        "d435/000000123": {"depth": (996, 0.3209, 0.2465, 0.1649)},
        "d415/000000000": {"depth": (219, 0.2760, 0.1537, 0.1216)}},
}


@pytest.mark.parametrize("protocol, size", list(AT_TABLE_SIZE))
def test_protocols_at_their_table_size(realdata, tmp_path, protocol, size):
    args = ["--resolution", size] if size else []
    result = CliRunner().invoke(cli, ["evaluate", str(realdata), "--pred", "depth", "-q",
                                      "--out", str(tmp_path), "--protocol", protocol, *args])
    assert result.exit_code == 0, result.stderr
    document = json.loads((tmp_path / "metrics.json").read_text())
    expected_size = size or "256x144"
    assert document["protocol"]["resolution"] == f"{expected_size} (nearest)"
    assert f"# protocol {protocol}: {expected_size} (nearest)" in result.stdout
    for key, rows in AT_TABLE_SIZE[(protocol, size)].items():
        assert sorted(document["frames"][key]) == sorted(rows)
        for name, (pixels, rmse, rel, mae) in rows.items():
            m = document["frames"][key][name]
            assert m["pixels"] == pixels
            assert (round(m["rmse"], 4), round(m["rel"], 4), round(m["mae"], 4)) == \
                (rmse, rel, mae), (key, name)
    if protocol == "cleargrasp":
        assert "REL med" in result.stdout
        assert round(document["frames"]["d435/000000123"]["depth"]["rel_median"], 4) == 0.0265


def test_protocol_rows_and_bad_protocol_options_on_the_fixture(tmp_path):
    folder = make_cleargrasp(tmp_path / "cg")

    def run(*args):
        return CliRunner().invoke(cli, ["evaluate", str(folder), "--pred", "depth", "-q",
                                        "--out", str(tmp_path / "out"), *args])

    result = run("--protocol", "transcg")
    assert result.exit_code == 0, result.stderr
    means = json.loads((tmp_path / "out" / "metrics.json").read_text())["means"]
    assert sorted(means) == ["depth", "depth:all"]
    # all pixels: 36 x 64 minus the ground truth's one NaN; the 35 object holes are the error
    assert means["depth:all"]["pixels"] == 36 * 64 - 1
    assert means["depth:all"]["mae"] == pytest.approx((35 * 0.55 + 100 * 0.05) / (36 * 64 - 1),
                                                      rel=1e-4)
    assert "depth:all" in result.stdout and "depth 0.3-1.5 m" in result.stdout
    assert run("--protocol", "transcg", "--only-valid").exit_code == 2
    bad = run("--resolution", "320by240")
    assert bad.exit_code == 2 and "WIDTHxHEIGHT" in bad.stderr
