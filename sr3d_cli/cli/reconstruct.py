"""``sr3d reconstruct SCENE``: a mesh per segmented object."""

from __future__ import annotations

import click

from sr3d_cli.backends import RECONSTRUCT
from sr3d_cli.cli.options import (UsageExit, check_masks, common_options, load_config,
                                  masks_option, scene_options)
from sr3d_cli.cli.stage_loop import batch_options, run_frames
from sr3d_cli.errors import FrameFailed, InputError


@click.command()
@click.argument("scene", type=click.Path(exists=True, file_okay=False))
@click.option("--backend", type=click.Choice(RECONSTRUCT.names), default=None,
              help="Reconstruction backend (default: reconstruct.backend).")
@masks_option
@click.option("--library", type=click.Path(exists=True, file_okay=False), default=None,
              help="Folder of meshes (implies --backend library).")
@batch_options
@scene_options
@common_options
def reconstruct(scene, backend, masks, library, batch, out, frames, fmt):
    """Write meshes/<frame>/<k>.ply (object frame: base centre, +z up the axis, height 1).

    \b
    Example:
      sr3d reconstruct sample_data/scene_0000 --frames 000000
    """
    from sr3d_cli.reconstruct import Reconstructor
    from sr3d_cli.stages import FrameState, reconstruct_frame, stage_record, stale

    if library and backend is None:
        backend = "library"
    cfg = load_config({"reconstruct.backend": backend, "reconstruct.masks": masks,
                       "reconstruct.library": library, "io.format": fmt})
    check_masks(cfg)
    try:
        reconstructor = Reconstructor(cfg.reconstruct)
    except InputError as exc:
        raise UsageExit(str(exc)) from None

    def work(frame):
        written, problems = reconstruct_frame(
            FrameState(frame, cfg.plane, cfg.reconstruct.masks), reconstructor,
            stage_record(cfg, frame.scene, frame.frame_id, "reconstruct"))
        if written == 0 and problems:  # instances, and no mesh for any
            raise FrameFailed("no mesh made (" + "; ".join(map(str, problems)) + ")")
        return problems

    run_frames("reconstruct", scene, cfg, out, frames, work, batch=batch,
               outputs=lambda source, fid: [source.output_path("meshes", fid, ".json")],
               stale=lambda source, fid: stale(cfg, source, fid, "reconstruct"))
