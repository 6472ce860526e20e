"""The loop every per-frame command shares: frames -> core call -> report, one bad frame at a time.

With ``workers > 1`` frames are spread over forked processes (each frame is independent and
writes only its own files); results come back in order of completion. ``--shard i/N`` keeps the
frames whose key hashes to i (stable across runs and machines, so N cluster jobs split a dataset
without talking to each other); ``--skip-existing`` leaves frames whose outputs all exist (every
file is written atomically, so an existing file is a whole one) and still match what they were
made from (:mod:`sr3d_cli.io.provenance`); ``--keep-stale`` keeps those that do not, with a
warning.

Each frame's run is recorded in ``log/<frame>.json`` under the scene's output folder:
``{"commands": {name: {"status": "done" | "failed", "seconds": s, "stages": {stage: s},
"error": message}}}`` (read by ``sr3d report``; timings differ from run to run).
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import time
import traceback
import zlib
from pathlib import Path
from typing import Callable

import click
from tqdm import tqdm

from sr3d_cli.cli.batch import check_writable, iter_frames, open_scenes
from sr3d_cli.cli.report import Report
from sr3d_cli.cli.workers import Workers
from sr3d_cli.config import Config
from sr3d_cli.errors import Problem, Sr3dError
from sr3d_cli.io.scene import Frame, SceneSource

log = logging.getLogger("sr3d")

_JOB: dict = {}  # the forked workers inherit the work function and the frame list


def _lost(index: int, why: str):
    """The result of a frame whose worker process ended without sending one."""
    return index, None, {}, f"no result: {why}", None, 0.0


def _run_one(index: int):
    """(index, problems, stage seconds, failure message or None, traceback or None, seconds)
    of one frame. ``work`` returns problems or (problems, {stage: seconds})."""
    source, frame_id = _JOB["pairs"][index]
    start = time.perf_counter()
    try:
        result = _JOB["work"](source.load_frame(frame_id))
    except Exception as exc:  # sent back to the parent as text, reported there
        reason = str(exc) if isinstance(exc, Sr3dError) else \
            f"unexpected {type(exc).__name__}: {exc}"
        return index, None, {}, reason, traceback.format_exc(), time.perf_counter() - start
    problems, stages = result if isinstance(result, tuple) else (result, {})
    return index, problems, stages, None, None, time.perf_counter() - start


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


def _finished(source: SceneSource, frame_id: str, paths: list[Path],
              stale: Callable[[SceneSource, str], str | None] | None, keep_stale: bool
              ) -> str | None:
    """Why ``--skip-existing`` may leave a frame (None: it must run): its outputs exist, are not
    empty (a JSON one readable), did not record a failed frame, and are current (or stale and
    ``keep_stale``)."""
    if not all(p.is_file() and p.stat().st_size > 0 for p in paths):
        return None
    for p in paths:
        if p.suffix == ".json":
            try:
                text = p.read_text(encoding="utf-8")
                json.loads(text)
            except (OSError, ValueError):
                return None
            if "frame_failed" in text:
                return None
    why = stale(source, frame_id) if stale is not None else None
    if why is None:
        return "outputs exist and are current (--skip-existing)"
    if keep_stale:
        log.warning("warning: %s: keeping stale outputs (%s; --keep-stale)",
                    source.frame_key(frame_id), why)
        return "outputs exist, stale, kept (--keep-stale)"
    log.info("%s: outputs are stale (%s): made again", source.frame_key(frame_id), why)
    return None


def run_frames(name: str, scene: str, cfg: Config, out: str | None, frames: str | None,
               work: Callable[[Frame], list[Problem] | tuple[list[Problem], dict]], *,
               batch: dict | None = None,
               outputs: Callable[[SceneSource, str], list[Path]] | None = None,
               after: Callable[[list[SceneSource]], None] | None = None,
               stale: Callable[[SceneSource, str], str | None] | None = None) -> None:
    """Load each selected frame and call ``work(frame)``, which returns the problems that do
    not fail it (:class:`~sr3d_cli.errors.Problem`, printed as warnings), or (problems,
    {stage: seconds}); or raises (that frame fails;
    :class:`~sr3d_cli.errors.FrameFailed` when it wrote outputs that say why). Each frame's
    outcome and time go to its run log (:func:`record_run`). ``batch``: the values of
    :func:`batch_options`; ``outputs(scene, frame_id)``: the files that mark a frame done;
    ``stale(scene, frame_id)``: why those outputs no longer match their inputs (None:
    current); ``after(scenes)`` runs once the frames are done. Ctrl-C stops the workers and
    exits 130. Exits with the report's code."""
    ctx = click.get_current_context()
    report = Report(verbose=ctx.meta["sr3d.verbose"])
    batch = batch or {}
    workers = batch.get("workers", 1)
    shard = parse_shard(batch.get("shard"))
    scenes = open_scenes(scene, cfg, out)
    for source in scenes:
        check_writable(source.out)
    pairs = [(s, f) for s, f in iter_frames(scenes, frames, report)
             if in_shard(s.frame_key(f), shard)]
    if batch.get("skip_existing") and outputs is not None:
        todo = []
        for s, f in pairs:
            why = _finished(s, f, outputs(s, f), stale, batch.get("keep_stale", False))
            if why is not None:
                report.skip(s.frame_key(f), why)
            else:
                todo.append((s, f))
        pairs = todo
    _JOB.update(pairs=pairs, work=work)
    bar = tqdm(total=len(pairs), desc=name, unit="frame", disable=ctx.meta["sr3d.quiet"])
    try:
        with contextlib.ExitStack() as stack:
            if workers > 1 and len(pairs) > 1:
                pool = stack.enter_context(Workers(min(workers, len(pairs)), _run_one, _lost))
                results = pool.map(len(pairs))
            else:
                results = map(_run_one, range(len(pairs)))
            _report_all(name, pairs, results, report, bar)
    except KeyboardInterrupt:
        report.interrupted = True
    finally:
        bar.close()
    if after is not None and not report.interrupted:
        after(scenes)
    report.finish("frames")


