"""lhgraph's benchmarks and real-data checks, one module each (benchmarks/README.md).

Run one with ``python -m benchmarks NAME [ARGS...]`` from the repository root (so that the
checkout's own ``lhgraph`` is imported); ``python -m benchmarks`` lists them. Every module has
a docstring whose first paragraph says what it measures and a ``main(argv) -> int`` entry
point. Modules whose names start with ``_`` are helpers, not benchmarks. This package imports
only the standard library: listing the benchmarks reads their docstrings without importing
them.
"""

from __future__ import annotations

import argparse
import ast
import shlex
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def names() -> list[str]:
    """The benchmarks' module names (``benchmarks/*.py`` not starting with ``_``), sorted."""
    return sorted(p.stem for p in HERE.glob("*.py") if not p.stem.startswith("_"))


def summary(name: str) -> str:
    """The first paragraph of benchmark ``name``'s docstring on one line, read without
    importing the module ("" without a docstring)."""
    doc = ast.get_docstring(ast.parse((HERE / f"{name}.py").read_text(encoding="utf-8")))
    return " ".join((doc or "").split("\n\n")[0].split())


def prog(path: str) -> str:
    """The command that runs the benchmark in file ``path`` (its ``__file__``): argparse's
    ``prog``."""
    return f"python -m benchmarks {Path(path).stem}"


def command(path: str, argv: list[str] | None) -> str:
    """The whole command line that reruns the benchmark in file ``path`` with ``argv``
    (``None``: this process's ``sys.argv[1:]``), as its results file quotes it."""
    return shlex.join([*prog(path).split(), *(sys.argv[1:] if argv is None else argv)])


def results_parser(path: str, doc: str) -> argparse.ArgumentParser:
    """The parser of the benchmark in file ``path`` (its ``__file__``) with docstring
    ``doc``: ``--output`` (default ``docs/results/<name>.md``) and ``--force`` (replace
    it); add the benchmark's own arguments to it."""
    parser = argparse.ArgumentParser(prog=prog(path),
                                     description=" ".join(doc.split("\n\n")[0].split()))
    parser.add_argument("--output", type=Path,
                        default=HERE.parent / "docs" / "results" / f"{Path(path).stem}.md")
    parser.add_argument("--force", action="store_true", help="replace an existing output")
    return parser


def begin(path: str, doc: str, argv: list[str] | None, title: str,
          parser: argparse.ArgumentParser | None = None
          ) -> tuple[argparse.Namespace, Path, float, list[str]]:
    """Start the benchmark in file ``path`` (its ``__file__``, docstring ``doc``): ``argv``
    parsed by ``parser`` (default: a plain :func:`results_parser`), its ``--output`` checked
    (refused when it exists, unless ``--force``), the clock read; ``(args, output, started,
    lines)`` with the results file's first lines (the ``title`` heading and the command that
    reruns it)."""
    from lhgraph.io.files import check_writable  # only when run: listing imports nothing

    args = (parser or results_parser(path, doc)).parse_args(argv)
    out = check_writable(args.output, args.force)
    return args, out, time.perf_counter(), [f"# {title}", "",
                                             f"Command: `{command(path, argv)}`  "]


def write_results(out: Path, lines: list[str], started: float) -> int:
    """Write a benchmark's markdown ``lines`` to ``out`` with a last line giving the run
    time since ``started`` (a ``time.perf_counter()`` reading), say so; 0 (the exit code)."""
    run = f"Run time: {(time.perf_counter() - started) / 60:.1f} min."
    out.write_text("\n".join([*lines, "", run]) + "\n")
    print(f"wrote {out}")
    return 0
