"""The ``sr3d`` command: a click group with one small module per subcommand."""

from __future__ import annotations

import click

from sr3d_cli import __version__
from sr3d_cli.cli.align import align
from sr3d_cli.cli.config_cmd import config
from sr3d_cli.cli.evaluate import evaluate
from sr3d_cli.cli.grasp import grasp
from sr3d_cli.cli.html_report import report
from sr3d_cli.cli.import_bag import import_bag
from sr3d_cli.cli.reconstruct import reconstruct
from sr3d_cli.cli.repair_depth import repair_depth
from sr3d_cli.cli.segment import segment
from sr3d_cli.cli.synth import synth


class Sr3dGroup(click.Group):
    """The command group; Ctrl-C ends any command with exit code 130 and one line, no
    traceback (files already written are whole: every write is atomic)."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            from sr3d_cli.cli.report import INTERRUPTED, say

            say("interrupted")
            raise SystemExit(INTERRUPTED) from None


@click.group(cls=Sr3dGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="sr3d")
def cli():
    """Repair the depth of transparent and specular objects from one RGB-D frame.

    Every command reads and writes scene folders (see README: "Scene folder").
    Exit codes: 0 all done, 1 some frames failed, 2 usage or configuration error,
    130 interrupted (Ctrl-C).
    """


cli.add_command(synth)
cli.add_command(segment)
cli.add_command(reconstruct)
cli.add_command(align)
cli.add_command(repair_depth)
cli.add_command(grasp)
cli.add_command(evaluate)
cli.add_command(import_bag)
cli.add_command(report)
cli.add_command(config)


def main() -> None:
    cli(prog_name="sr3d")
