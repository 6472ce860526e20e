"""``sr3d repair-depth SCENE``: the depth map with the transparent objects put back."""

from __future__ import annotations

import time

import click

from sr3d_cli.cli.options import (UsageExit, check_masks, common_options, load_config,
                                  masks_option, scene_options)
from sr3d_cli.cli.stage_loop import batch_options, run_frames
from sr3d_cli.errors import InputError


@click.command("repair-depth")
@click.argument("scene", type=click.Path(exists=True, file_okay=False))
@click.option("--npy", is_flag=True, help="Also write repaired/<frame>.npy (float32 metres).")
@click.option("--ply", is_flag=True, help="Also write repaired/<frame>.ply (coloured points).")
@click.option("--preview", is_flag=True,
              help="Also write repaired/<frame>_preview.png: RGB with outlines | raw | repaired.")
@masks_option
@click.option("--redo", type=click.Choice(["segment", "reconstruct", "align", "repair"]),
              default=None, help="Make this stage's outputs again, and every later stage's.")
@batch_options
@scene_options
@common_options
def repair_depth(scene, npy, ply, preview, masks, redo, batch, out, frames, fmt):
    """Run any stage (segment, reconstruct, align) whose output is missing or stale, then render
    the placed meshes into the depth: writes repaired/<frame>.png in the input's encoding and
    repaired/<frame>.json (what it was made from).

    A stage output is stale when the config keys it depends on or its upstream files changed
    since it was made; --keep-stale keeps such outputs (with a warning), --redo STAGE makes
    that stage and the later ones again. A frame with objects of which none could be placed
    fails (exit 1); its repaired depth is then the raw one.

    \b
    Example:
      sr3d repair-depth sample_data --preview --workers 2
    """
    from sr3d_cli.io import preview as previews
    from sr3d_cli.io.atomic import write_bytes, write_npy, write_png
    from sr3d_cli.io.images import write_depth
    from sr3d_cli.pipeline import Pipeline
    from sr3d_cli.io.atomic import write_json
    from sr3d_cli.io.provenance import RECORD_KEY
    from sr3d_cli.errors import FrameFailed
    from sr3d_cli.stages import depth_suffix, stage_record

    cfg = load_config({"io.format": fmt, "reconstruct.masks": masks})
    check_masks(cfg)
    if redo == "segment" and cfg.reconstruct.masks != "segment":
        raise UsageExit(f"--redo segment: masks come from {cfg.reconstruct.masks}, not segment")
    pipeline = Pipeline(cfg)
    try:  # build the backends (models loaded) once, before the batch: a bad model file is
        # one usage error
        _ = pipeline.segmenter, pipeline.reconstructor
    except InputError as exc:
        raise UsageExit(str(exc)) from None
    if batch.get("workers", 1) <= 1 and cfg.render.backend != "numpy":
        # pyrender's first import, were it left to the first frame, can swallow a Ctrl-C (one
        # of its window libraries imports inside a bare ``except:``); forked workers import
        # it themselves, as each makes its own GL context
        from sr3d_cli.render import import_pyrender

        try:
            import_pyrender()
        except Exception:  # noqa: BLE001 - no GL library: the numpy fallback says so later
            pass

    def work(frame):
        source, fid = frame.scene, frame.frame_id
        timings: dict[str, float] = {}
        state = pipeline.state(frame)
        problems = pipeline.ensure_upstream(state, timings, redo=redo,
                                            keep_stale=batch.get("keep_stale", False))
        record = stage_record(cfg, source, fid, "repair")
        start = time.perf_counter()
        depth, ids = pipeline.repaired_depth(state)
        timings["repair"] = time.perf_counter() - start
        scale = frame.camera.depth_scale
        write_depth(source.output_path("repaired", fid, depth_suffix(source, fid)), depth, scale)
        if npy:
            write_npy(source.output_path("repaired", fid, ".npy"), depth)
        if ply:
            write_bytes(source.output_path("repaired", fid, ".ply"),
                        previews.point_cloud_ply(depth, frame.rgb, frame.camera.K))
        if preview:
            write_png(source.output_path("repaired", fid, "_preview.png"),
                      previews.preview_image(frame.rgb, frame.depth_m, depth, ids))
        placed = len(state.pose_document().get("objects", []))
        document = {RECORD_KEY: record, "placed": placed}
        if placed == 0 and (ids > 0).any():  # objects, none placed: the raw depth, unrepaired
            document["frame_failed"] = "no object placed (" + "; ".join(map(str, problems)) + ")"
        write_json(source.output_path("repaired", fid, ".json"), document)
        if "frame_failed" in document:
            raise FrameFailed(document["frame_failed"])
        return problems, timings

    def outputs(source, fid):
        paths = [source.output_path("repaired", fid, depth_suffix(source, fid)),
                 source.output_path("repaired", fid, ".json")]
        paths += [source.output_path("repaired", fid, ".npy")] if npy else []
        paths += [source.output_path("repaired", fid, ".ply")] if ply else []
        return paths + ([source.output_path("repaired", fid, "_preview.png")] if preview else [])

    run_frames("repair-depth", scene, cfg, out, frames, work, batch=batch, outputs=outputs,
               stale=lambda source, fid: pipeline.stale_chain(source, fid, redo))
