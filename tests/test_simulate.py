"""Capture simulator: agreement with its own truth, quantisation, schedule, visibility, noise,
files, configs and the CLI."""

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.geometry.transforms import inverse, transform_points
from lhgraph.io.angles import load_angles
from lhgraph.io.stations import load_stations
from lhgraph.io.trajectory import load_trajectory
from lhgraph.model.board import load_board
from lhgraph.model.station import FactoryCalibration, StationModel, predict, sweep_angle
from lhgraph.signal.pulses import LightPulses
from lhgraph.sim.config import (
    ROTOR_PERIOD_S,
    MotionConfig,
    NoiseConfig,
    VisibilityConfig,
    default_config_text,
    default_simulation_config,
    load_simulation_config,
    paper_protocol,
)
from lhgraph.sim.simulate import (
    SYNC_SPACING_S,
    scene_of,
    simulate,
    solve_hit_times,
    write_simulation,
)

ROOT = Path(__file__).resolve().parent.parent
SIM_CONFIGS = ROOT / "configs" / "simulation"
FS = 2e6
# 2 MHz quantisation of the sync start (uniform, var 1/12) and of the pulse centre
# (mean of two independent edges, var 1/24), in rad
Q_RMS = np.sqrt(1 / 12 + 1 / 24) * 2 * np.pi / (ROTOR_PERIOD_S * FS)
SAMPLE_RAD = 2 * np.pi / (ROTOR_PERIOD_S * FS)


def residuals(cap, angles=None, trajectory=None, stations=None, board=None, times=None):
    """Measured minus predicted angles, the board pose interpolated at ``times``."""
    a = cap.angles if angles is None else angles
    traj = cap.trajectory if trajectory is None else trajectory
    truth = cap.truth if stations is None else stations
    board = cap.board if board is None else board
    times = a.time if times is None else times
    res = np.empty(len(a))
    for k in truth.indices():
        sel = a.lighthouse == k
        s = board.positions[board.index_of(a.sensor[sel])]
        res[sel] = a.angle[sel] - predict(truth.pose(k), traj.at(times[sel]), s, a.axis[sel],
                                          truth.stations[k].model)
    return res


@pytest.fixture(scope="module")
def default():
    return default_simulation_config()


@pytest.fixture(scope="module")
def capture(default):
    return simulate(replace(default, duration_s=3.0), seed=7)


def test_angles_agree_with_written_truth(capture, tmp_path):
    paths = write_simulation(capture, tmp_path)
    a = load_angles(paths["angles"])
    res = residuals(capture, a, load_trajectory(paths["trajectory"]),
                    load_stations(paths["truth"]), load_board(paths["board"]))
    assert len(a) > 10000
    assert np.sqrt(np.mean(res**2)) < 1.15 * Q_RMS
    assert np.max(np.abs(res)) < 1.05 * SAMPLE_RAD * 1.5  # sync and centre each < 1 sample


def test_quantisation_statistics(default):
    res = np.concatenate([residuals(simulate(default, seed=s)) for s in (11, 12, 13)])
    assert abs(np.std(res) / Q_RMS - 1) < 0.05
    assert abs(np.mean(res)) < 0.05 * Q_RMS


def test_written_files_round_trip(capture, tmp_path):
    paths = write_simulation(capture, tmp_path)
    a = load_angles(paths["angles"])
    for name in ("time", "lighthouse", "axis", "sensor"):
        np.testing.assert_array_equal(getattr(a, name), getattr(capture.angles, name))
    np.testing.assert_allclose(a.angle, capture.angles.angle, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.extra["sweep"], capture.angles.extra["sweep"])
    truth = load_stations(paths["truth"])
    assert truth.reference == 0 and truth.indices() == [0, 1]
    np.testing.assert_allclose(truth.pose(0), np.eye(4), atol=1e-15)
    np.testing.assert_allclose(truth.pose(1), capture.truth.pose(1), atol=1e-12)
    traj = load_trajectory(paths["trajectory"])
    np.testing.assert_array_equal(traj.time, capture.trajectory.time)
    np.testing.assert_allclose(traj.T_world_board, capture.trajectory.T_world_board, atol=1e-9)
    board = load_board(paths["board"])
    np.testing.assert_array_equal(board.positions, capture.board.positions)
    with pytest.raises(InputError, match="exists already"):
        write_simulation(capture, tmp_path)
    write_simulation(capture, tmp_path, overwrite=True)


