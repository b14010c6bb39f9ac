"""Contract files: round trips and one-line errors (file, row/key, exit code 2)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lhgraph.errors import InputError
from lhgraph.estimation.metrics import station_errors
from lhgraph.geometry.transforms import se3_exp, so3_exp
from lhgraph.io.angles import Angles, load_angles, save_angles
from lhgraph.io.stations import Station, Stations, load_stations, save_stations
from lhgraph.io.trajectory import Trajectory, load_trajectory, save_trajectory
from lhgraph.model.board import load_board, make_board, save_board
from lhgraph.model.calibration import StationCalibration, load_calibration, save_calibration
from lhgraph.model.station import FactoryCalibration, StationModel

HEADER = "time,lighthouse,axis,sensor,angle\n"


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_angles_round_trip_with_extra_column(tmp_path):
    rng = np.random.default_rng(0)
    n = 50
    a = Angles(np.sort(rng.uniform(0, 1, n)), rng.integers(0, 2, n), rng.integers(0, 2, n),
               rng.integers(0, 32, n), rng.uniform(-1, 1, n), {"sweep": np.arange(n)})
    path = save_angles(a, tmp_path / "a.csv")
    b = load_angles(path)
    np.testing.assert_allclose(b.time, a.time, atol=1e-9)
    np.testing.assert_array_equal(b.sensor, a.sensor)
    np.testing.assert_allclose(b.angle, a.angle, rtol=1e-11)
    np.testing.assert_array_equal(b.extra["sweep"], a.extra["sweep"])
    with pytest.raises(InputError, match="exists already"):
        save_angles(a, path)


@pytest.mark.parametrize(("text", "message"), [
    ("time,lighthouse,axis,angle\n0.1,0,0,0.2\n", "missing column"),
    (HEADER + "0.1,0,0,3,nan\n", "value is nan"),
    (HEADER + "0.1,0,0,3,abc\n", "expected a number"),
    (HEADER + "0.1,0,2,3,0.1\n", "axis must be 0 or 1"),
    (HEADER + "0.2,0,0,3,0.1\n0.1,0,0,3,0.1\n", "time goes backwards"),
    (HEADER + "0.1,0,0,3.5,0.1\n", "expected an integer"),
    (HEADER + "0.1,0,0,3\n", "expected 5 fields"),
    (HEADER, "no rows"),
    ("", "empty file"),
])
def test_bad_angles_name_file_and_row(tmp_path, text, message):
    path = _write(tmp_path, "bad.csv", text)
    with pytest.raises(InputError, match=message) as info:
        load_angles(path)
    assert str(path) in str(info.value)


def test_board_round_trip_and_unknown_sensor(tmp_path):
    rng = np.random.default_rng(1)
    board = make_board(rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), [3, 1, 4, 10, 5], "b")
    path = save_board(board, tmp_path / "b.toml")
    back = load_board(path)
    np.testing.assert_array_equal(back.ids, board.ids)
    np.testing.assert_allclose(back.positions, board.positions)
    np.testing.assert_allclose(np.linalg.norm(back.normals, axis=1), 1.0)
    np.testing.assert_array_equal(back.index_of([10, 3]), [3, 0])
    with pytest.raises(InputError, match=r"sensor id\(s\) \[7\]"):
        back.index_of([3, 7], "angles.csv")


@pytest.mark.parametrize(("text", "message"), [
    ("[[sensors]]\nid = 1\nposition = [0, 0]\nnormal = [0, 0, 1]\n",
     r"sensors\[0\]\.position: expected a list of 3"),
    ("[[sensors]]\nid = 1\nnormal = [0, 0, 1]\n", "missing key 'position'"),
    ("[[sensors]]\nid = 'a'\nposition = [0, 0, 0]\nnormal = [0, 0, 1]\n", "expected an integer"),
    ("sensors = 3\n", "at least one"),
    ("[[sensors]\n", "not valid TOML"),
])
def test_bad_board(tmp_path, text, message):
    path = _write(tmp_path, "board.toml", text)
    with pytest.raises(InputError, match=message):
        load_board(path)


def test_stations_round_trip_with_covariance_and_calibration(tmp_path):
    cal = FactoryCalibration(phase=[0.01, 0.02], tilt=[0.0, 0.001], curve=[0.0, 0.0],
                             gibphase=[1.0, 2.0], gibmag=[0.003, 0.0])
    T1 = se3_exp([0.1, 0.2, 0.3, 1.0, 2.0, 0.5])
    stations = Stations(0, {0: Station(np.eye(4)),
                            1: Station(T1, np.diag(np.arange(1.0, 7.0)), StationModel(cal))})
    path = save_stations(stations, tmp_path / "s.toml")
    back = load_stations(path)
    np.testing.assert_allclose(back.pose(1), T1, atol=1e-12)
    np.testing.assert_allclose(back.stations[1].covariance, np.diag(np.arange(1.0, 7.0)))
    np.testing.assert_allclose(back.stations[1].model.calibration.gibphase, [1.0, 2.0])
    assert back.stations[0].covariance is None


def test_bad_stations(tmp_path):
    path = _write(tmp_path, "s.toml", "reference = 2\n[lighthouses.0]\nposition = [0, 0, 0]\n"
                  "quaternion = [1, 0, 0, 0]\n")
    with pytest.raises(InputError, match="reference station 2"):
        load_stations(path)
    path = _write(tmp_path, "s2.toml", "reference = 0\n[lighthouses.0]\nposition = [0, 0, 0]\n"
                  "quaternion = [2, 0, 0, 0]\n")
    with pytest.raises(InputError, match="quaternion norm"):
        load_stations(path)


def test_calibration_round_trip(tmp_path):
    cal = {1: StationCalibration(FactoryCalibration(phase=[0.05, 0.06]), 178605925,
                                 np.array([0.0, 0.0, 127.0]))}
    back = load_calibration(save_calibration(cal, tmp_path / "ootx.toml"))
    assert back[1].id == 178605925
    np.testing.assert_allclose(back[1].calibration.phase, [0.05, 0.06])
    np.testing.assert_allclose(back[1].accel_dir, [0, 0, 127])


def test_trajectory_round_trip_and_errors(tmp_path):
    T = se3_exp(np.random.default_rng(2).normal(size=(4, 6)))
    traj = Trajectory(np.array([0.0, 0.1, 0.2, 0.3]), T)
    back = load_trajectory(save_trajectory(traj, tmp_path / "t.csv"))
    np.testing.assert_allclose(back.T_world_board, T, atol=1e-8)
    bad = _write(tmp_path, "bad.csv", "time,x,y,z,qw,qx,qy,qz\n0.2,0,0,0,1,0,0,0\n"
                 "0.1,0,0,0,1,0,0,0\n")
    with pytest.raises(InputError, match="time must increase"):
        load_trajectory(bad)


def test_metrics_known_error():
    T1 = np.eye(4)
    T1[:3, 3] = [2.0, 0.0, 0.0]
    T1_est = T1.copy()
    T1_est[:3, 3] += [0.001, -0.002, 0.003]
    T1_est[:3, :3] = so3_exp([0.0, 0.0, np.radians(0.5)])
    ref = se3_exp([0.3, -0.2, 0.1, 1.0, 2.0, 3.0])  # truth expressed in another world frame
    truth = Stations(0, {0: Station(ref), 1: Station(ref @ T1)})
    est = Stations(0, {0: Station(np.eye(4)), 1: Station(T1_est)})
    (e,) = station_errors(truth, est)
    np.testing.assert_allclose(e.position_m, [0.001, 0.002, 0.003], atol=1e-12)
    np.testing.assert_allclose(np.degrees(e.euler_rad), [0, 0, 0.5], atol=1e-9)


def test_cli_bad_input_is_one_line_exit_2(tmp_path):
    bad = _write(tmp_path, "a.csv", HEADER + "0.1,0,0,3,abc\n")
    board = _write(tmp_path, "b.toml", "[[sensors]]\nid = 3\nposition = [0, 0, 0]\n"
                   "normal = [0, 0, 1]\n")
    proc = subprocess.run(
        [sys.executable, "-m", "lhgraph", "solve", "--board", str(board), "--angles", str(bad),
         "--output", str(tmp_path / "out.toml")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "a.csv:2" in lines[0] and "Traceback" not in proc.stderr
    assert not (tmp_path / "out.toml").exists()


def test_angles_csv_with_byte_order_mark(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + (HEADER + "0.1,0,0,3,0.2\n0.2,1,1,4,-0.3\n").encode())
    a = load_angles(path)
    np.testing.assert_array_equal(a.sensor, [3, 4])
    assert a.extra == {}


def test_duplicate_hits_are_refused_with_their_line(tmp_path):
    rows = "0.1,0,0,3,0.2\n0.1,0,0,4,0.2\n0.1,0,0,3,0.2\n0.2,0,0,3,0.25\n0.2,0,0,3,0.25\n"
    path = _write(tmp_path, "dup.csv", HEADER + rows)
    with pytest.raises(InputError, match=r"dup\.csv:4: repeats an earlier row.*2 such rows"):
        load_angles(path)
    # same time and sensor but another angle is not a duplicate row
    load_angles(_write(tmp_path, "ok.csv", HEADER + "0.1,0,0,3,0.2\n0.1,0,0,3,0.21\n"))


def test_atomic_writer_refuses_and_leaves_nothing(tmp_path, monkeypatch):
    from lhgraph.io.files import check_writable, write_atomic

    target = write_atomic(tmp_path / "sub" / "a.txt", b"one")  # creates the directory
    assert target.read_bytes() == b"one"
    with pytest.raises(InputError, match="exists already"):
        write_atomic(target, b"two")
    assert write_atomic(target, b"two", overwrite=True).read_bytes() == b"two"
    with pytest.raises(InputError, match="is a directory"):
        write_atomic(tmp_path / "sub", b"x", overwrite=True)
    with pytest.raises(InputError, match=r"a\.txt: is not a directory"):
        write_atomic(target / "under" / "b.txt", b"x")
    with pytest.raises(InputError, match="is not a directory"):
        check_writable(target / "b.txt", False, create_parents=False)
    check_writable(tmp_path / "new" / "c.txt", False, create_parents=False)
    assert not (tmp_path / "new").exists()

    def broken_fsync(fd: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("os.fsync", broken_fsync)
    with pytest.raises(InputError, match="c.txt: cannot write: No space left"):
        write_atomic(tmp_path / "sub" / "c.txt", b"x")
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["a.txt"]


def test_read_only_directory_is_refused(tmp_path):
    import os

    from lhgraph.io.files import write_atomic

    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("this user may write into read-only directories (root)")
        with pytest.raises(InputError, match="locked: directory is not writable"):
            write_atomic(locked / "a.txt", b"x")
    finally:
        locked.chmod(0o755)


def test_cli_output_under_a_file_is_one_line_exit_2(tmp_path):
    angles = _write(tmp_path, "a.csv", HEADER + "0.1,0,0,3,0.1\n")
    board = _write(tmp_path, "b.toml", "[[sensors]]\nid = 3\nposition = [0, 0, 0]\n"
                   "normal = [0, 0, 1]\n")
    proc = subprocess.run(
        [sys.executable, "-m", "lhgraph", "solve", "--board", str(board), "--angles",
         str(angles), "--output", str(angles / "out.toml")],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "a.csv: is not a directory" in lines[0]
    assert "Traceback" not in proc.stderr


LH2_CAL = FactoryCalibration(phase=[0.0, 0.0032], tilt=[-0.052, 0.0497], curve=[-0.36, 0.42],
                             gibphase=[2.68, 1.02], gibmag=[-0.0007, -0.0016],
                             ogeephase=[1.22, 2.01], ogeemag=[-0.29, -0.28])


def test_lh2_keys_round_trip_in_both_files(tmp_path):
    T1 = se3_exp([0.1, 0.2, 0.3, 1.0, 2.0, 0.5])
    lh2 = StationModel(LH2_CAL, generation=2, channel=5)
    stations = Stations(0, {0: Station(np.eye(4), None, StationModel(generation=2, channel=1)),
                            1: Station(T1, None, lh2)})
    back = load_stations(save_stations(stations, tmp_path / "s.toml"))
    assert back.stations[0].model.generation == 2 and back.stations[0].model.channel == 1
    m = back.stations[1].model
    assert (m.generation, m.channel) == (2, 5)
    for key in ("tilt", "curve", "ogeephase", "ogeemag"):
        np.testing.assert_allclose(getattr(m.calibration, key), getattr(LH2_CAL, key))
    cal = {3: StationCalibration(LH2_CAL, 617301407, generation=2, channel=2)}
    c = load_calibration(save_calibration(cal, tmp_path / "ootx.toml"))[3]
    assert (c.generation, c.channel, c.id) == (2, 2, 617301407)
    np.testing.assert_allclose(c.calibration.ogeemag, LH2_CAL.ogeemag)
    assert c.model().generation == 2


def test_lh1_files_keep_their_keys(tmp_path):
    # an LH1 station writes neither generation nor the LH2 terms: old readers see old files
    cal = {0: StationCalibration(FactoryCalibration(phase=[0.05, 0.06]), 1)}
    text = save_calibration(cal, tmp_path / "ootx.toml").read_text()
    assert "generation" not in text and "ogee" not in text and "channel" not in text
    back = load_calibration(tmp_path / "ootx.toml")[0]
    assert back.generation == 1 and back.channel is None
    st = Stations(0, {0: Station(np.eye(4), None, StationModel(FactoryCalibration(
        phase=[0.01, 0.0])))})
    text = save_stations(st, tmp_path / "s.toml").read_text()
    assert "generation" not in text and "ogee" not in text


@pytest.mark.parametrize("extra, message", [
    ("generation = 3\n", "generation must be 1 or 2"),
    ("generation = 2\nchannel = 17\n", "channel must be 1-16"),
    ("generation = 2\nchannel = 0\n", "channel must be 1-16"),
    ("ogeemag = [0.1, 0.2]\n", "LH2 term: set generation = 2"),
    ("generation = 2\nogeemag = [0.1]\n", "ogeemag"),
    ("generation = \"2\"\n", "expected an integer"),
])
def test_bad_lh2_keys_name_file_and_key(tmp_path, extra, message):
    table = ("[lighthouses.0]\nid = 1\nphase = [0, 0]\ntilt = [0, 0]\ncurve = [0, 0]\n"
             "gibphase = [0, 0]\ngibmag = [0, 0]\n")
    ootx = _write(tmp_path, "ootx.toml", table + extra)
    with pytest.raises(InputError, match=message) as err:
        load_calibration(ootx)
    assert "ootx.toml:lighthouses.0" in str(err.value)
    stations = _write(tmp_path, "s.toml", "reference = 0\n[lighthouses.0]\nposition = [0, 0, 0]"
                      "\nquaternion = [1, 0, 0, 0]\n" + extra)
    with pytest.raises(InputError, match=message):
        load_stations(stations)


def test_unreadable_inputs_name_the_file_and_the_reason(tmp_path):
    from lhgraph.cli import main
    from lhgraph.io.files import read_toml

    a_file = _write(tmp_path, "log00", "not a folder")
    under = a_file / ".." / "system-config.yaml"  # what `LOG/../x` gives when LOG is a file
    with pytest.raises(InputError, match=r"system-config\.yaml: file not found \(a folder"):
        read_toml(under)
    with pytest.raises(InputError, match=r"angles\.csv: file not found \(a folder"):
        load_angles(a_file / "angles.csv")
    with pytest.raises(InputError, match="is a directory, expected a TOML file"):
        read_toml(tmp_path)
    assert main(["import", "crazyflie", str(a_file), "--system-config", str(under),
                 "--output", str(tmp_path / "out")]) == 2


def test_out_of_range_integers_and_degenerate_boards_are_refused(tmp_path):
    # an integer beyond 2^53 in a CSV (quoted or not) or a TOML, a board whose sensors all sit
    # at one point or 1e308 m away: one line naming the file and the place
    header = "time,lighthouse,axis,sensor,angle\n"
    for row in ('0.1,0,1,99999999999999999999999,0.1\n',
                '0.1,0,1,"99999999999999999999999",0.1\n'):
        with pytest.raises(InputError, match=r"big\.csv:2: column 'sensor': .* out of range"):
            load_angles(_write(tmp_path, "big.csv", header + row))
    sensor = "[[sensors]]\nid = {id}\nposition = {p}\nnormal = [0.0, 0.0, 1.0]\n"
    cases = {"id": (sensor.format(id=2**63, p="[0.0, 0.0, 0.0]"), "out of range"),
             "point": (sensor.format(id=0, p="[0.0, 0.0, 0.0]")
                       + sensor.format(id=1, p="[0.0, 0.0, 0.0]"), "span less than 1 mm"),
             "far": (sensor.format(id=0, p="[1e308, 0.0, 0.0]")
                     + sensor.format(id=1, p="[0.0, 0.0, 0.0]"), "more than 10 m")}
    for name, (text, message) in cases.items():
        with pytest.raises(InputError, match=rf"{name}\.toml:sensors.*{message}"):
            load_board(_write(tmp_path, f"{name}.toml", text))


def test_bom_station_indices_and_large_sweep_numbers(tmp_path):
    from lhgraph.io.files import read_toml

    assert read_toml(_write(tmp_path, "bom.toml", "\ufeff[a]\nb = 1\n")) == {"a": {"b": 1}}
    table = "[lighthouses.{}]\nposition = [0.0, 0.0, 0.0]\nquaternion = [1.0, 0.0, 0.0, 0.0]\n"
    for text, message in ((table.format("-1"), "must be >= 0"),
                          (table.format("1") + table.format("01"), "station 1 given twice")):
        with pytest.raises(InputError, match=message):
            load_stations(_write(tmp_path, "st.toml", "reference = 0\n" + text))
    # sweep numbers are keyed with the station, not packed into one integer: sweep 1 of
    # station 64 and sweep 2 of station 0 stay two sweeps
    header = "time,lighthouse,axis,sensor,angle,sweep\n"
    angles = load_angles(_write(tmp_path, "sw.csv", header + "0.1,64,0,0,0.1,1\n"
                                "0.1,0,0,0,0.1,2\n0.1,0,0,1,0.1,2\n"))
    assert sorted(np.bincount(angles.sweep_ids()).tolist()) == [1, 2]
