"""``sr3d report SCENE... -o report.html``: one self-contained HTML page for a batch."""

from __future__ import annotations

from pathlib import Path

import click

from sr3d_cli.cli.options import UsageExit, common_options, load_config


@click.command("report")
@click.argument("scenes", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), default="report.html",
              show_default=True, help="The HTML file to write.")
@click.option("--out", type=click.Path(file_okay=False),
              help="Where the commands wrote their outputs (their --out), if not beside SCENE.")
@click.option("--format", "fmt", type=click.Choice(["auto", "native", "cleargrasp", "transcg",
                                                    "bop"]),
              default=None, help="Input layout (default: io.format, auto-detected).")
@click.option("--title", default="sr3d report", show_default=True, help="Page title.")
@click.option("--rerun", "rerun_path", type=click.Path(dir_okay=False),
              help="Also log every frame (RGB, raw and repaired depth, masks, placed meshes, "
                   "grasps) to this Rerun recording (.rrd; extra viz: rerun-sdk).")
@common_options
def report(scenes, output, out, fmt, title, rerun_path):
    """Write one HTML page for the frames of SCENE...: the metrics of `sr3d evaluate`
    (sortable, worst frames first), each frame's previews and error maps, time per command and
    stage (from log/<frame>.json) and failures with their reasons. Pictures are embedded, so
    the page is one file. With --rerun, also a Rerun recording to open with `rerun FILE.rrd`.

    \b
    Example:
      sr3d report sample_data --out build/demo/sample_data -o report.html
    """
    from sr3d_cli.cli.batch import open_scenes
    from sr3d_cli.io.atomic import write_text
    from sr3d_cli.io.html_report import gather, render

    if out and len(scenes) > 1:
        raise UsageExit("--out goes with one SCENE (each SCENE's outputs are beside it)")
    cfg = load_config({"io.format": fmt})
    groups = []
    for scene in scenes:
        label = Path(scene).resolve().name if len(scenes) > 1 else ""
        groups.append((label, open_scenes(scene, cfg, out), Path(out) if out else Path(scene)))
    batch = gather(groups)
    try:
        write_text(output, render(batch, title))
    except OSError as exc:
        raise UsageExit(f"{output}: cannot write ({exc.strerror or exc})") from None
    click.echo(f"{output}: {len(batch.frames)} frames, {len(batch.failures)} failures")
    if rerun_path:
        _write_rerun(Path(rerun_path), [s for _, sources, _ in groups for s in sources], cfg)


def _write_rerun(path: Path, sources, cfg) -> None:
    from sr3d_cli.errors import MissingExtraError
    from sr3d_cli.grasp.gripper import Gripper
    from sr3d_cli.rerun_log import import_rerun, write_recording

    try:
        import_rerun()
    except MissingExtraError as exc:
        raise UsageExit(str(exc)) from None
    frames = []
    for source in sources:
        try:
            frames += [(source, fid) for fid in source.frame_ids()]
        except OSError:
            continue
    done, problems = write_recording(path, frames, Gripper.from_config(cfg.grasp))
    for problem in problems:
        click.echo(f"error: {problem}", err=True)
    click.echo(f"{path}: {done} frames logged (open with: rerun {path})")