def test_decoded_angle_and_time_from_samples(capture):
    """angles.csv is what a decoder computes from the quantised pulse edges and sync starts."""
    a, p, slots = capture.angles, capture.pulses, capture.slots
    centre = (p.start + p.end) / 2
    np.testing.assert_array_equal(a.time, centre / FS)
    sync = slots.sync_start_sample[a.extra["sweep"], a.lighthouse]
    Ts = slots.period_samples
    np.testing.assert_allclose(a.angle, (centre - sync - Ts / 4) * 2 * np.pi / Ts, atol=1e-15)
    assert np.all(slots.sweeping[a.extra["sweep"]] == a.lighthouse)
    assert np.all(slots.axis[a.extra["sweep"]] == a.axis)
    assert np.all(p.kind == LightPulses.SWEEP)
    # pulse width model: ~10 us at 2.5-3 m
    width_us = (p.end - p.start) / FS * 1e6
    assert 8 < np.median(width_us) < 13


def test_hit_time_solve_with_factory_model_and_motion(default):
    config = replace(default, duration_s=1.0, motion=replace(default.motion, speed_mps=2.0))
    cap = simulate(config, seed=3)
    model = StationModel(FactoryCalibration(phase=[0.02, -0.01], tilt=[0.01, -0.02],
                                            curve=[0.003, 0.002], gibphase=[0.5, 1.5],
                                            gibmag=[0.004, -0.003]),
                         rotor_offsets=[[0.0, 0.01, 0.02], [-0.01, 0.0, 0.015]])
    T_world_lh = cap.truth.stations[0].T_world_lh[None]
    t_sync = np.full(32, 0.5)
    zeros = np.zeros(32, dtype=int)
    t, T_wb, p_lh = solve_hit_times(cap.motion, T_world_lh, [model], cap.board.positions,
                                    t_sync, zeros, zeros + 1)
    angle = sweep_angle(p_lh, zeros + 1, model)
    np.testing.assert_allclose(angle, (t - t_sync - ROTOR_PERIOD_S / 4) * 120 * np.pi,
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(T_wb, cap.motion.pose(t), atol=1e-15)
    p_expected = transform_points(inverse(T_world_lh[0]),
                                  transform_points(T_wb, cap.board.positions))
    np.testing.assert_allclose(p_lh, p_expected, atol=1e-15)


def test_each_diode_hit_at_its_own_time(default):
    """With quantisation made negligible (1 GHz), angles match the motion at each hit's own
    time; one time per sweep (diodes hit ~100 us apart) leaves a visible error."""
    config = replace(default, duration_s=1.0, sample_rate_hz=1e9,
                     motion=replace(default.motion, speed_mps=2.0))
    cap = simulate(config, seed=3)
    sweep = cap.angles.extra["sweep"]
    span = np.array([np.ptp(cap.angles.time[sweep == k]) for k in np.unique(sweep)])
    assert np.median(span) > 50e-6
    exact = SimpleNamespace(at=cap.motion.pose)  # the 1 ms trajectory is too coarse here
    res = residuals(cap, trajectory=exact)
    mean_time = np.bincount(sweep, cap.angles.time) / np.maximum(np.bincount(sweep), 1)
    res_sweep = residuals(cap, trajectory=exact, times=mean_time[sweep])
    assert np.sqrt(np.mean(res**2)) < 3e-7
    assert np.sqrt(np.mean(res_sweep**2)) > 1e-5


def test_factory_calibration_and_rotor_offsets(default, tmp_path):
    model = StationModel(FactoryCalibration(phase=[0.03, -0.02], tilt=[0.02, 0.01],
                                            curve=[0.004, -0.003], gibphase=[1.0, 2.0],
                                            gibmag=[0.005, 0.002]),
                         rotor_offsets=[[0.0, 0.0, 0.02], [0.0, 0.015, 0.0]])
    cap = simulate(replace(default, duration_s=1.0, station_models={1: model}), seed=5)
    assert np.sqrt(np.mean(residuals(cap) ** 2)) < 1.2 * Q_RMS
    truth = load_stations(write_simulation(cap, tmp_path)["truth"])
    np.testing.assert_allclose(truth.stations[1].model.calibration.phase, [0.03, -0.02])
    np.testing.assert_allclose(truth.stations[1].model.rotor_offsets, model.rotor_offsets)
    assert truth.stations[0].model.calibration.is_zero()
    ideal = residuals(cap, stations=replace(truth, stations={
        k: replace(s, model=StationModel()) for k, s in truth.stations.items()}))
    assert np.median(np.abs(ideal[cap.angles.lighthouse == 1])) > 5e-3


def test_schedule_facts(default):
    cap = simulate(replace(default, duration_s=2.0, first_station=1), seed=9)
    slots = cap.slots
    sync = slots.sync_start_sample
    # both stations flash in every slot, station 1 first, 20000 ticks of 48 MHz apart
    gap = sync[:, 0] - sync[:, 1]
    assert np.all(np.abs(gap - SYNC_SPACING_S * FS) <= 1.0)
    # one slot every T/2, period close to 1/60 s on the board clock (clock offset <= 30 ppm)
    assert abs(slots.period_samples / (ROTOR_PERIOD_S * FS) - 1) <= 30e-6
    assert np.all(np.abs(np.diff(sync[:, 0]) - slots.period_samples / 2) <= 1.0)
    # each station/axis is swept every 4th slot: 30 Hz
    for station in (0, 1):
        for axis in (0, 1):
            k = np.flatnonzero((slots.sweeping == station) & (slots.axis == axis))
            assert np.all(np.diff(k) == 4)
            sweeps = np.unique(cap.angles.extra["sweep"][(cap.angles.lighthouse == station)
                                                         & (cap.angles.axis == axis)])
            assert abs(len(sweeps) / 2.0 - 30) <= 1
    assert np.all(slots.sync_start_sample[:, 1] < cap.n_samples)


def test_three_stations_from_explicit_poses(tmp_path):
    path = tmp_path / "three.toml"
    path.write_text("""
duration_s = 1.0
seed = 4
first_station = 2
[[stations]]
position = [0.0, -1.0, 2.0]
quaternion = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
[[stations]]
position = [1.5, -1.0, 2.0]
quaternion = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
[[stations]]
position = [-1.5, -1.0, 2.0]
quaternion = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
[motion]
centre_m = [0.0, 1.5, 1.6]
""")
    config = load_simulation_config(path)
    cap = simulate(config)
    assert cap.truth.indices() == [0, 1, 2]
    np.testing.assert_allclose(cap.truth.pose(0), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(cap.truth.pose(1)[:3, 3], [0.0, -1.5, 0.0], atol=1e-12)
    # 3 stations x 2 axes: each station/axis every 6th slot (20 Hz), station 2 flashes first
    pattern = cap.slots.sweeping * 2 + cap.slots.axis
    assert np.all(np.diff(np.flatnonzero(pattern == pattern[0])) == 6)
    assert set(cap.angles.lighthouse.tolist()) == {0, 1, 2}
    assert np.all(np.argmin(cap.slots.sync_start_sample, axis=1) == 2)
    assert np.sqrt(np.mean(residuals(cap) ** 2)) < 1.2 * Q_RMS


def test_visibility_limits():
    config = load_simulation_config(SIM_CONFIGS / "facing.toml")
    config = replace(config, duration_s=2.0,
                     visibility=VisibilityConfig(max_incidence_deg=60.0, fov_deg=55.0,
                                                 window_ms=(1.5, 6.0)))
    cap = simulate(config, seed=1)
    a = cap.angles
    assert 0 < len(a) < 0.9 * 32 * len(cap.slots)
    T_wb = cap.motion.pose(a.time)
    rows = cap.board.index_of(a.sensor)
    p = transform_points(T_wb, cap.board.positions[rows])
    n = np.einsum("nij,nj->ni", T_wb[:, :3, :3], cap.board.normals[rows])
    to_lh = np.stack([cap.truth.pose(k)[:3, 3] for k in a.lighthouse]) - p
    incidence = np.degrees(np.arccos(np.sum(n * to_lh, 1) / np.linalg.norm(to_lh, axis=1)))
    assert incidence.max() < 60.0 + 0.05
    assert incidence.max() > 55.0  # the limit is what removes hits
    sync = cap.slots.sync_start_sample[a.extra["sweep"], a.lighthouse]
    dt_ms = (a.time * FS - sync) / FS * 1e3
    assert dt_ms.min() >= 1.5 - 1e-3 and dt_ms.max() <= 6.0 + 1e-3
    for k in cap.truth.indices():
        sel = a.lighthouse == k
        p_lh = transform_points(inverse(cap.truth.pose(k)), p[sel])
        assert np.degrees(np.abs(np.arctan2(p_lh[:, 1:], p_lh[:, :1]))).max() <= 55.0 + 0.05


def test_flat_board_facing_stations_rarely_seen_by_both():
    facing = load_simulation_config(SIM_CONFIGS / "facing.toml")
    both = {}
    for board in ("paper32", "pyramid32"):
        cap = simulate(replace(facing, board=board, duration_s=2.0), seed=2)
        a = cap.angles
        cycle = a.extra["sweep"] // 4  # one 33 ms cycle sweeps every station/axis once
        seen = [set(cycle[a.lighthouse == k].tolist()) for k in (0, 1)]
        both[board] = len(seen[0] & seen[1]) / len(set(cycle.tolist()))
    assert both["pyramid32"] > 0.9
    assert both["paper32"] < both["pyramid32"] - 0.3


def test_noise_reflections_dropouts(default):
    base = replace(default, duration_s=3.0)
    clean = simulate(base, seed=21)
    noisy = simulate(replace(base, noise=NoiseConfig(reflection_fraction=0.1,
                                                     dropout_fraction=0.2)), seed=21)
    assert abs(len(noisy.angles) / len(clean.angles) - 0.8) < 0.02
    assert abs(noisy.reflected.mean() - 0.1) < 0.02
    assert np.sum(noisy.pulses.kind == LightPulses.REFLECTION) == noisy.reflected.sum()
    res = residuals(noisy)
    off = np.degrees(np.abs(res[noisy.reflected]))
    assert off.min() > 1.0 - 0.05 and off.max() < 20.0 + 0.05
    assert np.sqrt(np.mean(res[~noisy.reflected] ** 2)) < 1.2 * Q_RMS
    sigma = 1e-3
    gauss = simulate(replace(base, noise=NoiseConfig(angle_sigma_rad=sigma)), seed=22)
    assert abs(np.std(residuals(gauss)) / np.hypot(sigma, Q_RMS) - 1) < 0.05


def test_motion_speed_and_patterns(default):
    for pattern in ("wave", "circle", "figure8"):
        for speed in (0.3, 2.0):
            config = replace(default, duration_s=2.0,
                             motion=MotionConfig(pattern=pattern, speed_mps=speed))
            cap = simulate(config, seed=1)
            p = cap.trajectory.T_world_board[:, :3, 3]
            mean_speed = np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)) / 2.0
            assert abs(mean_speed / speed - 1) < 0.01, (pattern, speed)
            # the board keeps facing the stations on average
            z = cap.trajectory.T_world_board[:, :3, 2].mean(axis=0)
            centre = p.mean(axis=0)
            for k in (0, 1):
                to_lh = cap.truth.pose(k)[:3, 3] - centre
                assert z @ to_lh / np.linalg.norm(z) / np.linalg.norm(to_lh) > 0.8


