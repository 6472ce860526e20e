"""Options shared by every command, defined once and spelled the same everywhere."""

from __future__ import annotations

import functools
import logging
import warnings

import click

from sr3d_cli.config import Config, build_config
from sr3d_cli.errors import ConfigError

log = logging.getLogger("sr3d")


class UsageExit(click.ClickException):
    """A usage or configuration error: one line on stderr, exit code 2."""

    exit_code = 2

    def show(self, file=None):
        click.echo(f"error: {self.format_message()}", err=True)


def setup_logging(verbose: int, quiet: bool) -> None:
    level = logging.ERROR if quiet else (logging.DEBUG if verbose > 1 else
                                         logging.INFO if verbose else logging.WARNING)
    from sr3d_cli.cli.report import TqdmHandler

    handler = TqdmHandler()
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.handlers[:] = [handler]
    log.setLevel(level)
    log.propagate = False
    if not verbose:  # numerical warnings of the core are for -v
        warnings.simplefilter("ignore")


def common_options(func):
    """``--config``, ``--set``, ``-v``, ``-q``, ``--report``: every command."""

    @click.option("--config", "config_path", type=click.Path(dir_okay=False),
                  help="YAML config (every key and its default: sr3d config).")
    @click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
                  help="Override one config key; repeatable. Flags still win.")
    @click.option("-v", "--verbose", count=True, help="More messages; -v shows tracebacks.")
    @click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr, no progress bar.")
    @click.option("--report", "report_path", type=click.Path(dir_okay=False), default=None,
                  help="Also write the closing summary as JSON (counts, each failure's reason).")
    @functools.wraps(func)
    def wrapper(*args, config_path, sets, verbose, quiet, report_path, **kwargs):
        setup_logging(verbose, quiet)
        ctx = click.get_current_context()
        ctx.meta["sr3d.report"] = report_path
        ctx.meta["sr3d.verbose"] = verbose
        ctx.meta["sr3d.quiet"] = quiet
        ctx.meta["sr3d.config"] = (config_path, sets)
        return func(*args, **kwargs)

    return wrapper


def scene_options(func):
    """Options of commands that read scene folders: ``--out``, ``--frames``, ``--format``."""
    options = [
        click.option("--out", type=click.Path(file_okay=False),
                     help="Write outputs here instead of beside the input (for read-only data)."),
        click.option("--frames", help="Frame ids: 000001,000007 or 000001-000009 (default: all)."),
        click.option("--format", "fmt", type=click.Choice(["auto", "native", "cleargrasp", "transcg", "bop"]),
                     default=None, help="Input layout (default: io.format, auto-detected)."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def load_config(flags: dict | None = None) -> Config:
    """Build the config from the current command's --config/--set plus explicit ``flags``."""
    from sr3d_cli.onnx_model import resolve_providers, use_providers

    path, sets = click.get_current_context().meta.get("sr3d.config", (None, ()))
    try:
        cfg = build_config(path, sets, flags)
        if cfg.onnx.providers:  # asked for by name: checked before any frame
            import onnxruntime as ort

            resolve_providers(cfg.onnx.providers, ort.get_available_providers())
    except ConfigError as exc:
        raise UsageExit(str(exc)) from None
    use_providers(cfg.onnx.providers)
    return cfg


def masks_option(func):
    """``--masks segment|gt|DIR``: the instance masks a stage uses (reconstruct.masks)."""
    return click.option(
        "--masks", "masks", metavar="segment|gt|DIR", default=None,
        help="Instance masks: masks/ from segment (default), the ground truth (gt/masks; "
             "ClearGrasp's -mask.png and TransCG's gt masks in place), or a folder of "
             "<frame>.png masks made elsewhere (binary masks split into components).")(func)


def check_masks(cfg: Config) -> None:
    """A usage error where reconstruct.masks is neither segment, gt nor a folder."""
    from pathlib import Path

    which = cfg.reconstruct.masks
    if which not in ("segment", "gt") and not Path(which).is_dir():
        raise UsageExit(f"--masks / reconstruct.masks: {which!r} is neither segment, gt nor "
                        "a folder")
