"""``sr3d config``: print the effective configuration as YAML."""

from __future__ import annotations

import click
import yaml

from sr3d_cli.cli.options import UsageExit, common_options, load_config


class _Dumper(yaml.SafeDumper):
    """Sections and keys one per line; lists on one line, as configs/default.yaml writes them."""


_Dumper.add_representer(list, lambda dumper, data: dumper.represent_sequence(
    "tag:yaml.org,2002:seq", data, flow_style=True))


@click.command("config")
@click.argument("name", required=False)
@common_options
def config(name):
    """Print the configuration a command would run with (built-in defaults < --config FILE <
    --set), as YAML that --config reads back. NAME narrows it to one section or key.

    \b
    Example:
      sr3d config grasp --config my.yaml --set grasp.seeds=120
    """
    from sr3d_cli.config import to_dict

    data = to_dict(load_config())
    if name:
        section, _, key = name.partition(".")
        if section not in data or (key and key not in data[section]):
            raise UsageExit(f"unknown config {'key' if key else 'section'} '{name}'")
        data = {section: {key: data[section][key]} if key else data[section]}
    click.echo(yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False),
               nl=False)
