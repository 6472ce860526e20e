"""The loop every per-frame command shares: frames -> core call -> report, one bad frame at a time.

With ``workers > 1`` frames are spread over forked processes (each frame is independent and
writes only its own files); results come back in order of completion. ``--shard i/N`` keeps the
frames whose key hashes to i (stable across runs and machines, so N cluster jobs split a dataset
without talking to each other); ``--skip-existing`` leaves frames whose outputs all exist (every
file is written atomically, so an existing file is a whole one).

Each frame's run is recorded in ``log/<frame>.json`` under the scene's output folder:
``{"commands": {name: {"status": "done" | "failed", "seconds": s, "stages": {stage: s},
"error": message}}}`` (read by ``sr3d report``; timings differ from run to run).
"""

from __future__ import annotations

import functools
import logging
import json
import multiprocessing
import time
import traceback
import zlib
from pathlib import Path
from typing import Callable

import click
from tqdm import tqdm

from sr3d_cli.cli.batch import iter_frames, open_scenes
from sr3d_cli.cli.report import Report
from sr3d_cli.config import Config
from sr3d_cli.errors import Sr3dError
from sr3d_cli.io.scene import Frame, SceneSource

log = logging.getLogger("sr3d")

_JOB: dict = {}  # the forked workers inherit the work function and the frame list


def _run_one(index: int):
    """(index, messages, stage seconds, error, seconds) of one frame. ``work`` returns messages
    or (messages, {stage: seconds})."""
    source, frame_id = _JOB["pairs"][index]
    start = time.perf_counter()
    try:
        result = _JOB["work"](source.load_frame(frame_id))
    except Exception as exc:  # sent back to the parent, reported there
        seconds = time.perf_counter() - start
        if isinstance(exc, Sr3dError):
            return index, None, {}, exc, seconds
        return index, None, {}, RuntimeError(f"{type(exc).__name__}: {exc}\n"
                                             f"{traceback.format_exc()}"), seconds
    messages, stages = result if isinstance(result, tuple) else (result, {})
    return index, messages, stages, None, time.perf_counter() - start


def record_run(source: SceneSource, frame_id: str, command: str, seconds: float,
               stages: dict[str, float], error: str | None = None) -> None:
    """Merge this command's outcome into the frame's ``log/<frame>.json``; a log that cannot
    be written only costs a warning."""
    from sr3d_cli.io.atomic import write_json

    path = source.output_path("log", frame_id, ".json")
    try:
        doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    except (OSError, ValueError):
        doc = {}
    entry = {"status": "failed" if error else "done", "seconds": round(seconds, 4),
             "stages": {k: round(v, 4) for k, v in stages.items()}}
    if error:
        entry["error"] = error
    doc.setdefault("commands", {})[command] = entry
    try:
        write_json(path, doc)
    except OSError as exc:
        log.warning("warning: %s: cannot write the run log (%s)", path, exc.strerror or exc)