def test_seed_reproducible(default):
    config = replace(default, duration_s=1.0)
    a, b, c = simulate(config, seed=1), simulate(config, seed=1), simulate(config, seed=2)
    np.testing.assert_array_equal(a.angles.angle, b.angles.angle)
    assert len(a.angles) != len(c.angles) or not np.array_equal(a.angles.angle, c.angles.angle)
    assert c.config.seed == 2


def test_bundled_default_equals_repo_copy():
    assert default_config_text() == (SIM_CONFIGS / "default.toml").read_text()
    assert load_simulation_config(SIM_CONFIGS / "default.toml") == replace(
        default_simulation_config(), base_dir=str(SIM_CONFIGS))


@pytest.mark.parametrize("name", ["default", "facing", "ninety", "far", "fast", "realistic"])
def test_shipped_configs_load(name):
    config = load_simulation_config(SIM_CONFIGS / f"{name}.toml")
    scene = scene_of(config)
    assert scene.T_world_lh.shape == (2, 4, 4)


def test_layout_parameters(default):
    ninety = load_simulation_config(SIM_CONFIGS / "ninety.toml")
    scene = scene_of(ninety)
    # the stations' optical axes, projected on the floor, are 90 degrees apart
    forward = scene.T_world_lh[:, :3, 0]
    forward = forward - np.outer(forward @ scene.up, scene.up)
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    assert abs(np.degrees(np.arccos(forward[0] @ forward[1])) - 90) < 1e-6
    assert abs(np.linalg.norm(scene.T_world_lh[1, :3, 3]) - ninety.layout.baseline_m) < 1e-9
    far = load_simulation_config(SIM_CONFIGS / "far.toml")
    assert 5 < np.linalg.norm(scene_of(far).centre) < 6


