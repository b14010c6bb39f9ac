"""Decoder: simulated raw captures decode to the simulator's angles and OOTX; robustness."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lhgraph.cli import main
from lhgraph.model.calibration import StationCalibration, load_calibration
from lhgraph.model.station import CALIBRATION_KEYS, FactoryCalibration
from lhgraph.signal.capture import (
    Capture,
    edges_to_pulses,
    encode_capture,
    pulses_to_edges,
    write_capture,
)
from lhgraph.signal.decode import (
    DecodeOptions,
    decode_capture,
    decode_pulses,
    merge_carrier_gaps,
)
from lhgraph.signal.formats import decode_file
from lhgraph.signal.pulses import LightPulses
from lhgraph.sim.capture_sim import CaptureOptions, synthesize_capture
from lhgraph.sim.simulate import default_simulation_config, simulate

CALS = {
    0: StationCalibration(FactoryCalibration(phase=[0.0586, 0.0622], tilt=[0.0013, -0.0079],
                                             curve=[-0.0019, 0.0036], gibphase=[2.89, 0.024],
                                             gibmag=[0.0047, -0.0040]), 0x0AA54F65,
                          np.array([0.0, 127.0, 2.0])),
    1: StationCalibration(FactoryCalibration(phase=[0.0228, 0.0291], tilt=[-0.0095, -0.0079],
                                             curve=[0.0023, 0.0021], gibphase=[1.81, -1.18],
                                             gibmag=[0.0206, -0.0123]), 0xF77E2FF3,
                          np.array([10.0, 127.0, 7.0])),
}


@pytest.fixture(scope="module")
def sim():
    config = replace(default_simulation_config(), duration_s=7.0, first_station=1,
                     clock_ppm=21.0)
    return simulate(config, seed=11)


def _first(sim) -> int:
    return int(np.argmin(sim.slots.sync_start_sample[0]))


def _pair(sim, angles):
    """Row pairs (decoded, simulated) of the same pulse (same sensor and centre)."""
    key_s = np.round(sim.angles.time * 4e6).astype(np.int64) * 64 + sim.angles.sensor
    key_d = np.round(angles.time * 4e6).astype(np.int64) * 64 + angles.sensor
    _, i_d, i_s = np.intersect1d(key_d, key_s, return_indices=True)
    return i_d, i_s


def _check_equal(sim, result, tol=1e-6):
    a, s = result.angles, sim.angles
    i_d, i_s = _pair(sim, a)
    n = sim.slots.sync_start_sample.shape[1]
    assert np.array_equal((_first(sim) + a.lighthouse[i_d]) % n, s.lighthouse[i_s])
    assert np.array_equal(a.axis[i_d], s.axis[i_s])
    assert np.array_equal(a.extra["sweep"][i_d] - a.extra["sweep"][i_d][0],
                          s.extra["sweep"][i_s] - s.extra["sweep"][i_s][0])
    np.testing.assert_allclose(a.angle[i_d], s.angle[i_s], atol=tol, rtol=0)
    return i_d, i_s


def _sim_cals(sim):
    """CALS keyed by simulator station index."""
    return {i: CALS[i] for i in range(sim.slots.sync_start_sample.shape[1])}


def test_clean_capture_gives_the_simulators_angles_and_ootx(sim):
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(0))
    result = decode_capture(cap, sim.board)
    i_d, _ = _check_equal(sim, result)
    assert len(i_d) == len(sim.angles) == len(result.angles)
    assert result.report.dropped == {}
    for s in result.report.stations:
        assert s.period_s == pytest.approx(sim.slots.period_samples / 2e6, rel=1e-7)
    # OOTX: decoded station d is the simulator's station (first + d) % n
    for d, cal in result.calibrations.items():
        truth = CALS[(_first(sim) + d) % 2]
        assert cal.id == truth.id and np.array_equal(cal.accel_dir, truth.accel_dir)
        for key in CALIBRATION_KEYS:
            np.testing.assert_array_equal(getattr(cal.calibration, key),
                                          np.float16(getattr(truth.calibration, key)))
    assert sorted(result.calibrations) == [0, 1]


def test_chatter_echoes_and_missing_flashes(sim):
    opts = CaptureOptions(chatter_fraction=0.5, echo_fraction=0.2, missing_sync_fraction=0.02,
                          sync_shortfall_s=9e-6)
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(1), opts)
    result = decode_capture(cap, sim.board)
    assert result.report.merged_gaps > 1000
    assert any("reflections" in r for r in result.report.dropped)
    # hits timed from an earlier flash (their own was missed) differ by < 1 sample of angle
    i_d, _ = _check_equal(sim, result, tol=2 * np.pi / 33_333)
    assert len(i_d) >= 0.99 * len(sim.angles)
    assert any("sync flash missed" in note for note in result.report.notes)


def test_station_vanishing_and_single_station(sim):
    gone = (sim.angles.lighthouse == 0) & (sim.angles.time >= 3.0)
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(2),
                             CaptureOptions(vanish=(0, 3.0)))
    result = decode_capture(cap, sim.board)
    i_d, i_s = _check_equal(sim, result)
    assert len(i_d) == len(sim.angles) - np.count_nonzero(gone)
    # only one station from the start: still decoded, numbered 0
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(3),
                             CaptureOptions(vanish=(0, 0.0)))
    result = decode_capture(cap, sim.board)
    assert set(result.angles.lighthouse.tolist()) == {0}
    i_d, i_s = _pair(sim, result.angles)
    assert np.all(sim.angles.lighthouse[i_s] == 1)
    np.testing.assert_allclose(result.angles.angle[i_d], sim.angles.angle[i_s], atol=1e-6)
    assert len(i_d) == np.count_nonzero(sim.angles.lighthouse == 1)


def test_stuck_sensor_and_noise_burst(sim):
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(4))
    pulses = edges_to_pulses(cap)
    rng = np.random.default_rng(5)
    stuck_sensor = int(sim.board.ids[3])
    keep = pulses.sensor != stuck_sensor
    t0, t1 = 2_000_000, 2_040_000  # a 20 ms noise burst on every sensor
    n_noise = 3000
    noise = LightPulses(rng.choice(sim.board.ids, n_noise), rng.integers(t0, t1, n_noise),
                        np.zeros(n_noise, np.int64), np.full(n_noise, 2))
    noise.end = noise.start + rng.integers(1, 200, n_noise)
    stuck = LightPulses(np.array([stuck_sensor]), np.array([1_000_000]),
                        np.array([cap.length_samples]), np.array([2]))
    merged = LightPulses(*(np.concatenate([getattr(p, f) for p in (pulses, noise, stuck)])
                           for f in ("sensor", "start", "end", "kind")))
    merged.sensor[: len(pulses)][~keep] = stuck_sensor  # keep its pulses before it sticks
    bad = pulses_to_edges(merged, cap.length_samples, cap.channel_map)
    result = decode_capture(bad, sim.board)
    assert any("stuck high" in r for r in result.report.dropped)
    assert any("noise" in r for r in result.report.dropped)
    a = result.angles
    i_d, i_s = _pair(sim, a)
    clean = (sim.angles.time[i_s] < 0.99) | (sim.angles.time[i_s] > 1.03)
    np.testing.assert_allclose(a.angle[i_d][clean], sim.angles.angle[i_s][clean], atol=1e-6)
    far = (sim.angles.time < 0.99) | (sim.angles.time > 1.03)
    far &= (sim.angles.sensor != stuck_sensor) | (sim.angles.time < 0.5)
    assert len(i_d) >= 0.98 * np.count_nonzero(far)


def test_fitted_sync_reference(sim):
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(6),
                             CaptureOptions(missing_sync_fraction=0.05))
    measured = decode_capture(cap, sim.board)
    fitted = decode_capture(cap, sim.board, DecodeOptions(sync_reference="fitted"))
    assert len(fitted.angles) == len(sim.angles)
    i_d, i_s = _pair(sim, fitted.angles)
    diff = fitted.angles.angle[i_d] - sim.angles.angle[i_s]
    # the simulator times from the sampled sync edge, the fit from the (sub-sample) train:
    # they differ by the edge's quantisation, uniform within one sample
    sample_rad = 2 * np.pi / 33_333
    assert np.max(np.abs(diff)) < sample_rad
    assert 0.2 * sample_rad < np.std(diff) < 0.35 * sample_rad
    assert len(measured.angles) == len(sim.angles)


def test_rotor_jitter_follows_the_own_flash_not_the_fitted_train():
    # each station's flash and the sweep after it jitter together (the real sync train,
    # benchmarks/sync_reference.py): timing from the own flash keeps the simulator's
    # angles, timing from the fitted train carries the jitter, 2 pi sigma / T per sweep
    jitter_us = 2.0
    base = replace(default_simulation_config(), duration_s=4.0, clock_ppm=0.0)
    jittery = simulate(replace(base, noise=replace(base.noise, rotor_jitter_us=jitter_us)), 3)
    steady = simulate(base, 3)
    assert not np.array_equal(jittery.slots.sync_start_sample, steady.slots.sync_start_sample)
    cap = synthesize_capture(jittery, _sim_cals(jittery), np.random.default_rng(2))
    measured = decode_capture(cap, jittery.board)
    _check_equal(jittery, measured)
    fitted = decode_capture(cap, jittery.board, DecodeOptions(sync_reference="fitted"))
    i_d, i_s = _pair(jittery, fitted.angles)
    diff = fitted.angles.angle[i_d] - jittery.angles.angle[i_s]
    sweep = fitted.angles.extra["sweep"][i_d]
    _, inv, count = np.unique(sweep, return_inverse=True, return_counts=True)
    per_sweep = np.bincount(inv, diff) / count
    expected = 2 * np.pi * jitter_us * 1e-6 / (jittery.slots.period_samples / 2e6)
    assert 0.8 * expected < np.std(per_sweep) < 1.2 * expected
    # within a sweep every diode moves with it
    assert np.std(diff - per_sweep[inv]) < 0.1 * expected


def test_rotor_jitter_is_an_lh1_key_and_validated():
    from lhgraph.errors import InputError
    from lhgraph.sim.config import parse_simulation_config

    with pytest.raises(InputError, match="rotor_jitter_us"):
        parse_simulation_config({"noise": {"rotor_jitter_us": -1.0}}, "sim.toml")
    with pytest.raises(InputError, match="LH1"):
        parse_simulation_config({"generation": 2, "board": "crazyflie_deck",
                                 "noise": {"rotor_jitter_us": 1.0}}, "sim.toml")
    config = parse_simulation_config({"noise": {"rotor_jitter_us": 1.5}}, "sim.toml")
    assert config.noise.rotor_jitter_us == 1.5


def test_truncated_and_corrupted_files_decode_what_is_valid(sim, tmp_path):
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(7))
    data = encode_capture(cap)
    path = tmp_path / "cut.lhcap"
    path.write_bytes(data[: len(data) // 2])
    result, warnings = decode_file(path)
    assert "truncated" in warnings[0]
    i_d, _ = _check_equal(sim, result)
    assert 0.4 * len(sim.angles) < len(i_d) < 0.6 * len(sim.angles)
    flipped = bytearray(data)
    flipped[-1000] ^= 0xFF
    path.write_bytes(bytes(flipped))
    result, warnings = decode_file(path)
    assert any("CRC" in w for w in warnings)


def test_cli_decode_round_trip_and_errors(sim, tmp_path, capsys):
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(8))
    path = write_capture(cap, tmp_path / "c.lhcap")
    out = tmp_path / "out"
    assert main(["decode", str(path), "--output", str(out), "--quiet"]) == 0
    cals = load_calibration(out / "ootx.toml")
    assert {c.id for c in cals.values()} == {CALS[0].id, CALS[1].id}
    # raw dump of the same signal decodes to the same angles
    words = np.repeat(cap.port_word, np.diff(np.r_[cap.sample_index, cap.length_samples]))
    raw = tmp_path / "c.raw"
    words[: 4_000_000].astype("<u4").tofile(raw)
    assert main(["decode", str(raw), "--output", str(tmp_path / "r"), "--quiet"]) == 0
    # unreadable input: one line, exit 2
    junk = tmp_path / "junk.lhcap"
    junk.write_bytes(b"hello")
    capsys.readouterr()
    assert main(["decode", str(junk), "--output", str(tmp_path / "j")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "wrong magic" in err[0]
    assert main(["decode", str(tmp_path / "missing.lhcap"), "--output", str(out)]) == 2


def test_simulate_capture_flag(tmp_path):
    out = tmp_path / "sim"
    assert main(["simulate", "--seed", "2", "--capture", "--output", str(out), "--quiet"]) == 0
    assert (out / "capture.lhcap").exists()
    assert main(["decode", str(out / "capture.lhcap"), "--output", str(out / "d"),
                 "--quiet"]) == 0


def test_merge_carrier_gaps():
    p = LightPulses(np.array([1, 1, 1, 2, 1]), np.array([0, 12, 20, 13, 40]),
                    np.array([10, 15, 30, 14, 41]), np.zeros(5, np.int64))
    merged, n = merge_carrier_gaps(p.sorted(), 3)
    assert n == 1
    assert sorted(zip(merged.sensor.tolist(), merged.start.tolist(), merged.end.tolist(),
                      strict=True)) == [(1, 0, 15), (1, 20, 30), (1, 40, 41), (2, 13, 14)]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, 31), st.integers(0, 200_000), st.integers(1, 400)),
                max_size=300),
       st.integers(0, 3))
def test_random_pulse_trains_never_crash(items, n_syncs):
    sensor = np.array([i[0] for i in items], np.int64)
    start = np.array([i[1] for i in items], np.int64)
    length = np.array([i[2] for i in items], np.int64)
    # sprinkle a few sync-length pulses so the grid code runs too
    sensor = np.r_[sensor, np.arange(n_syncs)]
    start = np.r_[start, 16_667 * np.arange(n_syncs)]
    length = np.r_[length, np.full(n_syncs, 130)]
    pulses = LightPulses(sensor, start, start + length, np.zeros(len(sensor), np.int64))
    result = decode_pulses(pulses, 2e6)
    assert len(result.angles) <= len(sensor)
    assert np.all(np.abs(result.angles.angle) <= np.pi)
    cap = Capture(np.array([0]), np.array([0]), 10)
    assert len(decode_capture(cap).angles) == 0


@pytest.mark.filterwarnings("error")
def test_sync_flashes_off_the_grid_decode_to_nothing():
    """Found by the fuzz test above: flashes whose spacing suggests a slot length but that do
    not sit on a grid decode to nothing, every flash accounted for, without a crash or a
    numpy warning (a period fit on flashes of one slot is not attempted)."""
    start = np.array([0, 121, 215, 309, 49901], np.int64)
    pulses = LightPulses(np.zeros(5, np.int64), start, start + 90, np.zeros(5, np.int64))
    result = decode_pulses(pulses, 2e6)
    assert len(result.angles) == 0
    report = result.report
    assert (report.sync_flashes + report.dropped.get("sync flashes off the slot grid", 0)
            + report.dropped.get("duplicate sync flashes in one slot", 0)) == 5


def test_no_lighthouse_signal_is_one_line_exit_2_and_bounded(tmp_path, capsys):
    import tracemalloc

    from lhgraph.errors import InputError

    noise = tmp_path / "noise.bin"
    noise.write_bytes(np.random.default_rng(0).integers(0, 256, 5_000_000, np.uint8).tobytes())
    zeros = tmp_path / "zeros.dat"
    zeros.write_bytes(bytes(400_000))
    for path, extra in ((noise, []), (zeros, ["--format", "raw"])):
        out = tmp_path / f"out-{path.stem}"
        capsys.readouterr()
        assert main(["decode", str(path), "--output", str(out), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"{path}: no Lighthouse signal found" in err[0]
        assert not out.exists()
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="no Lighthouse signal"):
            decode_file(noise)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 150e6  # was 1.4 GB: every random bit became pulses


def test_quiet_decode_still_reports_dropped_records(sim, tmp_path, capsys):
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(9))
    data = encode_capture(cap)
    path = tmp_path / "cut.lhcap"
    path.write_bytes(data[: len(data) // 2])
    capsys.readouterr()
    assert main(["decode", str(path), "--output", str(tmp_path / "out"), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "truncated" in captured.err and "edge records present" in captured.err
    assert "sweep hits" not in captured.err  # the decoder's summary stays quiet


def test_decode_output_under_a_file_is_refused_before_decoding(sim, tmp_path, capsys):
    cap = synthesize_capture(sim, _sim_cals(sim), np.random.default_rng(10))
    path = write_capture(cap, tmp_path / "c.lhcap")
    capsys.readouterr()
    assert main(["decode", str(path), "--output", str(path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "c.lhcap: is not a directory" in err[0]
