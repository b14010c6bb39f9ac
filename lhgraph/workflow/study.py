"""Studies: a simulation protocol solved by several methods, in parallel and resumable.

``lhgraph study CONFIG.toml --output DIR`` (docs/workflow.md) expands a paper-protocol file
(:func:`lhgraph.sim.simulate.paper_protocol`), simulates every capture, solves it with every
method and stores one JSON per (capture, method) in ``DIR/results/`` as it finishes (a rerun
skips those). Then it writes the paper's Table III comparison (MAE and average per-setup SD
of the signed X, Y, Z (mm) and alpha, beta, gamma (deg) errors) and error-vs-speed and
error-vs-distance plots. Jobs run in processes (joblib) or on a Dask cluster.

The Table III computation here is the one shared by ``benchmarks/graph_benchmark.py`` and
``benchmarks/paper_protocol_baseline.py``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.choices import METHODS
from lhgraph.config import Table, check_fields, option, rules
from lhgraph.errors import InputError, LhgraphError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.geometry.transforms import euler_zyx
from lhgraph.io.files import read_json_object, read_toml, write_atomic
from lhgraph.io.stations import Stations
from lhgraph.report.figures import png_bytes
from lhgraph.sim.simulate import SimulationConfig, paper_protocol, simulate
from lhgraph.workflow.solve import solve
from lhgraph.workflow.solve_config import check_methods

COLUMNS = ["X (mm)", "Y (mm)", "Z (mm)", "alpha (deg)", "beta (deg)", "gamma (deg)"]
PAPER_MAE = [6.9, 9.3, 8.5, 0.10, 0.17, 0.16]
"""Table III of the paper: mean absolute error of its method on its simulation."""
PAPER_SD = [8.9, 13.5, 9.3, 0.11, 0.20, 0.22]
"""Table III of the paper: average over setups of the per-setup standard deviation."""


# --- Table III ---------------------------------------------------------------------------------


def signed_errors(truth: Stations, estimate: Stations) -> NDArray[np.float64]:
    """Signed errors (n, 6) of every non-reference station of the estimate present in both:
    ``p_est - p_true`` (mm) and the ZYX Euler angles of ``R_true^T R_est`` (deg), both in
    the frame of the estimate's reference station."""
    t = Stations(estimate.reference, truth.stations).relative_to_reference()
    e = estimate.relative_to_reference()
    rows = []
    for k in t.indices():
        if k == estimate.reference or k not in e.stations:
            continue
        Tt, Te = t.pose(k), e.pose(k)
        rows.append(np.r_[(Te[:3, 3] - Tt[:3, 3]) * 1e3,
                          np.degrees(euler_zyx(Tt[:3, :3].T @ Te[:3, :3]))])
    return np.array(rows).reshape(-1, 6)


@dataclass(frozen=True)
class ProtocolStatistics:
    """Table III figures of one method: MAE over all captures and stations, and the
    per-setup sample SD (ddof 1) of the signed errors averaged over setups with >= 2 rows."""

    mae: NDArray[np.float64]
    sd: NDArray[np.float64]
    captures: int


def protocol_statistics(names: Iterable[str], signed: Iterable[NDArray]) -> ProtocolStatistics:
    """Table III statistics from capture names ("setup03/meas2": the setup is the part
    before "/") and their signed errors ((n, 6) or (6,) each, see :func:`signed_errors`)."""
    setups: dict[str, list[NDArray]] = {}
    rows = []
    for name, s in zip(names, signed, strict=True):
        s = np.atleast_2d(s)
        setups.setdefault(name.split("/")[0], []).append(s)
        rows.append(s)
    if not rows:
        return ProtocolStatistics(np.full(6, np.nan), np.full(6, np.nan), 0)
    mae = np.mean(np.abs(np.concatenate(rows)), axis=0)
    sds = [np.std(np.concatenate(v), axis=0, ddof=1) for v in setups.values()
           if len(np.concatenate(v)) > 1]
    sd = np.mean(sds, axis=0) if sds else np.full(6, np.nan)
    return ProtocolStatistics(mae, sd, len(rows))


def _cells(values: Iterable[float]) -> list[str]:
    return [f"{v:.3f}" if i < 3 else f"{v:.4f}" for i, v in enumerate(values)]


