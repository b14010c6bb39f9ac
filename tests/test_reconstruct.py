"""Measurement reconstruction on synthetic sweep sequences with known answers."""

import numpy as np
import pytest

from lhgraph.errors import InputError
from lhgraph.estimation.reconstruct import Measurements, reconstruct_measurements, to_ideal
from lhgraph.io.angles import Angles
from lhgraph.model.board import make_board
from lhgraph.model.station import FactoryCalibration, StationModel, sweep_angle

SLOT = 1 / 120  # one sweep slot (s)
HIT_STEP = 50e-6  # sensor j is hit j * HIT_STEP after the sweep's first hit
N_SENSORS = 4
BOARD = make_board(np.eye(N_SENSORS, 3), np.tile([0.0, 0.0, 1.0], (N_SENSORS, 1)),
                   ids=[10, 11, 12, 13])


def az_true(sensor, t, slope=0.3):
    return 0.1 * sensor + slope * t


def el_true(sensor, t, slope=0.1):
    return -0.05 * sensor + slope * t


def make_angles(sweep_times, sweep_axes, drop=(), az_slope=0.3, el_slope=0.1,
                sweep_column=False):
    """Hits of station 0: every sensor in every sweep except ``(sweep, sensor)`` in drop."""
    rows = []
    for k, (t0, axis) in enumerate(zip(sweep_times, sweep_axes, strict=True)):
        for j in range(N_SENSORS):
            if (k, j) in drop:
                continue
            t = t0 + j * HIT_STEP
            angle = az_true(j, t, az_slope) if axis == 0 else el_true(j, t, el_slope)
            rows.append((t, axis, BOARD.ids[j], angle, k))
    rows.sort()
    t, axis, sensor, angle, k = (np.array(c) for c in zip(*rows, strict=True))
    extra = {"sweep": k.astype(np.int64)} if sweep_column else {}
    return Angles(t, np.zeros(len(t), dtype=np.int64), axis.astype(np.int64),
                  sensor.astype(np.int64), angle, extra)


def alternating(n):
    times = np.arange(n) * SLOT
    return times, np.arange(n) % 2


def test_full_interpolation_is_exact_for_linear_motion():
    times, axes = alternating(12)
    m = reconstruct_measurements(make_angles(times, axes), BOARD, "full")
    assert isinstance(m, Measurements)
    assert len(m) == 12 and m.azimuth.shape == (12, N_SENSORS)
    np.testing.assert_array_equal(m.sensor_ids, BOARD.ids)
    np.testing.assert_array_equal(m.source_axis, axes)
    mean_hit = HIT_STEP * (N_SENSORS - 1) / 2
    np.testing.assert_allclose(m.time, times + mean_hit, atol=1e-12)
    hit = times[:, None] + np.arange(N_SENSORS) * HIT_STEP
    j = np.arange(N_SENSORS)
    # first sweep (azimuth) has no earlier elevation: NaN; last (elevation) no later azimuth
    assert np.all(np.isnan(m.elevation[0])) and np.all(np.isnan(m.azimuth[-1]))
    np.testing.assert_allclose(m.azimuth[:-1], az_true(j, hit)[:-1], atol=1e-12)
    np.testing.assert_allclose(m.elevation[1:], el_true(j, hit)[1:], atol=1e-12)
    assert m.both().sum() == (12 - 2) * N_SENSORS


def test_sweep_column_and_time_gaps_group_alike():
    times, axes = alternating(10)
    a = reconstruct_measurements(make_angles(times, axes), BOARD)
    b = reconstruct_measurements(make_angles(times, axes, sweep_column=True), BOARD)
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_array_equal(a.azimuth, b.azimuth)
    np.testing.assert_array_equal(a.elevation, b.elevation)


def test_no_interpolation_across_long_gaps():
    times, axes = alternating(24)
    # sensor 2 misses one elevation sweep (11): bridged; later two in a row (17, 19): NaN
    m = reconstruct_measurements(make_angles(times, axes, drop={(11, 2), (17, 2), (19, 2)}),
                                 BOARD, "full", max_gap_periods=2.5)
    hit = times + 2 * HIT_STEP
    np.testing.assert_allclose(m.elevation[[10, 12], 2], el_true(2, hit[[10, 12]]), atol=1e-12)
    assert np.all(np.isnan(m.elevation[[16, 18, 20], 2]))
    assert np.isnan(m.elevation[17, 2]) and np.isnan(m.elevation[19, 2])
    assert np.all(np.isfinite(m.elevation[16:21, [0, 1, 3]]))


