"""``sr3d synth OUT``: synthetic scenes with ground truth."""

from __future__ import annotations

from pathlib import Path

import click
from tqdm import tqdm

from sr3d_cli.cli.options import common_options, load_config
from sr3d_cli.cli.report import Report


@click.command()
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--scenes", type=int, default=None, help="Number of scenes (default: synth.scenes).")
@click.option("--views", type=int, default=None, help="Frames per scene (default: synth.views).")
@click.option("--seed", type=int, default=None, help="Random seed (default: synth.seed).")
@click.option("--overwrite", is_flag=True, help="Regenerate scenes that already exist.")
@common_options
def synth(out, scenes, views, seed, overwrite):
    """Generate synthetic glassware scenes with full ground truth into OUT/scene_NNNN/.

    \b
    Example:
      sr3d synth build/synth --scenes 20 --seed 7
    """
    from sr3d_cli.render import make_renderer
    from sr3d_cli.synth.generate import write_scene

    cfg = load_config({"synth.scenes": scenes, "synth.views": views, "synth.seed": seed})
    ctx = click.get_current_context()
    report = Report(verbose=ctx.meta["sr3d.verbose"])
    renderer = make_renderer(cfg.render.backend)
    out = Path(out)
    for index in tqdm(range(cfg.synth.scenes), desc="synth", unit="scene",
                      disable=ctx.meta["sr3d.quiet"]):
        folder = out / f"scene_{index:04d}"
        if (folder / "camera.json").is_file() and not overwrite:
            report.skip(str(folder), "exists (use --overwrite)")
            continue
        try:
            write_scene(folder, index, cfg.synth, renderer)
            report.ok(cfg.synth.views)
        except Exception as exc:  # one bad scene does not stop the batch
            report.fail(str(folder), exc)
    click.echo(str(out))
    report.finish("frames")
