"""The whole chain for one frame: run whichever stage has no current output, then repair the
depth.

A stage output is current when what it records it was made from (config keys, upstream files:
:mod:`sr3d_cli.io.provenance`) matches what it would be made from now; a stale one is made again
(or, with ``keep_stale``, kept with a message), and so is every stage from ``redo`` on. Stage
objects (segmenter, reconstructor, aligner, renderer) are made once per batch, lazily, so a run
that finds every upstream output on disk and current loads no model.
"""

from __future__ import annotations

import logging

import numpy as np

from sr3d_cli.config import Config
from sr3d_cli.io.scene import Frame
from sr3d_cli import stages
from sr3d_cli.io.provenance import STAGES

log = logging.getLogger("sr3d")


class Pipeline:
    def __init__(self, cfg: Config):
        self.cfg = cfg
        self._segmenter = self._reconstructor = self._aligner = self._renderer = None

    @property
    def segmenter(self):
        if self._segmenter is None:
            from sr3d_cli.segment import Segmenter

            self._segmenter = Segmenter(self.cfg.segment, self.cfg.plane)
        return self._segmenter

    @property
    def reconstructor(self):
        if self._reconstructor is None:
            from sr3d_cli.reconstruct import Reconstructor

            self._reconstructor = Reconstructor(self.cfg.reconstruct)
        return self._reconstructor

    @property
    def aligner(self):
        if self._aligner is None:
            from sr3d_cli.align import Aligner

            self._aligner = Aligner(self.cfg.align)
        return self._aligner

    @property
    def renderer(self):
        if self._renderer is None:
            from sr3d_cli.render import make_renderer

            self._renderer = make_renderer(self.cfg.render.backend)
        return self._renderer

    def upstream_stages(self) -> list[str]:
        """The stages before repair this config runs: segment only where masks come from it."""
        first = "segment" if self.cfg.reconstruct.masks == "segment" else "reconstruct"
        return list(STAGES[STAGES.index(first):STAGES.index("repair")])

    def why_run(self, source, frame_id: str, stage: str, redo: str | None = None
                ) -> str | None:
        """Why ``stage`` must run for this frame: ``--redo``, its output missing or stale
        (None: current)."""
        if redo is not None and STAGES.index(stage) >= STAGES.index(redo):
            return f"--redo {redo}"
        return stages.stale(self.cfg, source, frame_id, stage)

    def stale_chain(self, source, frame_id: str, redo: str | None = None) -> str | None:
        """The first stage up to repair that must run for this frame, with why (None: none)."""
        for stage in self.upstream_stages() + ["repair"]:
            why = self.why_run(source, frame_id, stage, redo)
            if why is not None:
                return f"{stage}: {why}"
        return None

    def ensure_upstream(self, frame: Frame, timings: dict | None = None,
                        redo: str | None = None, keep_stale: bool = False) -> list[str]:
        """Segment, reconstruct and align where their outputs are missing, stale, or from
        ``redo`` on; with ``keep_stale`` a stale output is kept and a message says so."""
        import time

        source, fid = frame.scene, frame.frame_id
        messages: list[str] = []
        timings = {} if timings is None else timings
        which = self.cfg.reconstruct.masks
        for stage in self.upstream_stages():
            why = self.why_run(source, fid, stage, redo)
            if why is None:
                continue
            if keep_stale and why != "missing" and not why.startswith("--redo"):
                messages.append(f"{stage} output kept though stale ({why}; --keep-stale)")
                continue
            if why != "missing":
                log.info("%s: %s made again (%s)", frame.key, stage, why)
            record = stages.stage_record(self.cfg, source, fid, stage)
            t = time.perf_counter()
            if stage == "segment":
                inst = self.segmenter(fid, frame.rgb, frame.depth_m, frame.camera.K)
                stages.write_instances(source, fid, inst, self.cfg.segment.backend, record)
            elif stage == "reconstruct":
                _, msgs = stages.reconstruct_frame(frame, self.reconstructor, self.cfg.plane,
                                                   which, record)
                messages += msgs
            else:
                _, msgs = stages.align_frame(frame, self.aligner, self.cfg.plane, which,
                                             record=record)
                messages += [m for m in msgs if "no mesh" not in m]
            timings[stage] = time.perf_counter() - t
        return messages

    def repaired_depth(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """(repaired depth (H, W) float32 metres, instance ids) from the stage outputs on disk."""
        source, fid = frame.scene, frame.frame_id
        ids, _ = stages.load_instances(source, fid, frame.depth_m.shape,
                                       self.cfg.reconstruct.masks)
        placed = []
        for obj in stages.load_poses(source, fid):
            mesh = stages.load_mesh(stages.find_mesh(source, fid, obj["id"]))
            placed.append((int(obj["id"]), mesh, np.asarray(obj["T_cam_obj"], dtype=np.float64),
                           float(obj["scale"])))
        plane = None
        if self.cfg.repair.outside_render == "plane":
            plane, _ = stages.frame_plane(frame, ids, self.cfg.plane)
        from sr3d_cli.repair import repair_frame

        depth = repair_frame(frame.depth_m, ids, frame.camera, self.renderer, placed,
                             plane=plane, outside_render=self.cfg.repair.outside_render)
        return depth, ids
