"""What the spread of station 1 over 8 s slices of the hive recording is not: time shifts of
station 1's hits, motion-prior settings and per-diode angle biases, each against the
whole-bag solve.

    python -m benchmarks hive_slice_spread [--bag PATH] [--output FILE.md] [--force]

Imports ``data8.11.bag`` (read from ../shared, never copied; sync-bit offsets corrected)
into a temporary folder, then for each variant solves the whole bag and three 8 s slices
4 s apart from the motion start (gib -1, curve +1, as ``hive_evaluation.py`` picks) and
reports station 1's position difference per slice (in station 1's own frame: x along its
line of sight), their spread about the slices' own mean, the slices' reported 1-sigma, and
the whole-bag residual rms; then, from the default whole-bag solve, how much of the residual
repeats at each diode (per station and axis: the rms of the diodes' mean residuals against
their spread about it). Writes the
markdown to ``--output`` (default docs/results/hive_slice_spread.md) and prints it.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import prog
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.rests import rest_spans
from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.geometry.transforms import se3_log
from lhgraph.importers.hive import import_hive
from lhgraph.io.angles import Angles, load_angles
from lhgraph.io.files import check_writable
from lhgraph.io.trajectory import Trajectory, load_trajectory
from lhgraph.model.board import Board, load_board, with_sensor_offsets
from lhgraph.model.station import Convention
from lhgraph.workflow.inputs import station_models
from lhgraph.workflow.solve_config import SENSOR_OFFSET_SIGMA_M
from lhgraph.workflow.window import motion_start

REPO = Path(__file__).resolve().parents[1]
BAG = REPO.parent / "shared/data/hive-env8/data8.11.bag"
REST_KEEP_EVERY = 10
ONE_WINDOW = 100
VARIANTS: dict[str, tuple[float, GraphOptions]] = {
    "default": (0.0, GraphOptions()),
    "station 1 hits +2 ms": (2e-3, GraphOptions()),
    "station 1 hits +4 ms": (4e-3, GraphOptions()),
    "station 1 hits -2 ms": (-2e-3, GraphOptions()),
    "motion-prior floor 0.02": (0.0, GraphOptions.of(min_psd_factor=0.02)),
    "fixed prior 3 m^2/s^3, 30 rad^2/s^3": (0.0, GraphOptions.of(
        adapt_motion_prior=False, accel_psd_pos=3.0, accel_psd_rot=30.0)),
    "diode biases, prior 20 µrad": (0.0, GraphOptions.of(diode_bias_sigma_rad=2e-5)),
    "diode biases, prior 50 µrad": (0.0, GraphOptions.of(diode_bias_sigma_rad=5e-5)),
}


def shifted(angles: Angles, station: int, shift_s: float) -> Angles:
    """``angles`` with ``station``'s hits ``shift_s`` later, rows in time order."""
    t = angles.time + shift_s * (angles.lighthouse == station)
    order = np.argsort(t, kind="stable")
    out = angles.select(order)
    out.time = t[order]
    return out


def diode_means(res: Residuals, min_hits: int = 50) -> list[tuple[int, int, int, float, float]]:
    """Per (station, axis): the diodes with ``min_hits`` inlier residuals, the rms over them of
    their mean residual and the median of their standard deviation (µrad)."""
    ok = res.weight > 0.5
    rows = []
    for station in np.unique(res.lighthouse).tolist():
        for axis in (0, 1):
            means, spreads = [], []
            for sensor in np.unique(res.sensor).tolist():
                r = res.residual_rad[ok & (res.lighthouse == station) & (res.axis == axis)
                                     & (res.sensor == sensor)]
                if len(r) >= min_hits:
                    means.append(r.mean())
                    spreads.append(r.std())
            rows.append((station, axis, len(means), float(np.sqrt(np.mean(np.square(means))))
                         * 1e6, float(np.median(spreads)) * 1e6))
    return rows


def in_slice(angles: Angles, t0: float, k: int) -> np.ndarray:
    """Rows of ``angles`` in the k-th 8 s slice (4 s apart from ``t0``)."""
    return (angles.time >= t0 + 4 * k) & (angles.time < t0 + 4 * k + 8)


def difference(L_ref: np.ndarray, L: np.ndarray) -> tuple[np.ndarray, float]:
    """Station pose ``L`` less ``L_ref``: position in ``L_ref``'s frame (mm) and rotation (deg)."""
    D = np.linalg.inv(L_ref) @ L
    return D[:3, 3] * 1e3, float(np.degrees(np.linalg.norm(se3_log(D)[:3])))


def spread_cells(d: np.ndarray) -> tuple[str, str, str]:
    """Table cells of slice differences ``d`` (n, 3) mm: the triplets, the rms of their
    lengths, and the rms of their lengths about the slices' own mean."""
    return ("; ".join(f"({x:+.1f}, {y:+.1f}, {z:+.1f})" for x, y, z in d),
            f"{np.sqrt(np.mean(np.sum(d**2, axis=1))):.2f}",
            f"{np.sqrt(np.mean(np.sum((d - d.mean(axis=0))**2, axis=1))):.2f}")


