"""The decoder on a real LH1 recording: libsurvive's angles and OOTX, reproduced."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.model.station import CALIBRATION_KEYS
from lhgraph.signal.decode import DecodeOptions, decode_pulses
from lhgraph.signal.libsurvive import (
    match_angles,
    read_libsurvive,
    read_libsurvive_calibration,
)

FIXTURE = Path(__file__).parent / "data" / "libsurvive" / "lh1_test_cal_hmd_7s.rec.gz"
FULL = (Path(__file__).resolve().parents[2] / "shared" / "data" / "libsurvive-lh1"
        / "lh1_test_cal.rec.gz")
TICK_RAD = 2 * np.pi / 800_000  # one 48 MHz tick of angle


def _check_against_libsurvive(path: Path, min_rows: int, device: str = "HMD") -> None:
    rec = read_libsurvive(path, device)
    result = decode_pulses(rec.pulses, rec.sample_rate_hz, None, DecodeOptions(period="nominal"))
    a = result.angles
    theirs, ours = match_angles(rec, a.time, a.sensor)
    assert len(rec.angles.angle) >= min_rows
    assert len(theirs) >= 0.995 * len(rec.angles.angle)  # nearly every A line has our hit
    within = np.abs(a.angle[ours] - rec.angles.angle[theirs]) <= TICK_RAD + 5e-7  # 6 decimals
    assert np.mean(within) >= 0.99
    # conventions: same axis bit; our station = 1 - libsurvive's lh (we count flash order)
    assert np.array_equal(a.axis[ours], rec.angles.acode[theirs] & 1)
    assert np.array_equal(a.lighthouse[ours], 1 - rec.angles.lighthouse[theirs])
    # OOTX: every station's factory calibration equals libsurvive's (6 printed decimals)
    json_cal = read_libsurvive_calibration(str(path) + ".json")
    by_id = {c.id: c for c in json_cal.values()}
    assert sorted(result.calibrations) == [0, 1]
    for index, cal in result.calibrations.items():
        ref = by_id[cal.id]
        assert ref is json_cal[1 - index]
        for key in CALIBRATION_KEYS:
            np.testing.assert_allclose(getattr(cal.calibration, key),
                                       getattr(ref.calibration, key), atol=1.5e-6)


def test_trimmed_fixture_reproduces_libsurvive():
    _check_against_libsurvive(FIXTURE, 5000)


@pytest.mark.slow
@pytest.mark.skipif(not FULL.exists(), reason="../shared/data not present")
@pytest.mark.parametrize("device, rows", [("HMD", 22000), ("T20", 13000)])
def test_full_recording_reproduces_libsurvive(device, rows):
    # T20 (a tracker) also exercises the config's channelMap
    _check_against_libsurvive(FULL, rows, device)


def test_fitted_period_is_measured_and_close_to_nominal():
    rec = read_libsurvive(FIXTURE, "HMD")
    result = decode_pulses(rec.pulses, rec.sample_rate_hz)
    for s in result.report.stations:
        assert abs(s.period_s * 60 - 1) < 50e-6
        assert s.residual_rms_s < 5e-6  # the nominal period leaves ~14 us of drift


def test_reader_errors(tmp_path):
    with pytest.raises(InputError, match="devices with light data: HMD"):
        read_libsurvive(FIXTURE, "T20")
    bad = tmp_path / "x.rec.gz"
    bad.write_bytes(b"not gzip at all")
    with pytest.raises(InputError, match="unreadable"):
        read_libsurvive(bad, "HMD")
    # a truncated gzip keeps the lines read so far
    data = FIXTURE.read_bytes()
    cut = tmp_path / "cut.rec.gz"
    cut.write_bytes(data[: len(data) // 3])
    rec = read_libsurvive(cut, "HMD")
    assert 1000 < len(rec.pulses) < 31840


def test_timecode_wrap(tmp_path):
    lines = ["0.1 D C 1 4294967000 100", "0.2 D C 1 200 100", "0.3 D A 1 0 104 0.000002 0.1 0"]
    path = tmp_path / "w.rec.gz"
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines) + "\n")
    rec = read_libsurvive(path)
    assert rec.pulses.start.tolist() == [0, 496]
    assert rec.angles.timecode.tolist() == [400]


def test_cli_decodes_libsurvive(tmp_path, capsys):
    out = tmp_path / "dec"
    assert main(["decode", str(FIXTURE), "--device", "HMD", "--output", str(out),
                 "--quiet"]) == 0
    assert (out / "angles.csv").exists() and (out / "ootx.toml").exists()
    assert main(["decode", str(FIXTURE), "--device", "HMD", "--output", str(out)]) == 2
    assert "exists already" in capsys.readouterr().err
