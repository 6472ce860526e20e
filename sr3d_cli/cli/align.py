"""``sr3d align SCENE``: pose and scale of every reconstructed object."""

from __future__ import annotations

import click

from sr3d_cli.cli.options import (check_masks, common_options, load_config, masks_option,
                                  scene_options)
from sr3d_cli.cli.stage_loop import batch_options, run_frames


@click.command()
@click.argument("scene", type=click.Path(exists=True, file_okay=False))
@click.option("--mode", type=click.Choice(["sr3d", "paper"]), default=None,
              help="sr3d (plane prior + refinement, default) or the paper's plain method.")
@masks_option
@click.option("--bop", is_flag=True,
              help="Also write scene_gt.json per scene (BOP: cam_R_m2c, cam_t_m2c in mm).")
@batch_options
@scene_options
@common_options
def align(scene, mode, masks, bop, batch, out, frames, fmt):
    """Write poses/<frame>.json: T_cam_obj, scale, view and silhouette scores, diagnostics.

    \b
    Example:
      sr3d align sample_data/scene_0000 --masks gt
    """
    from sr3d_cli.align import Aligner
    from sr3d_cli.errors import FrameFailed
    from sr3d_cli.io.atomic import write_json
    from sr3d_cli.io.formats.bop import bop_scene_gt
    from sr3d_cli.stages import FrameState, align_frame, load_poses, stage_record, stale

    cfg = load_config({"align.mode": mode, "reconstruct.masks": masks, "io.format": fmt})
    check_masks(cfg)
    aligner = Aligner(cfg.align)

    def work(frame):
        objects, problems = align_frame(
            FrameState(frame, cfg.plane, cfg.reconstruct.masks), aligner,
            stage_record(cfg, frame.scene, frame.frame_id, "align"))
        if not objects and problems:  # instances, and none placed
            raise FrameFailed("no object placed (" + "; ".join(map(str, problems)) + ")")
        return problems

    def write_bop(scenes):
        for source in scenes:
            poses = {}
            for fid in source.frame_ids():
                if source.stage_file("poses", fid, (".json",)) is not None:
                    poses[fid] = load_poses(source, fid)
            write_json(source.out / "scene_gt.json", bop_scene_gt(poses))

    run_frames("align", scene, cfg, out, frames, work, batch=batch,
               outputs=lambda source, fid: [source.output_path("poses", fid, ".json")],
               stale=lambda source, fid: stale(cfg, source, fid, "align"),
               after=write_bop if bop else None)