def table_iii_markdown(stats: dict[str, ProtocolStatistics]) -> list[str]:
    """Markdown lines: MAE and average SD of each labelled method next to the paper's."""
    lines = ["| | " + " | ".join(COLUMNS) + " |", "|---" * 7 + "|"]
    for label, s in stats.items():
        lines.append(f"| {label} MAE | " + " | ".join(_cells(s.mae)) + " |")
        lines.append(f"| {label} average SD | " + " | ".join(_cells(s.sd)) + " |")
    lines.append("| paper MAE (Table III) | " + " | ".join(str(v) for v in PAPER_MAE) + " |")
    lines.append("| paper average SD (Table III) | " + " | ".join(str(v) for v in PAPER_SD)
                 + " |")
    return lines


# --- study configuration -------------------------------------------------------------------


@dataclass(frozen=True)
class StudyConfig:
    """A study: protocol file, methods, optional subset and capture length, solver options
    (``paper``: the PaperOptions fields the file sets)."""

    protocol: Path
    methods: list[str]
    setups: int | None = option(None, kind=int, gt=0)
    measurements: int | None = option(None, kind=int, gt=0)
    duration_s: float | None = option(None, kind=float, gt=0)
    graph: GraphOptions = field(default_factory=GraphOptions)
    paper: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def __post_init__(self) -> None:
        check_fields(self)

    def cases(self) -> list[tuple[str, SimulationConfig]]:
        """The (name, simulation config) of every capture of the study."""
        out = []
        seen: dict[str, int] = {}
        for name, config in paper_protocol(self.protocol):
            setup = name.split("/")[0]
            if setup not in seen and self.setups is not None and len(seen) >= self.setups:
                continue
            seen[setup] = seen.get(setup, 0) + 1
            if self.measurements is not None and seen[setup] > self.measurements:
                continue
            if self.duration_s is not None:
                config = dataclasses.replace(config, duration_s=self.duration_s)
            out.append((name, config))
        return out


def load_study_config(path: str | Path) -> StudyConfig:
    """Read a study TOML (schema in docs/workflow.md); paths relative to the file."""
    from lhgraph.estimation.baseline import PaperOptions

    path = Path(path)
    table = Table(read_toml(path), path)
    table.refuse_unknown({"protocol", "methods", "setups", "measurements", "duration_s",
                          "graph", "paper"})
    if not isinstance(table.get("protocol"), str):
        raise InputError("expected the protocol file's path (string)", path, "protocol")
    methods = check_methods(table.get("methods", list(METHODS)), path)
    table.options("paper", PaperOptions)
    protocol = path.parent / table.get("protocol")
    if not protocol.is_file():
        raise InputError(f"protocol file {protocol} not found", path, "protocol")
    declared = rules(StudyConfig)
    return StudyConfig(protocol, list(methods),
                       *(table.value(k, declared[k]) for k in ("setups", "measurements",
                                                              "duration_s")),
                       table.options("graph", GraphOptions), dict(table.get("paper", {})), path)


# --- running ---------------------------------------------------------------------------------


def result_file(out_dir: Path, name: str, method: str) -> Path:
    """Where the result of one (capture, method) is stored."""
    return out_dir / "results" / f"{name.replace('/', '__')}__{method}.json"


def run_case(name: str, config: SimulationConfig, method: str, graph: GraphOptions,
             paper: dict[str, Any]) -> dict[str, Any]:
    """Simulate one capture and solve it with ``method``: a JSON-ready record with the
    signed errors (see :func:`signed_errors`), norms, time, residual rms, or the error."""
    from lhgraph.estimation.baseline import PaperOptions

    capture = simulate(config)
    models = {k: s.model for k, s in capture.truth.stations.items()}
    record: dict[str, Any] = {
        "name": name, "method": method, "speed_mps": config.motion.speed_mps,
        "distance_m": config.layout.distance_m if config.layout is not None else None,
        "duration_s": config.duration_s, "hits": len(capture.angles)}
    tic = time.perf_counter()
    try:
        result = solve(capture.board, capture.angles, method, models,
                       graph_options=graph,
                       paper_options=PaperOptions(**paper))
    except LhgraphError as exc:
        return {**record, "error": str(exc), "seconds": time.perf_counter() - tic}
    signed = signed_errors(capture.truth, result.stations)
    return {**record, "seconds": time.perf_counter() - tic, "status": result.status,
            "signed": signed.tolist(),
            "position_mm": np.linalg.norm(signed[:, :3], axis=1).tolist(),
            "rms_urad": result.residuals.rms_urad() if result.residuals else None,
            "warnings": result.warnings}


