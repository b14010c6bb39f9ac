"""Measurement reconstruction (paper §"Measurement data reconstruction").

A station sweeps azimuth (axis 0) and elevation (axis 1) alternately, so one sweep gives
each hit sensor only one of its two angles. The paper's pose estimation needs both, so the
hits of one station are turned into *measurements*: at one time, an azimuth and an elevation
for every board sensor (NaN where unknown). Three variants:

- ``"full"`` (the paper's best, our default): every sweep becomes a measurement; each hit
  sensor's missing angle is linearly interpolated in time between that sensor's previous and
  next sweep of the other axis (at the sensor's own hit time).
- ``"half"``: only the sweeps of the axis whose angles varied most over the capture become
  measurements; the other (smoother) axis is interpolated onto them -> half as many.
- ``"merge"``: neighbouring azimuth/elevation sweeps are paired and merged (time = their
  mean), nothing is interpolated.

No value is interpolated across a gap longer than ``max_gap_periods`` sweep periods of the
interpolated axis, nor extrapolated past a sensor's first or last sample: such entries are
NaN. Angles are in radians and times in seconds, as in the angles CSV.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.angles import SWEEP_GAP_S, Angles
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel, ideal_from_measured

Array = NDArray[np.float64]

VARIANTS = ("full", "half", "merge")


@dataclass(frozen=True)
class Measurements:
    """Reconstructed measurements of one station.

    ``time`` (M,) s, increasing; ``azimuth`` and ``elevation`` (M, S) rad over the board's
    sensors in board order (``sensor_ids`` (S,)), NaN where a sensor has no value;
    ``source_axis`` (M,) the axis of the sweep a measurement came from (-1 for merged pairs).
    """

    lighthouse: int
    time: Array
    azimuth: Array
    elevation: Array
    sensor_ids: NDArray[np.int64]
    source_axis: NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.time)

    def both(self) -> NDArray[np.bool_]:
        """(M, S) mask of sensors that have both angles."""
        return np.isfinite(self.azimuth) & np.isfinite(self.elevation)

    def select(self, keep: NDArray[np.bool_]) -> Measurements:
        """The measurements where the (M,) mask ``keep`` is True."""
        return Measurements(self.lighthouse, self.time[keep], self.azimuth[keep],
                            self.elevation[keep], self.sensor_ids, self.source_axis[keep])


@dataclass(frozen=True)
class _Sweeps:
    """The sweeps of one axis: ``time`` (K,) mean hit time; ``angle``, ``hit_time`` (K, S)."""

    time: Array
    angle: Array
    hit_time: Array

    def period(self) -> float:
        """Median spacing of consecutive sweeps (s); inf with fewer than two sweeps."""
        return float(np.median(np.diff(self.time))) if len(self.time) > 1 else np.inf


def _sweeps_by_axis(angles: Angles, columns: NDArray, n_sensors: int,
                    sweep_gap_s: float) -> tuple[_Sweeps, _Sweeps]:
    """Group one station's hits into sweeps, one (K, S) table per axis."""
    sweep = angles.sweep_ids(sweep_gap_s) * 2 + angles.axis
    out = []
    for axis in (0, 1):
        sel = angles.axis == axis
        keys, row = np.unique(sweep[sel], return_inverse=True)
        angle = np.full((len(keys), n_sensors), np.nan)
        hit = np.full((len(keys), n_sensors), np.nan)
        angle[row, columns[sel]] = angles.angle[sel]  # a repeated sensor keeps its last hit
        hit[row, columns[sel]] = angles.time[sel]
        count = np.bincount(row, minlength=len(keys))
        t = np.bincount(row, weights=angles.time[sel], minlength=len(keys)) / np.maximum(count, 1)
        order = np.argsort(t, kind="stable")
        out.append(_Sweeps(t[order], angle[order], hit[order]))
    return out[0], out[1]


def _interpolate_sensor_angles(sweeps: _Sweeps, query_time: Array, max_gap_s: float) -> Array:
    """Angles of ``sweeps`` linearly interpolated per sensor at ``query_time`` (Q, S).

    Entries without a sample on both sides, or whose bracketing samples are more than
    ``max_gap_s`` apart, are NaN.
    """
    out = np.full(query_time.shape, np.nan)
    for j in range(query_time.shape[1]):
        have = np.isfinite(sweeps.angle[:, j])
        q = query_time[:, j]
        ask = np.isfinite(q)
        if have.sum() < 2 or not ask.any():
            continue
        t, a = sweeps.hit_time[have, j], sweeps.angle[have, j]
        qa = q[ask]
        i = np.searchsorted(t, qa, side="right")
        inside = (i > 0) & (i < len(t))
        i = np.clip(i, 1, len(t) - 1)
        ok = inside & (t[i] - t[i - 1] <= max_gap_s)
        values = np.where(ok, np.interp(qa, t, a), np.nan)
        out[np.flatnonzero(ask), j] = values
    return out


