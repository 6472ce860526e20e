"""``sr3d import-bag REC OUT``: a RealSense recording (.bag or .db3) to a native scene folder."""

from __future__ import annotations

import click

from sr3d_cli.cli.options import UsageExit, common_options


@click.command("import-bag")
@click.argument("bag", type=click.Path(dir_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--every", type=click.IntRange(min=1), default=1, show_default=True,
              help="Keep every Nth frame.")
@click.option("--limit", type=click.IntRange(min=1), default=None, help="At most N frames.")
@common_options
def import_bag(bag, out, every, limit):
    """Turn the RealSense recording BAG (.bag or .db3) into a scene folder: OUT/rgb, OUT/depth
    (aligned to colour) and OUT/camera.json (colour intrinsics, the device's depth scale).
    Needs the realsense extra (pyrealsense2)."""
    from pathlib import Path

    from sr3d_cli.errors import InputError
    from sr3d_cli.io.realsense import import_bag as run

    try:
        n = run(Path(bag), Path(out), every, limit)
    except InputError as exc:
        raise UsageExit(str(exc)) from None
    click.echo(f"{n} frames written to {out}")