def slice_differences(board: Board, data: Angles, models: dict, options: GraphOptions,
                      reference: SolveResult, t0: float) -> tuple[np.ndarray, float, float]:
    """Station 1 from the three 8 s slices of ``data`` (4 s apart from ``t0``) less its pose
    in ``reference``, in station 1's frame (mm, (3, 3)); the slices' median position 1-sigma
    (mm, largest axis) and the rms of their rotation differences (deg)."""
    diffs, sigmas, turns = [], [], []
    for k in range(3):
        r = solve_graph(board, data.select(in_slice(data, t0, k)), models, options)
        position_mm, turn_deg = difference(reference.stations.pose(1), r.stations.pose(1))
        diffs.append(position_mm)
        turns.append(turn_deg)
        sigmas.append(np.sqrt(np.max(np.diag(r.stations.stations[1].covariance)[3:])) * 1e3)
    return np.array(diffs), float(np.median(sigmas)), float(np.sqrt(np.mean(np.square(turns))))


def tracker_geometry(board: Board, angles: Angles, models: dict, t0: float) -> list[str]:
    """The tracker's sensor positions solved on the whole bag (``sensor_offset_sigma_m``, as
    ``lhgraph solve --board-output``), then the slices solved with that board by default,
    against the whole bag, the whole bag with its rests thinned and the moving span (the
    slices' union) solved alike."""
    lines = ["", "## The tracker's sensor positions solved on the whole bag", "",
             "The whole bag solved with the sensor offsets on (prior "
             f"{SENSOR_OFFSET_SIGMA_M * 1e3:g} mm, what `lhgraph solve --board-output` does), "
             "the board file corrected by them, and every solve of the table below run with "
             "the default options on the corrected board (or on the file's, for comparison). "
             "Reference: the whole bag, the whole bag with its rests thinned "
             f"(`rest_keep_every = {REST_KEEP_EVERY}`: one 0.1 s window in {REST_KEEP_EVERY} "
             "of the rests at both ends, lhgraph.estimation.rests; the slices hold no rest), "
             "or the moving span from the motion start to the last slice's end (the slices' "
             "union, without the rests).", ""]
    cal = solve_graph(board, angles, models, GraphOptions.of(
        sensor_offset_sigma_m=SENSOR_OFFSET_SIGMA_M))
    offsets_mm = np.linalg.norm(cal.sensor_offset_m, axis=1) * 1e3
    lines += [f"Sensor offsets found: rms {np.sqrt(np.mean(offsets_mm**2)):.2f} mm, largest "
              f"{offsets_mm.max():.2f} mm; whole-bag residual rms {cal.residuals.rms_urad():.1f}"
              " µrad with them.", "",
              "| board | reference | reference rms µrad | slice differences (x, y, z) mm | "
              "rms of the slice distances mm | rms rotation difference deg | slices about "
              "their mean mm |", "|---|---|---|---|---|---|---|"]
    moving = angles.select((angles.time >= t0) & (angles.time < t0 + 16))
    for name, b in (("file", board), ("solved on the whole bag",
                                      with_sensor_offsets(board, cal.sensor_offset_m))):
        for ref_name, data, options in (
                ("whole bag", angles, GraphOptions()),
                (f"whole bag, rests thinned (1 in {REST_KEEP_EVERY})", angles,
                 GraphOptions.of(rest_keep_every=REST_KEEP_EVERY)),
                ("moving span", moving, GraphOptions())):
            ref = solve_graph(b, data, models, options)
            d, _, turn = slice_differences(b, angles, models, options, ref, t0)
            triplets, rms, about_mean = spread_cells(d)
            lines.append(f"| {name} | {ref_name} | {ref.residuals.rms_urad():.1f} | {triplets} "
                         f"| {rms} | {turn:.3f} | {about_mean} |")
            print(lines[-1], flush=True)
    lines += held_out_boards(board, angles, models, t0)
    return lines


def held_out_board(board: Board, angles: Angles, models: dict, inside: np.ndarray,
                   rest_keep_every: int = 1) -> Board:
    """``board`` with its sensor positions solved (``SENSOR_OFFSET_SIGMA_M``) on the hits of
    ``angles`` outside the mask ``inside``, their rests thinned 1 in ``rest_keep_every``."""
    cal = solve_graph(board, angles.select(~inside), models,
                      GraphOptions.of(sensor_offset_sigma_m=SENSOR_OFFSET_SIGMA_M,
                                   rest_keep_every=rest_keep_every))
    return with_sensor_offsets(board, cal.sensor_offset_m)


def against_whole(board: Board, angles: Angles, models: dict, inside: np.ndarray,
                  rest_keep_every: int) -> tuple[np.ndarray, float]:
    """Station 1 solved from the hits ``inside`` less station 1 from all of ``angles`` (both
    with ``board``, rests thinned 1 in ``rest_keep_every``): :func:`difference`."""
    options = GraphOptions.of(rest_keep_every=rest_keep_every)
    whole = solve_graph(board, angles, models, options)
    part = solve_graph(board, angles.select(inside), models, options)
    return difference(whole.stations.pose(1), part.stations.pose(1))


