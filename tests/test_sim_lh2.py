"""LH2 simulation (lhgraph.sim.lh2): angles against the model, rotor periods per channel,
planes, visibility, noise, up to 16 stations, files, config errors, LH1 unchanged."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.io.angles import load_angles
from lhgraph.io.stations import load_stations
from lhgraph.model.lh2 import ideal_angles, lh1_equivalent
from lhgraph.model.station import sensor_in_station, sweep_angle
from lhgraph.sim.config import (
    LH2_PERIOD_TICKS,
    default_simulation_config,
    lh2_rotor_period_s,
    parse_simulation_config,
)
from lhgraph.sim.lh2 import PLANE_OFFSETS_RAD
from lhgraph.sim.simulate import simulate, write_simulation

ROOT = Path(__file__).resolve().parent.parent
LH2 = {"generation": 2, "duration_s": 1.0, "seed": 4, "clock_ppm": 0.0}


def lh2_config(**keys):
    return parse_simulation_config({**LH2, **keys}, "lh2.toml")


def ring(n, radius=3.0, height=4.0, **motion):
    """``n`` stations on a circle around the board's motion centre (site frame, z up), high
    up and aimed at it, so that the flat board (facing up on average) faces them all."""
    stations = []
    centre = 1.2
    pitch = np.arctan2(height - centre, radius)  # +pitch about y looks down
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    for i in range(n):
        a = 2 * np.pi * i / n
        cz, sz = np.cos((a + np.pi) / 2), np.sin((a + np.pi) / 2)  # +x toward the centre
        stations.append({"position": [radius * np.cos(a), radius * np.sin(a), height],
                         "quaternion": [cz * cp, -sz * sp, cz * sp, sz * cp]})
    return {"stations": stations, "motion": {"centre_m": [0.0, 0.0, centre], **motion}}


def model_residuals(cap):
    """Measured angle minus the station model at the exact board pose of each hit time."""
    a = cap.angles
    pose = cap.motion.pose(a.time)
    s = cap.board.positions[cap.board.index_of(a.sensor)]
    res = np.empty(len(a))
    for k in cap.truth.indices():
        sel = a.lighthouse == k
        p = sensor_in_station(cap.truth.pose(k), pose[sel], s[sel])
        res[sel] = a.angle[sel] - sweep_angle(p, a.axis[sel], cap.truth.stations[k].model)
    return res


@pytest.fixture(scope="module")
def noiseless():
    return simulate(lh2_config(factory={"0": {"channel": 3}, "1": {"channel": 9}}))


def test_angles_are_the_model_at_the_hit_time(noiseless):
    a = noiseless.angles
    assert len(a) > 4000
    assert set(np.unique(a.lighthouse)) == {0, 1}
    assert set(np.unique(a.axis)) == {0, 1}
    assert np.max(np.abs(model_residuals(noiseless))) < 1e-9
    assert np.all(np.diff(a.time) >= 0)
    assert noiseless.pulses is None and noiseless.slots is None
    assert "LH2" in noiseless.summary()


def test_hits_every_rotor_period_of_the_channel():
    cap = simulate(lh2_config(factory={"0": {"channel": 5}, "1": {"channel": 16}},
                              motion={"speed_mps": 0.0}, clock_ppm=100.0))
    a = cap.angles
    for k, channel in ((0, 5), (1, 16)):
        T = LH2_PERIOD_TICKS[channel - 1] / 48e6 * (1 + 100e-6)
        assert cap.truth.stations[k].model.channel == channel
        assert cap.truth.extra["simulation"]["rotor_periods_s"][k] == pytest.approx(T, 1e-12)
        for plane in (0, 1):
            sel = (a.lighthouse == k) & (a.axis == plane) & (a.sensor == a.sensor[0])
            dt = np.diff(a.time[sel])
            assert len(dt) > 40
            np.testing.assert_allclose(dt, T, atol=1e-9)  # a still board: exactly T


def test_planes_a_third_of_a_revolution_apart(noiseless):
    """A diode's plane-1 hit follows its plane-0 hit of the same revolution by
    T/3 + (alpha1 - alpha0) T/2pi (the planes' rotor offsets -pi/3, +pi/3)."""
    a = noiseless.angles
    assert PLANE_OFFSETS_RAD[1] - PLANE_OFFSETS_RAD[0] == pytest.approx(2 * np.pi / 3)
    T = noiseless.truth.extra["simulation"]["rotor_periods_s"][0]
    rev = a.extra["sweep"] // 2
    key0 = {(s, r): (t, x) for s, r, t, x, ax, lh in
            zip(a.sensor, rev, a.time, a.angle, a.axis, a.lighthouse, strict=True)
            if ax == 0 and lh == 0}
    pairs = [(t - key0[(s, r)][0], x - key0[(s, r)][1]) for s, r, t, x, ax, lh in
             zip(a.sensor, rev, a.time, a.angle, a.axis, a.lighthouse, strict=True)
             if ax == 1 and lh == 0 and (s, r) in key0]
    assert len(pairs) > 1000
    dt, dalpha = np.array(pairs).T
    # the board moves between the two hits: allow ~0.1 mrad of motion
    np.testing.assert_allclose(dt, T / 3 + dalpha * T / (2 * np.pi), atol=2e-6)


def test_sweep_column_groups_one_plane_pass(noiseless):
    a = noiseless.angles
    for k in (0, 1):
        sel = a.lighthouse == k
        assert np.all(a.extra["sweep"][sel] % 2 == a.axis[sel])
        for sweep in np.unique(a.extra["sweep"][sel])[:20]:
            t = a.time[sel & (a.extra["sweep"] == sweep)]
            assert np.ptp(t) < 2e-3


def test_four_stations_with_their_channels():
    channels = (2, 7, 11, 16)
    factory = {str(i): {"channel": c} for i, c in enumerate(channels)}
    cap = simulate(lh2_config(**ring(4), factory=factory))
    assert np.max(np.abs(model_residuals(cap))) < 1e-9
    assert set(np.unique(cap.angles.lighthouse)) == {0, 1, 2, 3}
    still = simulate(lh2_config(**ring(4, speed_mps=0.0), factory=factory)).angles
    for k, channel in enumerate(channels):
        sel = (still.lighthouse == k) & (still.axis == 0) & (still.sensor == still.sensor[0])
        assert np.sum(sel) > 40
        np.testing.assert_allclose(np.diff(still.time[sel]), lh2_rotor_period_s(channel),
                                   atol=1e-9)


def test_sixteen_stations_default_channels():
    cap = simulate(lh2_config(**ring(16, radius=4.0), duration_s=0.2))
    assert [cap.truth.stations[k].model.channel for k in range(16)] == list(range(1, 17))
    assert set(np.unique(cap.angles.lighthouse)) == set(range(16))
    assert np.max(np.abs(model_residuals(cap))) < 1e-9


def test_field_of_view_and_visibility(noiseless):
    a = noiseless.angles
    pose = noiseless.motion.pose(a.time)
    s = noiseless.board.positions[noiseless.board.index_of(a.sensor)]
    for k in (0, 1):
        sel = a.lighthouse == k
        ideal = ideal_angles(sensor_in_station(noiseless.truth.pose(k), pose[sel], s[sel]))
        az, el = lh1_equivalent(ideal[:, 0], ideal[:, 1])
        assert np.all(np.abs(az) <= np.radians(70)) and np.all(np.abs(el) <= np.radians(50))
    narrow = simulate(lh2_config(factory={"0": {"channel": 3}, "1": {"channel": 9}},
                                 visibility={"fov_h_deg": 2.0}))
    assert 0 < len(narrow.angles) < 0.6 * len(a)


def test_noise_reflections_and_dropouts():
    cap = simulate(lh2_config(noise={"angle_sigma_rad": 3e-5}))
    assert np.std(model_residuals(cap)) == pytest.approx(3e-5, rel=0.05)
    clean = simulate(lh2_config())
    lossy = simulate(lh2_config(noise={"dropout_fraction": 0.2, "sweep_dropout_fraction": 0.5,
                                       "reflection_fraction": 0.05}))
    sweeps = {k: len(np.unique(c.angles.extra["sweep"][c.angles.lighthouse == 0]))
              for k, c in (("clean", clean), ("lossy", lossy))}
    assert sweeps["lossy"] == pytest.approx(0.5 * sweeps["clean"], rel=0.2)
    assert len(lossy.angles) == pytest.approx(0.4 * len(clean.angles), rel=0.1)
    res = model_residuals(lossy)
    assert np.mean(lossy.reflected) == pytest.approx(0.05, abs=0.02)
    assert np.all(np.abs(res[lossy.reflected]) > np.radians(0.9))
    assert np.max(np.abs(res[~lossy.reflected])) < 1e-9


def test_files_round_trip_generation_and_channel(tmp_path):
    cap = simulate(lh2_config(duration_s=0.3, factory={"0": {"channel": 12}},
                              imu={"rate_hz": 100.0}))
    paths = write_simulation(cap, tmp_path)
    truth = load_stations(paths["truth"])
    assert [truth.stations[k].model.generation for k in (0, 1)] == [2, 2]
    assert [truth.stations[k].model.channel for k in (0, 1)] == [12, 2]
    angles = load_angles(paths["angles"])
    np.testing.assert_allclose(angles.angle, cap.angles.angle, atol=1e-11)
    assert paths["imu"].exists()
    with pytest.raises(InputError, match="cannot decode LH2"):
        write_simulation(cap, tmp_path / "raw", raw_capture=True)
    assert not (tmp_path / "raw").exists()


def test_shipped_config_and_cli(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["simulate", str(ROOT / "configs" / "sim_lh2.toml"), "--output", str(out),
                 "--seed", "2"]) == 0
    assert "LH2" in capsys.readouterr().out
    truth = load_stations(out / "truth.toml")
    assert truth.stations[1].model.generation == 2
    assert len(load_angles(out / "angles.csv")) > 20000


@pytest.mark.parametrize("doc, key", [
    ({"generation": 3}, "generation"),
    ({"generation": 2, "factory": {"0": {"channel": 17}}}, "factory.0.channel"),
    ({"generation": 2, "factory": {"0": {"channel": 0}}}, "factory.0.channel"),
    ({"generation": 2, "factory": {"1": {"channel": 1}}}, "factory.1.channel"),
    ({"generation": 2, "factory": {"0": {"channel": 2}}}, "factory.0.channel"),
    ({"factory": {"0": {"channel": 1}}}, "factory.0.channel"),
    ({"factory": {"0": {"ogeemag": [0.0, 0.1]}}}, "factory.0.ogeemag"),
    ({"noise": {"sweep_dropout_fraction": 0.1}}, "noise.sweep_dropout_fraction"),
    ({"visibility": {"fov_h_deg": 60.0}}, "visibility.fov_h_deg"),
    ({"generation": 2, "visibility": {"fov_deg": 60.0}}, "visibility.fov_deg"),
    ({"generation": 2, "visibility": {"window_ms": [1, 2]}}, "visibility.window_ms"),
    ({"generation": 2, "sample_rate_hz": 24e6}, "sample_rate_hz"),
    ({"generation": 2, "first_station": 0}, "first_station"),
    ({"generation": 2, "logging": {"timestamps": "deck"}}, "logging.timestamps"),
    ({"generation": 2, "noise": {"sweep_dropout_fraction": 1.5}}, "noise.sweep_dropout_fraction"),
    ({"generation": 2, **ring(17)}, "stations"),
])
def test_bad_config_values(doc, key):
    with pytest.raises(InputError) as err:
        parse_simulation_config(doc, "sim.toml")
    assert str(err.value).startswith(f"sim.toml:{key}: ")


def test_lh2_calibration_terms_reach_the_model():
    cap = simulate(lh2_config(duration_s=0.3, factory={"1": {
        "phase": [0.01, -0.02], "tilt": [0.003, 0.001], "ogeemag": [0.01, 0.0]}}))
    model = cap.truth.stations[1].model
    assert model.calibration.phase[1] == -0.02 and model.calibration.ogeemag[0] == 0.01
    assert np.max(np.abs(model_residuals(cap))) < 1e-9


def test_lh1_unchanged():
    """No ``generation`` is LH1 and ``generation = 1`` the same capture; the default config's
    angles are those of the simulator before LH2 (hard reference)."""
    default = replace(default_simulation_config(), duration_s=1.0)
    assert default.generation == 1
    one = parse_simulation_config({"generation": 1, "duration_s": 1.0}, "x.toml")
    absent = parse_simulation_config({"duration_s": 1.0}, "x.toml")
    a, b = simulate(one, seed=3).angles, simulate(absent, seed=3).angles
    np.testing.assert_array_equal(a.angle, b.angle)
    np.testing.assert_array_equal(a.time, b.time)
    ref = simulate(default, seed=3)
    assert ref.slots is not None and ref.pulses is not None
    assert len(ref.angles) == 3808
    assert ref.angles.angle[[0, 100, 1000]].tolist() == [
        -0.03321732749653742, -0.07581789802999692, -0.0969296851970211]
    assert ref.angles.time[[0, 100, 1000]].tolist() == [0.0087605, 0.033647, 0.2669215]