def test_half_interpolation_keeps_the_axis_that_varies_most():
    times, axes = alternating(12)
    m = reconstruct_measurements(make_angles(times, axes, az_slope=0.05, el_slope=0.4), BOARD,
                                 "half")
    assert len(m) == 6 and np.all(m.source_axis == 1)
    hit = times[axes == 1][:, None] + np.arange(N_SENSORS) * HIT_STEP
    j = np.arange(N_SENSORS)
    np.testing.assert_allclose(m.elevation, el_true(j, hit, 0.4), atol=1e-12)
    np.testing.assert_allclose(m.azimuth[:-1], az_true(j, hit, 0.05)[:-1], atol=1e-12)
    assert np.all(np.isnan(m.azimuth[-1]))
    m = reconstruct_measurements(make_angles(times, axes, az_slope=0.4, el_slope=0.05), BOARD,
                                 "half")
    assert len(m) == 6 and np.all(m.source_axis == 0)


def test_merge_pairs_the_closest_neighbours():
    # Two-station schedule: this station sweeps az then el one slot later, then waits 3 slots.
    # A lone elevation sweep starts the capture and must stay unpaired.
    times = np.r_[0.0, np.concatenate([[4 * k + 3, 4 * k + 4] for k in range(5)])] * SLOT
    axes = np.r_[1, np.tile([0, 1], 5)]
    m = reconstruct_measurements(make_angles(times, axes), BOARD, "merge")
    assert len(m) == 5 and np.all(m.source_axis == -1)
    mean_hit = HIT_STEP * (N_SENSORS - 1) / 2
    np.testing.assert_allclose(m.time, (times[1::2] + times[2::2]) / 2 + mean_hit, atol=1e-12)
    j = np.arange(N_SENSORS)
    np.testing.assert_allclose(m.azimuth, az_true(j, times[1::2, None] + j * HIT_STEP),
                               atol=1e-12)
    np.testing.assert_allclose(m.elevation, el_true(j, times[2::2, None] + j * HIT_STEP),
                               atol=1e-12)


def test_bad_inputs():
    times, axes = alternating(6)
    angles = make_angles(times, axes)
    with pytest.raises(InputError, match="variant"):
        reconstruct_measurements(angles, BOARD, "spline")
    other = make_board(np.eye(3), np.tile([0.0, 0.0, 1.0], (3, 1)), ids=[10, 11, 12])
    with pytest.raises(InputError, match=r"\[13\] not on the board"):
        reconstruct_measurements(angles, other)


def test_to_ideal_removes_the_factory_calibration():
    cal = FactoryCalibration(phase=[0.02, -0.015], tilt=[0.01, -0.02], curve=[0.003, 0.002],
                             gibphase=[1.0, 2.0], gibmag=[0.004, -0.003])
    model = StationModel(cal)
    rng = np.random.default_rng(0)
    az = rng.uniform(-0.8, 0.8, (5, 3))
    el = rng.uniform(-0.6, 0.6, (5, 3))
    d = np.stack([np.ones_like(az), np.tan(az), np.tan(el)], axis=-1).reshape(-1, 3)
    az_m = sweep_angle(d, np.zeros(len(d), dtype=int), model).reshape(az.shape)
    el_m = sweep_angle(d, np.ones(len(d), dtype=int), model).reshape(el.shape)
    el_m[0, 0] = np.nan
    meas = Measurements(0, np.arange(5.0), az_m, el_m, np.arange(3), np.zeros(5, dtype=int))
    ideal = to_ideal(meas, model)
    assert np.abs(az_m - az).max() > 1e-3  # the distortion is not negligible
    ok = np.isfinite(el_m)
    np.testing.assert_allclose(ideal.azimuth[ok], az[ok], atol=1e-9)
    np.testing.assert_allclose(ideal.elevation[ok], el[ok], atol=1e-9)
    assert np.isnan(ideal.elevation[0, 0])
    assert to_ideal(meas, StationModel()) is meas and to_ideal(meas, None) is meas
