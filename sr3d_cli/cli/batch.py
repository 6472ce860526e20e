"""Walking the frames of one or more scene folders with per-frame failure isolation."""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path
from typing import Iterator

from sr3d_cli.cli.options import UsageExit
from sr3d_cli.cli.report import Report
from sr3d_cli.config import Config
from sr3d_cli.errors import ConfigError, InputError
from sr3d_cli.io.formats import describe, discover_scenes
from sr3d_cli.io.frames import select_frames
from sr3d_cli.io.scene import SceneSource

log = logging.getLogger("sr3d")


def open_scenes(path: str | Path, cfg: Config, out: str | Path | None) -> list[SceneSource]:
    try:
        scenes = discover_scenes(path, cfg.io, out)
    except InputError as exc:
        raise UsageExit(str(exc)) from None
    if cfg.io.format == "auto":
        log.warning("format auto: found %s", describe(scenes))
    return scenes


def check_writable(folder: str | Path) -> None:
    """A usage error (before any work) where outputs cannot be written under ``folder``."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".sr3d-write-test.", dir=folder)
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise UsageExit(f"{folder}: cannot write outputs here ({exc.strerror or exc}); "
                        "use --out DIR") from None


def iter_frames(scenes: list[SceneSource], spec: str | None, report: Report
                ) -> Iterator[tuple[SceneSource, str]]:
    """(scene, frame id) pairs selected by ``spec``; a scene whose camera or folder is broken is
    reported once (all its frames counted as failed) and the others go on, as does a scene
    without frames and a depth file without a colour image."""
    plan: list[tuple[SceneSource, list[str]]] = []
    for scene in scenes:
        try:
            ids = scene.frame_ids()
            orphans = scene.orphan_depth(ids)
        except OSError as exc:
            report.fail(str(scene.root), InputError(scene.root, f"cannot list frames ({exc})"))
            continue
        for path in orphans if not spec else []:
            report.fail(scene.frame_key(path.stem),
                        InputError(path, "depth without a colour image (rgb/"
                                         f"{path.stem}.png or .jpg)"))
        if not ids and not orphans:
            report.fail(str(scene.root), InputError(scene.root, "no frames (no colour image)"))
        try:
            ids = select_frames(ids, spec)
        except ConfigError as exc:
            if len(scenes) == 1:
                raise UsageExit(str(exc)) from None
            ids = []
        if ids:
            plan.append((scene, ids))
    if spec and not plan:
        raise UsageExit(f"--frames {spec!r} matches no frame")
    for scene, ids in plan:
        try:
            _ = scene.camera  # read once, so a broken camera file fails the scene, not each frame
        except InputError as exc:
            report.fail(str(scene.root), exc, count=len(ids))
            continue
        for frame_id in ids:
            yield scene, frame_id
