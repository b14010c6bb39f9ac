"""What every command module shares: the registry of commands and the common output flags.

Each command is a pair ``add_<name>(subparsers)`` / ``run_<name>(args) -> int`` registered in
:data:`COMMANDS` by its module (the order of the modules' imports in :mod:`lhgraph.cli` is the
order of ``lhgraph --help``).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from lhgraph.report.assessment import Verdict

Runner = Callable[[argparse.Namespace], int]
Adder = Callable[[argparse._SubParsersAction], argparse.ArgumentParser]

COMMANDS: list[tuple[str, Adder, Runner]] = []


def at_least(low: float, kind: type = float, strict: bool = False
             ) -> Callable[[str], float]:
    """An argparse ``type``: a finite ``kind`` (int or float) of at least ``low`` (above it
    when ``strict``), else argparse's one-line error (exit 2)."""
    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            what = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not math.isfinite(value) or value < low or (strict and value == low):
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {low:g}, "
                                             f"got {text}")
        return value

    return parse


def add_common_output(p: argparse.ArgumentParser) -> None:
    """``--force`` and ``--quiet``, the flags of every command that writes files."""
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def add_verbose(p: argparse.ArgumentParser) -> None:
    """``--verbose``: the solver's own detail in the progress lines."""
    p.add_argument("--verbose", action="store_true",
                   help="progress with the solver's detail (errors, prior statistics)")


def progress_printer(args: argparse.Namespace) -> Callable[[str], None] | None:
    """Progress lines to stderr in a user's words (:class:`~lhgraph.report.progress.
    PlainProgress`); None with ``--quiet``."""
    if args.quiet:
        return None
    from lhgraph.report.progress import PlainProgress

    return PlainProgress(lambda msg: print(f"  {msg}", file=sys.stderr),
                         getattr(args, "verbose", False))


def print_verdict(args: argparse.Namespace, verdict: Verdict, label: str = "") -> None:
    """The verdict line (``verdict: OK``, ``verdict: check: ...``, ``verdict: FAILED: ...``)
    on stdout; with ``--quiet`` only a failed one, on stderr."""
    line = f"verdict{' ' + label if label else ''}: {verdict.text()}"
    if not args.quiet:
        print(line)
    elif verdict.failed:
        print(f"lhgraph {args.command}: {line}", file=sys.stderr)


def verdict_exit(verdicts: Iterable[Verdict]) -> int:
    """The exit code of a command that ends with verdicts: 3 (the code of
    :class:`~lhgraph.errors.SolverError`) when any failed, else 0 (docs/cli.md)."""
    from lhgraph.errors import SolverError

    return SolverError.exit_code if any(v.failed for v in verdicts) else 0
