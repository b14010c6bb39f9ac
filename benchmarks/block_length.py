"""The honest covariance's block length on the shared recordings of unmoved stations: how
the time-block sandwich's sigma, and each pair's difference in it, change with the number
of blocks the capture is cut into.

The pairs of `compare_pairs` (Bitcraze's LH2 hand-held log00 / log01 and LH1 hand-held
log02 / flight log00, hive's data8.11 / data8.17; SPEC §5) are imported once and solved by
the default graph method with ``covariance_blocks`` = each of ``--blocks`` (``min_block_s``
0.01 so the count decides), through the Python API. Per pair and count: the blocks' length
in each log, station 1's combined honest sigma (position along the difference, rotation
about its axis) and the difference in those sigmas. Writes docs/results/block_length.md;
pairs whose data is absent are skipped. Data: Crazyflie, hive (no licence: read from
../shared only). ~4 min.
"""

from __future__ import annotations

import argparse
import tempfile
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks.compare_pairs import DATA, PAIRS, ROOT, imported, solve_imported
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.layout_compare import compare_layouts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks block_length",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, nargs="+", default=[600, 240, 120, 60, 30, 12, 6])
    parser.add_argument("--output", type=Path,
                        default=ROOT / "docs" / "results" / "block_length.md")
    args = parser.parse_args(argv)
    lines = ["# Block length of the honest covariance", "",
             "Command: `python -m benchmarks block_length`  ",
             f"Each log solved by the default graph method with `covariance_blocks` = n "
             f"(`min_block_s` 0.01); {date.today()}. Station 1 against the reference; the "
             "difference in combined honest sigmas (position along it / rotation about its "
             "axis); the default is 30 blocks of at least 0.5 s (docs/uncertainty.md).", "",
             "| pair | blocks | block length (s) | sigma (mm / deg) | dp / sigma | dR / sigma |",
             "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="lhgraph-blocks-") as tmp:
        for name, logs in PAIRS.items():
            if not all((DATA / path).exists() for _, path in logs):
                lines.append(f"| {name} | skipped: data absent | | | | |")
                continue
            works = [imported(kind, DATA / path, Path(tmp) / f"{name[:3]}{i}")
                     for i, (kind, path) in enumerate(logs)]
            for n in args.blocks:
                options = GraphOptions.of(covariance_blocks=n, min_block_s=0.01)
                results = [solve_imported(w, options) for w in works]
                d = compare_layouts(*(r.stations for r in results)).differences[0]
                length = " / ".join(f"{r.diagnostics['covariance_block_s']:.2f}" for r in results)
                lines.append(f"| {name} | {n} | {length} | {d.sigma_position_m * 1e3:.2f} / "
                             f"{np.degrees(d.sigma_rotation_rad):.4f} | {d.position_sigmas:.1f} "
                             f"| {d.rotation_sigmas:.1f} |")
                print(lines[-1], flush=True)
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
