"""The ``starnav`` command: parse, call the library, print. Exit status 0 solved / done,
1 not solved, 2 bad input (one line on stderr, never a traceback).

One module per command or group of commands, each with ``add_parser(subparsers)`` (which
sets the command's ``run(args) -> int``); the options and output they share are in
``starnav.cli.common``.
"""

from __future__ import annotations

import importlib
import os
import sys

from starnav.cli.parser import EXIT_BAD_INPUT, EXIT_OK, Parser, freeze_at_exit
from starnav.errors import StarnavError

# in the order of ``starnav --help``; imported by ``build_parser``, so that a program that
# needs only ``starnav.cli.common`` (the drop-ins) does not import every command
COMMAND_MODULES = ("identify", "simulate", "demo", "pointing", "evaluate", "locate", "database",
                   "solve", "sky", "render", "calibrate", "serve", "track")  # fmt: skip


def build_parser() -> Parser:
    """The parser of every command."""
    parser = Parser(
        prog="starnav",
        description="Star identification and attitude from star-camera centroids and images. "
        "Exit status: 0 done/solved, 1 not solved, 2 bad input.",
    )
    parser.add_argument(
        "--version", action="version", version=f"%(prog)s {version()}", help="print the version"
    )
    subparsers = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(f"starnav.cli.{name}").add_parser(subparsers)
    return parser


def version() -> str:
    """The installed package's version (``importlib.metadata``), else ``starnav.__version__``
    (the source tree run without installing it)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed("starnav")
    except PackageNotFoundError:
        import starnav

        return starnav.__version__


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``starnav`` command."""
    freeze_at_exit()
    args = build_parser().parse_args(argv)
    args.own_process = argv is None  # the console script: the process is this command's alone
    try:
        return args.run(args)
    except StarnavError as exc:
        print(f"starnav {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        print(f"starnav {args.command}: error: out of memory (input too large)", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # output piped into head & co: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except KeyboardInterrupt:
        return 130


__all__ = ["build_parser", "main", "version"]
