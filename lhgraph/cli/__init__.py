"""Command-line interface: thin parsers over the Python API, one module per group of
commands (:mod:`~lhgraph.cli.calibrate`, :mod:`~lhgraph.cli.signal`,
:mod:`~lhgraph.cli.interop`, :mod:`~lhgraph.cli.use`), each registering its commands in
:data:`~lhgraph.cli.common.COMMANDS`. Errors derived from :class:`LhgraphError` become one
line on stderr and their exit code (2 for bad input); nothing else is caught.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from lhgraph.cli import calibrate, interop, signal, use  # noqa: F401  (they register)
from lhgraph.cli.common import COMMANDS
from lhgraph.errors import LhgraphError


def build_parser() -> argparse.ArgumentParser:
    """The ``lhgraph`` argument parser with every registered command."""
    parser = argparse.ArgumentParser(
        prog="lhgraph",
        description="Calibrate Lighthouse v1 base-station poses from a photodiode-board capture.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for _name, add, run in COMMANDS:
        p = add(sub)
        p.set_defaults(_run=run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lhgraph`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except LhgraphError as exc:
        print(f"lhgraph {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"lhgraph {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
