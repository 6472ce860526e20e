"""The loop every per-frame command shares: frames -> core call -> report, one bad frame at a time."""

from __future__ import annotations

import logging
from typing import Callable

import click
from tqdm import tqdm

from sr3d_cli.cli.batch import iter_frames, open_scenes
from sr3d_cli.cli.report import Report
from sr3d_cli.config import Config
from sr3d_cli.io.scene import Frame

log = logging.getLogger("sr3d")


def run_frames(name: str, scene: str, cfg: Config, out: str | None, frames: str | None,
               work: Callable[[Frame], list[str]]) -> None:
    """Load each selected frame and call ``work(frame)``, which returns object-level messages
    (printed as warnings). Exceptions fail that frame only. Exits with the report's code."""
    ctx = click.get_current_context()
    report = Report(verbose=ctx.meta["sr3d.verbose"])
    scenes = open_scenes(scene, cfg, out)
    pairs = list(iter_frames(scenes, frames, report))
    for source, frame_id in tqdm(pairs, desc=name, unit="frame", disable=ctx.meta["sr3d.quiet"]):
        key = source.frame_key(frame_id)
        try:
            messages = work(source.load_frame(frame_id))
        except Exception as exc:
            report.fail(key, exc)
            continue
        for message in messages:
            log.warning("warning: %s %s", key, message)
        report.ok()
    report.finish("frames")
