"""The CLI's handling of what it is given (issue 40): outputs never written over an input,
created folders announced, single-value options given once, defaults in the help, duplicate
sensor positions, implausible or other-generation factory calibrations refused, the
``ootx.toml`` beside the angles used and said so. Real data (read from ../shared, skipped
when absent) checks that every shipped calibration passes the range checks."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import build_parser, main
from lhgraph.errors import InputError
from lhgraph.io.files import check_writable, guard_inputs
from lhgraph.io.stations import Station, Stations, load_stations, save_stations
from lhgraph.model.board import load_board
from lhgraph.model.calibration import (
    CALIBRATION_RANGES,
    StationCalibration,
    load_calibration,
    save_calibration,
)
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / "configs"


def _sim(tmp_path: Path, config: str = "simulation/default.toml", seconds: float = 2.0,
         seed: int = 1) -> Path:
    """A short simulated capture written to ``tmp_path/sim``."""
    cfg = dataclasses.replace(load_simulation_config(CONFIGS / config), duration_s=seconds)
    out = tmp_path / "sim"
    write_simulation(simulate(cfg, seed), out)
    return out


def _solve_args(sim: Path, output: Path, *more: str) -> list[str]:
    return ["solve", "--board", str(sim / "board.toml"), "--angles", str(sim / "angles.csv"),
            "--output", str(output), "--quiet", *more]


# --- item 1: outputs never written over an input; created folders announced ---


def test_output_equal_to_an_input_is_refused_even_with_force(tmp_path, capsys):
    sim = _sim(tmp_path)
    angles = sim / "angles.csv"
    before = angles.read_bytes()
    for output in (angles, sim / "." / "angles.csv"):
        assert main(_solve_args(sim, output, "--force")) == 2
        err = capsys.readouterr().err
        assert "is an input of this command" in err and "--force" in err
    # the trajectory output, track's output and export's output alike
    assert main(_solve_args(sim, tmp_path / "r.toml", "--trajectory", str(angles),
                            "--force")) == 2
    assert main(["track", "--stations", str(sim / "truth.toml"), "--board",
                 str(sim / "board.toml"), "--angles", str(angles), "-o", str(angles),
                 "--force", "--quiet"]) == 2
    truth = (sim / "truth.toml").read_bytes()
    assert main(["export", "cfclient", str(sim / "truth.toml"), "--output",
                 str(sim / "truth.toml"), "--force", "--quiet"]) == 2
    assert "is an input of this command" in capsys.readouterr().err
    assert angles.read_bytes() == before and (sim / "truth.toml").read_bytes() == truth


def test_input_inside_the_output_folder_is_not_clobbered(tmp_path, capsys):
    """``simulate out/board.toml --output out --force`` would write its board over the
    configuration it reads."""
    out = tmp_path / "out"
    out.mkdir()
    config = out / "board.toml"
    config.write_text((CONFIGS / "simulation" / "default.toml").read_text())
    before = config.read_bytes()
    assert main(["simulate", str(config), "--output", str(out), "--force", "--quiet"]) == 2
    assert "board.toml: is an input of this command" in capsys.readouterr().err
    assert config.read_bytes() == before


def test_guard_sees_links_and_config_named_inputs(tmp_path, capsys):
    data = tmp_path / "angles.csv"
    data.write_text("x")
    link = tmp_path / "link.csv"
    link.symlink_to(data)
    hard = tmp_path / "hard.csv"
    hard.hardlink_to(data)
    with guard_inputs([data]):
        for path in (link, hard):
            with pytest.raises(InputError, match="is an input of this command"):
                check_writable(path, True)
    check_writable(link, True)  # no guard: the Python API is unchanged
    # an input a solve config names (not a command-line argument) is guarded too
    sim = _sim(tmp_path)
    config = tmp_path / "solve.toml"
    config.write_text(f'board = "{sim / "board.toml"}"\nangles = "{sim / "angles.csv"}"\n'
                      f'output = "{sim / "board.toml"}"\n')
    before = (sim / "board.toml").read_bytes()
    assert main(["solve", str(config), "--force", "--quiet"]) == 2
    assert "is an input of this command" in capsys.readouterr().err
    assert (sim / "board.toml").read_bytes() == before


def test_created_output_folders_are_announced(tmp_path, capsys):
    sim = _sim(tmp_path)
    out = tmp_path / "new" / "deeper" / "r.toml"
    assert main(_solve_args(sim, out)[:-1]) == 0
    err = capsys.readouterr().err
    assert err.count("created output folder") == 1
    assert f"lhgraph solve: created output folder {out.parent}" in err
    assert main([*_solve_args(sim, out)[:-1], "--force"]) == 0
    assert "created output folder" not in capsys.readouterr().err
    assert main(["simulate", "--output", str(tmp_path / "s2"), "--quiet"]) == 0
    assert "created output folder" not in capsys.readouterr().err  # --quiet: nothing


# --- item 2: every single-value option given once ---


def _parsers(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()):
    """(argv prefix, parser) of every command and sub-command."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*prefix, name), sub
                yield from _parsers(sub, (*prefix, name))