def test_paper_protocol():
    protocol = paper_protocol(ROOT / "configs" / "paper_simulation.toml")
    names = [name for name, _ in protocol]
    assert len(protocol) == 50 and len(set(names)) == 50 and names[12] == "setup03/meas3"
    assert len({c.seed for _, c in protocol}) == 50
    by_setup = {}
    for name, c in protocol:
        assert 2.0 <= c.layout.distance_m <= 6.0 and 1.0 <= c.layout.baseline_m <= 4.0
        assert c.noise == NoiseConfig() and c.duration_s == 8.0
        assert c.layout.relative_yaw_deg <= 90
        by_setup.setdefault(name.split("/")[0], []).append(c)
    for configs in by_setup.values():  # stations stay put within a setup; the board moves
        poses = [scene_of(c).T_world_lh for c in configs]
        for p in poses[1:]:
            np.testing.assert_allclose(p, poses[0], atol=1e-12)
        assert len({(c.motion.pattern, c.motion.speed_mps, c.layout.distance_m)
                    for c in configs}) == 5


BAD_CONFIGS = [
    ("duration_s = -1.0", "duration_s"),
    ("board = \"nope\"", "board"),
    ("first_station = 2", "first_station"),
    ("extra = 1", "extra"),
    ("[motion]\npattern = \"zigzag\"", "motion.pattern"),
    ("[motion]\nspeed_mps = \"fast\"", "motion.speed_mps"),
    ("[motion]\ncentre_m = [1.0, 2.0, 3.0]", "motion.centre_m"),
    ("[noise]\nbogus = 1", "noise.bogus"),
    ("[noise]\ndropout_fraction = 1.5", "noise.dropout_fraction"),
    ("[visibility]\nwindow_ms = [6.0, 1.0]", "visibility.window_ms"),
    ("[layout]\ndistance_m = 0.5", "layout.distance_m"),
    ("[layout]\nrelative_yaw_deg = 170.0", "layout.relative_yaw_deg"),
    ("[layout]\nstation_heights_m = [2.0]", "layout.station_heights_m"),
    ("[factory.5]\nphase = [0.0, 0.0]", "factory.5"),
    ("[factory.1]\nphase = [0.0]", "factory.1.phase"),
    ("[factory.1]\nwobble = [0.0, 0.0]", "factory.1.wobble"),
    ("[[stations]]\nposition = [0.0, 0.0, 0.0]\nquaternion = [1.0, 0.0, 0.0, 0.0]", "motion"),
    ("[[stations]]\nposition = [0.0, 0.0]\nquaternion = [1.0, 0.0, 0.0, 0.0]",
     "stations[0].position"),
]


@pytest.mark.parametrize(("text", "key"), BAD_CONFIGS)
def test_bad_config_names_file_and_key(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text + "\n")
    with pytest.raises(InputError) as info:
        load_simulation_config(path)
    assert str(info.value).startswith(f"{path}:{key}: "), str(info.value)


def test_cli_simulate(tmp_path, capsys):
    out = tmp_path / "sim"
    assert main(["simulate", str(SIM_CONFIGS / "fast.toml"), "--output", str(out),
                 "--seed", "3"]) == 0
    line = capsys.readouterr().out.strip()
    assert "station 0:" in line and "station 1:" in line and str(out) in line
    assert sorted(p.name for p in out.iterdir()) == ["angles.csv", "board.toml",
                                                     "trajectory.csv", "truth.toml"]
    assert main(["simulate", "--output", str(out), "--quiet"]) == 2
    assert "exists already" in capsys.readouterr().err
    assert main(["simulate", "--output", str(out), "--quiet", "--force"]) == 0
    assert capsys.readouterr().out == ""


def test_cli_bad_config_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[motion]\npattern = \"zigzag\"\n")
    assert main(["simulate", str(bad), "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "motion.pattern" in err and str(bad) in err
    assert not (tmp_path / "out").exists()
