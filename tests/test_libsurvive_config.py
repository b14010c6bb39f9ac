"""libsurvive's config.json (lhgraph/io/libsurvive_config.py, ``lhgraph export libsurvive``,
``lhgraph import libsurvive``): an exact round trip, a reader that follows libsurvive's own
parsing and reprojection rules, the committed libsurvive file (MIT) read, bad input."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.estimation.world_alignment import WorldOptions
from lhgraph.geometry.transforms import inverse, make_pose, quat_to_matrix, se3_exp
from lhgraph.importers.libsurvive import import_libsurvive
from lhgraph.io.libsurvive_config import (
    R_SURVIVE_LH,
    read_survive_config,
    variance_to_survive,
)
from lhgraph.io.stations import Station, Stations, load_stations, save_stations
from lhgraph.model import lh1
from lhgraph.model.calibration import StationCalibration, load_calibration, save_calibration
from lhgraph.model.factory import FactoryCalibration
from lhgraph.signal.libsurvive import read_libsurvive_calibration, read_libsurvive_poses
from lhgraph.workflow.export import export_libsurvive

FIXTURE_JSON = (Path(__file__).resolve().parent / "data" / "libsurvive"
                / "lh1_test_cal_hmd_7s.rec.gz.json")
AS_IS = ("--up", "none", "--origin", "world", "--x", "world")


def _room(tmp_path: Path, generation: int = 1) -> tuple[Path, Path, Stations]:
    """Two stations with covariances and factory calibrations, written as TOML files."""
    rng = np.random.default_rng(7)
    poses = {0: se3_exp(rng.normal(0, [0.3, 0.3, 0.3, 1, 1, 1])),
             1: se3_exp(rng.normal(0, [0.3, 0.3, 0.3, 2, 2, 1]))}
    cals, stations = {}, {}
    for k, T in poses.items():
        A = rng.normal(0, 1e-3, (6, 6))
        terms = {key: rng.uniform(-0.01, 0.01, 2)
                 for key in ("phase", "tilt", "curve", "gibmag")}
        lh2 = {"ogeephase": rng.uniform(-1, 1, 2), "ogeemag": rng.uniform(-0.1, 0.1, 2)} \
            if generation == 2 else {}
        cal = StationCalibration(
            FactoryCalibration(gibphase=rng.uniform(-3, 3, 2), **terms, **lh2),
            id=[178605925, 4152238579][k], accel_dir=rng.normal(0, 1, 3),
            generation=generation, channel=k + 3 if generation == 2 else None)
        cals[k] = cal
        stations[k] = Station(T, A @ A.T + 1e-8 * np.eye(6), cal.model())
    room = Stations(0, stations)
    save_stations(room, tmp_path / "stations.toml")
    save_calibration(cals, tmp_path / "ootx.toml")
    return tmp_path / "stations.toml", tmp_path / "ootx.toml", room


@pytest.mark.parametrize("generation", [1, 2])
def test_export_import_round_trip_is_exact(tmp_path, capsys, generation):
    stations, ootx, room = _room(tmp_path, generation)
    out = tmp_path / "config.json"
    assert main(["export", "libsurvive", str(stations), "--calibration", str(ootx),
                 "--output", str(out), *AS_IS]) == 0
    assert main(["import", "libsurvive", str(out), "--output", str(tmp_path / "back")]) == 0
    back = load_stations(tmp_path / "back" / "stations.toml")
    cals, cals_back = load_calibration(ootx), load_calibration(tmp_path / "back" / "ootx.toml")
    for k in room.indices():
        np.testing.assert_allclose(back.pose(k), room.pose(k), rtol=0, atol=1e-9)
        # libsurvive keeps the world-axis diagonal of the covariance, and that exactly
        np.testing.assert_allclose(
            variance_to_survive(back.pose(k), back.stations[k].covariance),
            variance_to_survive(room.pose(k), room.stations[k].covariance), rtol=1e-9)
        a, b = cals[k], cals_back[k]
        assert (a.id, a.generation, a.channel) == (b.id, b.generation, b.channel)
        for key in ("phase", "tilt", "curve", "gibphase", "gibmag", "ogeephase", "ogeemag"):
            np.testing.assert_array_equal(getattr(a.calibration, key),
                                          getattr(b.calibration, key))
        np.testing.assert_array_equal(a.accel_dir, b.accel_dir)
    assert "wrote" in capsys.readouterr().out


# --- a reader that follows libsurvive's own rules (its config reader and LH1 reprojection) ---

def _survive_values(text: str) -> dict[str, dict[str, object]]:
    """Parse as libsurvive does: a run of "tag":value members without enclosing braces,
    groups "lighthouseN":{...}; each value (or every element of an array) that reads fully
    as a base-10 integer is an integer entry (an array: its first element only), otherwise
    floats. Returns {group: {tag: int | float | list[float]}}, "" for the globals."""
    assert not text.lstrip().startswith("{"), "libsurvive's reader takes no enclosing braces"
    groups: dict[str, dict[str, object]] = {"": {}}
    current = ""
    for m in re.finditer(r'"([^"]*)"\s*:\s*(\{|\[[^\]]*\]|"[^"]*")|(\})', text):
        if m.group(3):
            current = ""
            continue
        tag, value = m.group(1), m.group(2)
        if value == "{":
            current = tag
            groups[current] = {}
            continue
        items = re.findall(r'"([^"]*)"', value)
        if all(re.fullmatch(r"-?\d+", v) for v in items):
            groups[current][tag] = int(items[0]) % 2**32  # strtoul, then a uint32
        else:
            floats = [float(v) for v in items]
            groups[current][tag] = floats if value.startswith("[") else floats[0]
    return groups


def _survive_angles(pose: list[float], p_world: np.ndarray) -> np.ndarray:
    """libsurvive's ideal LH1 angles of world points: world2lh is the inverse of the pose
    (x y z qw qx qy qz, lighthouse to world); axis 0 -atan2(x, -z), axis 1 atan2(y, -z)."""
    T = make_pose(quat_to_matrix(np.asarray(pose[3:7]) / np.linalg.norm(pose[3:7])),
                  pose[:3])
    p = (inverse(T) @ np.c_[p_world, np.ones(len(p_world))].T).T[:, :3]
    return np.stack([-np.arctan2(p[:, 0], -p[:, 2]), np.arctan2(p[:, 1], -p[:, 2])], axis=1)


def test_libsurvive_reads_the_export_as_our_stations(tmp_path):
    stations, ootx, room = _room(tmp_path)
    out = export_libsurvive(stations, tmp_path / "config.json", calibration=ootx,
                            options=WorldOptions(up="none", origin="world", x="world")).path
    groups = _survive_values(out.read_text())
    assert groups[""]["lighthouse-gen"] == 1
    cals = load_calibration(ootx)
    rng = np.random.default_rng(3)
    for k in room.indices():
        group = groups[f"lighthouse{k}"]
        assert group["index"] == k  # libsurvive reads lighthouseN only when index is N
        assert group["id"] == cals[k].id and group["OOTXSet"] == 1
        assert group["PositionSet"] == 1
        for tag in ("pose", "variance", "accel", "fcalphase", "fcalgibpha"):
            assert isinstance(group[tag], list)  # floats, never mistaken for an integer
        assert group["fcalgibpha"] == list(cals[k].calibration.gibphase)
        # points in front of the station, in the world: libsurvive's angles are ours
        T = room.pose(k)
        p_lh = np.c_[rng.uniform(1, 5, 50), rng.uniform(-2, 2, 50), rng.uniform(-2, 2, 50)]
        p_world = (T[:3, :3] @ p_lh.T).T + T[:3, 3]
        np.testing.assert_allclose(_survive_angles(group["pose"], p_world),
                                   lh1.ideal_angles(p_lh), atol=1e-12)


def test_the_committed_libsurvive_file(tmp_path):
    config = read_survive_config(FIXTURE_JSON)
    assert config.generation == 1 and "libsurvive detects it" in config.notes[0]
    cals = read_libsurvive_calibration(FIXTURE_JSON)
    assert cals[1].id == 4152238579  # written by libsurvive as the signed -142728717
    np.testing.assert_allclose(cals[0].calibration.gibphase, [2.890625, 0.024002])
    native = read_libsurvive_poses(FIXTURE_JSON)
    for k, lh in config.lighthouses.items():
        np.testing.assert_allclose(lh.T_world_lh[:3, :3], native[k][:3, :3] @ R_SURVIVE_LH)
        assert lh.T_world_lh[2, 2] > 0.99  # our z (up) is libsurvive's world z
    # the two stations face each other across the room: each one's forward (our +x) axis
    # points at the other
    T0, T1 = config.lighthouses[0].T_world_lh, config.lighthouses[1].T_world_lh
    towards = (T1[:3, 3] - T0[:3, 3]) / np.linalg.norm(T1[:3, 3] - T0[:3, 3])
    assert T0[:3, 0] @ towards > 0.95 and T1[:3, 0] @ -towards > 0.95
    imported = import_libsurvive(FIXTURE_JSON, tmp_path)
    assert set(imported.paths) == {"stations", "ootx"}
    assert load_stations(imported.paths["stations"]).extra["world"] == "libsurvive"


GOOD = ('"lighthouse-gen":"1",\n"lighthousecount":"1"\n"lighthouse0":{\n"index":"0",\n'
        '"id":"5",\n"mode":"0",\n"pose":["1.0","2.0","3.0","1.0","0.0","0.0","0.0"],\n'
        '"fcalphase":["0.01","0.02"],\n"OOTXSet":"1",\n"PositionSet":"1"\n}\n')


@pytest.mark.parametrize("text, message", [
    (GOOD.replace('"index":"0"', '"index":"1"'), "index is 1"),
    (GOOD.replace('"3.0","1.0","0.0"', '"3.0","1.0"'), "'pose' must hold 7 numbers"),
    (GOOD.replace('"0.01","0.02"', '"0.5","0.02"'), "phase"),
    (GOOD.replace('"2.0"', '"nan"'), "not a finite number"),
    (GOOD.replace("lighthouse0", "tracker0"), 'no "lighthouseN" groups'),
    (GOOD.replace('"PositionSet":"1"', '"PositionSet":"0"'), "no lighthouse has a pose"),
    ('"lighthouse0":{"index":"0", "pose":["1.0"', "never closed"),
    ("not a config at all", "not a libsurvive config"),
])
def test_bad_config_exits_2_naming_the_file(tmp_path, capsys, text, message):
    bad = tmp_path / "config.json"
    bad.write_text(text)
    assert main(["import", "libsurvive", str(bad), "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and message in err and "Traceback" not in err
    assert not (tmp_path / "out" / "stations.toml").exists()


def test_strict_json_and_a_station_without_pose(tmp_path, capsys):
    two = GOOD + GOOD.split('"lighthousecount":"1"\n', 1)[1].replace(
        "lighthouse0", "lighthouse1").replace('"index":"0"', '"index":"1"').replace(
        '"PositionSet":"1"', '"PositionSet":"0"')
    path = tmp_path / "config.json"
    path.write_text("{" + two.replace("\n}\n", "\n},\n", 1) + "}")  # one enclosing object
    assert main(["import", "libsurvive", str(path), "--output", str(tmp_path / "o"),
                 "--quiet"]) == 0
    assert "lighthouse1 has no pose" in capsys.readouterr().err  # said even when quiet
    stations = load_stations(tmp_path / "o" / "stations.toml")
    assert stations.indices() == [0]
    np.testing.assert_allclose(stations.pose(0)[:3, :3], R_SURVIVE_LH)
    assert sorted(load_calibration(tmp_path / "o" / "ootx.toml")) == [0, 1]


def test_export_refuses_to_overwrite(tmp_path, capsys):
    stations, ootx, _ = _room(tmp_path)
    out = tmp_path / "config.json"
    out.write_text("keep")
    assert main(["export", "libsurvive", str(stations), "--output", str(out)]) == 2
    assert out.read_text() == "keep" and "exists" in capsys.readouterr().err
