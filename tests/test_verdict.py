"""The verdict on a solve: printed after every `lhgraph solve`, stored in the stations TOML and
summary.json; a failed one (an unconverged solve) exits 3 and `lhgraph export` refuses it
unless told (docs/cli.md, docs/solve.md)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.estimation.result import Residuals
from lhgraph.io.stations import load_stations
from lhgraph.report.assessment import track_verdict, verdict
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "simulation" / "default.toml"


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("capture")
    sim = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=1.5), 7)
    write_simulation(sim, folder)
    return folder


def _flags(folder: Path, out: Path) -> list[str]:
    return ["--board", str(folder / "board.toml"), "--angles", str(folder / "angles.csv"),
            "--output", str(out)]


def test_plain_solve_prints_and_stores_the_verdict(capture, tmp_path, capsys):
    out = tmp_path / "result.toml"
    assert main(["solve", *_flags(capture, out)]) == 0
    printed = capsys.readouterr().out
    stored = load_stations(out).extra["verdict"]
    assert stored["status"] in ("ok", "check")
    assert f"verdict: {stored['text']}" in printed.splitlines()
    # a run directory: the verdict in summary.json and in its stations.toml, and printed
    config = tmp_path / "run.toml"
    config.write_text(f'board = "{capture / "board.toml"}"\nangles = "{capture / "angles.csv"}"\n')
    assert main(["solve", str(config), "--output", str(tmp_path / "run")]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["verdict"]["status"] in ("ok", "check")
    assert load_stations(tmp_path / "run" / "stations.toml").extra["verdict"] == summary["verdict"]
    assert f"verdict: {summary['verdict']['text']}" in capsys.readouterr().out.splitlines()


def test_unconverged_solve_exits_3_and_export_refuses_it(capture, tmp_path, capsys):
    config = tmp_path / "short.toml"
    config.write_text(f'board = "{capture / "board.toml"}"\nangles = "{capture / "angles.csv"}"\n'
                      "[graph]\nmax_iterations = 1\n")
    out = tmp_path / "result.toml"
    assert main(["solve", str(config), "--output", str(out)]) == 3
    printed = capsys.readouterr().out
    assert "verdict: FAILED: the solver stopped at its iteration limit after 1 iterations" in (
        printed)
    assert load_stations(out).extra["verdict"]["status"] == "failed"
    # --quiet still says why it exits 3
    assert main(["solve", str(config), "--output", str(out), "--force", "--quiet"]) == 3
    assert "verdict: FAILED" in capsys.readouterr().err
    yaml = tmp_path / "system-config.yaml"
    assert main(["export", "cfclient", str(out), "--output", str(yaml)]) == 3
    err = capsys.readouterr().err
    assert "verdict is FAILED" in err and "--force-unverified" in err and not yaml.exists()
    assert main(["export", "cfclient", str(out), "--output", str(yaml),
                 "--force-unverified"]) == 0
    assert "warning: exporting a result whose verdict is FAILED" in capsys.readouterr().err
    assert yaml.exists()


def _summary(status: str = "converged", warnings: list[str] | None = None) -> dict:
    return {"status": status, "iterations": 60, "warnings": warnings or [],
            "residuals": {"inlier_fraction": 0.99, "per_station_axis": {}},
            "stations": {"0": {}, "1": {"sigma_position_mm": [0.5, 0.5, 0.5]}}}


def test_verdict_status_and_reasons_name_their_cause():
    assert verdict(_summary()).status == "ok"
    assert verdict(_summary(warnings=["station 1: weak link"])).status == "check"
    stalled = verdict(_summary("stalled"))
    assert stalled.failed and "stalled" in stalled.text() and "IMU" not in stalled.text()
    # a track: large residuals blame the stations, and the IMU only when one was used
    rng = np.random.default_rng(0)
    n = 2000
    res = Residuals(np.arange(n) * 0.01, np.zeros(n, int), np.arange(n) % 2, np.zeros(n, int),
                    rng.normal(0, 0.03, n), np.full(n, 0.3))
    light = track_verdict("converged", 10, res, 3.0)
    assert light.failed and "another room" in light.text() and "IMU" not in light.text()
    assert "IMU" in track_verdict("converged", 10, res, 3.0, 9.8).text()
    good = dataclasses.replace(res, residual_rad=rng.normal(0, 6e-5, n), weight=np.ones(n))
    assert track_verdict("converged", 10, good, 3.0).ok
    g = track_verdict("converged", 10, good, 3.0, 1.0)
    assert g.failed and "not g" in g.text()


def test_an_imu_track_is_judged_by_its_own_misfit_not_the_light_only_calibrations():
    # the shared LH1 hand-held log tracked with its IMU through its own calibration: 404 urad
    # at 3.6 m (1.44 mm), 7x the light-only calibration's 57 urad, and the most accurate path
    rng = np.random.default_rng(1)
    n = 4000
    res = Residuals(np.arange(n) * 0.01, np.zeros(n, int), np.arange(n) % 2, np.zeros(n, int),
                    rng.normal(0, 404e-6, n), np.ones(n))
    with_imu = track_verdict("converged", 10, res, 3.6, 9.81, 57.0, 0.02)
    assert with_imu.ok, with_imu.text()
    light = track_verdict("converged", 10, res, 3.6, calibration_spread_urad=57.0)
    assert light.failed and "x the calibration's 57" in light.text()
    # with the IMU, another room's misfit still fails (89 mm residual-equivalent at 3.6 m)
    far = dataclasses.replace(res, residual_rad=rng.normal(0, 0.025, n))
    assert track_verdict("converged", 10, far, 3.6, 9.81, 57.0, 0.02).failed


def test_a_wide_sigma_names_the_receivers_size_when_that_is_most_of_it():
    summary = _summary()
    summary["stations"]["1"] = {"sigma_position_mm": [3.0, 24.0, 3.0],
                                "position_m": [2.4, -3.1, 1.7]}
    plain = verdict(summary)
    assert plain.status == "check" and "poorly determined" in plain.text()
    summary["resolved_options"] = {"uncertainty": {"receiver_scale_sigma": 0.006}}
    scaled = verdict(summary)
    assert scaled.status == "check" and "poorly determined" not in scaled.text()
    assert "26 mm of it the receiver's size" in scaled.text()  # 0.6 % of 4.3 m


def _track(folder: Path, stations: Path, out: Path, *extra: str) -> int:
    return main(["track", "--stations", str(stations), "--board", str(folder / "board.toml"),
                 "--angles", str(folder / "angles.csv"), "--output", str(out), *extra])


def test_track_reports_residuals_and_fails_on_another_rooms_stations(capture, tmp_path,
                                                                      capsys):
    assert _track(capture, capture / "truth.toml", tmp_path / "t.csv") == 0
    out = capsys.readouterr().out
    assert "residuals:" in out and "mm at the median range" in out
    assert "verdict: OK" in out.splitlines()
    # the stations of another simulated room: exit 3 naming the stations as the cause
    other = tmp_path / "other"
    far = load_simulation_config(CONFIG.with_name("far.toml"))
    write_simulation(simulate(dataclasses.replace(far, duration_s=0.5), 11), other)
    assert _track(capture, other / "truth.toml", tmp_path / "t2.csv") == 3
    out = capsys.readouterr().out
    assert "verdict: FAILED" in out and "the angles do not fit these stations" in out
    assert "another room" in out and "IMU" not in out
    # streaming: the same verdict, from the residuals of the path as it was reported
    assert _track(capture, capture / "truth.toml", tmp_path / "s.csv", "--streaming") == 0
    out = capsys.readouterr().out
    assert "streaming" in out and "verdict: OK" in out.splitlines()
    assert _track(capture, other / "truth.toml", tmp_path / "s2.csv", "--streaming") == 3
    out = capsys.readouterr().out
    assert "verdict: FAILED" in out and "the angles do not fit these stations" in out


def test_track_with_a_gravity_far_from_1_g_fails(tmp_path, capsys):
    # an accelerometer 20 % over scale (not a unit the load refuses) gives a track whose
    # gravity is not 1 g: the verdict fails it, exit 3
    from lhgraph.io.imu import load_imu, save_imu
    from lhgraph.sim.imu import ImuConfig

    config = dataclasses.replace(load_simulation_config(CONFIG), duration_s=2.0,
                                 imu=ImuConfig(rate_hz=200.0))
    write_simulation(simulate(config, 5), tmp_path)
    assert _track(tmp_path, tmp_path / "truth.toml", tmp_path / "t.csv",
                  "--imu", str(tmp_path / "imu.csv")) == 0
    assert "verdict: OK" in capsys.readouterr().out
    imu = load_imu(tmp_path / "imu.csv")
    save_imu(dataclasses.replace(imu, accel_mps2=imu.accel_mps2 * 1.2), tmp_path / "imu_s.csv")
    assert _track(tmp_path, tmp_path / "truth.toml", tmp_path / "t2.csv",
                  "--imu", str(tmp_path / "imu_s.csv")) == 3
    assert "not g" in capsys.readouterr().out