def _value(action: argparse.Action) -> str:
    return str(next(iter(action.choices))) if action.choices else "1"


def test_every_single_value_option_given_twice_is_refused(capsys):
    checked = 0
    for prefix, parser in _parsers(build_parser()):
        for action in parser._actions:
            if (not action.option_strings or action.nargs == 0 or action.dest == "help"
                    or isinstance(action, argparse._AppendAction)):  # repeatable by design
                continue
            flag = action.option_strings[0]
            with pytest.raises(SystemExit) as info:
                build_parser().parse_args([*prefix, flag, _value(action), flag, _value(action)])
            assert info.value.code == 2
            err = capsys.readouterr().err
            assert f"argument {'/'.join(action.option_strings)}: given more than once" in err
            checked += 1
    assert checked > 40


def test_repeated_angles_solve_every_capture_not_the_last(tmp_path, capsys):
    sim = _sim(tmp_path)
    assert main(_solve_args(sim, tmp_path / "r.toml", "--angles",
                            str(sim / "angles.csv"))) == 0
    one = tmp_path / "one.toml"
    assert main(_solve_args(sim, one)) == 0
    # the same capture twice is two captures' worth of information: a narrower white sigma
    two, single = load_stations(tmp_path / "r.toml"), load_stations(one)
    assert (np.trace(two.stations[1].covariance_white)
            < 0.7 * np.trace(single.stations[1].covariance_white))


# --- item 3: help text ---


def test_help_shows_defaults_both_generations_and_track_short_output(capsys):
    top = build_parser()
    assert "v1" not in top.format_help() and "LH1 or LH2" in top.format_help()
    for prefix, parser in _parsers(top):
        text = parser.format_help()
        assert "Lighthouse v1" not in text and "(Lighthouse deck, LH1)" not in text
        for action in parser._actions:
            if action.help and action.default not in (None, False, argparse.SUPPRESS):
                assert "default" in parser._get_formatter()._get_help_string(action), (
                    prefix, action.dest)
    helps = {prefix: p.format_help() for prefix, p in _parsers(top)}
    assert "(default: 8.0)" in helps[("capture",)]
    assert "(default: 1)" in helps[("study",)]
    assert "(default: auto)" in helps[("export", "cfclient")]
    assert "(default: None)" not in "".join(helps.values())
    assert "--output OUTPUT, -o OUTPUT" in helps[("track",)]
    args = top.parse_args(["track", "--stations", "s", "--angles", "a", "--board", "b",
                           "-o", "t.csv"])
    assert args.output == "t.csv"


# --- item 4: duplicate sensor positions ---


