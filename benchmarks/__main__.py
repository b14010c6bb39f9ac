"""``python -m benchmarks [--list]`` lists the benchmarks with their one-line descriptions;
``python -m benchmarks NAME [ARGS...]`` runs benchmark NAME's ``main(ARGS)`` and exits with
its code; an unknown NAME, or bad input to the benchmark (an lhgraph ``InputError``: an
existing output without ``--force``, a file that is not what it should be), is one line on
stderr and exit code 2."""

from __future__ import annotations

import importlib
import sys

from benchmarks import names, summary

USAGE = "usage: python -m benchmarks [--list] | NAME [ARGS...]  (NAME --help: its options)"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark named by ``argv[0]`` (default ``sys.argv[1:]``), or list them."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("--list", "-l", "-h", "--help"):
        print(USAGE)
        width = max(map(len, names()))
        for name in names():
            print(f"  {name:<{width}}  {summary(name)}")
        return 0
    name, *rest = argv
    if name not in names():
        print(f"python -m benchmarks: unknown benchmark {name!r} (python -m benchmarks --list "
              "names them)", file=sys.stderr)
        return 2
    module = importlib.import_module(f"benchmarks.{name}")
    from lhgraph.errors import InputError  # after the listing, which imports nothing

    try:
        return int(module.main(rest) or 0)
    except InputError as exc:
        print(f"python -m benchmarks {name}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
