"""hive bag importer: contract files, rates, CLI errors, and the verified axis mapping.

The real-data tests read ``<repo>/../shared/data/hive-env8/data8.11.bag`` (never copied into
the repository: it has no licence) and are skipped when it is absent.
"""

from __future__ import annotations

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.importers.hive import read_hive_bag
from lhgraph.importers.hive.bag import off_grid_sweeps
from lhgraph.importers.hive.conventions import CANDIDATE_MAPPINGS, HIVE_MAPPING, AxisMapping
from lhgraph.importers.hive.mapping_check import check_mappings
from lhgraph.io.angles import load_angles
from lhgraph.io.files import read_csv_columns
from lhgraph.io.trajectory import load_trajectory
from lhgraph.model.board import load_board
from lhgraph.model.calibration import load_calibration


@pytest.fixture(scope="module")
def imported(hive_import):
    return hive_import


@pytest.fixture(scope="module")
def bag(hive_bag):
    return read_hive_bag(hive_bag)


def test_axis_mapping_apply_and_labels():
    m = AxisMapping((1, 0), (1.0, -1.0))
    axis, angle = m.apply(np.array([0, 1, 1]), np.array([0.1, 0.2, -0.3]))
    assert axis.tolist() == [1, 0, 0]
    np.testing.assert_allclose(angle, [0.1, -0.2, 0.3])
    assert m.label == "az=-v el=+h"
    assert HIVE_MAPPING.label == "az=+h el=+v"
    assert len({c.label for c in CANDIDATE_MAPPINGS}) == 8


def test_import_writes_valid_contract_files(imported):
    result, out = imported
    angles = load_angles(out / "angles.csv")
    board = load_board(out / "board.toml")
    cal = load_calibration(out / "ootx.toml")
    mocap = load_trajectory(out / "mocap.csv")
    imu = read_csv_columns(out / "imu.csv", [(c, float) for c in
                                             ("time", "ax", "ay", "az", "gx", "gy", "gz")])
    assert angles.stations() == [0, 1] and sorted(cal) == [0, 1]
    assert [cal[i].id for i in (0, 1)] == [992178646, 1712309611]  # numeric serial order
    assert len(board.ids) == 24 and sorted(board.ids.tolist()) == list(range(24))
    np.testing.assert_allclose(np.linalg.norm(board.normals, axis=1), 1.0, atol=1e-6)
    assert np.all(np.abs(board.positions) < 0.15)  # a tracker, metres
    angles.check_board(board)
    assert np.all(np.abs(angles.angle) < 1.2) and len(angles) == result.n_hits > 15000
    # factory calibration: hive's horizontal motor feeds our axis 0 (phase values from the bag)
    np.testing.assert_allclose(cal[0].calibration.phase, [0.031036376953125, 0.0272369384765625])
    # one time base, all near 0 .. 26 s
    for t in (angles.time, mocap.time, imu["time"]):
        assert t.min() >= 0.0 and 24.0 < t.max() < 27.0
    # the tracker rests at the start: gravity ~9.8 m/s^2 on the accelerometer
    assert abs(np.linalg.norm([imu[k][:50].mean() for k in ("ax", "ay", "az")]) - 9.8) < 0.3


def test_import_rates(imported):
    result, _ = imported
    assert result.n_sensors == 24 and len(result.serials) == 2
    for rate in result.sweep_rate_hz.values():  # each station/axis is swept at 30 Hz
        assert 27.0 < rate < 33.0
    assert 240.0 < result.imu_rate_hz < 260.0
    assert 110.0 < result.mocap_rate_hz < 125.0
    assert "stations: 2" in result.summary()


def test_off_grid_sweeps_are_dropped_on_the_bag(imported):
    """Station 0 of data8.11.bag carries stray sweeps between its regular ones (angles
    0.16-0.65 rad off their neighbours); station 1 hardly any."""
    result, out = imported
    assert result.off_grid_sweeps[0] > 20 and result.off_grid_sweeps[1] < 10
    assert "off their station's timing grid" in result.summary()
    angles = load_angles(out / "angles.csv")
    for station in (0, 1):
        for axis in (0, 1):
            m = (angles.lighthouse == station) & (angles.axis == axis)
            _, first = np.unique(angles.extra["sweep"][m], return_index=True)
            gaps = np.diff(np.sort(angles.time[m][first]))
            assert gaps.min() > 0.75 * np.median(gaps)


def test_off_grid_sweep_rule():
    rng = np.random.default_rng(0)
    t_sweep = np.arange(40) / 30.0 + rng.uniform(-0.004, 0.004, 40)  # 30 Hz, 4 ms jitter
    stray = {10: t_sweep[10] + 0.012, 25: t_sweep[25] - 0.010}  # one late, one early stray
    times = np.concatenate([t_sweep, list(stray.values())])
    ids = np.arange(len(times))
    time, sweep = np.repeat(times, 3), np.repeat(ids, 3)  # three hits per sweep
    off = off_grid_sweeps(time, np.zeros(len(time), int), np.zeros(len(time), int), sweep)
    assert set(np.unique(sweep[off])) == {40, 41}


def test_verified_axis_mapping_is_best(bag):
    checks = {c.mapping.label: c for c in check_mappings(bag, n_pairs=24)}
    best = checks[HIVE_MAPPING.label]
    assert best.median_rms_rad < 100e-6 and best.facing > 0.95
    assert 1.0 < best.median_distance_m < 5.0
    for label, c in checks.items():
        # PnP cannot tell the station frame from itself turned about its optical axis by a
        # multiple of 90 deg (swap + one flip, or both flips): those tie exactly. The mirror
        # mappings fit worse and put the sensors' backs to the station.
        if abs(c.median_rms_rad - best.median_rms_rad) < 1e-9:
            assert c.facing > 0.95
        else:
            assert c.median_rms_rad > 1.4 * best.median_rms_rad, label
            assert c.facing < 0.1, label


def test_refuses_to_overwrite_without_force(imported, hive_bag, capsys):
    _, out = imported
    before = (out / "angles.csv").stat().st_mtime_ns
    assert main(["import", "hive", str(hive_bag), "--output", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists already" in err[0]
    assert (out / "angles.csv").stat().st_mtime_ns == before


def test_cli_force_overwrites(tmp_path, hive_bag, capsys):
    (tmp_path / "angles.csv").write_text("old\n")
    assert main(["import", "hive", str(hive_bag), "-o", str(tmp_path), "--force", "--quiet"]) == 0
    assert load_angles(tmp_path / "angles.csv").stations() == [0, 1]


@pytest.mark.parametrize("content", [None, b"not a bag at all\n", b"#ROSBAG V2.0\n\x00garbage"])
def test_cli_bad_bag_is_one_line_exit_2(tmp_path, capsys, content):
    bag = tmp_path / "x.bag"
    if content is not None:
        bag.write_bytes(content)
    assert main(["import", "hive", str(bag), "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bag) in err[0]
    assert not (tmp_path / "out" / "angles.csv").exists()
