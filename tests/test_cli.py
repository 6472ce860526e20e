"""The command line: exit codes, messages, config precedence, per-frame failure isolation."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.io.atomic import write_json
from sr3d_cli.io.images import write_depth
from tests.conftest import make_native_scene


def run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def test_evaluate_raw_depth_on_a_hand_made_scene(native_scene):
    code, out, err = run("evaluate", native_scene, "--pred", "depth", "-q")
    assert code == 0, err
    metrics = json.loads((native_scene / "metrics.json").read_text())
    m = metrics["means"]["depth"]
    # 48 object pixels: 24 holes (error 0.45), 24 see-through (0.5 vs 0.45)
    assert m["pixels"] == 96 and m["frames"] == 2
    assert m["mae"] == pytest.approx((24 * 0.45 + 24 * 0.05) / 48, abs=1e-6)
    assert m["coverage"] == pytest.approx(0.5)
    assert "full error" in metrics["holes"]
    assert "depth" in out and "0.2500" in out  # MAE in the printed table
    csv = (native_scene / "metrics.csv").read_text().splitlines()
    assert csv[0].startswith("frame,pred,pixels") and len(csv) == 4


def test_only_valid_and_side_by_side_predictions(native_scene, tmp_path):
    code, out, _ = run("evaluate", native_scene, "--pred", "depth", "--pred", "gt/depth",
                       "--only-valid", "--out", tmp_path / "o", "-q")
    assert code == 0
    means = json.loads((tmp_path / "o" / "metrics.json").read_text())["means"]
    assert means["depth"]["mae"] == pytest.approx(0.05, abs=1e-6)
    assert means["gt/depth"]["mae"] == 0.0
    assert not (native_scene / "metrics.json").exists()  # --out respected


def test_plot_writes_error_maps(native_scene):
    code, _, _ = run("evaluate", native_scene, "--pred", "depth", "--plot", "-q")
    assert code == 0
    assert sorted(p.name for p in (native_scene / "eval_plots" / "depth").iterdir()) == [
        "000000.png", "000001.png"]


def test_frames_selection_and_unknown_frame(native_scene):
    code, _, _ = run("evaluate", native_scene, "--pred", "depth", "--frames", "000001", "-q")
    assert code == 0
    assert json.loads((native_scene / "metrics.json").read_text())["means"]["depth"]["frames"] == 1
    code, _, err = run("evaluate", native_scene, "--pred", "depth", "--frames", "000009")
    assert code == 2 and "000009" in err and "matches no frame" in err


def test_config_errors_exit_2_naming_key_and_file(native_scene, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("evaluate:\n  holes: full\n  plott: true\n")
    code, _, err = run("evaluate", native_scene, "--config", bad)
    assert code == 2 and "'evaluate.plott'" in err and "bad.yaml" in err
    code, _, err = run("evaluate", native_scene, "--set", "evaluate.plot_max_error=big")
    assert code == 2 and "'evaluate.plot_max_error' in --set: expected a number" in err
    code, _, err = run("synth", tmp_path / "x", "--set", "synth.scenes=two")
    assert code == 2 and "synth.scenes" in err


def test_flags_beat_set_beat_file(native_scene, tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("evaluate:\n  pred: [repaired]\n  holes: ignore\n")
    code, _, _ = run("evaluate", native_scene, "--config", cfg, "--set", "evaluate.pred=depth",
                     "-q")
    metrics = json.loads((native_scene / "metrics.json").read_text())
    assert code == 0 and metrics["predictions"] == ["depth"]  # --set beat the file
    assert "only pixels where the prediction is valid" in metrics["holes"]  # file beat default
    code, _, _ = run("evaluate", native_scene, "--config", cfg, "--set", "evaluate.pred=depth",
                     "--pred", "gt/depth", "-q")
    metrics = json.loads((native_scene / "metrics.json").read_text())
    assert metrics["predictions"] == ["gt/depth"]  # the flag beat --set


def test_empty_or_missing_folder_is_a_usage_error(tmp_path):
    (tmp_path / "empty").mkdir()
    code, _, err = run("evaluate", tmp_path / "empty")
    assert code == 2 and "empty: no scene folder found" in err
    code, _, err = run("evaluate", tmp_path / "missing")
    assert code == 2


def _corrupt(scene: Path, case: str) -> str:
    """Break frame 000001 (or the scene) in one way; returns the text the error must contain."""
    if case == "sizes differ":
        write_depth(scene / "depth" / "000001.png", np.full((20, 32), 0.5), 0.001)
        return "000001.png: depth is 32x20 but the colour image is 32x24"
    if case == "truncated png":
        p = scene / "depth" / "000001.png"
        p.write_bytes(p.read_bytes()[:40])
        return "depth/000001.png: cannot decode image"
    if case == "absurd depth scale":
        write_depth(scene / "depth" / "000001.png", np.full((24, 32), 30.0), 0.001)
        return "000001.png: median depth is 30 m"
    if case == "missing gt":
        (scene / "gt" / "depth" / "000001.png").unlink()
        return "000001: no ground-truth depth"
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["sizes differ", "truncated png", "absurd depth scale",
                                  "missing gt"])
def test_one_bad_frame_is_reported_and_the_others_run(tmp_path, case):
    scene = make_native_scene(tmp_path / "scene", n_frames=3)
    expected = _corrupt(scene, case)
    code, _, err = run("evaluate", scene, "--pred", "depth", "-q")
    assert code == 1
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and expected in errors[0], err
    assert "Traceback" not in err
    metrics = json.loads((scene / "metrics.json").read_text())
    assert sorted(metrics["frames"]) == ["000000", "000002"]
    assert metrics["failed"] and expected in metrics["failed"][0]


def test_missing_camera_fails_that_scene_only(tmp_path):
    make_native_scene(tmp_path / "root" / "a")
    make_native_scene(tmp_path / "root" / "b")
    (tmp_path / "root" / "b" / "camera.json").unlink()
    code, _, err = run("evaluate", tmp_path / "root", "--pred", "depth", "-q")
    assert code == 1
    assert "b/camera.json: camera file does not exist" in err
    frames = json.loads((tmp_path / "root" / "metrics.json").read_text())["frames"]
    assert sorted(frames) == ["a/000000", "a/000001"]


def test_a_failed_run_does_not_damage_earlier_outputs(native_scene):
    run("evaluate", native_scene, "--pred", "depth", "-q")
    before = (native_scene / "metrics.json").read_text()
    code, _, _ = run("evaluate", native_scene, "--pred", "depth", "--set", "evaluate.holes=x")
    assert code == 2
    assert (native_scene / "metrics.json").read_text() == before


def test_rescaled_intrinsics_give_one_notice_and_a_scaled_K(native_scene, caplog):
    from sr3d_cli.io.scene import SceneSource

    cam = json.loads((native_scene / "camera.json").read_text())
    cam["K"] = [[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]]
    cam["width"], cam["height"] = 64, 48
    write_json(native_scene / "camera.json", cam)
    source = SceneSource(native_scene)
    with caplog.at_level("WARNING", logger="sr3d"):
        frames = [source.load_frame(f) for f in source.frame_ids()]
    assert frames[0].camera.fx == 50.0 and frames[0].camera.cx == pytest.approx(15.5)
    notices = [r.getMessage() for r in caplog.records]
    assert len(notices) == 1 and "intrinsics are for 64x48, images are 32x24" in notices[0]
    cam["width"] = 60
    write_json(native_scene / "camera.json", cam)
    with pytest.raises(Exception, match="intrinsics are for 60x48 but the images are 32x24"):
        SceneSource(native_scene).load_frame("000000")


def test_synth_writes_scenes_and_skips_existing(tmp_path):
    code, out, err = run("synth", tmp_path / "s", "--scenes", "2", "--seed", "3", "-q")
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["scene_0000", "scene_0001"]
    before = (tmp_path / "s" / "scene_0000" / "rgb" / "000000.png").read_bytes()
    code, _, _ = run("synth", tmp_path / "s", "--scenes", "2", "--seed", "4", "-q")
    assert code == 0  # skipped without --overwrite: nothing replaced
    assert (tmp_path / "s" / "scene_0000" / "rgb" / "000000.png").read_bytes() == before
    code, out, err = run("evaluate", tmp_path / "s", "--pred", "depth", "-q")
    assert code == 0, err
    assert json.loads((tmp_path / "s" / "metrics.json").read_text())["means"]["depth"]["frames"] == 2


def test_a_frame_without_a_table_fails_naming_its_depth_file(tmp_path):
    """The training-free segmenter finds glass where the table's readings fail: a frame whose
    depth holds no plane (readings scattered over 0.3-3 m) fails with the depth file and the
    way out named; the batch goes on with the next frame and the exit code says one failed."""
    root = make_native_scene(tmp_path / "scene", n_frames=2)
    noise = np.random.default_rng(0).uniform(0.3, 3.0, (24, 32)).astype(np.float32)
    write_depth(root / "depth" / "000000.png", noise, 0.001)
    result = CliRunner().invoke(cli, ["segment", str(root)])
    assert result.exit_code == 1, result.output
    assert "depth/000000.png: no support plane" in result.output
    assert "needs the table in view" in result.output and "--import-dir" in result.output
    assert "unexpected" not in result.output
    assert (root / "masks" / "000001.png").is_file()
    assert not (root / "masks" / "000000.png").exists()