def imported_bag(bag: Path) -> tuple[Board, Angles, dict, Trajectory]:
    """The board, angles (sync-bit offsets corrected), station models (default convention)
    and OptiTrack path of the bag, imported into a temporary folder."""
    with tempfile.TemporaryDirectory() as tmp:
        import_hive(bag, tmp)
        return (load_board(Path(tmp) / "board.toml"), load_angles(Path(tmp) / "angles.csv"),
                station_models(Path(tmp) / "ootx.toml", Convention()),
                load_trajectory(Path(tmp) / "mocap.csv"))


def held_out_boards(board: Board, angles: Angles, models: dict, t0: float) -> list[str]:
    """Each slice judged with a board solved without it: the sensor positions solved on the
    bag less that slice (its rests as they are, or thinned), then that board for the slice
    and for the whole bag (rests thinned 1 in ``REST_KEEP_EVERY``, or to one window each),
    so the board never saw the data it is judged on."""
    rests = " and ".join(f"{b - a:g} s" for a, b in rest_spans(angles))
    lines = ["", "Held out: each slice with the sensor positions solved on the bag *without* "
             "that slice, against the whole bag solved with the same board. Rests thinned 1 in "
             f"{REST_KEEP_EVERY}, or 1 in {ONE_WINDOW} (one 0.1 s window of each rest here: "
             f"{rests}).", "",
             "| board solved with | the whole bag's rests | slice differences (x, y, z) mm | "
             "rms of the slice distances mm | rms rotation difference deg |",
             "|---|---|---|---|---|"]
    boards: dict[tuple[int, int], Board] = {}  # (rests kept 1 in, slice) -> held-out board
    for board_keep, whole_keep in ((1, REST_KEEP_EVERY), (REST_KEEP_EVERY, REST_KEEP_EVERY),
                                   (1, ONE_WINDOW), (ONE_WINDOW, ONE_WINDOW)):
        diffs, turns = [], []
        for k in range(3):
            inside = in_slice(angles, t0, k)
            if (board_keep, k) not in boards:
                boards[board_keep, k] = held_out_board(board, angles, models, inside,
                                                       board_keep)
            position_mm, turn_deg = against_whole(boards[board_keep, k], angles, models,
                                                  inside, whole_keep)
            diffs.append(position_mm)
            turns.append(turn_deg)
        triplets, rms, _ = spread_cells(np.array(diffs))
        lines.append(f"| the rests {_kept(board_keep)} | {_kept(whole_keep)} | {triplets} | "
                     f"{rms} | {np.sqrt(np.mean(np.square(turns))):.3f} |")
        print(lines[-1], flush=True)
    return lines


def _kept(keep_every: int) -> str:
    return "as they are" if keep_every == 1 else f"thinned (1 in {keep_every})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--bag", type=Path, default=BAG)
    parser.add_argument("--output", default=str(REPO / "docs/results/hive_slice_spread.md"))
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    if not args.bag.is_file():
        print(f"{args.bag}: not there, nothing measured")
        return 0
    out = check_writable(args.output, args.force)
    board, angles, models, _ = imported_bag(args.bag)
    t0 = motion_start(angles)
    lines = ["# The hive recording: station 1 over 8 s slices, variants", "",
             f"`python -m benchmarks hive_slice_spread`, {time.strftime('%Y-%m-%d')}. Station "
             "1's position from each 8 s slice (from the motion start, 4 s apart) less the "
             "whole-bag solution's, in station 1's frame (x along its line of sight), mm; "
             "sigma = the slices' median reported 1-sigma (position, largest axis).", "",
             "| variant | whole-bag rms µrad | slice differences (x, y, z) mm | rms of the "
             "slice distances mm | slices about their mean mm | slice sigma mm |",
             "|---|---|---|---|---|---|"]
    default = None
    for name, (shift_s, options) in VARIANTS.items():
        data = shifted(angles, 1, shift_s) if shift_s else angles
        whole = solve_graph(board, data, models, options)
        default = default or whole
        d, sigma_mm, _ = slice_differences(board, data, models, options, whole, t0)
        triplets, rms, about_mean = spread_cells(d)
        lines.append(f"| {name} | {whole.residuals.rms_urad():.1f} | {triplets} | {rms} | "
                     f"{about_mean} | {sigma_mm:.2f} |")
        print(lines[-1], flush=True)
    lines += tracker_geometry(board, angles, models, t0)
    lines += ["", "What repeats at a diode: the default whole-bag solve's inlier residuals (robust "
              "weight > 0.5) per station, axis and diode (diodes with at least 50): the rms "
              "over the diodes of their mean residual, against the median of their spread "
              "about it.", "", "| station | axis | diodes | rms of the diode means µrad | "
              "median spread µrad |", "|---|---|---|---|---|"]
    for station, axis, n, means, spread in diode_means(default.residuals):
        lines.append(f"| {station} | {axis} | {n} | {means:.1f} | {spread:.1f} |")
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