def test_duplicate_sensor_positions_are_refused(tmp_path, capsys):
    sim = _sim(tmp_path)
    text = (sim / "board.toml").read_text()
    board = load_board(sim / "board.toml")
    # sensor 5 listed again under another id, at sensor 2's position (0.3 mm away)
    p = board.positions[2] + [3e-4, 0, 0]
    bad = tmp_path / "board.toml"
    bad.write_text(text + f"\n[[sensors]]\nid = 99\nposition = [{p[0]}, {p[1]}, {p[2]}]\n"
                   "normal = [0.0, 0.0, 1.0]\n")
    with pytest.raises(InputError, match=r"duplicate sensor positions: sensors "
                       rf"{board.ids[2]} and 99 are less than 1 mm apart"):
        load_board(bad)
    assert main(["solve", "--board", str(bad), "--angles", str(sim / "angles.csv"),
                 "--output", str(tmp_path / "r.toml"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err and "and 99" in err


# --- item 7: factory-calibration ranges ---


def _write_ootx(tmp_path: Path, **terms: list[float]) -> Path:
    path = tmp_path / "ootx.toml"
    lines = ["[lighthouses.0]"] + [f"{k} = {v}" for k, v in {
        "phase": [0.05, 0.06], "tilt": [0.001, -0.002], "curve": [0.003, 0.004],
        "gibphase": [1.0, 2.0], "gibmag": [0.01, -0.02], **terms}.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("key", sorted(CALIBRATION_RANGES))
def test_every_calibration_term_is_range_checked(tmp_path, key):
    bound = CALIBRATION_RANGES[key]
    value = [0.0, -1.5 * bound] if key != "accel_dir" else [0.0, 0.0, 300.0]
    extra = {"generation": 2} if key.startswith("ogee") else {}
    path = _write_ootx(tmp_path, **{key: value}, **extra)
    index = 2 if key == "accel_dir" else 1
    with pytest.raises(InputError) as info:
        load_calibration(path)
    message = str(info.value)
    assert f"lighthouses.0.{key}[{index}]" in message and f"[{-bound:g}, {bound:g}]" in message
    assert f"{value[index]:g}" in message


def test_implausible_phase_refused_on_the_command_line(tmp_path, capsys):
    sim = _sim(tmp_path)
    ootx = _write_ootx(tmp_path, phase=[0.5, 0.5])
    assert main(_solve_args(sim, tmp_path / "r.toml", "--calibration", str(ootx))) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{ootx}:lighthouses.0.phase[0]: 0.5 is outside the plausible range [-0.2, 0.2]" in err


def test_real_calibrations_pass_the_range_checks(tmp_path, shared_data):
    """Every factory calibration in the shared data and the libsurvive fixture loads."""
    from lhgraph.io.cfclient import read_system_config
    from lhgraph.signal.libsurvive import read_libsurvive_calibration

    sources: dict[str, dict[int, StationCalibration]] = {
        "fixture": read_libsurvive_calibration(
            REPO / "tests" / "data" / "libsurvive" / "lh1_test_cal_hmd_7s.rec.gz.json")}
    recording = shared_data / "libsurvive-lh1" / "lh1_test_cal.rec.gz.json"
    if recording.is_file():
        sources["libsurvive"] = read_libsurvive_calibration(recording)
    for yaml in sorted((shared_data / "bitcraze-positioning").glob("*/system-config.yaml")):
        sources[yaml.parent.name] = read_system_config(yaml).calibrations
    assert len(sources) >= 2
    for name, calibrations in sources.items():
        path = save_calibration(calibrations, tmp_path / f"{name}.toml")
        assert set(load_calibration(path)) == set(calibrations)


def test_hive_calibration_passes_the_range_checks(hive_import):
    _, out = hive_import
    assert len(load_calibration(out / "ootx.toml")) == 2


# --- items 5 and 6: the calibration beside the angles; the right generation ---


def _with_ootx_beside(tmp_path: Path) -> tuple[Path, Stations]:
    """A capture by stations with factory calibration terms, their ``ootx.toml`` beside."""
    sim = _sim(tmp_path, "simulation/realistic.toml", seconds=2.0, seed=2)
    truth = load_stations(sim / "truth.toml")
    save_calibration({k: StationCalibration(s.model.calibration) for k, s in
                      truth.stations.items()}, sim / "ootx.toml")
    return sim, truth


def test_calibration_beside_the_angles_is_used_and_said(tmp_path, capsys):
    sim, truth = _with_ootx_beside(tmp_path)
    args = _solve_args(sim, tmp_path / "beside.toml")[:-1]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert (f"lhgraph solve: using the factory calibration beside the angles, "
            f"{sim / 'ootx.toml'}") in err
    explicit = tmp_path / "explicit.toml"
    assert main(_solve_args(sim, explicit, "--calibration", str(sim / "ootx.toml"))) == 0
    assert "beside the angles" not in capsys.readouterr().err
    beside = load_stations(tmp_path / "beside.toml")
    np.testing.assert_allclose(beside.pose(1), load_stations(explicit).pose(1), atol=1e-9)
    true_1 = truth.relative_to_reference().pose(1)[:3, 3]
    assert np.linalg.norm(beside.pose(1)[:3, 3] - true_1) < 5e-3
    # track: the stations file's own calibration keys first, else the file beside the angles
    ideal = tmp_path / "ideal.toml"
    save_stations(Stations(truth.reference, {k: Station(s.T_world_lh) for k, s in
                                             truth.stations.items()}), ideal)
    track = ["track", "--board", str(sim / "board.toml"), "--angles", str(sim / "angles.csv"),
             "-o", str(tmp_path / "t.csv"), "--force"]
    for stations, said in ((sim / "truth.toml", False), (ideal, True)):
        assert main([*track, "--stations", str(stations)]) == 0
        assert ("using the factory calibration beside the angles"
                in capsys.readouterr().err) == said


def test_run_directory_records_the_calibration_beside_the_angles(tmp_path):
    sim, _ = _with_ootx_beside(tmp_path)
    config = tmp_path / "run.toml"
    config.write_text(f'board = "{sim / "board.toml"}"\nangles = "{sim / "angles.csv"}"\n')
    assert main(["solve", str(config), "--output", str(tmp_path / "run"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["inputs"]["calibration"]["path"] == str(sim / "ootx.toml")


def test_calibration_of_the_other_generation_is_refused(tmp_path, capsys):
    lh1 = _sim(tmp_path / "lh1")
    lh2 = _sim(tmp_path / "lh2", "sim_lh2.toml")
    lh2_ootx = lh2 / "ootx.toml"
    assert main(_solve_args(lh1, tmp_path / "a.toml", "--calibration", str(lh2_ootx))) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{lh2_ootx}: station(s) 0, 1 are LH2 in this file but their sweeps" in err
    lh1_ootx = save_calibration({k: StationCalibration(s.model.calibration) for k, s in
                                 load_stations(lh1 / "truth.toml").stations.items()},
                                tmp_path / "lh1_ootx.toml")
    assert main(_solve_args(lh2, tmp_path / "b.toml", "--calibration", str(lh1_ootx))) == 2
    assert f"{lh1_ootx}: station(s) 0, 1 are LH1 in this file" in capsys.readouterr().err
    assert main(["track", "--stations", str(lh1 / "truth.toml"), "--board",
                 str(lh1 / "board.toml"), "--angles", str(lh1 / "angles.csv"), "-o",
                 str(tmp_path / "t.csv"), "--calibration", str(lh2_ootx), "--quiet"]) == 2
    assert "are LH2 in this file" in capsys.readouterr().err
    assert not (tmp_path / "a.toml").exists() and not (tmp_path / "t.csv").exists()
