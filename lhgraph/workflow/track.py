"""``lhgraph track``: the board's path with the stations held fixed, from files to a
trajectory CSV (docs/track.md).

:func:`track_files` checks the output and every input before the work (one line naming the
file, nothing written), tracks in batch (:func:`lhgraph.estimation.graph.track.track`) or one
sync cycle at a time (:func:`lhgraph.estimation.graph.streaming.track_stream`) and writes the
contract trajectory CSV with the added columns ``lighthouse``, ``hits``, ``sigma_m``
atomically. A track ends with a verdict on its residuals
(:func:`lhgraph.report.assessment.track_verdict`): the angles fit the stations, or not (batch:
the graph's residuals; streaming: those of the path as reported,
:func:`lhgraph.estimation.graph.path_residuals.path_residuals`). With ``watch`` the capture is
also watched for a station that moved during it (:mod:`lhgraph.estimation.station_watch`):
batch, every window with the whole path; streaming, each window as soon as the path reported
so far covers it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.path_residuals import path_residuals
from lhgraph.estimation.graph.streaming import DELAY_S, StreamingEstimate, track_stream
from lhgraph.estimation.graph.track import TrackedPath, track
from lhgraph.estimation.result import Residuals
from lhgraph.estimation.spread import robust_sigma
from lhgraph.estimation.station_watch import Watcher, WatchOptions, WatchResult
from lhgraph.io.angles import load_angles
from lhgraph.io.files import check_writable
from lhgraph.io.imu import load_imu
from lhgraph.io.stations import Stations, load_stations
from lhgraph.io.trajectory import save_trajectory
from lhgraph.model.boards import board_by_name
from lhgraph.report.assessment import Verdict, track_verdict
from lhgraph.workflow.inputs import calibration_beside, check_generations, station_models

Progress = Callable[[str], None]


@dataclass(frozen=True)
class TrackOutput:
    """What :func:`track_files` did: the path, the file written, the mode, the wall time per
    sync cycle (streaming; s) and the optimiser's status (batch)."""

    path: TrackedPath
    written: Path
    streaming: bool
    cycle_s: list[float]
    status: str
    residuals: Residuals | None = None
    range_m: float = float("nan")
    verdict: Verdict | None = None
    watch: WatchResult | None = None

    def summary(self) -> str:
        """States, time span, how well determined, what was written; batch: the residuals
        (rms of the inliers, robust spread, also as mm at the median station-board range)."""
        t = self.path.trajectory.time
        sigma = np.median(self.path.sigma_m) * 1e3
        how = (f"streaming, {len(self.cycle_s)} cycles, median update "
               f"{np.median(self.cycle_s) * 1e3:.1f} ms" if self.streaming else self.status)
        lines = [f"{len(t)} board states over {t[-1] - t[0]:.1f} s ({how}), median position "
                 f"sigma {sigma:.2f} mm; wrote {self.written}"]
        if self.residuals is not None:
            r = self.residuals
            spread = robust_sigma(r.residual_rad)
            lines.append(f"residuals: {len(r.residual_rad)} hits, rms {r.rms_urad():.1f} µrad "
                         f"(inliers), robust spread {spread * 1e6:.1f} µrad = "
                         f"{spread * self.range_m * 1e3:.2f} mm at the median range "
                         f"{self.range_m:.2f} m, inlier fraction {r.inlier_fraction():.3f}")
        if self.watch is not None:
            lines.append(self.watch.summary())
        return "\n".join(lines)