@dataclass
class StudyResult:
    """All records of a study (finished earlier or now) and the files written."""

    records: list[dict[str, Any]]
    ran: int
    skipped: int
    files: list[Path] = field(default_factory=list)

    def statistics(self) -> dict[str, ProtocolStatistics]:
        """Table III statistics per method (failed captures left out)."""
        out = {}
        for method in dict.fromkeys(r["method"] for r in self.records):
            ok = [r for r in self.records if r["method"] == method and "error" not in r]
            out[method] = protocol_statistics([r["name"] for r in ok],
                                              [np.array(r["signed"]) for r in ok])
        return out


def case_key(config: SimulationConfig, method: str, graph: GraphOptions,
             paper: dict[str, Any]) -> str:
    """SHA-256 of everything that determines a (capture, method) result: a stored result is
    reused only when its key matches."""
    text = repr((config, method, graph if method == "graph" else None,
                 sorted(paper.items()) if method == "paper" else None))
    return hashlib.sha256(text.encode()).hexdigest()


def run_study(study: StudyConfig, out_dir: str | Path, jobs: int = 1,
              scheduler: str | None = None, rerun: bool = False,
              progress: Callable[[str], None] | None = None) -> StudyResult:
    """Run every (capture, method) of ``study`` whose result is not stored in ``out_dir``
    (``DIR/results/*.json``, each written as it finishes; a stored result counts when its
    :func:`case_key` matches, so changing the study reruns what changed; ``rerun`` reruns
    all), then rewrite the summary (``study.md``, ``study.json``, plots). ``scheduler``: a
    Dask scheduler address (joblib's dask backend) instead of ``jobs`` local processes.
    A non-empty ``out_dir`` that is not a study directory (no ``results/``) is refused."""
    from joblib import Parallel, delayed, parallel_config

    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("exists and is not a directory", out_dir)
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / "results").is_dir():
        raise InputError("not empty and not a study directory (no results/ in it)", out_dir)
    say = progress or (lambda _msg: None)
    cases = study.cases()
    todo, records = [], []
    for name, config in cases:
        for method in study.methods:
            key = case_key(config, method, study.graph, study.paper)
            path = result_file(out_dir, name, method)
            stored = read_json_object(path) if path.exists() and not rerun else None
            if stored is not None and stored.get("key") == key:
                records.append(stored)
            else:
                todo.append((name, config, method, key))
    say(f"{len(cases)} captures x {len(study.methods)} methods: {len(records)} stored, "
        f"{len(todo)} to run on {scheduler or f'{jobs} local process(es)'}")
    backend: dict[str, Any] = {"backend": "loky", "n_jobs": jobs}
    client = None
    if scheduler is not None and todo:
        try:
            from dask.distributed import Client
        except ImportError:
            raise InputError("--scheduler needs dask[distributed]: "
                             "pip install 'lhgraph[dask]'") from None
        try:
            client = Client(scheduler, timeout=10)
        except (OSError, ValueError) as exc:  # ValueError: not an address
            raise InputError(f"cannot reach the Dask scheduler {scheduler} ({exc})",
                             where="--scheduler") from None
        backend = {"backend": "dask", "n_jobs": -1}
    try:
        with parallel_config(**backend):
            stream = Parallel(return_as="generator_unordered")(
                delayed(_keyed)(key, run_case, n, c, m, study.graph, study.paper)
                for n, c, m, key in todo)
            for i, record in enumerate(stream, 1):
                write_atomic(result_file(out_dir, record["name"], record["method"]),
                             json.dumps(record).encode(), overwrite=True)
                records.append(record)
                outcome = (f"failed: {record['error']}" if "error" in record else
                           f"{max(record['position_mm']):.3f} mm")
                say(f"[{i}/{len(todo)}] {record['name']} {record['method']}: {outcome} "
                    f"({record['seconds']:.1f} s)")
    finally:
        if client is not None:
            client.close()
    order = {(n, m): i for i, (n, m) in enumerate((n, m) for n, _ in cases
                                                   for m in study.methods)}
    records = sorted(records, key=lambda r: order[(r["name"], r["method"])])
    result = StudyResult(records, len(todo), len(records) - len(todo))
    result.files = write_summary(study, result, out_dir)
    return result


def _keyed(key: str, fn: Callable[..., dict[str, Any]], *args: Any) -> dict[str, Any]:
    return {**fn(*args), "key": key}


