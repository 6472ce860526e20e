"""``sr3d import-bag REC OUT``: a ROS 1 or ROS 2 recording to a native scene folder."""

from __future__ import annotations

import click

from sr3d_cli.cli.options import UsageExit, common_options


@click.command("import-bag")
@click.argument("bag", type=click.Path())
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--every", type=click.IntRange(min=1), default=1, show_default=True,
              help="Keep every Nth frame.")
@click.option("--start", type=click.FloatRange(min=0), default=None,
              help="Seconds after the first frame to start at.")
@click.option("--end", type=click.FloatRange(min=0), default=None,
              help="Seconds after the first frame to stop at.")
@click.option("--limit", type=click.IntRange(min=1), default=None, help="At most N frames.")
@click.option("--colour-topic", help="Colour image topic (default: found by name).")
@click.option("--depth-topic", help="Depth image topic, aligned to colour (default: found by "
                                    "name).")
@click.option("--info-topic", help="Colour CameraInfo topic (default: beside the colour topic).")
@click.option("--depth-scale", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Metres per unit of 16-bit depth (default: the recording's Depth Units, "
                   "else 0.001).")
@common_options
def import_bag(bag, out, every, start, end, limit, colour_topic, depth_topic, info_topic,
               depth_scale):
    """Turn the recording BAG into a scene folder: OUT/rgb, OUT/depth (aligned to colour),
    OUT/camera.json (colour intrinsics, depth scale) and OUT/recording.json (topics, stamps).

    BAG is a ROS 1 .bag, a ROS 2 bag folder, or the .db3 / .mcap file inside one; topics are
    found as the RealSense ROS 1 / ROS 2 drivers and the RealSense Viewer name them. Needs the
    bag extra (rosbags).

    \b
    Example:
      sr3d import-bag capture.bag scenes/desk --every 5
    """
    from pathlib import Path

    from sr3d_cli.errors import Sr3dError
    from sr3d_cli.io.bags import Selection, import_recording

    if start is not None and end is not None and end < start:
        raise UsageExit(f"--end {end:g} is before --start {start:g}")
    try:
        n = import_recording(Path(bag), Path(out), Selection(every, start, end, limit),
                             colour_topic=colour_topic, depth_topic=depth_topic,
                             info_topic=info_topic, depth_scale=depth_scale)
    except Sr3dError as exc:
        raise UsageExit(str(exc)) from None
    click.echo(f"{n} frames written to {out}")