def _report_all(name: str, pairs: list, results, report: Report, bar: tqdm) -> None:
    """Report and log each frame's result as it comes."""
    for index, problems, stages, failure, details, seconds in results:
        source, frame_id = pairs[index]
        key = source.frame_key(frame_id)
        bar.update()
        if failure is not None:
            report.fail(key, failure, details=details)
            record_run(source, frame_id, name, seconds, stages, report.failures[-1])
            continue
        record_run(source, frame_id, name, seconds, stages)
        for problem in problems:
            log.warning("warning: %s %s", key, problem)
        report.ok()


def batch_options(func):
    """``--workers``, ``--shard``, ``--skip-existing``, gathered into one ``batch`` dict."""

    @click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
                  help="Frames processed in parallel (processes).")
    @click.option("--shard", metavar="I/N|auto",
                  help="Only the frames of shard I of N (0-based; a stable split). auto: from "
                       "a Slurm job array or a Kubernetes indexed Job (README: \"Running on a "
                       "cluster\").")
    @click.option("--skip-existing", is_flag=True,
                  help="Leave frames whose outputs exist and are current (resume an "
                       "interrupted run); stale ones are made again.")
    @click.option("--keep-stale", is_flag=True,
                  help="Keep outputs whose recorded inputs or config keys changed (with a "
                       "warning) instead of making them again.")
    @functools.wraps(func)
    def wrapper(*args, workers, shard, skip_existing, keep_stale, **kwargs):
        parse_shard(shard)  # a bad spec is a usage error before any work
        return func(*args, batch={"workers": workers, "shard": shard,
                                  "skip_existing": skip_existing, "keep_stale": keep_stale},
                    **kwargs)

    return wrapper
