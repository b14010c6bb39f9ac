"""Human-facing summaries of a solve (mm and degrees only here)."""

from __future__ import annotations

from typing import Any

import numpy as np

from lhgraph.estimation.metrics import PoseError
from lhgraph.estimation.result import SolveResult
from lhgraph.geometry.transforms import euler_zyx

SIGMA_NOTE = (
    "x, y, z: world frame (the reference station's unless gravity-aligned); roll, pitch, yaw: "
    "R = Rz(yaw) Ry(pitch) Rx(roll)\n"
    "sigma: length of the 1-sigma uncertainty, sqrt(sx^2 + sy^2 + sz^2), of the position (mm) "
    "and the rotation (deg); per axis in summary.json and report.html")


def covariance_note(result: SolveResult) -> list[str]:
    """Which covariance the sigmas are (the honest time-block one, or the white one) and, for
    the honest one, the white-noise sigmas beside it; nothing for a result without both."""
    white = {k: s.covariance_white for k, s in result.stations.stations.items()
             if s.covariance_white is not None and np.any(s.covariance_white)}
    n = int(result.diagnostics.get("covariance_blocks", 0))
    if not white:
        return []
    if (result.options or {}).get("uncertainty", {}).get("covariance") == "white" or n < 2:
        return ["sigma: white noise (the residuals taken as independent): it does not cover "
                "what repeats between recordings (docs/uncertainty.md)"]
    block = result.diagnostics.get("covariance_block_s", float("nan"))
    parts = ", ".join(f"{k} {np.sqrt(np.trace(c[3:, 3:])) * 1e3:.3f} mm / "
                      f"{np.degrees(np.sqrt(np.trace(c[:3, :3]))):.4f} deg"
                      for k, c in sorted(white.items()))
    return [f"sigma: honest, from the spread of {n} time blocks of {block:.2f} s (covers "
            "residuals correlated in time; the verdict and compare use it; docs/uncertainty.md)",
            f"white-noise sigma (independent residuals), by station: {parts}"]


def calibration_lines(result: SolveResult) -> list[str]:
    """With a solved board scale (``board_scale_sigma``) its line, and one line per station
    with solved factory terms (``factory_terms``): each term's solved value, its shift from
    the decoded (OOTX) value and its honest sigma per axis, in mrad; nothing when the solve
    held both."""
    lines = []
    if result.board_scale is not None:
        b = result.board_scale
        lines.append(f"board scale solved: {b['correction'] * 100:+.3f} % +- "
                     f"{b['sigma'] * 100:.3f} % (the sensors at {1 + b['correction']:.5f} "
                     "times the board file's positions)")
    for sid, terms in sorted((result.factory_terms or {}).items()):
        parts = []
        for key, v in terms.items():
            axes = ", ".join(f"{a * 1e3:+.2f} ({d * 1e3:+.2f} +- {s * 1e3:.2f})" for a, d, s in
                             zip(v["solved_rad"], v["shift_rad"], v["sigma_rad"], strict=True))
            parts.append(f"{key} {axes}")
        lines.append(f"station {sid} factory terms, mrad (shift from OOTX +- sigma) per axis: "
                     + "; ".join(parts))
    return lines


def format_solution(result: SolveResult, errors: list[PoseError] | None = None) -> str:
    """A plain-text table of the stations, residuals, timings and (optional) errors."""
    lines = [f"method {result.method}: {result.status} after {result.iterations} iterations"]
    if result.stations.extra.get("world") == "gravity":
        spread = result.diagnostics.get("gravity_spread_deg", float("nan"))
        lines.append(f"world: gravity-aligned (z up from the stations' accelerometers, which "
                     f"agree within {spread:.2f} deg), origin at the reference station")
    lines.append(f"{'station':>7} {'x mm':>9} {'y mm':>9} {'z mm':>9} {'roll':>8} {'pitch':>8} "
                 f"{'yaw deg':>8} {'sigma mm':>9} {'sigma deg':>9}")
    for k in result.stations.indices():
        s = result.stations.stations[k]
        p = s.T_world_lh[:3, 3] * 1e3
        e = np.degrees(euler_zyx(s.T_world_lh[:3, :3]))
        if s.covariance is not None and np.any(s.covariance):
            sp = np.sqrt(np.trace(s.covariance[3:, 3:])) * 1e3
            sr = np.degrees(np.sqrt(np.trace(s.covariance[:3, :3])))
            sig = f"{sp:9.3f} {sr:9.4f}"
        else:
            sig = f"{'-':>9} {'-':>9}"
        ref = " (reference)" if k == result.stations.reference else ""
        lines.append(f"{k:>7} {p[0]:9.1f} {p[1]:9.1f} {p[2]:9.1f} {e[0]:8.3f} {e[1]:8.3f} "
                     f"{e[2]:8.3f} {sig}{ref}")
    if any(s.covariance is not None for s in result.stations.stations.values()):
        lines.append(SIGMA_NOTE)
        lines.extend(covariance_note(result))
    lines.extend(calibration_lines(result))
    if result.residuals is not None:
        r = result.residuals
        lines.append(f"residuals: {len(r.residual_rad)} hits, rms {r.rms_urad():.1f} µrad "
                     f"(inliers), inlier fraction {r.inlier_fraction():.3f}")
    if result.timings_s:
        lines.append("time: " + ", ".join(f"{k} {v:.3f} s" for k, v in result.timings_s.items()))
    lines.extend(result.captures)
    for w in result.warnings:
        lines.append(f"warning: {w}")
    if errors:
        lines.append(f"{'error':>7} {'X mm':>9} {'Y mm':>9} {'Z mm':>9} {'alpha':>8} {'beta':>8} "
                     f"{'gamma':>8} {'|p| mm':>9} {'angle deg':>9}")
        for e in errors:
            row = e.row_mm_deg()
            lines.append(f"{e.station:>7} " + " ".join(f"{v:9.3f}" for v in row[:3]) + " "
                         + " ".join(f"{v:8.4f}" for v in row[3:6])
                         + f" {row[6]:9.3f} {row[7]:9.4f}")
    return "\n".join(lines)


def print_solution(result: SolveResult, errors: list[PoseError] | None = None,
                   flush: bool = False) -> None:
    """Print :func:`format_solution` to stdout (``flush``: at once, e.g. before a long step)."""
    print(format_solution(result, errors), flush=flush)


def format_comparison(rows: list[dict[str, Any]]) -> str:
    """Plain-text table of the comparison rows (``lhgraph.workflow.rundir.comparison_rows``)."""
    lines = [f"{'method':>7} {'station':>7} {'|p| mm':>9} {'angle deg':>9} {'rms µrad':>9} "
             f"{'time s':>7}"]

    def num(v: float | None, fmt: str) -> str:
        return format(v, fmt) if v is not None else format("-", fmt.split(".")[0] + "s")

    for r in rows:
        lines.append(f"{r['method']:>7} {r['station']:>7} {num(r['position_norm_mm'], '9.3f')} "
                     f"{num(r['rotation_deg'], '9.4f')} {num(r['rms_urad'], '9.1f')} "
                     f"{num(r['seconds'], '7.2f')}")
    return "\n".join(lines)
