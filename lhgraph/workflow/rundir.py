"""Run directories: a configured solve written as one folder with results, summary and report.

``lhgraph solve CONFIG.toml --output DIR`` (docs/workflow.md) writes, per method::

    stations.toml    contract stations file with the 6x6 covariance (graph method)
    trajectory.csv   board path T_world_board (world = reference station)
    residuals.csv    one row per hit: time, lighthouse, axis, sensor, residual_rad, weight
    summary.json     errors vs truth, residual statistics, timings, versions, input hashes
    report.html      self-contained report (figures as base64 PNG)

With several methods (config key ``methods``) each gets a subdirectory ``DIR/<method>/``
and ``DIR`` holds a comparison ``summary.json`` and ``report.html``.
"""

from __future__ import annotations

import json
import math
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lhgraph.errors import InputError
from lhgraph.estimation.metrics import PoseError, station_errors
from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.geometry.transforms import euler_zyx, matrix_to_quat
from lhgraph.io.files import check_writable, read_json_object, write_atomic, write_csv_columns
from lhgraph.io.stations import Stations, load_stations, save_stations
from lhgraph.io.trajectory import save_trajectory
from lhgraph.model.board import save_board
from lhgraph.report.assessment import (
    Verdict,
    coverage,
    residual_statistics,
    verdict,
    view_points,
)
from lhgraph.workflow.inputs import SolveInputs, check_inputs, load_inputs
from lhgraph.workflow.solve import run_config, with_verdict
from lhgraph.workflow.solve_config import SolveConfig

RUN_FILES = ("stations.toml", "trajectory.csv", "residuals.csv", "summary.json", "report.html")
COMPARISON_FILES = ("summary.json", "report.html")


def is_run_directory(output: str | Path) -> bool:
    """An output is a run directory when it is an existing directory or its name does not
    end in ``.toml`` (otherwise it is a stations TOML file)."""
    output = Path(output)
    return output.is_dir() or output.suffix.lower() != ".toml"


@dataclass
class MethodRun:
    """One method's solve and what was written for it."""

    method: str
    result: SolveResult
    errors: list[PoseError] | None
    summary: dict[str, Any]
    directory: Path


@dataclass
class RunDirectory:
    """A finished run directory: the runs, the top-level report and every file written."""

    directory: Path
    runs: list[MethodRun]
    report: Path
    files: list[Path] = field(default_factory=list)


