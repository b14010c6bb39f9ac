"""lhgraph compare: two calibrations of one room, station by station (#39 item 5). Known
answers on stations built here: identical layouts are the same in any world, a station
shifted or turned past the rule is "moved" with exit 3, sigmas scale the rule, bad inputs
are one line with exit 2."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.estimation.layout_compare import CompareOptions, compare_layouts
from lhgraph.estimation.receiver_scale import RESULT_KEY, receiver_scale_covariance
from lhgraph.geometry.transforms import se3_exp, so3_exp
from lhgraph.io.stations import Station, Stations, save_stations


def _layout(sigma_mm: float = 1.0, sigma_deg: float = 0.01) -> Stations:
    cov = np.diag([np.radians(sigma_deg)] * 3 + [sigma_mm * 1e-3] * 3) ** 2
    poses = {0: np.eye(4), 1: se3_exp([0.1, -0.2, 1.5, 4.0, 0.3, 0.1]),
             2: se3_exp([-0.3, 0.4, -1.2, 1.0, 3.0, -0.2])}
    return Stations(0, {k: Station(T, None if k == 0 else cov.copy()) for k, T in
                        poses.items()})


def _moved(s: Stations, k: int, dp_m=(0, 0, 0), rot_deg: float = 0.0) -> Stations:
    T = s.pose(k).copy()
    T[:3, 3] += dp_m
    T[:3, :3] = T[:3, :3] @ so3_exp([0, 0, np.radians(rot_deg)])
    return Stations(s.reference, {**s.stations, k: dataclasses.replace(s.stations[k],
                                                                       T_world_lh=T)})


def _in_another_world(s: Stations) -> Stations:
    T_new_world = se3_exp([0.2, 0.5, -0.7, 3.0, -1.0, 2.0])
    return Stations(s.reference, {k: dataclasses.replace(st, T_world_lh=T_new_world
                                                         @ st.T_world_lh)
                                  for k, st in s.stations.items()}, dict(s.extra))


def test_same_layout_in_any_world():
    a = _layout()
    c = compare_layouts(a, _in_another_world(a))
    assert c.verdict() == "same layout" and not c.moved
    assert max(d.position_m for d in c.differences) < 1e-9
    assert max(d.rotation_rad for d in c.differences) < 1e-9


def test_a_shifted_station_moved_by_its_shift_in_combined_sigmas():
    a = _layout(sigma_mm=2.0)
    b = _in_another_world(_moved(a, 2, dp_m=(0.03, 0.04, 0.0)))  # 50 mm
    c = compare_layouts(a, b)
    d = {x.station: x for x in c.differences}
    assert d[2].moved and not d[1].moved
    assert d[2].position_m == pytest.approx(0.05, abs=1e-9)
    # two files of 2 mm each: the combined sigma along any direction is 2 * sqrt(2) mm
    assert d[2].sigma_position_m == pytest.approx(2e-3 * np.sqrt(2), rel=1e-9)
    assert d[2].position_sigmas == pytest.approx(50 / (2 * np.sqrt(2)), rel=1e-6)
    assert np.isnan(d[2].sigma_white_position_m)  # the files have no white covariance
    assert c.verdict().startswith("station 2 moved by 50.0 mm / 0.00 deg (17.7 /")


def _with_scale_share(s: Stations, sigma: float, recorded: bool = True) -> Stations:
    """``s`` with each station's receiver-scale share added to its covariance, as a
    few-diode solve gives, and the spread recorded in the result (or not)."""
    return Stations(s.reference, {k: dataclasses.replace(
        st, covariance=None if st.covariance is None else
        st.covariance + receiver_scale_covariance(st.T_world_lh, sigma))
        for k, st in s.stations.items()}, {RESULT_KEY: sigma} if recorded else {})


def test_one_receivers_scale_share_is_taken_out_of_the_difference():
    """Two results of one deck share its scale error: their 50 mm bump is judged against the
    2 mm sigmas of the solves, not the ~40 mm the scale share adds along station 2's 3.2 m
    baseline; results that do not record the share keep it."""
    a = _layout(sigma_mm=2.0)
    b = _moved(a, 2, dp_m=(0.03, 0.04, 0.0))
    plain = compare_layouts(a, b).differences[1]
    shared = compare_layouts(_with_scale_share(a, 0.01),
                             _in_another_world(_with_scale_share(b, 0.01))).differences[1]
    assert shared.station == plain.station == 2
    # put back once: the scale's effect on the 50 mm difference itself, 0.5 mm
    assert shared.sigma_position_m == pytest.approx(np.hypot(plain.sigma_position_m, 5e-4),
                                                    rel=1e-6)
    assert shared.moved
    unrecorded = compare_layouts(_with_scale_share(a, 0.01, False),
                                 _with_scale_share(b, 0.01, False)).differences[1]
    assert unrecorded.sigma_position_m > 10 * plain.sigma_position_m


def test_the_rule_needs_both_the_floor_and_k_sigma():
    a = _layout(sigma_mm=20.0)
    b = _moved(a, 1, dp_m=(0.06, 0, 0))  # 60 mm: over the 40 mm floor, 2.1 combined sigma
    assert not compare_layouts(a, b).moved
    assert compare_layouts(a, b, options=CompareOptions(k_sigma=2.0)).moved
    tight = _layout(sigma_mm=0.1)
    assert not compare_layouts(tight, _moved(tight, 1, dp_m=(0.01, 0, 0))).moved  # floor
    assert compare_layouts(tight, _moved(tight, 1, dp_m=(0.01, 0, 0)),
                           options=CompareOptions(floor_mm=5.0)).moved
    assert compare_layouts(tight, _moved(tight, 1, rot_deg=1.0)).moved  # over 0.6 deg


def test_without_covariances_only_the_floor_judges():
    a = _layout()
    bare = Stations(0, {k: Station(s.T_world_lh) for k, s in a.stations.items()})
    c = compare_layouts(bare, _moved(bare, 1, dp_m=(0.0, 0.0, 0.05)))
    assert c.moved[0].station == 1 and np.isnan(c.moved[0].sigma_position_m)
    assert "sigma" not in c.verdict()


def test_common_reference_and_refusals():
    a = _layout()
    b = Stations(1, dict(a.stations))
    assert compare_layouts(a, b).reference == 0  # A's reference, B has it
    assert compare_layouts(a, b, reference=2).reference == 2
    with pytest.raises(InputError, match="station 7 is not in both"):
        compare_layouts(a, b, reference=7)
    with pytest.raises(InputError, match="share 1 station"):
        compare_layouts(a, Stations(0, {0: a.stations[0], 5: a.stations[1]}))
    with pytest.raises(InputError, match="k_sigma"):
        CompareOptions(k_sigma=0)


def test_cli_exit_codes_table_and_json(tmp_path: Path, capsys):
    a = _layout()
    pa, pb, pc = tmp_path / "a.toml", tmp_path / "b.toml", tmp_path / "c.toml"
    save_stations(a, pa)
    save_stations(_in_another_world(a), pb)
    save_stations(_moved(a, 1, dp_m=(0.0, 0.1, 0.0)), pc)
    assert main(["compare", str(pa), str(pb)]) == 0
    out = capsys.readouterr().out
    assert "verdict: same layout" in out and "in the frame of station 0" in out
    assert main(["compare", str(pa), str(pc), "--json", str(tmp_path / "c.json"),
                 "--quiet"]) == 3
    assert capsys.readouterr().out.strip().startswith("MOVED: station 1 moved by 100.0 mm")
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["moved"] == [1] and doc["stations"]["1"]["position_m"] == pytest.approx(0.1)
    # bad input: one line, exit 2; the JSON is not written over an input
    (tmp_path / "bad.toml").write_text("reference = 0\n[lighthouses.0]\nposition = [0, 0]\n")
    for args in (["compare", str(pa), str(tmp_path / "bad.toml")],
                 ["compare", str(pa), str(tmp_path / "none.toml")],
                 ["compare", str(pa), str(pb), "--json", str(pa)],
                 ["compare", str(pa), str(pb), "--k-sigma", "-1"]):
        assert main(args) == 2, args
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err


def test_white_sigmas_beside_the_honest_ones_which_judge():
    honest = _layout(sigma_mm=5.0)
    a = Stations(0, {k: dataclasses.replace(s, covariance_white=None if s.covariance is None
                                            else s.covariance / 25)
                     for k, s in honest.stations.items()})
    b = _moved(a, 1, dp_m=(0.02, 0, 0))  # 20 mm: 2.8 honest sigmas, 14 white ones
    d = compare_layouts(a, b, options=CompareOptions(floor_mm=0.0)).differences[0]
    assert d.sigma_position_m == pytest.approx(5e-3 * np.sqrt(2), rel=1e-9)
    assert d.sigma_white_position_m == pytest.approx(1e-3 * np.sqrt(2), rel=1e-9)
    assert not d.moved  # judged on the honest sigma (3 x 7.1 mm), not the white one
