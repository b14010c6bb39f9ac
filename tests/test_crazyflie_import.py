"""Crazyflie uSD log: reader and writer (round trip, CRC, truncation, not a log), the LH1
angles (repeats dropped; LH2 logs recognised), the Bitcraze calibration mapping, and the real
import.

Synthetic logs are built with the project's own writer. The real-data tests read
``<repo>/../shared/data/bitcraze-positioning`` (no licence: never copied into the repository)
and are skipped when it is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.importers.crazyflie import (
    EventType,
    UsdLog,
    encode_usd_log,
    import_crazyflie,
    read_usd_log,
    write_usd_log,
)
from lhgraph.importers.crazyflie.sweeps import lh1_angles
from lhgraph.io.angles import load_angles
from lhgraph.io.files import read_csv_columns
from lhgraph.io.stations import load_stations
from lhgraph.model.bitcraze import (
    calibration_from_bitcraze,
    calibration_to_bitcraze,
    firmware_equivalent,
)
from lhgraph.model.board import load_board
from lhgraph.model.boards import crazyflie_deck
from lhgraph.model.station import FactoryCalibration, StationModel, ideal_from_measured

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bitcraze-positioning"
LH1 = DATA / "lh1_crossingBeam_move"
needs_data = pytest.mark.skipif(not (LH1 / "log02").is_file(),
                                reason="shared Bitcraze dataset absent")

TYPES = (
    EventType(0xFFFF, "fixedFrequency", tuple((f"{s}.{k}", "f") for s in ("gyro", "acc")
                                              for k in "xyz")),
    EventType(0, "activeMarkerModeChanged", (("mode", "B"),)),
    EventType(1, "lhAngle", (("sensor", "B"), ("basestation", "B"), ("sweep", "B"),
                             ("angle", "f"), ("correctedAngle", "f"))),
)


def synthetic_log(version: int = 2, period_s: float = 1 / 30, n_cycles: int = 60,
                  repeat: bool = True) -> UsdLog:
    """A two-station LH1-like log: each station's pair (4 sensors x 2 sweeps) every
    ``period_s``; with ``repeat``, station 0's pair logged again next to station 1's."""
    unit = 1e-3 if version == 1 else 1e-6
    rng = np.random.default_rng(1)
    rows = []
    for c in range(n_cycles):
        t0 = 1.0 + c * period_s
        fresh = rng.uniform(-0.5, 0.5, (2, 2, 4))
        for bs, t_log in ((0, t0), (1, t0 + period_s / 2)):
            stations = (0, 1) if (bs == 1 and repeat) else (bs,)
            for sensor in range(4):
                for b in stations:
                    for sweep in (0, 1):
                        rows.append((t_log, sensor, b, sweep, fresh[b, sweep, sensor]))
    rows.sort(key=lambda r: r[0])
    ang = np.zeros(len(rows), dtype=[("timestamp", "<u8"), ("sensor", "u1"),
                                     ("basestation", "u1"), ("sweep", "u1"), ("angle", "<f4"),
                                     ("correctedAngle", "<f4")])
    for i, (t, s, b, w, a) in enumerate(rows):
        ang[i] = (round(t / unit) + (i if version == 2 else 0), s, b, w, a, a + 0.01)
    n_imu = 200
    imu = np.zeros(n_imu, dtype=[("timestamp", "<u8")] + [(v, "<f4") for v, _ in
                                                          TYPES[0].variables])
    imu["timestamp"] = np.round((1.0 + np.arange(n_imu) * 0.01) / unit)
    imu["acc.z"] = 1.0
    imu["gyro.x"] = 90.0
    marker = np.zeros(2, dtype=[("timestamp", "<u8"), ("mode", "u1")])
    marker["timestamp"] = np.round(np.array([1.1, 2.5]) / unit)
    marker["mode"] = (1, 0)
    return UsdLog(version, TYPES, {"fixedFrequency": imu, "activeMarkerModeChanged": marker,
                                   "lhAngle": ang})


@pytest.mark.parametrize("version", [1, 2])
def test_written_log_round_trips(tmp_path, version):
    log = synthetic_log(version)
    path = write_usd_log(log, tmp_path / "log00")
    back = read_usd_log(path)
    assert back.notes == () and back.version == version and back.types == log.types
    for name, ev in log.events.items():
        for field in ev.dtype.names:
            np.testing.assert_array_equal(back.events[name][field], ev[field])
    assert encode_usd_log(back) == path.read_bytes()


def test_crc_mismatch_keeps_events_and_says_so(tmp_path):
    data = bytearray(encode_usd_log(synthetic_log()))
    data[-10] ^= 0x40  # a value byte of the last event
    (tmp_path / "log").write_bytes(bytes(data))
    log = read_usd_log(tmp_path / "log")
    assert any("CRC mismatch" in n for n in log.notes)
    assert log.count("lhAngle") == synthetic_log().events["lhAngle"].size


def test_corrupted_timestamp_drops_that_event_only(tmp_path):
    log = synthetic_log()
    data = bytearray(encode_usd_log(log))
    n = len(data)
    body = n // 2
    # find an lhAngle event start near the middle by re-encoding a prefix
    offsets = []
    pos = data.index(b"correctedAngle(f)\0") + len("correctedAngle(f)\0")
    size = {0xFFFF: 2 + 8 + 24, 0: 2 + 8 + 1, 1: 2 + 8 + 11}
    while pos < n - 4:
        offsets.append(pos)
        pos += size[data[pos] | data[pos + 1] << 8]
    hit = next(o for o in offsets if o > body and data[o] == 1 and data[o + 1] == 0)
    data[hit + 2:hit + 10] = (0).to_bytes(8, "little")  # time 0: back in time
    (tmp_path / "log").write_bytes(bytes(data))
    back = read_usd_log(tmp_path / "log")
    assert any("CRC mismatch" in s for s in back.notes)
    assert any("event(s) going back in time" in s
               for s in back.notes)
    assert log.count("lhAngle") - 2 <= back.count("lhAngle") < log.count("lhAngle")


@pytest.mark.parametrize("cut", [1, 3, 7, 25])
def test_truncated_log_keeps_whole_events(tmp_path, cut):
    data = encode_usd_log(synthetic_log())
    (tmp_path / "log").write_bytes(data[:-cut])
    log = read_usd_log(tmp_path / "log")
    total = sum(len(v) for v in synthetic_log().events.values())
    kept = sum(len(v) for v in log.events.values())
    assert kept < total or cut <= 4
    assert any("CRC mismatch" in n for n in log.notes)
    if cut > 4:
        assert any("dropped bytes" in n and "the CRC is missing" in n for n in log.notes)


def _event_offsets(data: bytes) -> list[int]:
    """Where each event of the synthetic log starts (its three types' sizes, version 2)."""
    pos = data.index(b"correctedAngle(f)\0") + len("correctedAngle(f)\0")
    size = {0xFFFF: 2 + 8 + 24, 0: 2 + 8 + 1, 1: 2 + 8 + 11}
    offsets = []
    while pos < len(data) - 4:
        offsets.append(pos)
        pos += size[data[pos] | data[pos + 1] << 8]
    return offsets


@pytest.mark.parametrize("damage", ["flipped id", "byte lost", "bytes inserted"])
def test_damage_in_the_middle_resynchronises_and_keeps_the_rest(tmp_path, capsys, damage):
    log = synthetic_log()
    data = bytearray(encode_usd_log(log))
    offsets = _event_offsets(bytes(data))
    i = len(offsets) // 2
    at = offsets[i]
    if damage == "flipped id":
        data[at + 1] ^= 0x80  # the event's id becomes unknown
    elif damage == "byte lost":
        del data[at + 5]
    else:
        data[at:at] = b"\x07\x07\x07"
    path = tmp_path / "log00"
    path.write_bytes(bytes(data))
    back = read_usd_log(path)
    total = sum(len(v) for v in log.events.values())
    kept = sum(len(v) for v in back.events.values())
    # the damaged event and at most one more lost (none when bytes were only inserted)
    assert total - 2 <= kept <= total and (kept < total) == (damage != "bytes inserted")
    gaps = [n for n in back.notes if n.startswith("dropped bytes") and "resumed at" in n]
    assert len(gaps) == 1 and at <= int(gaps[0].split()[2].split("-")[0]) < at + 40, back.notes
    # every event after the damage is back, exactly (of the types with many events: the
    # damaged one may be one of the two marker events)
    for name, ev in log.events.items():
        for field in ev.dtype.names if len(ev) > 20 else ():
            np.testing.assert_array_equal(back.events[name][field][-10:], ev[field][-10:])
    # said even when quiet
    assert main(["import", "crazyflie", str(path), "-o", str(tmp_path / "o"), "--quiet"]) == 0
    assert "dropped bytes" in capsys.readouterr().err


@pytest.mark.parametrize("content", [b"", b"hello world", b"\xbc\x07\x00\x01\x00",
                                     b"\xbc\x02\x00\x01\x00\x01\x00ab"])
def test_not_a_log_is_one_line_exit_2(tmp_path, capsys, content):
    path = tmp_path / "log00"
    path.write_bytes(content)
    assert main(["import", "crazyflie", str(path), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0]
    assert not (tmp_path / "out" / "angles.csv").exists()


def test_repeats_dropped_and_angles_at_30_hz(tmp_path):
    log = synthetic_log()
    angles, summary = lh1_angles(log)
    assert summary.repeats[0] == 60 * 8 and summary.repeats[1] == 0
    assert summary.kept == {0: 60 * 8, 1: 60 * 8}
    sel = (angles.lighthouse == 0) & (angles.axis == 0) & (angles.sensor == 2)
    np.testing.assert_allclose(np.diff(angles.extra["log_time"][sel]), 1 / 30, atol=5e-5)
    before = angles.extra["log_time"] - angles.time  # the hit precedes its logging
    assert np.all((before > 0) & (before < 2.5 / 120))
    np.testing.assert_allclose(angles.extra["corrected_angle"] - angles.angle, 0.01, atol=1e-6)


def test_import_synthetic_writes_contract_files(tmp_path, capsys):
    write_usd_log(synthetic_log(), tmp_path / "log07")
    out = tmp_path / "out"
    assert main(["import", "crazyflie", str(tmp_path / "log07"), "-o", str(out)]) == 0
    assert "station 0: 480" in capsys.readouterr().out
    a = load_angles(out / "angles.csv")
    assert a.stations() == [0, 1] and "corrected_angle" in a.extra
    np.testing.assert_allclose(load_board(out / "board.toml").positions, crazyflie_deck().positions)
    imu = read_csv_columns(out / "imu.csv", [("time", float), ("az", float), ("gx", float)])
    np.testing.assert_allclose(imu["az"], 9.80665, rtol=1e-6)
    np.testing.assert_allclose(imu["gx"], np.pi / 2, rtol=1e-6)
    assert not (out / "mocap.csv").exists()
    assert main(["import", "crazyflie", str(tmp_path / "log07"), "-o", str(out)]) == 2
    assert "exists already" in capsys.readouterr().err


def test_invalid_hits_and_imu_samples_are_dropped_and_counted(tmp_path, capsys):
    # hits the angles CSV cannot hold (an angle beyond pi, sweep 7, a sensor not on the deck)
    # and IMU samples it cannot (a NaN, a repeated stamp) are left out and counted; the
    # written files read back
    from lhgraph.io.imu import load_imu

    log = synthetic_log()
    ang, imu = log.events["lhAngle"], log.events["fixedFrequency"]
    ang["angle"][3], ang["sweep"][10], ang["sensor"][20] = 100.0, 7, 9
    imu["acc.x"][5] = np.nan
    imu["timestamp"][50] = imu["timestamp"][49]
    write_usd_log(log, tmp_path / "log01")
    out = tmp_path / "out"
    assert main(["import", "crazyflie", str(tmp_path / "log01"), "-o", str(out)]) == 0
    summary = capsys.readouterr().out
    assert "dropped invalid hits (an angle not finite or beyond pi, a sweep not 0 or 1, a " \
           "sensor not on the deck): 3" in summary
    assert "dropped 2 samples" in summary
    a = load_angles(out / "angles.csv")  # the reader's own checks: the angles are valid
    assert set(a.sensor.tolist()) <= {0, 1, 2, 3} and len(a) < 960
    assert len(load_imu(out / "imu.csv").time) == 200 - 2


def test_lh2_log_is_imported_as_lh2(tmp_path, capsys):
    write_usd_log(synthetic_log(period_s=1 / 50), tmp_path / "log00")
    r = import_crazyflie(tmp_path / "log00", tmp_path / "o")
    assert r.system_type == 2 and "LH2" in r.summary()
    a = load_angles(tmp_path / "o" / "angles.csv")
    # a plane-0 hit is moved back from its stamp by about a third of a turn (~6.7 ms)
    back = a.extra["log_time"] - a.time
    assert np.median(back[a.axis == 0]) == pytest.approx(0.02 / 3, abs=2e-3)
    assert np.median(np.abs(back[a.axis == 1])) < 1e-3
    # an LH1 system configuration does not describe an LH2 log
    yaml_path = tmp_path / "lh1.yaml"
    yaml_path.write_text("type: lighthouse_system_configuration\nversion: '1'\nsystemType: 1\n")
    assert main(["import", "crazyflie", str(tmp_path / "log00"), "--system-config",
                 str(yaml_path), "-o", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "LH2 sweeps" in err[0]


def test_calibration_mapping_round_trip():
    rng = np.random.default_rng(3)
    sweeps = [{"phase": rng.normal(0, 0.05), "tilt": rng.normal(0, 0.01),
               "curve": rng.normal(0, 0.005), "gibphase": rng.uniform(-3, 3),
               "gibmag": rng.normal(0, 0.01), "ogeephase": 0.0, "ogeemag": 0.0}
              for _ in range(2)]
    back = calibration_to_bitcraze(calibration_from_bitcraze(sweeps))
    for s, b in zip(sweeps, back, strict=True):
        for key, value in s.items():
            assert b[key] == pytest.approx(value, abs=1e-12)


@needs_data
def test_mapping_reproduces_corrected_angle():
    from lhgraph.io.cfclient import read_system_config

    angles, _ = lh1_angles(read_usd_log(LH1 / "log02"))
    config = read_system_config(LH1 / "system-config.yaml")
    # a logged group (both sweeps of every station) spans < 1 ms; groups are >= 15 ms apart
    log_time = angles.extra["log_time"]
    order = np.argsort(log_time)
    t = np.empty(len(order), dtype=np.int64)
    t[order] = np.cumsum(np.r_[0, np.diff(log_time[order]) > 1e-3])
    for bs in (0, 1):
        pairs = {}
        for ax in (0, 1):
            s = (angles.lighthouse == bs) & (angles.axis == ax)
            pairs[ax] = {(tt, k): (a, c) for tt, k, a, c in zip(
                t[s], angles.sensor[s], angles.angle[s], angles.extra["corrected_angle"][s],
                strict=True)}
        keys = sorted(set(pairs[0]) & set(pairs[1]))
        m = np.array([[pairs[0][k][0], pairs[1][k][0]] for k in keys])
        c = np.array([[pairs[0][k][1], pairs[1][k][1]] for k in keys])
        broadcast = config.calibrations[bs].calibration
        az, el = ideal_from_measured(m[:, 0], m[:, 1],
                                     StationModel(firmware_equivalent(broadcast)))
        assert np.median(np.abs(np.c_[az, el] - c)) < 2e-5
        # the default (broadcast) curve sign is not the firmware's: the two corrections
        # differ by twice the curve term, largest where the other angle is
        az, el = ideal_from_measured(m[:, 0], m[:, 1], StationModel(broadcast))
        curve = -2 * broadcast.curve[None, :] * np.c_[c[:, 1], c[:, 0]] ** 2
        assert np.median(np.abs(np.c_[az, el] - c - curve)) < 2e-5
        assert np.percentile(np.abs(curve), 99) > 5e-4
        identity = ideal_from_measured(m[:, 0], m[:, 1], StationModel(FactoryCalibration()))
        assert np.median(np.abs(np.c_[identity[0], identity[1]] - c)) > 1e-2


@needs_data
def test_real_import_end_to_end(tmp_path):
    r = import_crazyflie(LH1 / "log02", tmp_path, LH1 / "system-config.yaml")
    assert r.notes == () and r.version == 2
    assert "the curve with its broadcast sign" in r.summary()
    assert r.sweeps.repeats[0] > 5000 and r.sweeps.repeats[1] < 100
    a = load_angles(tmp_path / "angles.csv")
    for bs in (0, 1):
        sel = (a.lighthouse == bs) & (a.axis == 0) & (a.sensor == 0)
        # the stations' 30 Hz on the deck's clock (the log's own says 33.0 ms)
        assert np.median(np.diff(a.time[sel])) == pytest.approx(1 / 30, abs=1e-4)
    st = load_stations(tmp_path / "stations-cfclient.toml")
    assert st.indices() == [0, 1]
    assert 3.0 < np.linalg.norm(st.pose(0)[:3, 3] - st.pose(1)[:3, 3]) < 5.0
    mocap = read_csv_columns(tmp_path / "mocap.csv", [("time", float), ("x", float)])
    assert mocap["time"][0] >= r.mocap.time[0] - 1e-6
    # Qualisys and the deck's clock agree; the log's own runs 1.09 % slow against both
    assert r.clock.scale == pytest.approx(1.01106, abs=2e-5)
    assert r.mocap.rate == pytest.approx(1.0, abs=1e-4)
    for name in ("board.toml", "imu.csv", "ootx.toml"):
        assert (tmp_path / name).is_file()


def test_a_real_log_damaged_in_the_middle_loses_only_the_damage(shared_data, tmp_path):
    # a byte lost half-way through a shared log (a copy in tmp, never kept): the reader
    # resynchronises and keeps all but the few events around it
    source = shared_data / "bitcraze-positioning" / "lh1_crossingBeam_move" / "log02"
    data = bytearray(source.read_bytes())
    del data[len(data) // 2]
    (tmp_path / "log02").write_bytes(bytes(data))
    clean, damaged = read_usd_log(source), read_usd_log(tmp_path / "log02")
    n_clean, n_damaged = (sum(len(v) for v in log.events.values()) for log in (clean, damaged))
    assert n_clean - 3 <= n_damaged < n_clean
    assert sum("resumed at byte" in n for n in damaged.notes) == 1, damaged.notes
    for name, ev in clean.events.items():
        np.testing.assert_array_equal(damaged.events[name]["timestamp"][-50:],
                                      ev["timestamp"][-50:])
