"""Options shared by several subcommands."""

from __future__ import annotations

import click

config_option = click.option(
    "--config", "config_name", default="default", show_default=True, metavar="NAME|PATH",
    help="A built-in config (default, tum, rgbd, video, fast) or a YAML file.",
)
set_option = click.option(
    "--set", "overrides", multiple=True, metavar="KEY=VALUE",
    help="Override one config key, e.g. --set frontend.window=30 (repeatable).",
)