def track_files(board: str | Path, angles: str | Path, stations: str | Path, output: str | Path,
                calibration: str | Path | None = None, streaming: bool = False,
                overwrite: bool = False, options: GraphOptions | None = None,
                progress: Progress | None = None, delay_s: float | None = None,
                imu: str | Path | None = None, watch_options: WatchOptions | None = None
                ) -> TrackOutput:
    """Track the board of ``board`` (a board TOML or a built-in name) through ``angles`` with
    the stations of ``stations`` held fixed and write the trajectory CSV ``output``.

    Factory calibration: ``calibration`` if given, else the stations file's keys, else the
    ``ootx.toml`` beside the angles (said through ``progress``); one of the other generation
    than the angles' sweeps is refused (InputError). ``streaming``: per sync cycle, each
    state as estimated ``delay_s`` after it (default
    :data:`~lhgraph.estimation.graph.streaming.DELAY_S`); ``imu``: the receiver's
    ``imu.csv`` (board frame, the angles' clock) for the graph's IMU factors (batch only);
    ``watch_options``: also watch for a station that moved during the capture (each move
    said through ``progress`` when found)."""
    check_writable(output, overwrite, create_parents=False)  # the folder: when writing
    if imu is not None and streaming:
        raise InputError("IMU factors are batch only: drop --streaming or --imu", "--imu")
    if delay_s is not None and not streaming:
        raise InputError("a delay applies to streaming only: add --streaming or drop it",
                         "--delay")
    delay_s = DELAY_S if delay_s is None else delay_s
    if not 0 <= delay_s < 0.5:
        raise InputError(f"must be in [0, 0.5) s, the smoother's lag (got {delay_s:g})",
                         "--delay")
    if calibration is not None and not Path(calibration).is_file():
        raise InputError("calibration file not found", calibration)
    the_board = board_by_name(str(board), source="--board")
    the_angles = load_angles(angles)
    fixed = load_stations(stations)
    missing = [s for s in the_angles.stations() if s not in fixed.stations]
    if missing:
        raise InputError(f"no [lighthouses.<index>] table for station(s) "
                         f"{', '.join(map(str, missing))} seen in {angles}", stations)
    if calibration is None and all(s.model.calibration.is_zero()
                                   for s in fixed.stations.values()):
        calibration, note = calibration_beside(angles, None)
        if note and progress is not None:
            progress(note)
    models = station_models(calibration)
    if calibration is not None:
        check_generations(models, the_angles, calibration, angles)
    stream = None if imu is None else load_imu(imu)
    track_models = models or {k: fixed.stations[k].model for k in fixed.indices()}
    watcher = None if watch_options is None else Watcher(
        the_board, the_angles, fixed, track_models, watch_options, options)
    if streaming:
        estimates = stream_and_watch(track_stream(the_board, the_angles, fixed, models,
                                                  options, delay_s=delay_s), watcher, progress)
        if not estimates:
            raise InputError("too short to track in streaming mode (no estimate after the "
                             "warm-up)", angles)
        path = TrackedPath.concatenate([e.path for e in estimates if e.path])
        cycle_s, status = [e.update_s for e in estimates[1:-1]], "streaming"
    else:
        result = track(the_board, the_angles, fixed, models, options, progress=progress,
                       imu=stream)
        path, cycle_s, status = result.path, [], result.status
    watched = None
    if watcher is not None:
        watcher.catch_up(path.trajectory.time, path.trajectory.T_world_board,
                         progress=progress)
        watched = watcher.result()
    written = save_trajectory(path.trajectory, output, overwrite, path.columns())
    range_m = median_range(path, fixed)
    calibrated = (fixed.extra.get("verdict") or {}).get("residual_spread_urad")
    if streaming:
        # the residuals of the path as reported; each update is one smoother step, with no
        # convergence to judge
        residuals = path_residuals(the_board, the_angles, fixed, path, models, options)
        return TrackOutput(path, written, streaming, cycle_s, status, residuals, range_m,
                           track_verdict("converged", 0, residuals, range_m,
                                         calibration_spread_urad=calibrated), watched)
    gravity = None if result.gravity is None else float(np.linalg.norm(result.gravity))
    bias = None if result.imu_bias is None else float(np.linalg.norm(result.imu_bias[3:]))
    return TrackOutput(path, written, streaming, cycle_s, status, result.residuals, range_m,
                       track_verdict(status, result.iterations, result.residuals, range_m,
                                     gravity, calibrated, bias), watched)


def stream_and_watch(estimates: Iterable[StreamingEstimate], watcher: Watcher | None,
                     progress: Progress | None) -> list[StreamingEstimate]:
    """Every streaming estimate; with a ``watcher``, each watch window solved as soon as
    the path reported so far reaches its end (a move is said when found, as it would be
    live)."""
    out: list[StreamingEstimate] = []
    times: list[np.ndarray] = []
    poses: list[np.ndarray] = []
    for estimate in estimates:
        out.append(estimate)
        if watcher is None or not estimate.path:
            continue
        times.append(estimate.path.trajectory.time)
        poses.append(estimate.path.trajectory.T_world_board)
        covered = float(times[-1][-1])
        if watcher.due(covered):
            watcher.catch_up(np.concatenate(times), np.concatenate(poses), covered, progress)
    return out


def median_range(path: TrackedPath, stations: Stations) -> float:
    """Median distance (m) from each state's board position to the station whose sweep made
    it: what turns an angle residual into a distance."""
    p_lh = np.stack([stations.pose(int(k))[:3, 3] for k in path.lighthouse])
    return float(np.median(np.linalg.norm(path.trajectory.T_world_board[:, :3, 3] - p_lh,
                                          axis=1)))
