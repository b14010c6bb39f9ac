"""IMU units are checked on load (#40 item 6): an accelerometer in g or a gyro in deg/s in an
``imu.csv`` (m/s^2, rad/s) is refused with exit 2, one line naming the file, the unit and the
fix, instead of a track that fails its verdict with an unrelated message. Known answers: a
simulated stream (rad/s, m/s^2) and the same stream converted; the shared Crazyflie log's
stream, imported and converted (skipped without ../shared)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.importers.crazyflie import import_crazyflie
from lhgraph.io.imu import (
    STANDARD_GRAVITY_MPS2,
    ImuStream,
    check_units,
    gravity_coherence,
    load_imu,
    save_imu,
)
from lhgraph.sim.imu import ImuConfig
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "simulation" / "default.toml"


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("units")
    config = dataclasses.replace(load_simulation_config(CONFIG), duration_s=6.0,
                                 imu=ImuConfig(rate_hz=200.0))
    write_simulation(simulate(config, 3), folder)
    return folder


def _in_deg_s(stream: ImuStream) -> ImuStream:
    return dataclasses.replace(stream, gyro_rad_s=np.degrees(stream.gyro_rad_s))


def test_the_right_units_load_and_keep_gravity_coherent(capture):
    stream = load_imu(capture / "imu.csv")
    assert gravity_coherence(stream, 1.0) > 0.99  # the right unit de-rotates gravity
    assert gravity_coherence(_in_deg_s(stream), 1.0) < gravity_coherence(stream, 1.0) - 0.15


def test_a_gyro_in_deg_s_is_refused_naming_the_fix(capture, tmp_path):
    save_imu(_in_deg_s(load_imu(capture / "imu.csv")), tmp_path / "imu.csv")
    with pytest.raises(InputError, match="gyro reads in deg/s.*multiply gx,gy,gz by pi/180"):
        load_imu(tmp_path / "imu.csv")


def test_an_accelerometer_in_g_is_refused_naming_the_fix(capture, tmp_path):
    stream = load_imu(capture / "imu.csv")
    save_imu(dataclasses.replace(stream, accel_mps2=stream.accel_mps2 / STANDARD_GRAVITY_MPS2),
             tmp_path / "imu.csv")
    with pytest.raises(InputError, match="accelerometer reads in g.*multiply ax,ay,az by 9.8"):
        load_imu(tmp_path / "imu.csv")


def test_a_receiver_that_does_not_turn_cannot_tell_and_is_let_through():
    t = np.arange(0, 10, 0.01)
    still = ImuStream(t, np.tile([0.0, 0.0, STANDARD_GRAVITY_MPS2], (len(t), 1)),
                      np.full((len(t), 3), 0.2))  # a 0.2 deg/s bias: no rotation to go by
    check_units(still, "imu.csv")
    assert np.isnan(gravity_coherence(ImuStream(t, still.accel_mps2), 1.0))  # no gyro


def test_track_with_a_gyro_in_deg_s_exits_2_in_one_line(capture, tmp_path, capsys):
    save_imu(_in_deg_s(load_imu(capture / "imu.csv")), tmp_path / "imu_deg.csv")
    code = main(["track", "--stations", str(capture / "truth.toml"),
                 "--board", str(capture / "board.toml"), "--angles", str(capture / "angles.csv"),
                 "--imu", str(tmp_path / "imu_deg.csv"), "--output", str(tmp_path / "t.csv")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "imu_deg.csv" in err and "deg/s" in err
    assert not (tmp_path / "t.csv").exists()


def test_the_shared_crazyflie_stream_passes_and_its_conversions_do_not(shared_data, tmp_path):
    log = shared_data / "bitcraze-positioning" / "lh1_crossingBeam_move"
    import_crazyflie(log / "log02", tmp_path, log / "system-config.yaml")
    stream = load_imu(tmp_path / "imu.csv")  # the importer's m/s^2 and rad/s pass
    with pytest.raises(InputError, match="deg/s"):
        check_units(_in_deg_s(stream), "imu.csv")
    with pytest.raises(InputError, match="in g"):
        check_units(dataclasses.replace(
            stream, accel_mps2=stream.accel_mps2 / STANDARD_GRAVITY_MPS2), "imu.csv")
