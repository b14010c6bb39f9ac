"""Station geometries judged on the real Crazyflie LH1 log: issue #14's measure (b), and (a).

(b) The log's own ``correctedAngle`` (the deck firmware's factory-corrected angles) turned
into crossing-beam positions through a stations TOML, as the Crazyflie computes on board
with an uploaded geometry: at every moment (station 0's fresh pairs), each station's
azimuth and elevation of each diode are interpolated linearly in time (neighbours within
``--max-gap`` on both sides), the two rays of a diode are intersected (midpoint of the
shortest segment) and the diodes seen by both stations are averaged. Positions are compared
with the Qualisys marker body as the dataset's authors do: mocap on the written clock by the
marker on/off events (``mocap.csv`` of ``lhgraph import crazyflie``), then a search of
+-100 ms at both ends (offset and clock rate) for the smallest rigid-fit (Kabsch) residual;
percentiles of the position error after the best rigid fit.

(a) ``--track NAME=T.csv``: a trajectory CSV (``lhgraph track`` output with the same
stations TOML, its ``ootx.toml`` and ``crazyflie_deck``) evaluated the same way (positions
only), over every pose and again over the poses at moments (b) could use (every station
seen within ``--max-gap`` on both sides: where one station alone sees the deck, the
tracking error dominates whatever the geometry), and over those where every diode's two
sweeps from every station are that near (the deck fully seen: the position no longer rests
on the 4-diode pattern's size or on the motion prior). Tracking takes minutes, so it is run
beforehand and passed in, e.g.

    lhgraph track --stations DIR/stations-cfclient.toml --angles DIR/angles.csv \
        --board crazyflie_deck --calibration DIR/ootx.toml --output DIR/track-cfclient.csv

    python -m benchmarks crazyflie_evaluation [--log lh1|lh2] [--mocap NPY | --import-dir DIR] \
        [--stations NAME=FILE ...] [--track NAME=T.csv ...] [--write-docs | --output FILE]

Default: imports the shared log (with the ``mocapNN.npy`` beside it, or ``--mocap``) into a
temporary directory, evaluates ``stations-cfclient.toml`` and prints the table;
``--write-docs`` also writes it to docs/results/crazyflie_evaluation[_lh2].md, ``--output``
to another file.

A mocap of another recording is refused (one line naming the file, exit code 2), by two
checks: the importer's clock rate (log seconds per mocap second, from the mocap's first and
last rows against the log's marker events) must be within 1 +- ``MAX_RATE_ERROR`` (every
shared log with its own mocap: 1.0000 on the deck's clock; with the mocap of a recording of
another length: 0.49 or 1.98), and, the check that also catches another recording of the
same length and the one an ``--import-dir`` allows, at least one geometry's positions must
follow the mocap: rms error after the best rigid fit and time search at most
``MAX_ALIGNED_RMS_M`` (the shared logs with their own mocap: 19-36 mm; with another
recording's: over 1 m).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import prog
from lhgraph.errors import InputError, LhgraphError
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import transform_points
from lhgraph.importers.crazyflie import import_crazyflie
from lhgraph.importers.crazyflie.convert import default_mocap_path
from lhgraph.io.angles import Angles, load_angles
from lhgraph.io.files import read_csv_columns
from lhgraph.io.stations import Stations, load_stations
from lhgraph.io.trajectory import load_trajectory
from lhgraph.model import lh1, lh2

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "bitcraze-positioning"
LOGS = {"lh1": DATA / "lh1_crossingBeam_move" / "log02",
        "lh2": DATA / "lh2_crossingBeam_move" / "log00"}
SEARCH_S = 0.1
MAX_RATE_ERROR = 0.05
MAX_ALIGNED_RMS_M = 0.25
PERCENTILES = (25, 50, 75, 90, 95)


def ray_directions(a0: np.ndarray, a1: np.ndarray, generation: int = 1) -> np.ndarray:
    """Unit directions (station frame) of a station's ideal angle pairs (LH1: azimuth and
    elevation; LH2: the two planes' angles)."""
    d = (lh2 if generation == 2 else lh1).direction(a0, a1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def crossing_points(o0: np.ndarray, d0: np.ndarray, o1: np.ndarray, d1: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Midpoints of the shortest segments between rays ``o + s d`` (world), and the segment
    lengths (m): the crossing beams."""
    w = o0 - o1
    b = np.sum(d0 * d1, -1)
    dd, e = np.sum(d0 * w, -1), np.sum(d1 * w, -1)
    den = 1.0 - b * b
    s, u = (b * e - dd) / den, (e - b * dd) / den
    p0, p1 = o0 + s[..., None] * d0, o1 + u[..., None] * d1
    return (p0 + p1) / 2, np.linalg.norm(p0 - p1, axis=-1)


def interpolated(angles: Angles, station: int, axis: int, sensor: int, moments: np.ndarray,
                 max_gap_s: float) -> np.ndarray:
    """``corrected_angle`` of one series at ``moments`` (NaN without neighbours within
    ``max_gap_s`` on both sides)."""
    s = (angles.lighthouse == station) & (angles.axis == axis) & (angles.sensor == sensor)
    t, v = angles.time[s], angles.extra["corrected_angle"][s]
    out = np.full(len(moments), np.nan)
    if len(t) < 2:
        return out
    i = np.clip(np.searchsorted(t, moments), 1, len(t) - 1)
    ok = (moments >= t[i - 1]) & (moments <= t[i]) & (moments - t[i - 1] <= max_gap_s) \
        & (t[i] - moments <= max_gap_s)
    out[ok] = np.interp(moments[ok], t, v)
    return out


def crossing_beam_positions(angles: Angles, stations: Stations, max_gap_s: float = 0.05,
                            stations_pair: tuple[int, int] = (0, 1)
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Deck positions (world of ``stations``) at station ``pair[0]``'s fresh axis-1 hits:
    ``(time, position (N, 3))``, moments without a diode seen by both stations left out."""
    a, b = stations_pair
    moments = np.unique(angles.time[(angles.lighthouse == a) & (angles.axis == 1)])
    points = []
    for k in np.unique(angles.sensor):
        rays = []
        for st in (a, b):
            az = interpolated(angles, st, 0, k, moments, max_gap_s)
            el = interpolated(angles, st, 1, k, moments, max_gap_s)
            T = stations.pose(st)
            generation = stations.stations[st].model.generation
            rays.append((np.broadcast_to(T[:3, 3], (len(moments), 3)),
                         ray_directions(az, el, generation) @ T[:3, :3].T))
        p, _ = crossing_points(*rays[0], *rays[1])
        points.append(p)
    stack = np.stack(points)
    seen = np.all(np.isfinite(stack), axis=2)
    P = np.where(seen[..., None], stack, 0.0).sum(axis=0) / np.maximum(seen.sum(0), 1)[:, None]
    ok = seen.any(axis=0)
    return moments[ok], P[ok]


def seen_by_all(angles: Angles, t: np.ndarray, max_gap_s: float, every_diode: bool = False
                ) -> np.ndarray:
    """Whether every station (``every_diode``: every sweep of every diode of every station) has
    a hit within ``max_gap_s`` before and after each of ``t`` (the moments measure (b) can
    use; with ``every_diode``, those where each diode's two rays can be crossed)."""
    columns = (angles.lighthouse, angles.axis, angles.sensor) if every_diode \
        else (angles.lighthouse,)
    keys, series = np.unique(np.stack(columns, axis=1), axis=0, return_inverse=True)
    ok = np.ones(len(t), dtype=bool)
    for j in range(len(keys)):
        ts = np.unique(angles.time[series.ravel() == j])
        if len(ts) < 2:
            return np.zeros(len(t), dtype=bool)
        i = np.clip(np.searchsorted(ts, t), 1, len(ts) - 1)
        ok &= (t >= ts[0]) & (t <= ts[-1]) & (t - ts[i - 1] <= max_gap_s) \
            & (ts[i] - t <= max_gap_s)
    return ok


def _mocap_at(t_m: np.ndarray, p_m: np.ndarray, t: np.ndarray, max_gap_s: float = 0.02
              ) -> np.ndarray:
    i = np.clip(np.searchsorted(t_m, t), 1, len(t_m) - 1)
    ok = (t >= t_m[i - 1]) & (t <= t_m[i]) & (t_m[i] - t_m[i - 1] <= max_gap_s)
    out = np.full((len(t), 3), np.nan)
    out[ok] = np.stack([np.interp(t[ok], t_m, p_m[:, j]) for j in range(3)], axis=1)
    return out


def aligned_errors(t: np.ndarray, p: np.ndarray, t_m: np.ndarray, p_m: np.ndarray,
                   step_s: float = 0.005) -> tuple[np.ndarray, float, float]:
    """Position errors (m) after the best rigid fit over a +-100 ms search of the mocap's
    start and end offsets (coarse ``step_s`` grid, then 1 ms around the best); also the
    offsets (s) at the start and end."""
    t0, t1 = t_m[0], t_m[-1]

    def residual(d0: float, d1: float) -> tuple[float, np.ndarray]:
        shifted = t_m + d0 + (d1 - d0) * (t_m - t0) / (t1 - t0)
        q = _mocap_at(shifted, p_m, t)
        ok = np.all(np.isfinite(q), axis=1)
        T = weighted_kabsch(p[ok], q[ok])
        e = np.full(len(t), np.nan)
        e[ok] = np.linalg.norm(transform_points(T, p[ok]) - q[ok], axis=1)
        return float(np.sqrt(np.nanmean(e**2))), e

    best = (np.inf, 0.0, 0.0)
    for grid in (np.arange(-SEARCH_S, SEARCH_S + 1e-9, step_s), None):
        if grid is None:
            c0, c1 = best[1], best[2]
            g0 = np.arange(c0 - step_s, c0 + step_s + 1e-9, 0.001)
            g1 = np.arange(c1 - step_s, c1 + step_s + 1e-9, 0.001)
        else:
            g0 = g1 = grid
        for d0 in g0:
            for d1 in g1:
                r, _ = residual(d0, d1)
                if r < best[0]:
                    best = (r, float(d0), float(d1))
    _, e = residual(best[1], best[2])
    return e[np.isfinite(e)], best[1], best[2]


def check_clock_rate(rate: float, source: str | Path) -> None:
    """Refuse (InputError naming ``source``) a mocap whose clock rate on the log (log seconds
    per mocap second) is outside 1 +- ``MAX_RATE_ERROR``: not this recording's."""
    if not abs(rate - 1.0) <= MAX_RATE_ERROR:
        raise InputError(f"clock rate {rate:.4f} log s per mocap s, outside 1 +- "
                         f"{MAX_RATE_ERROR:g}: the mocap of another recording?", source)


def check_alignment(rms_m: list[float], source: str | Path) -> None:
    """Refuse (InputError naming ``source``) a mocap that no geometry's positions follow: the
    rms errors (m) after the best rigid fit and time search all above ``MAX_ALIGNED_RMS_M``."""
    if rms_m and not min(rms_m) <= MAX_ALIGNED_RMS_M:
        raise InputError(f"the positions do not follow the mocap: {min(rms_m) * 1e3:.0f} mm rms "
                         f"after the best fit (at most {MAX_ALIGNED_RMS_M * 1e3:.0f} mm "
                         "expected): the mocap of another recording, or every geometry wrong?",
                         source)


def row(name: str, e: np.ndarray, d0: float, d1: float, n: int) -> str:
    pct = np.percentile(e * 1e3, PERCENTILES)
    return (f"| {name} | {n} | " + " | ".join(f"{x:.1f}" for x in pct)
            + f" | {np.sqrt(np.mean(e**2)) * 1e3:.1f} | {d0 * 1e3:+.0f} / {d1 * 1e3:+.0f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.splitlines()[0])
    source = ap.add_mutually_exclusive_group()
    source.add_argument("--import-dir", type=Path, help="output of lhgraph import crazyflie")
    source.add_argument("--mocap", type=Path,
                        help="Qualisys mocapNN.npy for the shared log (default: beside it)")
    ap.add_argument("--log", choices=sorted(LOGS), default="lh1",
                    help="the shared log imported without --import-dir (default lh1)")
    ap.add_argument("--stations", nargs="*", default=[], help="NAME=stations.toml")
    ap.add_argument("--track", nargs="*", default=[], help="NAME=trajectory.csv (measure a)")
    ap.add_argument("--max-gap", type=float, default=0.05, help="interpolation gap (s)")
    destination = ap.add_mutually_exclusive_group()
    destination.add_argument("--write-docs", action="store_true",
                             help="also write docs/results/crazyflie_evaluation.md "
                             "(lh2: _lh2.md)")
    destination.add_argument("--output", type=Path, help="also write the table to this file")
    args = ap.parse_args(argv)
    suffix = "" if args.log == "lh1" else f"_{args.log}"
    if args.write_docs:
        args.output = ROOT / f"docs/results/crazyflie_evaluation{suffix}.md"
    try:
        return evaluate(args)
    except LhgraphError as exc:
        print(f"{prog(__file__)}: {exc}", file=sys.stderr)
        return exc.exit_code


def evaluate(args: argparse.Namespace) -> int:
    """The evaluation of ``main``'s arguments: print the table (and write it to
    ``args.output`` when set); InputError for a mocap of another recording."""
    start = time.perf_counter()
    tmp = None
    if args.import_dir is None:
        tmp = tempfile.TemporaryDirectory()
        args.import_dir = Path(tmp.name)
        log = LOGS[args.log]
        imported = import_crazyflie(log, args.import_dir, log.with_name("system-config.yaml"),
                                    mocap=args.mocap)
        if imported.mocap is not None:
            check_clock_rate(imported.mocap.rate, args.mocap or default_mocap_path(log))
    angles = load_angles(args.import_dir / "angles.csv")
    mocap = read_csv_columns(args.import_dir / "mocap.csv",
                             [("time", float), ("x", float), ("y", float), ("z", float)])
    t_m = mocap["time"]
    p_m = np.stack([mocap["x"], mocap["y"], mocap["z"]], axis=1)
    geometries = dict(s.split("=", 1) for s in args.stations) or {
        "cfclient": str(args.import_dir / "stations-cfclient.toml")}
    lines = [f"# Crazyflie {args.log.upper()} log: station geometries against Qualisys", "",
             "`python -m benchmarks crazyflie_evaluation` (docs/crazyflie.md). Position error "
             "(mm) after the best rigid fit to the mocap, offsets searched +-100 ms at both "
             "ends (start / end offset in the last column, ms).", "",
             "## (b) the log's correctedAngle as crossing-beam positions", "",
             "| geometry | moments | " + " | ".join(f"p{p}" for p in PERCENTILES)
             + " | rms | offsets |", "|---" * (len(PERCENTILES) + 4) + "|"]
    rms_m = []
    for name, path in geometries.items():
        t, p = crossing_beam_positions(angles, load_stations(path), args.max_gap)
        e, d0, d1 = aligned_errors(t, p, t_m, p_m)
        lines.append(row(name, e, d0, d1, len(e)))
        rms_m.append(float(np.sqrt(np.mean(e**2))))
    check_alignment(rms_m, args.import_dir / "mocap.csv")
    lines += ["", "## (a) tracked positions (`lhgraph track`)", ""]
    if args.track:
        lines += ["| track | poses | " + " | ".join(f"p{p}" for p in PERCENTILES)
                  + " | rms | offsets |", "|---" * (len(PERCENTILES) + 4) + "|"]
        tracks = [(name, load_trajectory(path)) for name, path in
                  (s.split("=", 1) for s in args.track)]
        for name, tr in tracks:
            e, d0, d1 = aligned_errors(tr.time, tr.T_world_board[:, :3, 3], t_m, p_m)
            lines.append(row(name, e, d0, d1, len(e)))
        gap = f"{args.max_gap * 1e3:.0f} ms"
        for every_diode, moments in ((False, f"both stations within {gap}"),
                                     (True, f"every diode's two sweeps from both stations "
                                            f"within {gap}")):
            for name, tr in tracks:  # the poses at moments (b) could use
                sel = seen_by_all(angles, tr.time, args.max_gap, every_diode)
                e, d0, d1 = aligned_errors(tr.time[sel], tr.T_world_board[sel, :3, 3], t_m,
                                           p_m)
                lines.append(row(f"{name}, {moments}", e, d0, d1, len(e)))
    else:
        lines.append("Not measured: no `--track` trajectory given.")
    lines += ["", f"Run time: {time.perf_counter() - start:.1f} s.", ""]
    if args.output is not None:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text("\n".join(lines))
    print("\n".join(lines))
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
