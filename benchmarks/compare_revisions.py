"""Two revisions of lhgraph side by side, through the CLI only (the file contract is the one
interface both must share): same answers, and the whole `lhgraph solve` process timed.

    python -m benchmarks compare_revisions --base REV [--head REV] [--runs 5] [--seeds 2]
        [--log IMPORTED_LOG_DIR ...]
        [--output docs/results/compare_revisions.md] [--force]

``--base`` and ``--head`` are git revisions checked out into temporary worktrees; without
``--head`` the working tree itself is the head. Each is run with ``PYTHONPATH`` pointing at
its checkout and its bytecode compiled first, as an install does.

1. Answers: simulated captures of every bundled family (``configs/simulation/*.toml``,
   ``--seeds`` seeds each), written once by the *base* revision's ``lhgraph simulate``, are
   solved by both revisions (with the capture's ``ootx.toml`` when the simulator writes one;
   without it a family with factory calibration is solved with ideal stations, and its error
   against the truth is large by design: this section compares the revisions, not the
   accuracy) as run directories (``lhgraph solve CONFIG --output DIR``, graph
   method); the table compares each station's position and rotation between the two
   solutions, the position error against the truth, the LM iterations and the final error
   (``summary.json``).
2. Run time: ``lhgraph solve --board --angles --output R.toml`` on the 8 s default capture
   (seed 1, as in graph_benchmark.py), the two revisions alternating A B A B after one
   warm-up each, ``--runs`` pairs; wall time and the children's CPU time per run, medians and
   the ratio head/base pair by pair; beside it the bare ``python -c "import numpy, gtsam"``
   process, the floor neither can go below.
3. With ``--log DIR`` (repeatable; an ``lhgraph import`` output folder: board.toml,
   angles.csv, ootx.toml): that log solved alike by both revisions, timed the same way, and
   the largest station position difference between their answers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
import tomllib
from contextlib import ExitStack
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import command, prog

ROOT = Path(__file__).resolve().parents[1]


def worktree(stack: ExitStack, rev: str) -> Path:
    """A detached worktree of ``rev`` in a temporary directory, removed on exit."""
    path = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="lhgraph-rev-"))) / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(path), rev],
                   check=True)
    stack.callback(subprocess.run, ["git", "-C", str(ROOT), "worktree", "remove", "--force",
                                    str(path)], check=False)
    return path


def tree_env(tree: Path) -> dict[str, str]:
    """The environment that makes ``python -m lhgraph`` run ``tree``'s code."""
    return dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")


def lhgraph(tree: Path, *args: str) -> subprocess.CompletedProcess:
    """Run ``python -m lhgraph ARGS`` with ``tree``'s code (started in ``tree``: ``-m`` puts
    the working directory ahead of ``PYTHONPATH``)."""
    return subprocess.run([sys.executable, "-m", "lhgraph", *args], env=tree_env(tree),
                          cwd=tree, check=True, capture_output=True, text=True)


def check_code(tree: Path) -> None:
    """Refuse to compare unless ``python -m lhgraph`` really imports ``tree``'s package."""
    found = subprocess.run([sys.executable, "-c", "import lhgraph; print(lhgraph.__file__)"],
                           env=tree_env(tree), cwd=tree, check=True, capture_output=True,
                           text=True).stdout.strip()
    if not Path(found).resolve().is_relative_to(tree.resolve()):
        raise SystemExit(f"{tree}: python imports lhgraph from {found}, not from this tree")


