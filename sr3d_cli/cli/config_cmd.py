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
    --set), as YAML that --config reads back: the user-facing keys by section, the tuning
    constants under advanced. NAME narrows it to a section (with its advanced keys), an
    advanced section or one key.

    \b
    Example:
      sr3d config grasp --config my.yaml --set grasp.seeds=120
    """
    from sr3d_cli.config import to_layout

    data = to_layout(load_config())
    if name:
        data = _narrowed(data, name)
    click.echo(yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False),
               nl=False)


def _narrowed(layout: dict, name: str) -> dict:
    """The part of ``layout`` that ``name`` names: ``section``, ``section.key``,
    ``advanced[.section[.key]]``; each key where the layout holds it."""
    from sr3d_cli.config import ADVANCED_SECTION, is_advanced

    advanced = layout[ADVANCED_SECTION]
    section, _, key = name.partition(".")
    if section == ADVANCED_SECTION:
        inner, _, key = key.partition(".")
        if not inner:
            return {section: advanced}
        if inner in advanced and (not key or key in advanced[inner]):
            return {section: {inner: {key: advanced[inner][key]} if key else advanced[inner]}}
    elif key and is_advanced(section, key):
        return {ADVANCED_SECTION: {section: {key: advanced[section][key]}}}
    elif key and key in layout.get(section, {}):
        return {section: {key: layout[section][key]}}
    elif not key and (section in layout or section in advanced):
        parts = {section: layout[section]} if section in layout else {}
        if section in advanced:
            parts[ADVANCED_SECTION] = {section: advanced[section]}
        return parts
    raise UsageExit(f"unknown config {'key' if key else 'section'} '{name}'")
