"""``lhgraph export cfclient``: cfclient's system-config.yaml (LH1 and LH2 systems), read
back by cflib, in a gravity world chosen from the receiver's IMU or the stations' OOTX
accelerometers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.estimation.gravity import accel_dir_from_up
from lhgraph.estimation.world_alignment import (
    STANDARD_GRAVITY_MPS2,
    WorldOptions,
    still_mask,
    up_from_imu,
)
from lhgraph.geometry.transforms import make_pose, so3_exp
from lhgraph.io.cfclient import SystemConfig, read_system_config, write_system_config
from lhgraph.io.files import write_csv_columns
from lhgraph.io.stations import Station, Stations, save_stations
from lhgraph.io.trajectory import Trajectory, save_trajectory
from lhgraph.model.bitcraze import BITCRAZE_KEYS, calibration_from_bitcraze
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.model.station import FactoryCalibration, StationModel
from lhgraph.workflow.export import export_cfclient

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "bitcraze-positioning"
TILT = so3_exp([0.12, -0.25, 0.4])
"""R_w_true: the input world w is tilted against the true z-up world (7 + 14 deg)."""


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = a @ b / np.linalg.norm(a) / np.linalg.norm(b)
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _true_stations() -> dict[int, np.ndarray]:
    """Two stations 4 m apart, 2.5 m high, looking down at the room (true z-up world)."""
    T0 = make_pose(so3_exp([0, 0, -0.6]) @ so3_exp([0, 0.5, 0]), [-2.0, 1.5, 2.5])
    T1 = make_pose(so3_exp([0, 0, 2.4]) @ so3_exp([0, 0.45, 0]), [2.0, -1.2, 2.6])
    return {0: T0, 1: T1}


def _calibrations(up: bool = False) -> dict[int, StationCalibration]:
    """Factory calibrations like real stations' (a few mrad), ids as Bitcraze's uids."""
    out = {}
    for k, T in _true_stations().items():
        s = 1.0 + 0.3 * k
        cal = FactoryCalibration(phase=[0.018 * s, 0.054], tilt=[-0.005, 0.0035 * s],
                                 curve=[-0.0044, 0.0066 * s], gibphase=[1.7 - k, 0.55 + k],
                                 gibmag=[0.017 * s, -0.0067])
        accel = accel_dir_from_up(T[:3, :3].T @ [0, 0, 1]) if up else np.zeros(3)
        out[k] = StationCalibration(cal, 4_000_000_000 + k, accel)
    return out


def _lh2_calibrations() -> dict[int, StationCalibration]:
    """LH2 factory calibrations like the shared log's (all seven terms per light plane, in
    Bitcraze's convention, which is ours), channels 1 and 2."""
    out = {}
    for k in _true_stations():
        s = 1.0 + 0.3 * k
        cal = FactoryCalibration(phase=[0.0, 0.0032 * s], tilt=[-0.052, 0.0497 * s],
                                 curve=[-0.364 * s, 0.416], gibphase=[2.68 - k, 1.02 + k],
                                 gibmag=[-0.00073 * s, 0.0047], ogeephase=[1.22, 2.01 * s],
                                 ogeemag=[-0.292, -0.282 * s])
        out[k] = StationCalibration(cal, 3_400_000_000 + k, generation=2, channel=k + 1)
    return out


def _write_setup(tmp_path: Path, up: bool = False, generation: int | None = None,
                 calibrations: dict[int, StationCalibration] | None = None,
                 **extra: object) -> tuple[Path, Path]:
    """Stations in the tilted world w (reference 0) and their ootx.toml (default: LH1);
    ``generation`` (one for all, or None: no ``generation`` key) goes into the stations'
    models."""
    T_w_true = make_pose(TILT, [0.3, -0.2, 0.1])
    model = StationModel() if generation is None else StationModel(generation=generation)
    stations = Stations(0, {k: Station(T_w_true @ T, None, model)
                            for k, T in _true_stations().items()}, dict(extra))
    tmp_path.mkdir(parents=True, exist_ok=True)
    return (save_stations(stations, tmp_path / "stations.toml"),
            save_calibration(_calibrations(up) if calibrations is None else calibrations,
                             tmp_path / "ootx.toml"))


