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


class StoreOnce(argparse._StoreAction):
    """argparse's ``store`` action (every option and positional that takes a value) that
    refuses a second value: ``--angles A.csv --angles B.csv`` would solve B alone."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        given = namespace.__dict__.setdefault("_given_once", {})
        if self.dest in given:
            raise argparse.ArgumentError(self, f"given more than once ({given[self.dest]}, "
                                         f"then {values}): give it once")
        given[self.dest] = values
        super().__call__(parser, namespace, values, option_string)


class DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Help with every option's default, ``(default: X)``, unless it has none (None, False)
    or its help already says what it is."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or action.default is False or "default" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    """The parser of ``lhgraph`` and of every (sub-)subcommand (argparse makes subparsers of
    their parent's class): single values stored once (:class:`StoreOnce`), defaults shown
    (:class:`DefaultsFormatter`)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", DefaultsFormatter)
        super().__init__(*args, **kwargs)
        self.register("action", None, StoreOnce)
        self.register("action", "store", StoreOnce)


def mark_inputs(p: argparse.ArgumentParser, *dests: str) -> None:
    """Name the arguments of ``p`` that are input files: no output may be written over them,
    not even with ``--force`` (:func:`lhgraph.io.files.guard_inputs`)."""
    p.set_defaults(_inputs=dests)


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
