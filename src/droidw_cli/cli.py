"""The ``droidw`` command line: a thin click group over the subcommands.

Subcommands live in :mod:`droidw_cli.commands` and are imported lazily, so
``droidw --help`` does not pay for importing torch.  A :class:`UserError`
anywhere becomes one line on stderr and exit code 2.
"""

from __future__ import annotations

import importlib
import sys

import click

from droidw_cli import __version__
from droidw_cli.errors import UserError

# name -> (module, attribute, one-line help)
COMMANDS: dict[str, tuple[str, str, str]] = {
    "track": ("droidw_cli.commands.track", "track", "Track a video or image sequence: trajectory, depth, uncertainty."),
    "eval": ("droidw_cli.commands.evaluate", "evaluate", "Evaluate a trajectory against ground truth (ATE / RPE)."),
    "export": ("droidw_cli.commands.export", "export", "Export a run: PLY point clouds, dynamic objects (JSON), uncertainty overlays, a rendered view."),
    "backends": ("droidw_cli.commands.backends", "backends", "List the BA backends and whether they can run here."),
    "demo": ("droidw_cli.commands.demo", "demo", "Generate a synthetic dynamic scene, track it and evaluate it."),
    "synth": ("droidw_cli.commands.synth", "synth", "Generate a synthetic dynamic-scene sequence with exact ground truth."),
    "batch": ("droidw_cli.commands.batch", "batch", "Track and evaluate every sequence of a manifest (Ray for parallel runs)."),
    "view": ("droidw_cli.commands.view", "view", "Show a run in the rerun viewer, or save it as an .rrd file."),
    "map": ("droidw_cli.commands.map", "map_command", "Fit a 3D Gaussian map to a run: static scene, objects over time."),
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [name for name, (mod, _, _) in COMMANDS.items() if importlib.util.find_spec(mod) is not None]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module, attr, _ = COMMANDS[name]
        return getattr(importlib.import_module(module), attr)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][2]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="droidw")
def cli() -> None:
    """droidw: dense SLAM for videos of busy scenes, on an ordinary CPU.

    \b
    Examples:
      droidw demo
      droidw track video.mp4 --calib auto --out run/
      droidw eval --gt groundtruth.txt --est run/
      droidw export ply run/ --out static.ply
      droidw batch manifest.yaml --out runs/ --workers 4
      droidw view run/ --save run.rrd
      droidw map run/ --out map/
    """


def main(argv: list[str] | None = None) -> None:
    """Console entry point: user errors become one line and exit code 2."""
    try:
        cli.main(args=argv, prog_name="droidw", standalone_mode=False)
    except UserError as exc:
        click.echo(f"droidw: error: {exc}", err=True)
        sys.exit(2)
    except OSError as exc:  # a path the system refused: no such folder, no permission, a full disk
        from droidw_cli.io.outputs import describe_os_error

        click.echo(f"droidw: error: {describe_os_error(exc)}", err=True)
        sys.exit(2)
    except click.exceptions.Abort:
        click.echo("droidw: aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        click.echo("droidw: interrupted", err=True)
        sys.exit(130)


if __name__ == "__main__":
    main()
