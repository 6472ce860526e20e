"""Stage outputs record what they were made from: a changed config key or upstream file makes
exactly the stages that depend on it again; --keep-stale keeps them, --redo forces them; Ctrl-C
stops a batch cleanly."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.io.provenance import fingerprint

FRAME = "000000"
RECORDS = {"segment": f"masks/{FRAME}.json", "reconstruct": f"meshes/{FRAME}.json",
           "align": f"poses/{FRAME}.json", "repair": f"repaired/{FRAME}.json"}


@pytest.fixture(scope="module")
def small_scenes(tmp_path_factory) -> Path:
    """Two generated scenes at 160x120 (seed 3), one frame each."""
    from sr3d_cli.config import SynthConfig
    from sr3d_cli.render import make_renderer
    from sr3d_cli.synth.generate import write_scene

    root = tmp_path_factory.mktemp("small3")
    cfg = SynthConfig(seed=3, views=1, resolutions=["160x120"])
    for i in range(2):
        write_scene(root / f"scene_{i:04d}", i, cfg, make_renderer("auto"))
    return root


@pytest.fixture
def repaired(small_scenes, tmp_path) -> Path:
    """scene_0000 copied and repaired once."""
    scene = tmp_path / "scene"
    shutil.copytree(small_scenes / "scene_0000", scene)
    result = run("repair-depth", scene, "-q")
    assert result.exit_code == 0, result.output
    return scene


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def stamps(scene: Path) -> dict[str, tuple[int, bytes]]:
    """(mtime in ns, bytes) of each stage's record file."""
    return {stage: ((scene / rel).stat().st_mtime_ns, (scene / rel).read_bytes())
            for stage, rel in RECORDS.items()}


def remade(before: dict, after: dict) -> set[str]:
    return {stage for stage in RECORDS if before[stage][0] != after[stage][0]}


def recorded(scene: Path, stage: str) -> dict:
    return json.loads((scene / RECORDS[stage]).read_text())["made_from"]


@pytest.mark.parametrize("setting, stages", [
    ("advanced.align.refine_evals=40", {"align", "repair"}),  # recorded as align.refine_evals
    ("reconstruct.levels=30", {"reconstruct", "align", "repair"}),
    ("repair.outside_render=keep", {"repair"}),
    ("segment.min_area=5000", {"segment", "reconstruct", "align", "repair"}),
    ("plane.iterations=200", {"segment", "reconstruct", "align", "repair"}),
])
def test_a_changed_key_remakes_exactly_the_stages_that_depend_on_it(repaired, setting, stages):
    before = stamps(repaired)
    time.sleep(0.01)
    result = run("repair-depth", repaired, "--set", setting, "-q")
    assert result.exit_code in (0, 1), result.output  # min_area=5000 may leave no object
    assert "Traceback" not in result.output
    after = stamps(repaired)
    assert remade(before, after) == stages
    key, value = setting.removeprefix("advanced.").split("=")
    first = min(stages, key=list(RECORDS).index)
    assert str(recorded(repaired, first)["config"][key]) == value
    # the same again: nothing is stale, only the repaired depth is rendered again
    again = stamps(repaired)
    time.sleep(0.01)
    run("repair-depth", repaired, "--set", setting, "-q")
    assert remade(again, stamps(repaired)) == {"repair"}


def test_skip_existing_leaves_current_frames_and_remakes_stale_ones(repaired):
    result = run("repair-depth", repaired, "--skip-existing")
    assert result.exit_code == 0 and "0 frames done, 1 skipped" in result.output
    before = stamps(repaired)
    result = run("repair-depth", repaired, "--skip-existing", "--set", "align.refine_evals=40")
    assert result.exit_code == 0 and "1 frames done" in result.output, result.output
    assert remade(before, stamps(repaired)) == {"align", "repair"}
    # a single stage's command: stale masks are made again, or kept with a warning
    before = stamps(repaired)
    result = run("segment", repaired, "--skip-existing", "--keep-stale",
                 "--set", "segment.min_area=5000")
    assert result.exit_code == 0 and "keeping stale outputs" in result.output
    assert "segment.min_area was 150, now 5000" in result.output
    assert remade(before, stamps(repaired)) == set()
    result = run("segment", repaired, "--skip-existing", "--set", "segment.min_area=5000", "-q")
    assert result.exit_code == 0 and remade(before, stamps(repaired)) == {"segment"}


