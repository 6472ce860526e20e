"""Options shared by every command, defined once and spelled the same everywhere."""

from __future__ import annotations

import functools
import logging
import sys

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
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.handlers[:] = [handler]
    log.setLevel(level)
    log.propagate = False


def common_options(func):
    """``--config``, ``--set``, ``-v``, ``-q``: every command."""

    @click.option("--config", "config_path", type=click.Path(dir_okay=False),
                  help="YAML config (every key: configs/default.yaml).")
    @click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
                  help="Override one config key; repeatable. Flags still win.")
    @click.option("-v", "--verbose", count=True, help="More messages; -v shows tracebacks.")
    @click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr, no progress bar.")
    @functools.wraps(func)
    def wrapper(*args, config_path, sets, verbose, quiet, **kwargs):
        setup_logging(verbose, quiet)
        ctx = click.get_current_context()
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