def _hand_held(tmp_path: Path, rest_s: float = 2.0, noise: float = 0.02,
               seed: int = 1) -> tuple[Path, Path, Trajectory]:
    """A receiver at rest for ``rest_s`` then waved for 30 s, in the tilted world w: its
    trajectory (100 Hz) and an accelerometer stream (board frame, m/s^2, 100 Hz)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, rest_s + 30.0, 0.01)
    m = np.clip(t - rest_s, 0.0, None)
    ramp = np.minimum(m / 2.0, 1.0) ** 2
    p = np.stack([0.4 * np.sin(0.9 * m), 0.3 * np.sin(1.3 * m + 1.0) - 0.3 * np.sin(1.0),
                  1.0 + 0.2 * np.sin(0.7 * m)], axis=1) * ramp[:, None]
    p[:, 2] += 0.05
    rotvec = np.stack([0.4 * np.sin(1.1 * m), 0.3 * np.sin(0.8 * m), 0.9 * np.sin(0.5 * m)],
                      axis=1) * ramp[:, None]
    R_true_board = so3_exp(rotvec + [0.0, 0.0, 0.35])
    # linear acceleration by finite differences of the analytic path (small: enough here)
    a_true = np.gradient(np.gradient(p, t, axis=0), t, axis=0)
    f_board = np.einsum("nji,nj->ni", R_true_board, a_true + [0, 0, STANDARD_GRAVITY_MPS2])
    f_board += noise * rng.standard_normal(f_board.shape)
    gyro = np.zeros_like(f_board)
    gyro[t > rest_s] = 0.5
    T_w_true = make_pose(TILT, [0.3, -0.2, 0.1])
    traj = Trajectory(t, T_w_true @ make_pose(R_true_board, p))
    imu = write_csv_columns(tmp_path / "imu.csv",
                            {"time": t, **{f"a{c}": f_board[:, i] for i, c in enumerate("xyz")},
                             **{f"g{c}": gyro[:, i] for i, c in enumerate("xyz")}}, {}, False)
    return imu, save_trajectory(traj, tmp_path / "trajectory.csv"), traj



def assert_same_system(a: dict, b: dict, system_type: int) -> None:
    """Two system-config documents ``a`` (the original) and ``b`` agree: keys, system type,
    geometry (float32 rotations are made orthonormal: 1e-6) and every calibration term."""
    assert a.keys() == b.keys() and a["systemType"] == b["systemType"] == system_type
    for k in a["geos"]:
        for key in ("origin", "rotation"):
            np.testing.assert_allclose(b["geos"][k][key], a["geos"][k][key], atol=1e-6)
    for k in a["calibs"]:
        assert b["calibs"][k]["uid"] == a["calibs"][k]["uid"]
        for s in (0, 1):
            for key, value in a["calibs"][k]["sweeps"][s].items():
                assert b["calibs"][k]["sweeps"][s][key] == pytest.approx(value, abs=1e-12)

def test_file_reads_back_with_cflib(tmp_path):
    cfm = pytest.importorskip("cflib.localization").LighthouseConfigFileManager
    stations, ootx = _write_setup(tmp_path)
    out = tmp_path / "system-config.yaml"
    result = export_cfclient(stations, out, calibration=ootx,
                             options=WorldOptions(up="none", origin="world", x="world"))
    geos, calibs, system_type = cfm.read(str(out))
    assert system_type == 1 and sorted(geos) == [0, 1] and sorted(calibs) == [0, 1]
    for k, T in result.config.T_world_lh.items():
        np.testing.assert_allclose(geos[k].origin, T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(geos[k].rotation_matrix, T[:3, :3], atol=1e-12)
        sweeps = [s.as_file_object() for s in calibs[k].sweeps]
        ours = _calibrations()[k].calibration
        theirs = calibration_from_bitcraze(sweeps)
        for key, value in ours.as_dict().items():
            np.testing.assert_allclose(getattr(theirs, key), value, atol=1e-12, err_msg=key)
        assert calibs[k].uid == 4_000_000_000 + k
    # cflib's own writer and ours agree on the document
    mine = yaml.safe_load(out.read_text())
    cfm.write(str(tmp_path / "cflib.yaml"), geos, calibs, system_type)
    assert yaml.safe_load((tmp_path / "cflib.yaml").read_text()) == mine


def test_round_trip_ours_yaml_ours(tmp_path):
    T = _true_stations()
    config = SystemConfig(1, T, _calibrations())
    back = read_system_config(write_system_config(config, tmp_path / "a.yaml"))
    assert back.system_type == 1
    for k in T:
        np.testing.assert_allclose(back.T_world_lh[k], T[k], atol=1e-12)
        assert back.calibrations[k].id == config.calibrations[k].id
        for key, value in config.calibrations[k].calibration.as_dict().items():
            np.testing.assert_allclose(getattr(back.calibrations[k].calibration, key), value,
                                       atol=1e-12)


def test_round_trip_of_the_shared_file(tmp_path):
    """YAML -> our stations TOML and ootx.toml -> export -> YAML: the same document."""
    source = SHARED / "lh1_crossingBeam_move" / "system-config.yaml"
    if not source.exists():
        pytest.skip("shared Bitcraze data not available")
    config = read_system_config(source)
    stations = save_stations(Stations(0, {k: Station(T) for k, T in config.T_world_lh.items()}),
                             tmp_path / "stations.toml")
    ootx = save_calibration(config.calibrations, tmp_path / "ootx.toml")
    out = tmp_path / "out.yaml"
    assert main(["export", "cfclient", str(stations), "--calibration", str(ootx), "--output",
                 str(out), "--up", "none", "--origin", "world", "--x", "world",
                 "--quiet"]) == 0
    assert_same_system(yaml.safe_load(source.read_text()), yaml.safe_load(out.read_text()), 1)


WORLD_AS_IS = WorldOptions(up="none", origin="world", x="world")


def test_lh2_file_reads_back_with_cflib(tmp_path):
    cfm = pytest.importorskip("cflib.localization").LighthouseConfigFileManager
    stations, ootx = _write_setup(tmp_path, generation=2, calibrations=_lh2_calibrations())
    out = tmp_path / "system-config.yaml"
    result = export_cfclient(stations, out, calibration=ootx, options=WORLD_AS_IS)
    assert result.config.system_type == 2 and "systemType 2 (LH2)" in result.summary()
    geos, calibs, system_type = cfm.read(str(out))
    assert system_type == 2 and sorted(geos) == [0, 1] and sorted(calibs) == [0, 1]
    for k, T in result.config.T_world_lh.items():
        np.testing.assert_allclose(geos[k].origin, T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(geos[k].rotation_matrix, T[:3, :3], atol=1e-12)
        ours = _lh2_calibrations()[k].calibration
        for plane, sweep in enumerate(calibs[k].sweeps):  # Bitcraze's LH2 terms are ours
            theirs = sweep.as_file_object()
            assert sorted(theirs) == sorted(BITCRAZE_KEYS)
            for key in BITCRAZE_KEYS:
                assert theirs[key] == pytest.approx(getattr(ours, key)[plane], abs=1e-12), key
        assert calibs[k].uid == 3_400_000_000 + k
    mine = yaml.safe_load(out.read_text())
    cfm.write(str(tmp_path / "cflib.yaml"), geos, calibs, system_type)
    assert yaml.safe_load((tmp_path / "cflib.yaml").read_text()) == mine


def test_lh2_round_trip_through_our_reader(tmp_path):
    """Stations TOML + ootx.toml (LH2) -> export (CLI) -> read_system_config: the poses and
    all seven terms of each plane come back, as generation-2 calibrations."""
    stations, ootx = _write_setup(tmp_path, generation=2, calibrations=_lh2_calibrations())
    out = tmp_path / "system-config.yaml"
    assert main(["export", "cfclient", str(stations), "--calibration", str(ootx), "--output",
                 str(out), "--up", "none", "--origin", "world", "--x", "world",
                 "--quiet"]) == 0
    back = read_system_config(out)
    T_w_true = make_pose(TILT, [0.3, -0.2, 0.1])
    assert back.system_type == 2 and sorted(back.T_world_lh) == [0, 1]
    for k, T in _true_stations().items():
        np.testing.assert_allclose(back.T_world_lh[k], T_w_true @ T, atol=1e-12)
        cal = back.calibrations[k]
        assert cal.generation == 2 and cal.id == 3_400_000_000 + k
        for key in BITCRAZE_KEYS:
            np.testing.assert_allclose(getattr(cal.calibration, key),
                                       getattr(_lh2_calibrations()[k].calibration, key),
                                       atol=1e-12, err_msg=key)
        assert np.any(cal.calibration.ogeemag) and np.any(cal.calibration.ogeephase)


@pytest.mark.parametrize("generation, calibration, extra, expected", [
    (2, False, {}, 2),             # the stations' models alone
    (None, True, {}, 2),           # the calibration's generation (stations file: no key)
    (None, False, {"system_type": 2}, 2),  # the old key on a file without generation keys
    (None, False, {"system_type": 1}, 1),
    (2, True, {"system_type": 2}, 2),
])
def test_system_type_from_the_generation(tmp_path, generation, calibration, extra, expected):
    stations, ootx = _write_setup(tmp_path, generation=generation,
                                  calibrations=_lh2_calibrations(), **extra)
    result = export_cfclient(stations, tmp_path / "a.yaml",
                             calibration=ootx if calibration else None, options=WORLD_AS_IS)
    assert result.config.system_type == expected
    assert read_system_config(tmp_path / "a.yaml").system_type == expected
    assert len(result.config.calibrations) == (2 if calibration else 0)


def test_mixed_or_contradicting_generations_are_refused(tmp_path, capsys):
    lh1_stations, lh1_ootx = _write_setup(tmp_path / "lh1")
    lh2_stations, lh2_ootx = _write_setup(tmp_path / "lh2", generation=2,
                                          calibrations=_lh2_calibrations())
    mixed_cal = {0: _lh2_calibrations()[0], 1: _calibrations()[1]}
    _, mixed_ootx = _write_setup(tmp_path / "mixed_cal", calibrations=mixed_cal)
    mixed = tmp_path / "mixed.toml"  # station 0 LH2, station 1 LH1 (no generation key)
    mixed.write_text(lh1_stations.read_text().replace("[lighthouses.0]\n",
                                                      "[lighthouses.0]\ngeneration = 2\n"))
    lh2_old_key, _ = _write_setup(tmp_path / "key1", generation=2, system_type=1)
    lh1_old_key, _ = _write_setup(tmp_path / "key2", system_type=2)
    bad_key, _ = _write_setup(tmp_path / "key3", system_type=3)
    list_key, _ = _write_setup(tmp_path / "key4", system_type=[2])
    out = tmp_path / "out" / "system-config.yaml"

    def export(stations: Path, *more: str) -> list[str]:
        return ["export", "cfclient", str(stations), "--output", str(out), *more]
    cases = [
        (export(mixed), "mixed generations in the stations file (LH1: station(s) 1; LH2: "
         "station(s) 0)"),
        (export(lh1_stations, "--calibration", str(mixed_ootx)),
         "mixed generations in the calibration file"),
        (export(lh2_stations, "--calibration", str(lh1_ootx)),
         "the stations file says LH2 (generation = 2) but the calibration"),
        (export(lh2_old_key), "system_type = 1 (LH1) contradicts"),
        (export(lh1_old_key, "--calibration", str(lh1_ootx)),
         "system_type = 2 (LH2) contradicts the calibration's generation"),
        (export(bad_key), "system_type must be 1 (LH1) or 2 (LH2), got 3"),
        (export(list_key), "system_type must be 1 (LH1) or 2 (LH2), got [2]"),
    ]
    for args, match in cases:
        _one_line_refusal(capsys, args, match)
        assert not out.exists() and not out.parent.exists()
    assert main(export(lh2_stations, "--calibration", str(lh2_ootx), "--quiet")) == 0
    assert read_system_config(out).system_type == 2


def test_lh2_shared_log_import_then_export_reproduces_its_file(tmp_path):
    """``lhgraph import crazyflie`` of the shared LH2 log with its system-config.yaml, then
    the export of its stations-cfclient.toml with its ootx.toml: cfclient's file again
    (geometry to float32 precision, the calibration terms exactly)."""
    data = SHARED / "lh2_crossingBeam_move"
    if not (data / "log00").exists() or not (data / "system-config.yaml").exists():
        pytest.skip("shared Bitcraze LH2 log not available")
    imported = tmp_path / "import"
    assert main(["import", "crazyflie", str(data / "log00"), "--system-config",
                 str(data / "system-config.yaml"), "--output", str(imported), "--quiet"]) == 0
    out = tmp_path / "system-config.yaml"
    assert main(["export", "cfclient", str(imported / "stations-cfclient.toml"),
                 "--calibration", str(imported / "ootx.toml"), "--output", str(out),
                 "--up", "none", "--origin", "world", "--x", "world", "--quiet"]) == 0
    a, b = yaml.safe_load((data / "system-config.yaml").read_text()), yaml.safe_load(
        out.read_text())
    assert a["geos"].keys() == b["geos"].keys() and a["calibs"].keys() == b["calibs"].keys()
    for k in a["calibs"]:
        for s in (0, 1):
            assert b["calibs"][k]["sweeps"][s].keys() == a["calibs"][k]["sweeps"][s].keys()
    assert_same_system(a, b, 2)


def test_still_mask_finds_the_rest():
    t = np.arange(0.0, 10.0, 0.01)
    a = np.tile([0.0, 0.0, STANDARD_GRAVITY_MPS2], (len(t), 1))
    a[t > 4.0] += 3.0 * np.sin(7.0 * t[t > 4.0])[:, None]
    still = still_mask(t, a, None)
    assert np.all(still[t < 3.7]) and not np.any(still[t > 4.3])
    gyro = np.zeros_like(a)
    gyro[t < 2.0] = 0.3  # turning at constant rate: not at rest
    assert not np.any(still_mask(t, a, gyro)[t < 1.7])


@pytest.mark.parametrize("samples, tol_deg", [("still", 0.1), ("all", 0.3)])
def test_imu_gravity_world_has_z_up(tmp_path, samples, tol_deg):
    _, _, traj = _hand_held(tmp_path)
    stream = np.loadtxt(tmp_path / "imu.csv", delimiter=",", skiprows=1)
    up = up_from_imu(stream[:, 0], stream[:, 1:4], stream[:, 4:7], traj,
                     WorldOptions(imu_samples=samples))
    assert up.samples == samples and up.consistency > 0.95
    assert angle_deg(up.up_world, TILT[:, 2]) < tol_deg  # true z in w


def test_export_in_the_imu_world(tmp_path):
    stations, ootx = _write_setup(tmp_path)
    imu, trajectory, traj = _hand_held(tmp_path)
    out = tmp_path / "system-config.yaml"
    assert main(["export", "cfclient", str(stations), "--calibration", str(ootx), "--imu",
                 str(imu), "--trajectory", str(trajectory), "--output", str(out),
                 "--quiet"]) == 0
    written = read_system_config(out)
    truth = _true_stations()
    start = traj.T_world_board[0]
    T_w_true = make_pose(TILT, [0.3, -0.2, 0.1])
    T_true_start = np.linalg.inv(T_w_true) @ start
    for k, T in written.T_world_lh.items():
        # z up: each station's tilt matches the truth within a small angle
        assert angle_deg(T[:3, :3].T @ [0, 0, 1], truth[k][:3, :3].T @ [0, 0, 1]) < 0.1
        # origin at the receiver's start: station heights relative to it
        assert T[2, 3] == pytest.approx(truth[k][2, 3] - T_true_start[2, 3], abs=5e-3)


def test_receiver_start_puts_the_receiver_at_the_origin(tmp_path):
    stations, ootx = _write_setup(tmp_path)
    _, trajectory, traj = _hand_held(tmp_path)
    # cfclient's origin is the receiver resting on the floor: not while it is waved
    with pytest.raises(InputError, match="moving at t = 10.000 s"):
        export_cfclient(stations, tmp_path / "a.yaml", imu=tmp_path / "imu.csv",
                        trajectory=trajectory, options=WorldOptions(at_s=10.0))
    result = export_cfclient(stations, tmp_path / "a.yaml", imu=tmp_path / "imu.csv",
                             trajectory=trajectory, options=WorldOptions(at_s=1.0))
    T = result.alignment.T_new_w @ traj.at(np.array([1.0]))[0]
    np.testing.assert_allclose(T[:3, 3], 0.0, atol=1e-9)
    assert abs(T[1, 0]) < 1e-9 and T[0, 0] > 0  # receiver's x: the world's +x, tilted only
    assert result.alignment.origin == result.alignment.x == "receiver-start"


def test_export_in_the_ootx_world(tmp_path):
    stations, ootx = _write_setup(tmp_path, up=True)
    result = export_cfclient(stations, tmp_path / "a.yaml", calibration=ootx)
    assert result.alignment.up.source == "ootx" and result.alignment.origin == (
        "reference-station")
    truth = _true_stations()
    for k, T in result.config.T_world_lh.items():
        # accel_dir is int8: about 0.5 deg of rounding
        assert angle_deg(T[:3, :3].T @ [0, 0, 1], truth[k][:3, :3].T @ [0, 0, 1]) < 1.0
    np.testing.assert_allclose(result.config.T_world_lh[0][:3, 3], 0.0, atol=1e-12)
    assert abs(result.config.T_world_lh[0][1, 0]) < 1e-12  # forward axis along +x


def _one_line_refusal(capsys, args: list[str], match: str) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and match in err, err


def test_bad_inputs_exit_2_one_line_nothing_written(tmp_path, capsys):
    stations, ootx = _write_setup(tmp_path)
    imu, trajectory, _ = _hand_held(tmp_path)
    stream = np.loadtxt(imu, delimiter=",", skiprows=1)
    g_units = write_csv_columns(tmp_path / "imu_g.csv", {
        "time": stream[:, 0], **{f"a{c}": stream[:, 1 + i] / STANDARD_GRAVITY_MPS2
                                 for i, c in enumerate("xyz")}}, {}, False)
    bad_yaml = tmp_path / "bad.yaml"
    bad_yaml.write_text("type: lighthouse_system_configuration\nversion: '1'\nsystemType: 1\n"
                        "geos:\n  0: {origin: [0, 0, 0], rotation: [[1, 0, 0], [0, 1, 0], "
                        "[0, 0, 2]]}\n")
    out = tmp_path / "out" / "system-config.yaml"
    base = ["export", "cfclient", str(stations), "--output", str(out)]
    cases = [
        (["export", "cfclient", str(tmp_path / "none.toml"), "--output", str(out)],
         "file not found"),
        (base + ["--imu", str(imu)], "--imu needs --trajectory"),
        (base + ["--up", "imu"], "--up imu needs"),
        (base + ["--up", "ootx"], "--up ootx needs"),
        (base + ["--up", "ootx", "--calibration", str(ootx)], "no accelerometer vector"),
        (base + ["--origin", "receiver-start"], "needs the receiver's trajectory"),
        (base + ["--trajectory", str(trajectory), "--at", "99"], "outside the trajectory"),
        (base + ["--imu", str(g_units), "--trajectory", str(trajectory)], "m/s^2"),
        (base + ["--calibration", str(imu)], "not valid TOML"),
    ]
    for args, match in cases:
        _one_line_refusal(capsys, args, match)
        assert not out.exists() and not out.parent.exists()
    out.parent.mkdir()
    out.write_text("keep")
    _one_line_refusal(capsys, base, "exists already")
    assert out.read_text() == "keep"
    with pytest.raises(InputError, match="not a rotation matrix"):
        read_system_config(bad_yaml)
    with pytest.raises(InputError, match="type must be"):
        bad_yaml.write_text("geos: {}\n")
        read_system_config(bad_yaml)


def test_no_still_period_falls_back_to_all_samples(tmp_path):
    _, _, traj = _hand_held(tmp_path, rest_s=0.0)
    stream = np.loadtxt(tmp_path / "imu.csv", delimiter=",", skiprows=1)
    up = up_from_imu(stream[:, 0], stream[:, 1:4], stream[:, 4:7], traj)
    assert up.samples == "all" and angle_deg(up.up_world, TILT[:, 2]) < 0.5
    with pytest.raises(InputError, match="no still IMU sample"):
        up_from_imu(stream[:, 0], stream[:, 1:4], stream[:, 4:7], traj,
                    WorldOptions(imu_samples="still"))


def test_an_imu_in_the_wrong_frame_is_flagged(tmp_path):
    stations, _ = _write_setup(tmp_path)
    imu, trajectory, _ = _hand_held(tmp_path)
    stream = np.loadtxt(imu, delimiter=",", skiprows=1)
    turned = write_csv_columns(tmp_path / "turned.csv", {  # axes x <- z, z <- -x
        "time": stream[:, 0], "ax": stream[:, 3], "ay": stream[:, 2], "az": -stream[:, 1]},
        {}, False)
    # (samples at rest in one orientation cannot reveal a wrong frame: the motion can)
    with pytest.raises(InputError, match="agree poorly .* track it with --imu"):
        export_cfclient(stations, tmp_path / "a.yaml", imu=turned, trajectory=trajectory,
                        options=WorldOptions(imu_samples="all"))
    assert not (tmp_path / "a.yaml").exists()