def shard_from_env(env: dict[str, str]) -> tuple[tuple[int, int], str] | None:
    """(index, count) and where it came from: a Slurm job array (``SLURM_ARRAY_TASK_ID``,
    ``_MIN``, ``_STEP``, ``_COUNT`` or ``_MAX``: task ids need not start at 0) or a Kubernetes
    indexed Job (``JOB_COMPLETION_INDEX``, with ``SR3D_SHARD_COUNT`` set to the Job's
    completions, which Kubernetes does not pass to the pod). None when neither is there."""
    def number(key: str) -> int | None:
        try:
            return int(env[key])
        except (KeyError, ValueError):
            return None

    task = number("SLURM_ARRAY_TASK_ID")
    if task is not None:
        first = number("SLURM_ARRAY_TASK_MIN") or 0
        step = number("SLURM_ARRAY_TASK_STEP") or 1
        count = number("SLURM_ARRAY_TASK_COUNT")
        if count is None and number("SLURM_ARRAY_TASK_MAX") is not None:
            count = (number("SLURM_ARRAY_TASK_MAX") - first) // step + 1
        if count is not None:
            return ((task - first) // step, count), "Slurm array"
    index = number("JOB_COMPLETION_INDEX")
    if index is not None and number("SR3D_SHARD_COUNT") is not None:
        return (index, number("SR3D_SHARD_COUNT")), "Kubernetes indexed Job"
    return None


def parse_shard(spec: str | None, env: dict[str, str] | None = None) -> tuple[int, int] | None:
    """``I/N`` -> (I, N); ``auto`` -> from the environment (:func:`shard_from_env`)."""
    if not spec:
        return None
    if spec == "auto":
        import os

        found = shard_from_env(dict(os.environ) if env is None else env)
        if found is None:
            raise click.BadParameter(
                "auto: no Slurm array (SLURM_ARRAY_TASK_ID with SLURM_ARRAY_TASK_COUNT) or "
                "Kubernetes indexed Job (JOB_COMPLETION_INDEX with SR3D_SHARD_COUNT) in the "
                "environment", param_hint="--shard")
        (i, n), where = found
        if not (n >= 1 and 0 <= i < n):
            raise click.BadParameter(f"auto: {where} gives shard {i} of {n}",
                                     param_hint="--shard")
        log.info("--shard auto: shard %d of %d (%s)", i, n, where)
        return i, n
    try:
        i, n = (int(x) for x in spec.split("/"))
    except ValueError:
        i, n = -1, 0
    if not (n >= 1 and 0 <= i < n):
        raise click.BadParameter(f"expected i/N with 0 <= i < N, got {spec!r}",
                                 param_hint="--shard")
    return i, n


def in_shard(key: str, shard: tuple[int, int] | None) -> bool:
    return shard is None or zlib.crc32(key.encode("utf-8")) % shard[1] == shard[0]


def run_frames(name: str, scene: str, cfg: Config, out: str | None, frames: str | None,
               work: Callable[[Frame], list[str] | tuple[list[str], dict]], *,
               batch: dict | None = None,
               outputs: Callable[[SceneSource, str], list[Path]] | None = None,
               after: Callable[[list[SceneSource]], None] | None = None) -> None:
    """Load each selected frame and call ``work(frame)``, which returns object-level messages
    (printed as warnings), or (messages, {stage: seconds}). Exceptions fail that frame only;
    each frame's outcome and time go to its run log (:func:`record_run`). ``batch``: the values of
    :func:`batch_options` (workers, shard, skip_existing); ``outputs(scene, frame_id)``: the files
    that mark a frame done; ``after(scenes)`` runs once the frames are done. Exits with the
    report's code."""
    ctx = click.get_current_context()
    report = Report(verbose=ctx.meta["sr3d.verbose"])
    batch = batch or {}
    workers = batch.get("workers", 1)
    shard = parse_shard(batch.get("shard"))
    scenes = open_scenes(scene, cfg, out)
    pairs = [(s, f) for s, f in iter_frames(scenes, frames, report)
             if in_shard(s.frame_key(f), shard)]
    if batch.get("skip_existing") and outputs is not None:
        todo = []
        for s, f in pairs:
            if all(p.is_file() for p in outputs(s, f)):
                report.skip(s.frame_key(f), "outputs exist (--skip-existing)")
            else:
                todo.append((s, f))
        pairs = todo
    _JOB.update(pairs=pairs, work=work)
    bar = tqdm(total=len(pairs), desc=name, unit="frame", disable=ctx.meta["sr3d.quiet"])
    if workers > 1 and len(pairs) > 1:
        pool = multiprocessing.get_context("fork").Pool(min(workers, len(pairs)))
        results = pool.imap_unordered(_run_one, range(len(pairs)))
    else:
        pool, results = None, map(_run_one, range(len(pairs)))
    try:
        for index, messages, stages, error, seconds in results:
            source, frame_id = pairs[index]
            key = source.frame_key(frame_id)
            bar.update()
            if error is not None:
                report.fail(key, error)
                record_run(source, frame_id, name, seconds, stages, report.failures[-1])
                continue
            record_run(source, frame_id, name, seconds, stages)
            for message in messages:
                log.warning("warning: %s %s", key, message)
            report.ok()
    finally:
        bar.close()
        if pool is not None:
            pool.close()
            pool.join()
    if after is not None:
        after(scenes)
    report.finish("frames")


def batch_options(func):
    """``--workers``, ``--shard``, ``--skip-existing``, gathered into one ``batch`` dict."""

    @click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
                  help="Frames processed in parallel (processes).")
    @click.option("--shard", metavar="I/N|auto",
                  help="Only the frames of shard I of N (0-based; a stable split). auto: from "
                       "a Slurm job array or a Kubernetes indexed Job (README: \"Running on a "
                       "cluster\").")
    @click.option("--skip-existing", is_flag=True,
                  help="Leave frames whose outputs exist (resume an interrupted run).")
    @functools.wraps(func)
    def wrapper(*args, workers, shard, skip_existing, **kwargs):
        parse_shard(shard)  # a bad spec is a usage error before any work
        return func(*args, batch={"workers": workers, "shard": shard,
                                  "skip_existing": skip_existing}, **kwargs)

    return wrapper
