"""The Crazyflie logs' accelerometer against the mocap's accelerations: how much of the
motion it reports, by time scale, and how late.

    python -m benchmarks imu_bandwidth [--output FILE] [--force]

Issue #39 item 2 wants the deck's metric scale from its accelerometer; on the shared logs
the graph's IMU-scaled solves come out 3-8 % small while the mocap says our light-only
geometry is 0.4-0.8 % small (docs/results/anchored_stations.md). This checks the
accelerometer itself, without any solve: the log's Qualisys positions (on the written
clock through the marker events, as imported) are resampled at 200 Hz and twice differentiated (a
cubic Savitzky-Golay filter over 45 ms); that and the accelerometer (`imu.csv`, 100 Hz) are
then smoothed alike, by a cubic Savitzky-Golay filter of window W. Compared is the specific
force's magnitude less gravity, |f| - g (so neither the receiver's orientation nor the IMU's
mounting enters): over a +-50 ms search of the accelerometer's delay, the best correlation,
that delay (positive: the accelerometer late) and the regression slope of the accelerometer
on the mocap (1: it reports the motion in full) at moments where the mocap's |f| - g exceeds
0.5 m/s^2. Writes docs/results/imu_bandwidth.md. Data: Crazyflie (no licence: read from
../shared only). ~1 min.
"""

from __future__ import annotations

import tempfile
from datetime import date
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter

from benchmarks import begin, write_results
from benchmarks.compare_pairs import imported_logs
from lhgraph.io.files import read_csv_columns

LOGS = ("lh1_crossingBeam_move/log02", "lh1_crossingBeam_flight/log00",
        "lh2_crossingBeam_move/log00", "lh2_crossingBeam_move/log01")
STEP_S = 0.005
WINDOWS_S = (0.1, 0.2, 0.5, 1.0)
DELAYS_S = np.arange(-0.05, 0.0501, 0.005)
GRAVITY = 9.81
MIN_DYNAMIC = 0.5
DIFFERENTIATOR = 9
"""Samples (45 ms) of the cubic Savitzky-Golay filter that differentiates the mocap twice,
before both signals get the same smoothing."""


def columns(path: Path, names: tuple[str, ...]) -> np.ndarray:
    """Float columns ``names`` of a CSV, stacked ``(N, len(names))``."""
    c = read_csv_columns(path, [(n, float) for n in names])
    return np.stack([c[n] for n in names], axis=1)


def resampled(t: np.ndarray, x: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Columns of ``x`` ``(N, k)`` at times ``t`` interpolated onto ``grid``."""
    return np.stack([np.interp(grid, t, x[:, j]) for j in range(x.shape[1])], axis=1)


def compared(m: np.ndarray, imu: np.ndarray, window_s: float
             ) -> tuple[float, float, float, int]:
    """For an imported log's mocap ``m`` (time, x, y, z) and accelerometer ``imu`` (time, ax,
    ay, az): the best correlation of the accelerometer's |f| - g with the mocap's, its delay
    (s), the slope at that delay, and the moments compared."""
    grid = np.arange(max(m[0, 0], imu[0, 0]) + 1.0, min(m[-1, 0], imu[-1, 0]) - 1.0, STEP_S)
    n = int(round(window_s / STEP_S)) | 1
    acc = savgol_filter(resampled(m[:, 0], m[:, 1:], grid), DIFFERENTIATOR, 3, deriv=2,
                        delta=STEP_S, axis=0)
    f_mocap = np.linalg.norm(savgol_filter(acc, n, 3, axis=0) + [0.0, 0.0, GRAVITY],
                             axis=1) - GRAVITY
    smooth = savgol_filter(resampled(imu[:, 0], imu[:, 1:], grid), n, 3, axis=0)
    moving = np.abs(f_mocap) > MIN_DYNAMIC
    best = (-np.inf, 0.0, 0.0)
    for delay in DELAYS_S:
        f_imu = np.linalg.norm(resampled(grid, smooth, grid + delay), axis=1) - GRAVITY
        c = float(np.corrcoef(f_imu[moving], f_mocap[moving])[0, 1])
        if c > best[0]:
            k = float(f_imu[moving] @ f_mocap[moving] / (f_mocap[moving] @ f_mocap[moving]))
            best = (c, float(delay), k)
    return (*best, int(moving.sum()))


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "The Crazyflie accelerometer against the mocap")
    lines += [f"{date.today()}; |f| - g of the accelerometer against the mocap's, both "
              "smoothed by a cubic Savitzky-Golay window W; per W: best correlation, the "
              "accelerometer's delay there (ms, positive: late), the slope accelerometer / "
              "mocap (1: the motion in full), moments compared "
              f"(mocap |f| - g above {MIN_DYNAMIC} m/s^2).", "",
              "| log | " + " | ".join(f"W = {w:g} s" for w in WINDOWS_S) + " |",
              "|---|" + "---|" * len(WINDOWS_S)]
    with tempfile.TemporaryDirectory(prefix="lhgraph-imu-") as tmp:
        for log, work in imported_logs(LOGS, Path(tmp)):
            if work is None:
                lines.append(f"| {log} | skipped: data absent |" + " |" * (len(WINDOWS_S) - 1))
                continue
            mocap = columns(work / "mocap.csv", ("time", "x", "y", "z"))
            imu = columns(work / "imu.csv", ("time", "ax", "ay", "az"))
            cells = []
            for w in WINDOWS_S:
                c, delay, k, n = compared(mocap, imu, w)
                cells.append(f"r {c:.2f}, {delay * 1e3:+.0f} ms, slope {k:.2f} ({n})")
            lines.append(f"| {log} | " + " | ".join(cells) + " |")
            print(lines[-1], flush=True)
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