def sha256_of(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    import hashlib  # here, not at the top: `lhgraph solve` to a stations file never needs it

    digest = hashlib.sha256()
    with Path(path).open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def versions() -> dict[str, str]:
    """Versions of lhgraph, gtsam, numpy and Python."""
    import importlib.metadata  # here, not at the top: 15 ms of start-up for every solve

    out = {}
    for name in ("lhgraph", "gtsam", "numpy"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "unknown"
    out["python"] = platform.python_version()
    return out


def input_files(config: SolveConfig) -> dict[str, Path]:
    """The input files a config names (config, board, angles or capture, calibration, truth,
    imu)."""
    named = {"config": config.path, "board": config.board, "angles": config.angles,
             "capture": config.capture, "calibration": config.calibration,
             "truth": config.truth, "imu": config.imu}
    return {k: Path(v) for k, v in named.items() if v is not None}


def station_summary(stations: Stations) -> dict[str, Any]:
    """Pose (m, quaternion wxyz, ZYX Euler roll/pitch/yaw deg) and 1-sigma of every station:
    body-frame (mm, deg) and in the printed axes (world x, y, z mm; roll, pitch, yaw deg)."""
    from lhgraph.report.uncertainty import pose_sigma

    out = {}
    for k in stations.indices():
        s = stations.stations[k]
        entry: dict[str, Any] = {"position_m": s.T_world_lh[:3, 3].tolist(),
                                 "quaternion_wxyz": matrix_to_quat(s.T_world_lh[:3, :3]).tolist(),
                                 "euler_deg": np.degrees(euler_zyx(s.T_world_lh[:3, :3])).tolist()}
        if s.covariance is not None:
            entry["sigma_position_mm"] = (np.sqrt(np.diag(s.covariance)[3:]) * 1e3).tolist()
            entry["sigma_rotation_deg"] = np.degrees(np.sqrt(np.diag(s.covariance)[:3])).tolist()
            sigma = pose_sigma(s.T_world_lh, s.covariance)
            entry["sigma_position_world_mm"] = (sigma.position_m * 1e3).tolist()
            entry["sigma_euler_deg"] = np.degrees(sigma.euler_rad).tolist()
        if s.covariance_white is not None:
            entry["sigma_white_position_mm"] = (np.sqrt(np.diag(s.covariance_white)[3:])
                                                * 1e3).tolist()
            entry["sigma_white_rotation_deg"] = np.degrees(
                np.sqrt(np.diag(s.covariance_white)[:3])).tolist()
        out[str(k)] = entry
    return out


def error_summary(errors: list[PoseError]) -> dict[str, Any]:
    """Paper-style errors per station (|X|, |Y|, |Z| mm, |alpha|, |beta|, |gamma| deg)."""
    return {str(e.station): {"position_mm": (e.position_m * 1e3).tolist(),
                             "euler_deg": np.degrees(e.euler_rad).tolist(),
                             "position_norm_mm": e.position_norm_m * 1e3,
                             "rotation_deg": math.degrees(e.rotation_rad)}
            for e in errors}


def _json_safe(value: Any) -> Any:
    """NaN/inf become null; numpy scalars become Python numbers."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def method_options(config: SolveConfig, method: str) -> dict[str, Any]:
    """The solver options a method was given (the graph's flat, as in the config; what they
    resolved to is the summary's ``resolved_options``)."""
    if method == "graph":
        options = config.graph.flat()
        if config.reference is not None:
            options["reference"] = config.reference
        return options
    from lhgraph.estimation.baseline import PaperOptions

    return {**asdict(PaperOptions()), "reference": config.reference}


def summarise(config: SolveConfig, inputs: SolveInputs, result: SolveResult,
              errors: list[PoseError] | None, hashes: dict[str, dict[str, str]],
              load_s: float) -> dict[str, Any]:
    """The ``summary.json`` document of one method's run (docs/workflow.md)."""
    summary = _json_safe({
        "method": result.method,
        "status": result.status,
        "iterations": result.iterations,
        "final_error": result.final_error,
        "error_history": result.error_history,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "versions": versions(),
        "inputs": hashes,
        "seed": config.seed,
        "options": method_options(config, result.method),
        "resolved_options": result.options,
        "option_rules": result.option_rules,
        "hits": len(inputs.angles),
        "stations": station_summary(result.stations),
        "reference": result.stations.reference,
        "residuals": residual_statistics(result.residuals) if result.residuals else None,
        "errors": error_summary(errors) if errors is not None else None,
        "timings_s": {"load": load_s, **result.timings_s},
        "warnings": result.warnings,
        "captures": result.captures,
        "factory_terms": ({str(k): v for k, v in result.factory_terms.items()}
                          if result.factory_terms else None),
        "board_scale": result.board_scale,
        "diagnostics": result.diagnostics,
        "coverage": {str(k): coverage(view_points(inputs.angles, k))
                     for k in inputs.angles.stations()},
        "decode": inputs.notes,
        "resume_key": resume_key(config, result.method, hashes),
    })
    summary["verdict"] = run_verdict(summary).as_dict()
    return summary


def run_verdict(summary: dict[str, Any]) -> Verdict:
    """The verdict on one method's run from its ``summary.json`` document (also one written
    before the document held its ``verdict``)."""
    return verdict(summary, {int(k): v for k, v in (summary.get("coverage") or {}).items()})


def resume_key(config: SolveConfig, method: str, hashes: dict[str, dict[str, str]]) -> str:
    """SHA-256 of what a method's result depends on: the input files' hashes (the config
    file's excepted, so adding a method to it keeps the others), the method, its options,
    the duration window and the world frame."""
    import hashlib

    data = {"inputs": {k: v["sha256"] for k, v in hashes.items() if k != "config"},
            "method": method, "options": _json_safe(method_options(config, method)),
            "duration_s": config.duration_s, "world": config.world}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def finished_run(folder: Path, method: str, key: str, truth: Stations | None
                 ) -> MethodRun | None:
    """The method's run kept in ``folder`` when it finished (its ``summary.json``, written
    last, has ``key`` and every file it lists is there), else None."""
    from lhgraph.io.files import read_csv_columns
    from lhgraph.io.trajectory import load_trajectory

    summary = read_json_object(folder / "summary.json")
    if summary is None:
        return None
    if summary.get("resume_key") != key or summary.get("method") != method or not all(
            (folder / name).is_file() for name in RUN_FILES):
        return None
    cols = read_csv_columns(folder / "residuals.csv", [
        ("time", float), ("lighthouse", int), ("axis", int), ("sensor", int),
        ("residual_rad", float), ("weight", float)])
    residuals = Residuals(cols["time"], cols["lighthouse"], cols["axis"], cols["sensor"],
                          cols["residual_rad"], cols["weight"])
    timings = {k: v for k, v in summary["timings_s"].items() if k not in ("load", "report")}
    result = SolveResult(method, load_stations(folder / "stations.toml"),
                         load_trajectory(folder / "trajectory.csv"), residuals,
                         summary["status"], summary["iterations"],
                         summary["final_error"] if summary["final_error"] is not None
                         else float("nan"), timings, summary["warnings"],
                         summary.get("diagnostics") or {},
                         error_history=summary["error_history"])
    errors = station_errors(truth, result.stations) if truth is not None else None
    return MethodRun(method, result, errors, summary, folder)


def save_residuals(res: Residuals, path: str | Path, overwrite: bool = False) -> Path:
    """Write ``residuals.csv``: time, lighthouse, axis, sensor, residual_rad, weight."""
    return write_csv_columns(
        path, {"time": res.time, "lighthouse": res.lighthouse, "axis": res.axis,
               "sensor": res.sensor, "residual_rad": res.residual_rad, "weight": res.weight},
        {"time": "{:.9f}", "lighthouse": "{:d}", "axis": "{:d}", "sensor": "{:d}",
         "residual_rad": "{:.6e}", "weight": "{:.4f}"}, overwrite)


def planned_files(output: Path, methods: list[str], board: bool = False) -> list[Path]:
    """Every file a run directory for ``methods`` will hold (with ``board``, the graph's
    ``board.toml``: its solved sensor positions)."""
    folders = {m: output if len(methods) == 1 else output / m for m in methods}
    files = [folders[m] / name for m in methods for name in RUN_FILES]
    if board and "graph" in folders:
        files.append(folders["graph"] / "board.toml")
    return files + ([output / name for name in COMPARISON_FILES] if len(methods) > 1 else [])


def _write_json(path: Path, data: dict[str, Any], overwrite: bool) -> Path:
    return write_atomic(path, (json.dumps(data, indent=2) + "\n").encode(), overwrite)


def run_to_directory(config: SolveConfig, output: str | Path, overwrite: bool = False,
                     progress: Callable[[str], None] | None = None, resume: bool = False,
                     on_run: Callable[[MethodRun], None] | None = None) -> RunDirectory:
    """Solve the config with each of its methods and write the run directory ``output``.

    Refuses (InputError, nothing written) when any target file exists and neither
    ``overwrite`` nor ``resume``, or when ``output`` is an existing file. With ``resume`` a
    method that finished before with the same inputs and options (:func:`finished_run`) is
    kept, every other one is computed (its leftovers replaced) and the comparison rewritten.
    ``on_run(run)`` is called as each method's run is ready (e.g. to print it at once).
    """
    from lhgraph.report.html import comparison_report, method_report  # matplotlib: slow

    output = Path(output)
    if output.exists() and not output.is_dir():
        raise InputError("exists and is not a directory", output)
    if config.trajectory is not None:
        raise InputError("'trajectory' is for a stations-TOML output; a run directory always "
                         "holds trajectory.csv", config.path, "trajectory")
    if config.board_output is not None:
        raise InputError("'board_output' is for a stations-TOML output; a run directory holds "
                         "board.toml when graph.sensor_offset_sigma_m is set",
                         config.path, "board_output")
    methods = config.method_list()
    check_inputs(config)
    board = config.graph.board
    for target in planned_files(output, methods, board.sensor_offset_sigma_m > 0
                                or board.board_scale_sigma > 0):
        if target.exists() and not target.is_dir() and not (overwrite or resume):
            raise InputError("exists already (--resume keeps the methods that finished and "
                             "computes the rest; --force recomputes everything)", target)
        check_writable(target, True)
    say = progress or (lambda _msg: None)
    hashes = {k: {"path": str(p), "sha256": sha256_of(p)}
              for k, p in input_files(config).items()}
    truth = load_stations(config.truth) if config.truth else None
    folders = {m: output if len(methods) == 1 else output / m for m in methods}
    kept = {m: run for m in methods if resume and (run := finished_run(
        folders[m], m, resume_key(config, m, hashes), truth)) is not None}
    tic = time.perf_counter()
    inputs = load_inputs(config)
    load_s = time.perf_counter() - tic
    say(f"loaded {len(inputs.angles)} hits of stations {inputs.angles.stations()} "
        f"in {load_s:.2f} s")
    runs: list[MethodRun] = []
    files: list[Path] = []
    replace = overwrite or resume
    for method in methods:
        if method in kept:
            say(f"[{method}] kept: finished before with the same inputs and options")
            run = kept[method]
        else:
            run = _run_method(config, inputs, method, folders[method], truth, hashes, load_s,
                              replace, say, files, method_report)
        runs.append(run)
        if on_run is not None:
            on_run(run)
    report = output / "report.html"
    if len(methods) > 1:
        rows = comparison_rows(runs)
        comparison = _json_safe({"methods": methods, "inputs": hashes, "seed": config.seed,
                                 "versions": versions(),
                                 "runs": {r.method: f"{r.method}/summary.json" for r in runs},
                                 "kept": sorted(kept), "comparison": rows})
        html = comparison_report({r.method: r.result for r in runs}, rows, truth,
                                 {r.method: r.summary for r in runs}, inputs.angles)
        files.append(write_atomic(report, html.encode(), replace))
        files.append(_write_json(output / "summary.json", comparison, replace))
    return RunDirectory(output, runs, report, files)


def _run_method(config: SolveConfig, inputs: SolveInputs, method: str, folder: Path,
                truth: Stations | None, hashes: dict[str, dict[str, str]], load_s: float,
                overwrite: bool, say: Callable[[str], None], files: list[Path],
                method_report: Callable[..., str]) -> MethodRun:
    """Solve one method and write its files, ``summary.json`` last (the mark that it
    finished); the paths written are appended to ``files``."""
    say(f"[{method}] solving")
    result = run_config(config, lambda msg: say(f"[{method}] {msg}"), inputs, method)
    errors = station_errors(truth, result.stations) if truth is not None else None
    summary = summarise(config, inputs, result, errors, hashes, load_s)
    files.append(save_stations(with_verdict(result.stations, run_verdict(summary)),
                               folder / "stations.toml", overwrite))
    if result.trajectory is not None:
        files.append(save_trajectory(result.trajectory, folder / "trajectory.csv", overwrite))
    if result.sensor_offset_m is not None or result.board_scale is not None:
        files.append(save_board(result.corrected_board(inputs.board), folder / "board.toml",
                                overwrite))
    if result.residuals is not None:
        files.append(save_residuals(result.residuals, folder / "residuals.csv", overwrite))
    say(f"[{method}] writing the report")
    tic = time.perf_counter()
    html = method_report(method, result, summary, inputs.angles, truth)
    summary["timings_s"]["report"] = time.perf_counter() - tic
    files.append(write_atomic(folder / "report.html", html.encode(), overwrite))
    files.append(_write_json(folder / "summary.json", summary, overwrite))
    return MethodRun(method, result, errors, summary, folder)


def solve_seconds(result: SolveResult) -> float:
    """Solver wall time: its ``total`` timing, else the sum of its stages."""
    t = result.timings_s
    return float(t.get("total", sum(t.values())))


def comparison_rows(runs: list[MethodRun]) -> list[dict[str, Any]]:
    """One row per (method, non-reference station): errors (when known), rms, time."""
    rows = []
    for run in runs:
        s = run.summary
        by_station = s["errors"] or {}
        for k in run.result.stations.indices():
            if k == run.result.stations.reference:
                continue
            e = by_station.get(str(k))
            rows.append({"method": run.method, "station": k,
                         "position_norm_mm": e["position_norm_mm"] if e else None,
                         "rotation_deg": e["rotation_deg"] if e else None,
                         "position_mm": e["position_mm"] if e else None,
                         "euler_deg": e["euler_deg"] if e else None,
                         "rms_urad": (s["residuals"] or {}).get("rms_urad"),
                         "inlier_fraction": (s["residuals"] or {}).get("inlier_fraction"),
                         "seconds": solve_seconds(run.result)})
    return rows
