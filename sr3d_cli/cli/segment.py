"""``sr3d segment SCENE``: instance masks of the transparent objects."""

from __future__ import annotations

import click

from sr3d_cli.backends import SEGMENT
from sr3d_cli.cli.options import UsageExit, common_options, load_config, scene_options
from sr3d_cli.cli.stage_loop import batch_options, run_frames
from sr3d_cli.errors import InputError


@click.command()
@click.argument("scene", type=click.Path(exists=True, file_okay=False))
@click.option("--backend", type=click.Choice(SEGMENT.names),
              default=None, help="Segmentation backend (default: segment.backend).")
@click.option("--prompt", default=None, help='Text label stored with every instance ("glass cup").')
@click.option("--import-dir", "import_dir", type=click.Path(file_okay=False), default=None,
              help="Folder of masks made elsewhere (<frame>.png; implies --backend import).")
@click.option("--boxes", type=click.Path(exists=True), default=None,
              help="Boxes JSON (or folder) prompting SAM instead of the training-free boxes.")
@click.option("--points", type=click.Path(exists=True), default=None,
              help="Points JSON (or folder), one object per point, prompting SAM.")
@click.option("--preview", is_flag=True,
              help="Also write masks/<frame>_preview.png: the instances with their scores.")
@batch_options
@scene_options
@common_options
def segment(scene, backend, prompt, import_dir, boxes, points, preview, batch, out, frames, fmt):
    """Write masks/<frame>.png (instance ids) and masks/<frame>.json (label, score, bbox).

    Instances scored below segment.min_score are dropped.

    Example: sr3d segment my_scene --preview
    """
    from sr3d_cli.io.atomic import write_png
    from sr3d_cli.io.preview import instances_preview
    from sr3d_cli.segment import Segmenter
    from sr3d_cli.errors import Problem
    from sr3d_cli.stages import FrameState, segment_frame, stage_record, stale

    if import_dir and backend is None:
        backend = "import"
    cfg = load_config({"segment.backend": backend, "segment.prompt": prompt,
                       "segment.import_dir": import_dir, "segment.boxes": boxes,
                       "segment.points": points, "io.format": fmt})
    try:
        segmenter = Segmenter(cfg.segment, cfg.plane)
    except InputError as exc:
        raise UsageExit(str(exc)) from None

    def work(frame):
        instances = segment_frame(FrameState(frame, cfg.plane), segmenter, cfg.segment.backend,
                                  stage_record(cfg, frame.scene, frame.frame_id, "segment"))
        if preview:
            write_png(frame.scene.output_path("masks", frame.frame_id, "_preview.png"),
                      instances_preview(frame.rgb, instances.ids, instances.objects))
        return [] if instances.objects else [Problem("no transparent object found")]

    run_frames("segment", scene, cfg, out, frames, work, batch=batch,
               outputs=lambda source, fid: [source.output_path("masks", fid),
                                            source.output_path("masks", fid, ".json")],
               stale=lambda source, fid: stale(cfg, source, fid, "segment"))