@pytest.mark.parametrize("damage, stages", [
    ("poses_cut", {"align", "repair"}),
    ("masks_png_empty", {"segment", "repair"}),
    ("mesh_gone", {"reconstruct", "repair"}),
])
def test_damaged_stage_outputs_are_made_again(repaired, damage, stages):
    """A run stopped hard or a full disk can leave a stage output cut off, empty or gone:
    repair-depth makes that stage again instead of failing the frame (the stages after it
    read the same files as before, so stay)."""
    if damage == "poses_cut":
        path = repaired / RECORDS["align"]
        path.write_bytes(path.read_bytes()[:200])
    elif damage == "masks_png_empty":
        (repaired / f"masks/{FRAME}.png").write_bytes(b"")
    else:
        meshes = json.loads((repaired / RECORDS["reconstruct"]).read_text())["objects"]
        (repaired / f"meshes/{FRAME}/{sorted(meshes)[0]}.ply").unlink()
    before = stamps(repaired)
    result = run("repair-depth", repaired, "-v")
    assert result.exit_code == 0, result.output
    assert remade(before, stamps(repaired)) == stages
    assert "made again" in result.output
    assert json.loads((repaired / RECORDS["align"]).read_text())["objects"]


def test_skip_existing_makes_an_empty_output_again(repaired):
    path = repaired / f"repaired/{FRAME}.png"
    path.write_bytes(b"")
    result = run("repair-depth", repaired, "--skip-existing", "-q")
    assert result.exit_code == 0, result.output
    assert path.stat().st_size > 0 and cv2.imread(str(path), cv2.IMREAD_UNCHANGED) is not None


def test_keep_stale_keeps_upstream_outputs_with_a_warning(repaired):
    before = stamps(repaired)
    result = run("repair-depth", repaired, "--keep-stale", "--set", "align.refine_evals=40")
    assert result.exit_code == 0, result.output
    assert "align output kept though stale (align.refine_evals was 80, now 40" in result.output
    assert remade(before, stamps(repaired)) == {"repair"}


def test_redo_remakes_a_stage_and_every_later_one(repaired):
    before = stamps(repaired)
    result = run("repair-depth", repaired, "--redo", "reconstruct", "-q")
    assert result.exit_code == 0, result.output
    assert remade(before, stamps(repaired)) == {"reconstruct", "align", "repair"}
    result = run("repair-depth", repaired, "--redo", "segment", "--masks", "gt", "-q")
    assert result.exit_code == 2 and "--redo segment" in result.output


def test_outputs_made_for_other_masks_are_made_again(small_scenes, tmp_path):
    """reconstruct and align from the true masks, then repair-depth with segment's: the meshes
    and poses are made again for the masks in use, never mixed."""
    scene = tmp_path / "scene"
    shutil.copytree(small_scenes / "scene_0001", scene)
    for command in ("reconstruct", "align"):
        assert run(command, scene, "--masks", "gt", "-q").exit_code == 0
    gt = fingerprint(scene / "gt" / "masks" / f"{FRAME}.png")
    assert recorded(scene, "align")["inputs"]["masks"] == gt
    result = run("repair-depth", scene, "-q")
    assert result.exit_code in (0, 1) and "Traceback" not in result.output
    segmented = fingerprint(scene / "masks" / f"{FRAME}.png")
    assert segmented != gt
    for stage in ("reconstruct", "align", "repair"):
        assert recorded(scene, stage)["inputs"]["masks"] == segmented, stage
    meshes = json.loads((scene / RECORDS["reconstruct"]).read_text())["objects"]
    on_disk = sorted(p.stem for p in (scene / "meshes" / FRAME).glob("*.ply"))
    assert sorted(meshes) == [k for k in on_disk if "_" not in k]  # no mesh of the gt run left


def _untimed(entry):
    """A log/<frame>.json document without its timings (they differ between any two runs)."""
    if isinstance(entry, dict):
        return {k: _untimed(v) for k, v in entry.items() if k not in ("seconds", "stages")}
    return entry


