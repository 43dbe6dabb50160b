"""``python -m droidw_cli``: the same as the ``droidw`` command."""

from droidw_cli.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