def _interpolated(own: _Sweeps, other: _Sweeps, own_axis: int,
                  max_gap_periods: float) -> tuple[Array, Array]:
    """(azimuth, elevation) tables for the sweeps ``own`` with ``other`` interpolated."""
    filled = _interpolate_sensor_angles(other, own.hit_time, max_gap_periods * other.period())
    return (own.angle, filled) if own_axis == 0 else (filled, own.angle)


def _variation(sweeps: _Sweeps) -> float:
    """Mean per-second total variation of each sensor's angle series (rad/s)."""
    a = sweeps.angle
    steps = np.abs(np.diff(a, axis=0))
    total = np.nansum(steps)
    duration = np.nansum(np.diff(sweeps.hit_time, axis=0) * np.isfinite(steps))
    return float(total / duration) if duration > 0 else 0.0


def _merged_pairs(az: _Sweeps, el: _Sweeps, max_pair_gap_s: float | None) -> tuple[
        Array, Array, Array]:
    """Pair neighbouring azimuth/elevation sweeps: (time, azimuth, elevation).

    Candidate pairs are consecutive sweeps (in time) of different axes at most
    ``max_pair_gap_s`` apart (default 0.6x the shorter axis period); the closest pairs are
    taken first and every sweep is used at most once.
    """
    if max_pair_gap_s is None:
        max_pair_gap_s = 0.6 * min(az.period(), el.period())
    t = np.concatenate([az.time, el.time])
    axis = np.concatenate([np.zeros(len(az.time), int), np.ones(len(el.time), int)])
    index = np.concatenate([np.arange(len(az.time)), np.arange(len(el.time))])
    order = np.argsort(t, kind="stable")
    t, axis, index = t[order], axis[order], index[order]
    gap = np.diff(t)
    candidates = np.flatnonzero((axis[:-1] != axis[1:]) & (gap <= max_pair_gap_s))
    used = np.zeros(len(t), dtype=bool)
    first = []
    for k in candidates[np.argsort(gap[candidates], kind="stable")]:
        if not used[k] and not used[k + 1]:
            used[k] = used[k + 1] = True
            first.append(k)
    first = np.sort(np.array(first, dtype=int))
    second = first + 1
    i_az = np.where(axis[first] == 0, index[first], index[second])
    i_el = np.where(axis[first] == 1, index[first], index[second])
    return 0.5 * (t[first] + t[second]), az.angle[i_az], el.angle[i_el]


def reconstruct_measurements(
    angles: Angles,
    board: Board,
    variant: str = "full",
    *,
    max_gap_periods: float = 2.5,
    sweep_gap_s: float = SWEEP_GAP_S,
    max_pair_gap_s: float | None = None,
) -> Measurements:
    """Measurements (both angles per sensor) of one station's hits, paper-style.

    ``angles`` must hold the hits of a single station (rad, s); ``variant`` is ``"full"``,
    ``"half"`` or ``"merge"`` (see the module docstring). ``max_pair_gap_s`` (merge only)
    defaults to 0.6x the shorter axis sweep period. Unknown sensor ids raise
    :class:`InputError`.
    """
    if variant not in VARIANTS:
        raise InputError(f"unknown reconstruction variant '{variant}' (expected one of "
                         f"{', '.join(VARIANTS)})", where="reconstruction")
    stations = angles.stations()
    if len(stations) != 1:
        raise ValueError(f"expected the hits of one station, got stations {stations}")
    columns = angles.check_board(board)
    az, el = _sweeps_by_axis(angles, columns, len(board.ids), sweep_gap_s)

    if variant == "merge":
        time, azimuth, elevation = _merged_pairs(az, el, max_pair_gap_s)
        source = np.full(len(time), -1, dtype=np.int64)
    else:
        if variant == "full":
            kept = (0, 1)
        else:
            kept = (0,) if _variation(az) >= _variation(el) else (1,)
        parts = []
        for axis in kept:
            own, other = (az, el) if axis == 0 else (el, az)
            a, e = _interpolated(own, other, axis, max_gap_periods)
            parts.append((own.time, a, e, np.full(len(own.time), axis, dtype=np.int64)))
        time = np.concatenate([p[0] for p in parts])
        order = np.argsort(time, kind="stable")
        time = time[order]
        azimuth = np.concatenate([p[1] for p in parts])[order]
        elevation = np.concatenate([p[2] for p in parts])[order]
        source = np.concatenate([p[3] for p in parts])[order]
    return Measurements(stations[0], time, azimuth, elevation, board.ids.copy(), source)


def to_ideal(meas: Measurements, model: StationModel | None) -> Measurements:
    """Measurements with the factory-calibration distortion of ``model`` removed.

    Each (azimuth, elevation) pair is mapped to the ideal angles of the same direction with
    :func:`lhgraph.model.lh1.ideal_from_measured` (far field: rotor offsets are ignored). A
    ``None`` or all-zero calibration returns ``meas`` unchanged.
    """
    if model is None or model.calibration.is_zero():
        return meas
    az, el = ideal_from_measured(meas.azimuth, meas.elevation, model)
    return Measurements(meas.lighthouse, meas.time, az, el, meas.sensor_ids, meas.source_axis)
