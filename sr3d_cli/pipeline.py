"""The whole chain for one frame: run whichever stage has no current output, then repair the
depth.

A stage output is current when what it records it was made from (config keys, upstream files:
:mod:`sr3d_cli.io.provenance`) matches what it would be made from now; a stale one is made again
(or, with ``keep_stale``, kept with a message), and so is every stage from ``redo`` on. The
frame's stage data lives in one :class:`~sr3d_cli.stages.FrameState` (:meth:`Pipeline.state`):
the table is fitted once for every stage, each stage takes what an earlier one made in memory
and writes its own outputs once, and outputs that were current are read once. Stage objects
(segmenter, reconstructor, aligner, renderer) are made once per batch, lazily, so a run that
finds every upstream output on disk and current loads no model.
"""

from __future__ import annotations

import logging

import numpy as np

from sr3d_cli import stages
from sr3d_cli.config import Config
from sr3d_cli.errors import Problem
from sr3d_cli.io.provenance import STAGES
from sr3d_cli.io.scene import Frame

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

    def state(self, frame: Frame) -> stages.FrameState:
        """A frame's stage data, to pass to :meth:`ensure_upstream` and
        :meth:`repaired_depth`."""
        return stages.FrameState(frame, self.cfg.plane, self.cfg.reconstruct.masks)

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

    def ensure_upstream(self, state: stages.FrameState, timings: dict | None = None,
                        redo: str | None = None, keep_stale: bool = False) -> list[Problem]:
        """Segment, reconstruct and align where their outputs are missing, stale, or from
        ``redo`` on, each taking its inputs from ``state`` and leaving its outputs there; with
        ``keep_stale`` a stale output is kept and a problem says so. ``timings``: seconds per
        stage run, filled in."""
        import time

        source, fid = state.source, state.frame_id
        problems: list[Problem] = []
        timings = {} if timings is None else timings
        for stage in self.upstream_stages():
            why = self.why_run(source, fid, stage, redo)
            if why is None:
                continue
            redone = redo is not None and STAGES.index(stage) >= STAGES.index(redo)
            if keep_stale and why != stages.MISSING and not redone:
                problems.append(Problem(f"{stage} output kept though stale ({why}; "
                                        "--keep-stale)"))
                continue
            if why != stages.MISSING:
                log.info("%s: %s made again (%s)", state.frame.key, stage, why)
            record = stages.stage_record(self.cfg, source, fid, stage)
            t = time.perf_counter()
            if stage == "segment":
                stages.segment_frame(state, self.segmenter, self.cfg.segment.backend, record)
            elif stage == "reconstruct":
                problems += stages.reconstruct_frame(state, self.reconstructor, record)[1]
            else:  # an object without a mesh is reconstruct's problem, reported there
                found = stages.align_frame(state, self.aligner, record)[1]
                problems += [p for p in found if not p.upstream]
            timings[stage] = time.perf_counter() - t
        return problems

    def repaired_depth(self, state: stages.FrameState) -> tuple[np.ndarray, np.ndarray]:
        """(repaired depth (H, W) float32 metres, instance ids (H, W) int32) from the frame's
        stage data (:meth:`ensure_upstream` first)."""
        frame = state.frame
        ids, _ = state.instances()
        placed = []
        for obj in state.pose_document().get("objects", []):
            k = int(obj["id"])
            placed.append((k, state.mesh(k), np.asarray(obj["T_cam_obj"], dtype=np.float64),
                           float(obj["scale"])))
        rcfg = self.cfg.repair
        plane = state.plane()[0] if rcfg.outside_render == "plane" or rcfg.beyond_mask else None
        from sr3d_cli.repair import repair_frame

        depth = repair_frame(frame.depth_m, ids, frame.camera, self.renderer, placed,
                             plane=plane, outside_render=rcfg.outside_render,
                             beyond_mask=rcfg.beyond_mask, keep_nearer=rcfg.keep_nearer)
        return depth, ids
