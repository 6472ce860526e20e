"""``sr3d synth OUT``: synthetic scenes with ground truth."""

from __future__ import annotations

from pathlib import Path

import click
from tqdm import tqdm

from sr3d_cli.cli.options import common_options, load_config
from sr3d_cli.cli.report import Report


def _families(ctx, param, value: str) -> tuple[str, ...]:
    """``--families a,b``: names checked against the generator's families and kinds."""
    from sr3d_cli.synth.families import kinds_for

    names = tuple(v.strip() for v in value.split(",") if v.strip())
    try:
        kinds_for(names)
    except ValueError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from exc
    return names


@click.command()
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--scenes", type=int, default=None, help="Number of scenes (default: synth.scenes).")
@click.option("--views", type=int, default=None, help="Frames per scene (default: synth.views).")
@click.option("--seed", type=int, default=None, help="Random seed (default: synth.seed).")
@click.option("--families", default="revolution", show_default=True, callback=_families,
              metavar="NAME[,NAME...]",
              help="Object families drawn from, each kind equally likely: revolution (bottle, "
                   "glass, flask, goblet, beaker, vial), handle (mug, pitcher), square "
                   "(square_bottle, rect_bottle), flat (flat_bottle), open (bowl, thin_glass: "
                   "scenes seen from above), single kinds, or all.")
@click.option("--overwrite", is_flag=True, help="Regenerate scenes that already exist.")
@common_options
def synth(out, scenes, views, seed, families, overwrite):
    """Generate synthetic glassware scenes with full ground truth into OUT/scene_NNNN/.

    The default families draw the bundled sample_data byte for byte (seed 0); `--families all`
    adds handles, square, flat and open vessels.

    \b
    Example:
      sr3d synth build/synth --scenes 20 --seed 7
      sr3d synth build/shapes --scenes 24 --seed 13300 --families all
      sr3d synth build/mugs --families mug,square_bottle
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
            write_scene(folder, index, cfg.synth, renderer, families)
            report.ok(cfg.synth.views)
        except Exception as exc:  # one bad scene does not stop the batch
            report.fail(str(folder), exc)
    click.echo(str(out))
    report.finish("frames")