def _outputs(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` by relative path; a frame's log without its timings."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file():
            name = p.relative_to(root).as_posix()
            data = p.read_bytes()
            if name.split("/")[-2:-1] == ["log"] and name.endswith(".json"):
                data = json.dumps(_untimed(json.loads(data)), sort_keys=True).encode()
            out[name] = data
    return out


@pytest.mark.slow
def test_ctrl_c_with_workers_exits_130_cleanly(small_scenes, tmp_path):
    src = tmp_path / "data"
    for i in range(2):  # enough frames that the run is still going when the signal comes
        for copy in range(30):  # (a loaded machine segments 24 in about 3 s)
            shutil.copytree(small_scenes / f"scene_{i:04d}", src / f"s{i}{copy:02d}")
    clean, stopped = tmp_path / "clean", tmp_path / "stopped"
    cmd = [sys.executable, "-m", "sr3d_cli", "segment", str(src), "--workers", "2", "--out"]
    subprocess.run(cmd + [str(clean), "-q"], check=True, timeout=300)
    proc = subprocess.Popen(cmd + [str(stopped)], process_group=0, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = time.time() + 120
    while time.time() < deadline and not list(stopped.rglob("masks/*.json")):
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal sends
    output, _ = proc.communicate(timeout=30)
    assert proc.returncode == 130, output
    assert "Traceback" not in output and "interrupted" in output
    partial = _outputs(stopped)
    assert partial and not any(".tmp" in name for name in partial)
    reference = _outputs(clean)
    assert all(data == reference[name] for name, data in partial.items())


def test_grasp_warns_when_it_plans_on_stale_outputs(repaired):
    result = run("grasp", repaired, "--set", "align.refine_evals=40")
    assert result.exit_code == 0, result.output
    assert "planned on stale outputs (align: align.refine_evals was 80, now 40)" in result.output
    result = run("grasp", repaired)
    assert result.exit_code == 0 and "stale" not in result.output


def test_align_and_reconstruct_fail_a_frame_where_no_object_is_made(tmp_path):
    from tests.conftest import make_native_scene

    scene = make_native_scene(tmp_path / "scene", 1)  # a 48-pixel object: below min_pixels
    result = run("reconstruct", scene, "--masks", "gt", "-q")
    assert result.exit_code == 1 and "failed: 000000: no mesh made (object 1: mask has 48 px" \
        in result.output
    assert "frame_failed" in json.loads((scene / "meshes" / f"{FRAME}.json").read_text())
    result = run("align", scene, "--masks", "gt", "-q")
    assert result.exit_code == 1 and "no object placed" in result.output
    # a failed frame is not done for --skip-existing; made with a smaller minimum it is
    result = run("reconstruct", scene, "--masks", "gt", "--skip-existing", "-q",
                 "--set", "reconstruct.min_pixels=10")
    assert result.exit_code == 0 and (scene / "meshes" / FRAME / "1.ply").is_file()


def test_a_changed_imported_mask_makes_the_masks_again(tmp_path):
    from sr3d_cli.io.atomic import write_png
    from tests.conftest import make_native_scene

    scene = make_native_scene(tmp_path / "scene", 1)
    imported = tmp_path / "imported"
    mask = np.zeros((24, 32), np.uint8)
    mask[8:14, 10:18] = 1
    write_png(imported / f"{FRAME}.png", mask)
    args = ("segment", scene, "--import-dir", imported, "--set", "segment.min_area=10",
            "--skip-existing", "-q")
    assert run(*args).exit_code == 0
    assert run(*args).exit_code == 0 and recorded(scene, "segment")["inputs"]["imported"]
    before = (scene / RECORDS["segment"]).stat().st_mtime_ns
    mask[8:14, 10:12] = 0  # the imported mask changes: the masks are stale
    write_png(imported / f"{FRAME}.png", mask)
    assert run(*args).exit_code == 0
    assert (scene / RECORDS["segment"]).stat().st_mtime_ns != before
    ids = cv2.imread(str(scene / "masks" / f"{FRAME}.png"), cv2.IMREAD_UNCHANGED)
    assert (ids > 0).sum() == 6 * 6
