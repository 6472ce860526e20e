"""A batch as a Rerun recording (extra ``viz``: rerun-sdk), opened with ``rerun FILE.rrd``.

Per frame (timeline ``frame``, one step per frame in batch order), everything in the camera
frame (OpenCV: x right, y down, z forward; metres) under ``world``:

- ``world/camera``: the pinhole (K, size) with ``rgb``, ``raw_depth``, ``repaired_depth``
  (depth images) and ``masks`` (instance ids) as its images;
- ``world/objects/<id>``: each placed mesh (``T_cam_obj`` and scale applied);
- ``world/grasps``: the best grasps of each object as gripper line strips, red (score 0) to
  green (1).

What a frame lacks (no repaired depth yet, no grasps) is cleared at that frame, so the viewer
never shows an earlier frame's outputs over this one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sr3d_cli.errors import MissingExtraError, Sr3dError
from sr3d_cli.io import images
from sr3d_cli.io.scene import SceneSource


def import_rerun():
    try:
        import rerun as rr
    except ImportError:
        raise MissingExtraError("--rerun", "rerun-sdk", "viz") from None
    return rr


def open_recording(path: Path, name: str = "sr3d"):
    """A recording stream that writes to the file ``path``."""
    rr = import_rerun()
    rec = rr.RecordingStream(name)
    rec.save(str(path))
    rec.log("world", rr.ViewCoordinates.RDF, static=True)
    return rec


def log_frame(rec, step: int, source: SceneSource, frame_id: str, gripper=None,
              per_object: int = 3) -> list[str]:
    """Log one frame's inputs and outputs at ``step``; returns what was found (entity names).
    Raises :class:`~sr3d_cli.errors.Sr3dError` when the frame itself cannot be read."""
    import rerun as rr

    from sr3d_cli import stages
    from sr3d_cli.geometry.transforms import place_points
    from sr3d_cli.io.preview import best_per_object, gripper_points, score_colours

    frame = source.load_frame(frame_id)
    h, w = frame.depth_m.shape
    rec.set_time("frame", sequence=step)
    rec.log("world/camera", rr.Pinhole(image_from_camera=frame.camera.K, width=w, height=h))
    rec.log("world/camera/rgb", rr.Image(frame.rgb))
    rec.log("world/camera/raw_depth", rr.DepthImage(frame.depth_m, meter=1.0))
    for entity in ("world/camera/repaired_depth", "world/camera/masks", "world/grasps"):
        rec.log(entity, rr.Clear(recursive=False))
    rec.log("world/objects", rr.Clear(recursive=True))
    logged = ["rgb", "raw_depth"]
    path = source.stage_file("repaired", frame_id, images.DEPTH_SUFFIXES)
    if path is not None:
        repaired = source.read_depth_checked(path, (h, w))
        rec.log("world/camera/repaired_depth", rr.DepthImage(repaired, meter=1.0))
        logged.append("repaired_depth")
    if source.stage_file("masks", frame_id, (".png",)) is not None:
        ids, _ = stages.load_instances(source, frame_id, (h, w))
        rec.log("world/camera/masks", rr.SegmentationImage(ids.astype(np.uint16)))
        logged.append("masks")
    if source.stage_file("poses", frame_id, (".json",)) is not None:
        for obj in stages.load_poses(source, frame_id):
            mesh = stages.load_mesh(stages.find_mesh(source, frame_id, obj["id"]))
            verts = place_points(np.asarray(mesh.vertices), np.asarray(obj["T_cam_obj"]),
                                 float(obj["scale"]))
            rec.log(f"world/objects/{int(obj['id'])}",
                    rr.Mesh3D(vertex_positions=verts, triangle_indices=np.asarray(mesh.faces)))
            logged.append(f"objects/{int(obj['id'])}")
    if gripper is not None and source.stage_file("grasps", frame_id, (".npy",)) is not None:
        g = stages.load_grasps(source, frame_id).sorted()
        keep = best_per_object(g, per_object)
        strips = []
        for i in keep:
            p = gripper_points(g, i, gripper)
            strips += [p[:4], p[4:]]
        colours = np.repeat(score_colours(g.scores[keep]), 2, axis=0)
        rec.log("world/grasps", rr.LineStrips3D(strips, colors=colours, radii=0.001))
        logged.append("grasps")
    return logged


def write_recording(path: Path, frames: list[tuple[SceneSource, str]], gripper=None
                    ) -> tuple[int, list[str]]:
    """Log every frame to ``path``; returns (frames logged, one message per frame that could not
    be read)."""
    rec = open_recording(path)
    done, problems = 0, []
    try:
        for step, (source, fid) in enumerate(frames):
            try:
                log_frame(rec, step, source, fid, gripper)
                done += 1
            except (Sr3dError, ValueError, OSError) as exc:
                problems.append(f"{source.frame_key(fid)}: {exc}")
    finally:
        rec.flush()
        rec.disconnect()
    return done, problems
