"""``sr3d align SCENE``: pose and scale of every reconstructed object."""

from __future__ import annotations

import click

from sr3d_cli.cli.options import common_options, load_config, scene_options
from sr3d_cli.cli.stage_loop import run_frames, workers_option


@click.command()
@click.argument("scene", type=click.Path(exists=True, file_okay=False))
@click.option("--mode", type=click.Choice(["sr3d", "paper"]), default=None,
              help="sr3d (plane prior + refinement, default) or the paper's plain method.")
@click.option("--masks", "masks", type=click.Choice(["segment", "gt"]), default=None,
              help="Instance masks: masks/ from segment (default) or the ground truth.")
@workers_option
@scene_options
@common_options
def align(scene, mode, masks, workers, out, frames, fmt):
    """Write poses/<frame>.json: T_cam_obj, scale, view and silhouette scores, diagnostics."""
    from sr3d_cli.align import Aligner
    from sr3d_cli.stages import align_frame

    cfg = load_config({"align.mode": mode, "reconstruct.masks": masks, "io.format": fmt})
    aligner = Aligner(cfg.align)

    def work(frame):
        _, messages = align_frame(frame, aligner, cfg.plane, cfg.reconstruct.masks)
        return messages

    run_frames("align", scene, cfg, out, frames, work, workers)
