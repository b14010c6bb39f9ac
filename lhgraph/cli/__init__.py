"""Command-line interface: thin parsers over the Python API, one module per group of
commands (:mod:`~lhgraph.cli.calibrate`, :mod:`~lhgraph.cli.signal`,
:mod:`~lhgraph.cli.interop`, :mod:`~lhgraph.cli.use`), each registering its commands in
:data:`~lhgraph.cli.common.COMMANDS`. Errors derived from :class:`LhgraphError` become one
line on stderr and their exit code (2 for bad input); nothing else is caught. Every parser
is a :class:`~lhgraph.cli.common.Parser` (single values given once, defaults in the help);
while a command runs, its input files (:func:`~lhgraph.cli.common.mark_inputs`) are guarded
against being written over and each output folder it creates is announced.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from lhgraph.cli import calibrate, interop, signal, use  # noqa: F401  (they register)
from lhgraph.cli.common import COMMANDS, Parser
from lhgraph.errors import LhgraphError


class _Version(argparse.Action):
    """``--version``: the installed package's version (read only when asked)."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: object):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help=str(kwargs.get("help")))

    def __call__(self, parser: argparse.ArgumentParser, *_args: object) -> None:
        print(f"lhgraph {version()}")
        parser.exit()


def version() -> str:
    """The installed distribution's version (``lhgraph.__version__``, kept equal by
    tests/test_solve_cli.py)."""
    import importlib.metadata

    try:
        return importlib.metadata.version("lhgraph")
    except importlib.metadata.PackageNotFoundError:
        return "unknown (not installed: pip install -e .)"


def build_parser() -> argparse.ArgumentParser:
    """The ``lhgraph`` argument parser with every registered command."""
    parser = Parser(
        prog="lhgraph",
        description="Calibrate Lighthouse base-station poses (LH1 or LH2) from a receiver's "
        "capture.",
    )
    parser.add_argument("--version", action=_Version, help="print the version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for _name, add, run in COMMANDS:
        p = add(sub)
        p.set_defaults(_run=run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lhgraph`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from lhgraph.io.files import guard_inputs

    def created(folder: object) -> None:
        if not getattr(args, "quiet", False):
            print(f"lhgraph {args.command}: created output folder {folder}", file=sys.stderr)

    inputs = []
    for dest in getattr(args, "_inputs", ()):
        value = getattr(args, dest, None)
        inputs += value if isinstance(value, list) else [value]
    try:
        with guard_inputs(inputs, created):
            return int(args._run(args) or 0)
    except LhgraphError as exc:
        print(f"lhgraph {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # a file the readers and writers did not anticipate failing
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"lhgraph {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"lhgraph {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
