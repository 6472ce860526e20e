"""``sr3d grasp SCENE``: parallel-jaw grasps on the repaired depth and the placed meshes."""

from __future__ import annotations

import click

from sr3d_cli.cli.options import (check_masks, common_options, load_config, masks_option,
                                  scene_options)
from sr3d_cli.cli.stage_loop import batch_options, run_frames


@click.command()
@click.argument("scene", type=click.Path(exists=True, file_okay=False))
@click.option("--object", "only", type=int, default=None, help="Plan for this object id only.")
@click.option("--from", "depth_source", type=click.Choice(["repaired", "raw"]), default=None,
              help="Plan on the repaired scene (default) or on the raw sensor depth.")
@masks_option
@click.option("--hand-poses", is_flag=True,
              help="Also write grasps/<frame>_hand_poses.npy: (n, 4, 4) hand poses, "
                   "Contact-GraspNet convention.")
@click.option("--preview", is_flag=True,
              help="Also write grasps/<frame>_preview.png: the best grasps over the RGB image.")
@batch_options
@scene_options
@common_options
def grasp(scene, only, depth_source, masks, hand_poses, preview, batch, out, frames, fmt):
    """Propose 6-DoF parallel-jaw grasps per object: writes grasps/<frame>.json and .npy
    (graspnetAPI's 17 numbers per grasp). Needs masks/ and, unless --from raw, repaired/ and
    poses/ (run `sr3d repair-depth` first). A frame with objects and no grasp fails (exit 1);
    its grasps file says why.

    \b
    Example:
      sr3d grasp sample_data/scene_0000 --preview
    """
    from sr3d_cli.errors import FrameFailed, Problem
    from sr3d_cli.grasp.planner import Planner
    from sr3d_cli.pipeline import Pipeline
    from sr3d_cli.io.atomic import write_png
    from sr3d_cli.io.preview import grasp_preview
    from sr3d_cli.stages import grasp_frame, load_grasps, stage_record, stale

    cfg = load_config({"io.format": fmt, "grasp.source": depth_source,
                       "reconstruct.masks": masks})
    check_masks(cfg)
    planner = Planner(cfg.grasp)
    pipeline = Pipeline(cfg)  # only to tell whether the stage outputs planned on are current

    def work(frame):
        n, problems, failure = grasp_frame(
            frame, planner, cfg.plane, cfg.grasp.source, only,
            cfg.grasp.base_to_tip if hand_poses else None, cfg.reconstruct.masks,
            stage_record(cfg, frame.scene, frame.frame_id, "grasp"))
        if failure is not None:
            raise FrameFailed(failure)
        if cfg.grasp.source == "repaired":
            why = pipeline.stale_chain(frame.scene, frame.frame_id)
            if why is not None:
                problems = problems + [Problem(f"planned on stale outputs ({why}): run "
                                               "`sr3d repair-depth` to make them again")]
        if preview:
            write_png(frame.scene.output_path("grasps", frame.frame_id, "_preview.png"),
                      grasp_preview(frame.rgb, load_grasps(frame.scene, frame.frame_id),
                                    frame.camera.K, planner.gripper))
        return problems

    run_frames("grasp", scene, cfg, out, frames, work, batch=batch,
               outputs=lambda source, fid: [source.output_path("grasps", fid, ".json"),
                                            source.output_path("grasps", fid, ".npy")],
               stale=lambda source, fid: stale(cfg, source, fid, "grasp"))