def timed(cmd: list[str], tree: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one whole process running ``tree``'s code."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    tic = time.perf_counter()
    subprocess.run(cmd, env=tree_env(tree), cwd=tree, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - tic
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def quaternion_angle_deg(qa: list[float], qb: list[float]) -> float:
    """Angle (deg) between two rotations given as unit quaternions (the chord form, exact
    near zero where arccos of the dot product is not)."""
    a, b = np.asarray(qa), np.asarray(qb)
    chord = min(np.linalg.norm(a - b), np.linalg.norm(a + b))
    return float(np.degrees(4.0 * np.arcsin(min(chord / 2.0, 1.0))))


def answers(base: Path, head: Path, work: Path, seeds: int) -> list[str]:
    """Section 1: both revisions on the same captures."""
    rows = ["| capture | dp base-head (mm) | dR (deg) | error base / head (mm) | "
            "iterations base / head | final error base / head |", "|---|---|---|---|---|---|"]
    worst_p = worst_r = 0.0
    same_iter = 0
    n = 0
    # the families both revisions have (a newer config may use keys the base does not know)
    families = sorted({p.stem for p in (base / "configs/simulation").glob("*.toml")}
                      & {p.stem for p in (head / "configs/simulation").glob("*.toml")})
    for family in families:
        for seed in range(1, seeds + 1):
            cap = work / f"{family}-{seed}"
            lhgraph(base, "simulate", str(base / "configs/simulation" / f"{family}.toml"),
                    "--seed", str(seed), "--output", str(cap))
            calibration = 'calibration = "ootx.toml"\n' if (cap / "ootx.toml").exists() else ""
            imu = 'imu = "imu.csv"\n' if (cap / "imu.csv").exists() else ""
            (cap / "solve.toml").write_text(
                'board = "board.toml"\nangles = "angles.csv"\ntruth = "truth.toml"\n'
                f'method = "graph"\n{calibration}{imu}')
            summary = {}
            for name, tree in (("base", base), ("head", head)):
                run = cap / f"run-{name}"
                lhgraph(tree, "solve", str(cap / "solve.toml"), "--output", str(run), "--force",
                        "--quiet")
                summary[name] = json.loads((run / "summary.json").read_text())
            sta = {name: summary[name]["stations"] for name in summary}
            dp = max(np.linalg.norm(np.subtract(sta["base"][k]["position_m"],
                                                sta["head"][k]["position_m"]))
                     for k in sta["base"])
            dr = max(quaternion_angle_deg(sta["base"][k]["quaternion_wxyz"],
                                          sta["head"][k]["quaternion_wxyz"])
                     for k in sta["base"])
            sb, sh = (graph_summary(summary[k]) for k in ("base", "head"))
            worst_p, worst_r = max(worst_p, dp), max(worst_r, dr)
            same_iter += sb["iterations"] == sh["iterations"]
            n += 1
            rows.append(f"| {family}/{seed} | {dp * 1e3:.2e} | {dr:.1e} | "
                        f"{sb['error_mm']:.4f} / {sh['error_mm']:.4f} | "
                        f"{sb['iterations']} / {sh['iterations']} | "
                        f"{sb['final_error']:.6g} / {sh['final_error']:.6g} |")
            print(rows[-1], flush=True)
    return ["## 1. Same answers", "",
            f"{n} simulated captures ({len(families)} families x {seeds} seeds), graph method: "
            f"largest station difference between the revisions {worst_p * 1e3:.2e} mm / "
            f"{worst_r:.1e} deg; same LM iteration count on {same_iter} of {n}.", "", *rows, ""]


def graph_summary(summary: dict) -> dict:
    """Iterations, final error and the largest station position error (mm) from a
    one-method run directory's summary.json (docs/workflow.md)."""
    errors = [e["position_norm_mm"] for e in (summary["errors"] or {}).values()]
    return {"iterations": summary["iterations"], "final_error": summary["final_error"],
            "error_mm": max(errors, default=float("nan"))}


def timing(base: Path, head: Path, work: Path, runs: int, inputs: list[str], title: str
           ) -> list[str]:
    """The whole ``lhgraph solve`` process on ``inputs`` (its ``--board``, ``--angles``, ...
    arguments), base and head alternating."""
    trees = {"base": base, "head": head, "bare": base}
    solve = [sys.executable, "-m", "lhgraph", "solve", *inputs, "--output",
             str(work / "out.toml"), "--force", "--quiet"]
    bare = [sys.executable, "-c", "import numpy, gtsam"]
    for name in ("base", "head"):  # warm-up
        timed(solve, trees[name])
    wall: dict[str, list[float]] = {"base": [], "head": [], "bare": []}
    cpu: dict[str, list[float]] = {"base": [], "head": [], "bare": []}
    for _ in range(runs):
        for name in ("base", "head"):
            w, c = timed(solve, trees[name])
            wall[name].append(w)
            cpu[name].append(c)
        w, c = timed(bare, trees["bare"])
        wall["bare"].append(w)
        cpu["bare"].append(c)
    ratio = np.array(wall["head"]) / np.array(wall["base"])
    cpu_ratio = np.array(cpu["head"]) / np.array(cpu["base"])
    med = {k: float(np.median(v)) for k, v in wall.items()}
    rows = ["| process | wall median (min-max) s | CPU median s |", "|---|---|---|"]
    for name, label in (("base", "base `lhgraph solve`"), ("head", "head `lhgraph solve`"),
                        ("bare", "`python -c \"import numpy, gtsam\"`")):
        rows.append(f"| {label} | {med[name]:.3f} ({min(wall[name]):.3f}-{max(wall[name]):.3f}) "
                    f"| {np.median(cpu[name]):.3f} |")
    return [f"## Whole `lhgraph solve` process, {title}", "",
            f"{runs} pairs after one warm-up each, base and head alternating, bare import "
            "after each pair.", "", *rows, "",
            f"Ratio head / base, pair by pair: wall median {np.median(ratio):.3f} "
            f"(min {ratio.min():.3f}, max {ratio.max():.3f}), CPU median "
            f"{np.median(cpu_ratio):.3f}; above the bare import: "
            f"{(med['head'] - med['bare']) / (med['base'] - med['bare']):.3f}.", ""]


def log_inputs(folder: Path) -> list[str]:
    """The ``lhgraph solve`` inputs of an imported log ``folder`` (``lhgraph import``'s
    board.toml, angles.csv and ootx.toml), as absolute paths (both revisions run in their own
    tree)."""
    folder = folder.resolve()
    inputs = ["--board", str(folder / "board.toml"), "--angles", str(folder / "angles.csv")]
    if (folder / "ootx.toml").is_file():
        inputs += ["--calibration", str(folder / "ootx.toml")]
    return inputs


def same_answer(base: Path, head: Path, work: Path, inputs: list[str]) -> str:
    """One line: the largest station difference between the two revisions' solves of
    ``inputs``."""
    out = {}
    for name, tree in (("base", base), ("head", head)):
        out[name] = work / f"{name}.toml"
        subprocess.run([sys.executable, "-m", "lhgraph", "solve", *inputs, "--output",
                        str(out[name]), "--force", "--quiet"], env=tree_env(tree), cwd=tree,
                       check=True)
    a, b = (tomllib.loads(out[n].read_text())["lighthouses"] for n in ("base", "head"))
    d_mm = max(float(np.max(np.abs(np.subtract(a[k]["position"], b[k]["position"])))) * 1e3
               for k in a)
    return f"largest station position difference head - base: {d_mm:.3g} mm"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="git revision of the reference code")
    parser.add_argument("--head", help="git revision to compare (default: the working tree)")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--output", default=str(ROOT / "docs/results/compare_revisions.md"))
    parser.add_argument("--force", action="store_true")
    parser.add_argument("--log", action="append", default=[], type=Path,
                        help="an imported log folder (lhgraph import's output) to solve and "
                             "time too; repeatable")
    args = parser.parse_args(argv)
    out = Path(args.output)
    if out.exists() and not args.force:
        print(f"{out}: exists (use --force)", file=sys.stderr)
        return 2
    with ExitStack() as stack:
        base = worktree(stack, args.base)
        head = worktree(stack, args.head) if args.head else ROOT
        work = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="lhgraph-ab-")))
        for tree in (base, head):
            check_code(tree)
        rev = {name: subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", r],
                                    capture_output=True, text=True, check=True).stdout.strip()
               for name, r in (("base", args.base), ("head", args.head or "HEAD"))}
        head_label = rev["head"] + ("" if args.head else " + working tree")
        lines = ["# Two revisions side by side", "",
                 f"Command: `{command(__file__, argv)}`  ",
                 f"Base {rev['base']}, head {head_label}; machine: {platform.machine()}, "
                 f"{os.cpu_count()} cores, Python {platform.python_version()}; {date.today()}",
                 ""]
        lines += answers(base, head, work, args.seeds)
        cap = work / "default-8s"
        lhgraph(base, "simulate", "--seed", "1", "--output", str(cap))
        for tree in (base, head):
            subprocess.run([sys.executable, "-m", "compileall", "-q", str(tree / "lhgraph")],
                           check=True)
        lines += timing(base, head, work, args.runs,
                        ["--board", str(cap / "board.toml"), "--angles",
                         str(cap / "angles.csv")], "8 s capture")
        for folder in args.log:
            inputs = log_inputs(folder)
            lines += timing(base, head, work, args.runs, inputs, f"log `{folder.name}`")
            lines += [same_answer(base, head, work, inputs), ""]
    out.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
