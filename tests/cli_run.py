"""Run the droidw CLI in-process for a test: exit code, stdout and stderr."""

from __future__ import annotations

from droidw_cli.cli import main


def run(argv, capsys) -> tuple[int, str, str]:
    try:
        main(argv)
        code = 0
    except SystemExit as exc:
        code = exc.code
    cap = capsys.readouterr()
    return code, cap.out, cap.err
