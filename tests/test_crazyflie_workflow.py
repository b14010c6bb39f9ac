"""The documented Crazyflie workflow, end to end on every shared Bitcraze log
(docs/crazyflie.md): ``import crazyflie`` -> ``solve`` -> ``track`` -> ``export cfclient
--imu --trajectory``. Every solve and track prints its verdict; the export is z up with the
stations within 50 mm of the heights in cfclient's own ``system-config.yaml``, or it is
refused with the reason (a receiver that never rests on the floor at the origin, a track
whose poses disagree with the accelerometer). Where cfclient's heights are not a fair
reference (the LH1 flight log: its own geometry is 170 mm off the mocap's), the export is
also held against the stations anchored to the log's Qualisys path
(benchmarks/anchored_stations.py) exported the same way. The logs have no licence: read
from ``../shared``, skipped when absent. One import, solve and track per log (module
fixture): about 15-40 s a log."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from benchmarks.anchored_stations import anchoring_hits, save_anchored
from lhgraph.cli import main
from lhgraph.io.cfclient import read_system_config
from lhgraph.io.stations import load_stations
from lhgraph.io.trajectory import load_trajectory
from lhgraph.model.bitcraze import firmware_equivalent
from lhgraph.model.calibration import load_calibration

LOGS = {"lh1_move_log02": ("lh1_crossingBeam_move", "log02"),
        "lh1_flight_log00": ("lh1_crossingBeam_flight", "log00"),
        "lh2_move_log00": ("lh2_crossingBeam_move", "log00"),
        "lh2_move_log01": ("lh2_crossingBeam_move", "log01")}
HEIGHT_TOLERANCE_M = 0.05
REFUSALS = ("is moving at t =", "agree poorly", "the tracked pose there is wrong")
KNOWN_OFF = {"lh1_flight_log00": (
    "stations 95 / 173 mm below cfclient's file, but the reference is off: the stations "
    "anchored to the log's Qualisys path, exported the same way, are 57 / 137 mm below it "
    "too, ours within 37 / 36 mm of them, cfclient's own stations 83 / 61 mm above them "
    "(docs/results/export_heights.md, docs/results/anchored_stations.md)")}


def _run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def _inputs(out: Path) -> list[str]:
    """The imported folder ``out``'s board, angles and calibration options."""
    return ["--board", str(out / "board.toml"), "--angles", str(out / "angles.csv"),
            "--calibration", str(out / "ootx.toml")]


def _track_and_export(capsys: pytest.CaptureFixture, out: Path, stations: Path, track: str,
                      config: str) -> tuple[tuple[int, str, str], tuple[int, str, str]]:
    """``stations`` tracked on the imported folder ``out`` (to ``out/track``) and exported
    for cfclient with its IMU (to ``out/config``), as the README does: what each printed."""
    tracked = _run(capsys, "track", *_inputs(out), "--stations", str(stations), "--output",
                   str(out / track))
    exported = _run(capsys, "export", "cfclient", str(stations), "--calibration",
                    str(out / "ootx.toml"), "--imu", str(out / "imu.csv"), "--trajectory",
                    str(out / track), "--output", str(out / config))
    return tracked, exported


@pytest.fixture(scope="module")
def workflows(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    return {}


@pytest.fixture(params=sorted(LOGS))
def workflow(request, workflows, shared_data: Path, tmp_path_factory, capsys) -> dict:
    """Import, solve and track one log once (module-wide), keeping what each printed."""
    name = request.param
    if name in workflows:
        return workflows[name]
    folder, log = LOGS[name]
    data = shared_data / "bitcraze-positioning" / folder
    if not (data / log).is_file():
        pytest.skip(f"shared Bitcraze log {folder}/{log} absent")
    out = tmp_path_factory.mktemp(name)
    assert _run(capsys, "import", "crazyflie", str(data / log), "--system-config",
                str(data / "system-config.yaml"), "--output", str(out), "--quiet")[0] == 0
    solve = _run(capsys, "solve", *_inputs(out), "--output", str(out / "stations.toml"))
    track, export = _track_and_export(capsys, out, out / "stations.toml", "track.csv",
                                      "system-config.yaml")
    workflows[name] = {"name": name, "out": out, "data": data, "solve": solve, "track": track,
                       "export": export}
    return workflows[name]


def test_solve_and_track_print_a_verdict(workflow):
    for step in ("solve", "track"):
        code, out, _ = workflow[step]
        verdicts = [line for line in out.splitlines() if line.startswith("verdict: ")]
        assert len(verdicts) == 1, step
        assert code == (3 if verdicts[0].startswith("verdict: FAILED") else 0), step


def test_export_is_within_50_mm_of_cfclients_heights_or_refused(workflow, request):
    if workflow["name"] in KNOWN_OFF:
        request.node.add_marker(pytest.mark.xfail(reason=KNOWN_OFF[workflow["name"]],
                                                  strict=True))
    code, _, err = workflow["export"]
    if code != 0:
        assert code == 2 and any(r in err for r in REFUSALS), err
        assert not (workflow["out"] / "system-config.yaml").exists()
        return
    ours = read_system_config(workflow["out"] / "system-config.yaml").T_world_lh
    theirs = read_system_config(workflow["data"] / "system-config.yaml").T_world_lh
    for k, T in ours.items():
        assert abs(T[2, 3] - theirs[k][2, 3]) < HEIGHT_TOLERANCE_M, (k, T[2, 3], theirs[k][2, 3])


def test_export_is_within_50_mm_of_the_mocap_anchored_stations_exported_alike(workflow,
                                                                               capsys):
    """The export's heights against a geometry that owes nothing to either solve: each
    station resected on the log's Qualisys path, then tracked and exported by the same
    commands (so the same gravity-levelled world and origin)."""
    code, _, _ = workflow["export"]
    if code != 0:
        pytest.skip("the export was refused (the refusal has its own test)")
    out = workflow["out"]
    _, stations = save_anchored(out, load_stations(out / "stations.toml"),
                                load_trajectory(out / "track.csv"))
    track, export = _track_and_export(capsys, out, stations, "track-anchored.csv",
                                      "anchored.yaml")
    assert track[0] in (0, 3) and export[0] == 0
    ours = read_system_config(out / "system-config.yaml").T_world_lh
    truth = read_system_config(out / "anchored.yaml").T_world_lh
    for k, T in ours.items():
        assert abs(T[2, 3] - truth[k][2, 3]) < HEIGHT_TOLERANCE_M, (k, T[2, 3], truth[k][2, 3])


def test_the_broadcast_curve_sign_fits_the_mocap_better_than_the_firmwares(workflow):
    """On the LH1 logs our default (the broadcast curve, docs/crazyflie.md#the-lh1-curves-sign)
    leaves a smaller residual than the firmware's sign when the stations are resected on the
    log's Qualisys path (the board's orientation from the track)."""
    calibration = load_calibration(workflow["out"] / "ootx.toml")
    if calibration[0].generation != 1:
        pytest.skip("an LH2 log: no curve term applied")
    out = workflow["out"]
    hits = anchoring_hits(out, load_stations(out / "stations.toml"),
                          load_trajectory(out / "track.csv"))
    residual = {}
    for name, convert in (("broadcast", lambda c: c), ("firmware", firmware_equivalent)):
        models = {k: replace(calibration[k], calibration=convert(calibration[k].calibration))
                  .model() for k in hits.models}
        residual[name] = replace(hits, models=models).resect(
            solve_lever=True).median_abs_residual_rad
    assert residual["broadcast"] < 0.95 * residual["firmware"], residual
