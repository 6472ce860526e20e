"""The whole chain for one frame: run whichever stage has no output yet, then repair the depth.

Stage objects (segmenter, reconstructor, aligner, renderer) are made once per batch, lazily, so
a run that finds every upstream output on disk loads no model.
"""

from __future__ import annotations

import numpy as np

from sr3d_cli.config import Config
from sr3d_cli.io.scene import Frame
from sr3d_cli import stages


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

    def ensure_upstream(self, frame: Frame, timings: dict | None = None) -> list[str]:
        """Segment, reconstruct and align where their outputs are missing."""
        import time

        source, fid = frame.scene, frame.frame_id
        messages: list[str] = []
        timings = {} if timings is None else timings
        if source.stage_file("masks", fid, (".png",)) is None:
            t = time.perf_counter()
            inst = self.segmenter(fid, frame.rgb, frame.depth_m, frame.camera.K)
            stages.write_instances(source, fid, inst, self.cfg.segment.backend)
            timings["segment"] = time.perf_counter() - t
        ids, records = stages.load_instances(source, fid, frame.depth_m.shape)
        if any(not stages.mesh_path(source, fid, k).is_file() for k in records):
            t = time.perf_counter()
            _, msgs = stages.reconstruct_frame(frame, self.reconstructor, self.cfg.plane,
                                               "segment")
            messages += msgs
            timings["reconstruct"] = time.perf_counter() - t
        if source.stage_file("poses", fid, (".json",)) is None:
            t = time.perf_counter()
            _, msgs = stages.align_frame(frame, self.aligner, self.cfg.plane)
            messages += [m for m in msgs if "no mesh" not in m]
            timings["align"] = time.perf_counter() - t
        return messages

    def repaired_depth(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """(repaired depth (H, W) float32 metres, instance ids) from the stage outputs on disk."""
        source, fid = frame.scene, frame.frame_id
        ids, _ = stages.load_instances(source, fid, frame.depth_m.shape)
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