SUMMARY_FILES = ("study.md", "study.json", "error_vs_speed.png", "error_vs_distance.png")


def _scatter(records: list[dict[str, Any]], key: str, xlabel: str, path: Path) -> Path:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 3.5))
    ax = fig.add_subplot()
    for method in dict.fromkeys(r["method"] for r in records):
        ok = [r for r in records if r["method"] == method and "error" not in r
              and r[key] is not None]
        ax.semilogy([r[key] for r in ok], [max(r["position_mm"]) for r in ok], "o",
                    label=method, alpha=0.7)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("position error (mm)")
    ax.legend()
    ax.grid(alpha=0.3)
    # the study's own plot, redrawn on every run of the study
    return write_atomic(path, png_bytes(fig, 90), overwrite=True)


def _pairwise(methods: list[str], records: list[dict[str, Any]]) -> list[str]:
    """Per-capture comparison of the first method with each other one: on how many captures
    its position error is the smaller, the median ratio and the worst capture."""
    error = {(r["name"], r["method"]): max(r["position_mm"]) for r in records
             if "error" not in r}
    lines = []
    for other in methods[1:]:
        names = [n for (n, m) in error if m == methods[0] and (n, other) in error]
        if not names:
            continue
        ratio = np.array([error[(n, methods[0])] / error[(n, other)] for n in names])
        worst = names[int(np.argmax(ratio))]
        if not lines:
            lines = ["", "| method | vs | captures | its error smaller on | median error ratio "
                     "| worst capture (errors mm) |", "|---|---|---|---|---|---|"]
        lines.append(f"| {methods[0]} | {other} | {len(names)} | {int(np.sum(ratio < 1))} | "
                     f"{np.median(ratio):.3f} | {worst} ({error[(worst, methods[0])]:.3f} vs "
                     f"{error[(worst, other)]:.3f}) |")
    return lines


def write_summary(study: StudyConfig, result: StudyResult, out_dir: Path) -> list[Path]:
    """(Re)write ``study.md`` (Table III, failures, plots), ``study.json`` and the two PNG
    plots: derived files, always replaced."""
    stats = result.statistics()
    records = result.records
    failed = [r for r in records if "error" in r]
    lines = ["# Study: " + (study.path.name if study.path else "protocol"), "",
             f"Protocol `{study.protocol.name}`: {len({r['name'] for r in records})} captures"
             + (f" of {study.duration_s:g} s" if study.duration_s else "")
             + f", methods {', '.join(study.methods)}; {len(failed)} failed solves.", "",
             "## Table III layout", ""]
    lines += table_iii_markdown({f"method {m}": st for m, st in stats.items()})
    lines += ["", "| method | captures | median position error (mm) | median solve time (s) |",
              "|---|---|---|---|"]
    for method in study.methods:
        ok = [r for r in records if r["method"] == method and "error" not in r]
        pos = [max(r["position_mm"]) for r in ok]
        lines.append(f"| {method} | {len(ok)} | "
                     f"{np.median(pos) if pos else float('nan'):.3f} | "
                     f"{np.median([r['seconds'] for r in ok]) if ok else float('nan'):.2f} |")
    lines += _pairwise(study.methods, records)
    lines += ["", *(f"- failed: {r['name']} {r['method']}: {r['error']}" for r in failed), "",
              "## Error vs board speed and distance", "",
              "![error vs speed](error_vs_speed.png)", "",
              "![error vs distance](error_vs_distance.png)", ""]
    files = [_scatter(records, "speed_mps", "mean board speed (m/s)",
                      out_dir / "error_vs_speed.png"),
             _scatter(records, "distance_m", "board distance (m)",
                      out_dir / "error_vs_distance.png")]
    files.append(write_atomic(out_dir / "study.md", "\n".join(lines).encode(), True))
    doc = {"protocol": str(study.protocol), "methods": study.methods,
           "statistics": {m: {"mae": s.mae.tolist(), "sd": s.sd.tolist(),
                              "captures": s.captures} for m, s in stats.items()},
           "columns": COLUMNS, "paper": {"mae": PAPER_MAE, "sd": PAPER_SD},
           "failed": [[r["name"], r["method"], r["error"]] for r in failed]}
    files.append(write_atomic(out_dir / "study.json",
                              json.dumps(doc, indent=2).encode(), True))
    return files
