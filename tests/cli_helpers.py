"""Running ``starnav`` commands in-process from tests."""

from __future__ import annotations

from starnav.cli import main


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    """``starnav ARGV...`` in this process: (exit code, stdout, stderr), argparse's own usage
    errors (SystemExit) included."""
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err
