"""What the benchmark's sections share: generated sets, staged scene copies, a grasp planner per
random draw, the timed repair of one frame and the one-core pin."""

from __future__ import annotations

import hashlib
import os
import shutil
import time
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from sr3d_cli.config import SynthConfig
from sr3d_cli.io.images import write_depth
from sr3d_cli.synth.generate import write_scene

ROOT = Path(__file__).resolve().parent
SHARED = ROOT.parent.parent / "shared"
OTHER_CONTACTS = ("pads", "line")  # contact models judged beside the default grid of rays


def generated_set(folder: Path, count: int, cfg: SynthConfig, renderer) -> None:
    """Make sure ``folder`` holds scenes 0..count-1 of ``cfg``'s seed as the current generator
    draws them: a stamp of the generator's sources (sr3d_cli/synth, sr3d_cli/geometry) is kept
    with the set, and a changed generator regenerates it instead of measuring stale scenes."""
    package = ROOT.parent / "sr3d_cli"
    digest = hashlib.sha256()
    for path in sorted([*(package / "synth").glob("*.py"), *(package / "geometry").glob("*.py")]):
        digest.update(path.read_bytes())
    stamp = folder / "GENERATOR"
    if folder.is_dir() and not (stamp.is_file() and stamp.read_text() == digest.hexdigest()):
        shutil.rmtree(folder)
    for i in range(count):
        if not (folder / f"scene_{i:04d}" / "camera.json").is_file():
            write_scene(folder / f"scene_{i:04d}", i, cfg, renderer)
    folder.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest.hexdigest())


def grasp_planners(grasp_cfg, draws: int) -> list:
    """One grasp planner per random draw of seed points (``grasp.seed`` 0 .. draws-1), each
    with ``grasp_cfg`` (the ``grasp`` config) otherwise."""
    import copy

    from sr3d_cli.grasp.planner import Planner

    made = []
    for seed in range(draws):
        drawn = copy.copy(grasp_cfg)
        drawn.seed = seed
        made.append(Planner(drawn))
    return made


def staged(source, out: Path):
    """The same scene read from its folder, its stage outputs written under ``out``."""
    return type(source)(source.root, out=out, name=source.name, io=source.io)


def timed_repair(pipeline, frame, timings: dict, write: bool = False
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Run the frame's missing stages and render its repaired depth (written too, with
    ``write``); returns (depth (H, W) m, ids (H, W) int32). ``timings`` gets the seconds of
    each stage run, ``render`` (the write included) and ``total``; on an error it keeps those
    of the stages that ran."""
    start = time.perf_counter()
    state = pipeline.state(frame)
    pipeline.ensure_upstream(state, timings)
    t0 = time.perf_counter()
    depth, ids = pipeline.repaired_depth(state)
    if write:
        write_depth(frame.scene.output_path("repaired", frame.frame_id), depth,
                    frame.camera.depth_scale)
    timings["render"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - start
    return depth, ids


@contextmanager
def one_core():
    """This process pinned to one CPU core for the block (the targets' "on one core"): every
    thread of it, as BLAS and OpenCV start their workers at import and a worker left on
    another core still works or spins there (the main thread alone pinned, the grasp stage
    used 1.4 s of CPU per 0.7 s; threads started in the block inherit the pin)."""
    tasks = sorted(int(t) for t in os.listdir("/proc/self/task")) \
        if os.path.isdir("/proc/self/task") else [0]
    before = {t: os.sched_getaffinity(t) for t in tasks}
    core = {min(before[tasks[0]])}
    for t in tasks:
        os.sched_setaffinity(t, core)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # OpenCV's pool, sized at import for every core
    try:
        yield
    finally:
        cv2.setNumThreads(threads)
        for t, cores in before.items():
            try:
                os.sched_setaffinity(t, cores)
            except OSError:  # the thread has ended
                pass
