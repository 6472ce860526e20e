"""The loop every per-frame command shares: frames -> core call -> report, one bad frame at a time.

With ``workers > 1`` frames are spread over forked processes (each frame is independent and
writes only its own files); results come back in order of completion.
"""

from __future__ import annotations

import logging
import multiprocessing
import traceback
from typing import Callable

import click
from tqdm import tqdm

from sr3d_cli.cli.batch import iter_frames, open_scenes
from sr3d_cli.cli.report import Report
from sr3d_cli.config import Config
from sr3d_cli.errors import Sr3dError
from sr3d_cli.io.scene import Frame

log = logging.getLogger("sr3d")

_JOB: dict = {}  # the forked workers inherit the work function and the frame list


def _run_one(index: int):
    source, frame_id = _JOB["pairs"][index]
    try:
        return index, _JOB["work"](source.load_frame(frame_id)), None
    except Exception as exc:  # sent back to the parent, reported there
        if isinstance(exc, Sr3dError):
            return index, None, exc
        return index, None, RuntimeError(f"{type(exc).__name__}: {exc}\n"
                                         f"{traceback.format_exc()}")


def run_frames(name: str, scene: str, cfg: Config, out: str | None, frames: str | None,
               work: Callable[[Frame], list[str]], workers: int = 1) -> None:
    """Load each selected frame and call ``work(frame)``, which returns object-level messages
    (printed as warnings). Exceptions fail that frame only. Exits with the report's code."""
    ctx = click.get_current_context()
    report = Report(verbose=ctx.meta["sr3d.verbose"])
    scenes = open_scenes(scene, cfg, out)
    pairs = list(iter_frames(scenes, frames, report))
    _JOB.update(pairs=pairs, work=work)
    bar = tqdm(total=len(pairs), desc=name, unit="frame", disable=ctx.meta["sr3d.quiet"])
    if workers > 1 and len(pairs) > 1:
        pool = multiprocessing.get_context("fork").Pool(min(workers, len(pairs)))
        results = pool.imap_unordered(_run_one, range(len(pairs)))
    else:
        pool, results = None, map(_run_one, range(len(pairs)))
    try:
        for index, messages, error in results:
            source, frame_id = pairs[index]
            key = source.frame_key(frame_id)
            bar.update()
            if error is not None:
                report.fail(key, error)
                continue
            for message in messages:
                log.warning("warning: %s %s", key, message)
            report.ok()
    finally:
        bar.close()
        if pool is not None:
            pool.close()
            pool.join()
    report.finish("frames")


def workers_option(func):
    return click.option("--workers", type=int, default=1, show_default=True,
                        help="Frames processed in parallel (processes).")(func)
