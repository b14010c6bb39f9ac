"""Self-contained HTML reports of a run directory (figures embedded as base64 PNG).

Figures (matplotlib, no display needed): the 3-D scene (station axes, board path, position
covariance ellipsoids scaled up), residual histograms per station/axis, residual vs measured
angle, residual rms per sensor, and the optimiser's convergence. Frames: world = reference
station (+x forward, +y left, +z up); residuals in microradians.
"""

from __future__ import annotations

import base64
import html
import json
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Stations
from lhgraph.report.figures import png_bytes

ELLIPSOID_SCALE = 100.0
AXIS_LENGTH_M = 0.3
AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")
STYLE = """body{font-family:sans-serif;max-width:1100px;margin:1em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;
text-align:right}th{background:#eee}img{max-width:100%}pre{background:#f6f6f6;padding:0.5em}
.warn{color:#a40}"""


def png_tag(fig: Figure, alt: str) -> str:
    """``<img>`` with the figure as an embedded base64 PNG."""
    data = base64.b64encode(png_bytes(fig, 90)).decode()
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def covariance_ellipsoid(T_world_lh: NDArray, covariance: NDArray, scale: float,
                         n: int = 16) -> NDArray:
    """Points (3, n, n) of the 1-sigma position ellipsoid scaled by ``scale``, world frame.

    ``covariance`` is the 6x6 right-perturbation covariance ``[omega, v]`` of ``T_world_lh``:
    the position perturbation in the world is ``R v``, so its covariance is ``R S_vv R^T``.
    """
    R = T_world_lh[:3, :3]
    cov = R @ covariance[3:, 3:] @ R.T
    w, V = np.linalg.eigh(cov)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, np.pi, n))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
    axes = V * (scale * np.sqrt(np.clip(w, 0, None)))
    return np.einsum("ij,jkl->ikl", axes, sphere) + T_world_lh[:3, 3, None, None]


def _draw_station_axes(ax, T: NDArray, label: str, style: str = "-", alpha: float = 1.0
                       ) -> None:
    o = T[:3, 3]
    for i, colour in enumerate(AXIS_COLOURS):
        e = o + AXIS_LENGTH_M * T[:3, i]
        ax.plot(*np.c_[o, e], style, color=colour, alpha=alpha, lw=2)
    ax.text(*o, f" {label}", fontsize=8)


def _equal_aspect(ax, points: NDArray) -> None:
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre, half = (lo + hi) / 2, max(np.max(hi - lo) / 2, 0.1)
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, strict=True):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))


def scene_figure(results: dict[str, SolveResult], truth: Stations | None,
                 scale: float = ELLIPSOID_SCALE) -> Figure:
    """3-D scene: station axes (x red, y green, z blue), board paths and the stations'
    1-sigma position ellipsoids x ``scale``; the truth's stations dashed when given."""
    fig = Figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    points = []
    for name, result in results.items():
        st = result.stations.relative_to_reference()
        for k in st.indices():
            T = st.pose(k)
            _draw_station_axes(ax, T, f"{name} {k}" if len(results) > 1 else f"station {k}")
            points.append(T[:3, 3])
            cov = st.stations[k].covariance
            if cov is not None and np.any(cov):
                e = covariance_ellipsoid(T, cov, scale)
                ax.plot_wireframe(*e, color="tab:purple", lw=0.4, alpha=0.6,
                                  label=f"1-sigma position x{scale:g}")
        if result.trajectory is not None:
            p = result.trajectory.T_world_board[:, :3, 3]
            ax.plot(*p.T, lw=0.6, label=f"board path ({name})")
            points.append(p)
    if truth is not None:
        t = Stations(results[next(iter(results))].stations.reference,
                     truth.stations).relative_to_reference()
        for k in t.indices():
            _draw_station_axes(ax, t.pose(k), "", style="--", alpha=0.5)
        ax.plot([], [], "k--", alpha=0.5, label="truth")
    _equal_aspect(ax, np.vstack([np.atleast_2d(p) for p in points]))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    ax.legend(unique.values(), unique.keys(), fontsize=7, loc="upper left")
    ax.set_title("world = reference station; axes x red, y green, z blue", fontsize=9)
    return fig


def _groups(res: Residuals) -> list[tuple[int, int, NDArray[np.bool_]]]:
    return [(int(lh), ax, (res.lighthouse == lh) & (res.axis == ax))
            for lh in np.unique(res.lighthouse) for ax in (0, 1)]


def histogram_figure(res: Residuals) -> Figure:
    """Residual histograms (urad) per station and axis; outliers (weight <= 0.5) stacked."""
    groups = _groups(res)
    fig = Figure(figsize=(9, 2.2 * ((len(groups) + 1) // 2)))
    inl = res.weight > 0.5
    lim = 5 * max(np.std(res.residual_rad[inl]) * 1e6, 1.0) if np.any(inl) else 100.0
    bins = np.linspace(-lim, lim, 61)
    for i, (lh, axis, mask) in enumerate(groups):
        ax = fig.add_subplot((len(groups) + 1) // 2, 2, i + 1)
        r = np.clip(res.residual_rad * 1e6, -lim, lim)
        ax.hist([r[mask & inl], r[mask & ~inl]], bins=bins, stacked=True,
                label=["inlier", "outlier (clipped)"], color=["tab:blue", "tab:orange"])
        ax.set_title(f"station {lh}, axis {axis}: {mask.sum()} hits", fontsize=9)
        ax.set_xlabel("residual (urad)")
        if i == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def measured_angles(res: Residuals, angles: Angles) -> NDArray[np.float64]:
    """The measured angle (rad) of every residual row, matched on time, station, axis and
    sensor (NaN when the row is not in ``angles``)."""
    lookup = dict(zip(zip(angles.time.tolist(), angles.lighthouse.tolist(),
                          angles.axis.tolist(), angles.sensor.tolist(), strict=True),
                      angles.angle.tolist(), strict=True))
    keys = zip(res.time.tolist(), res.lighthouse.tolist(), res.axis.tolist(),
               res.sensor.tolist(), strict=True)
    return np.array([lookup.get(k, np.nan) for k in keys])


def angle_figure(res: Residuals, angles: Angles) -> Figure:
    """Residual (urad) vs measured angle (deg) per station/axis, inliers."""
    angle = measured_angles(res, angles)
    fig = Figure(figsize=(9, 3.2))
    ax = fig.add_subplot()
    inl = res.weight > 0.5
    for lh, axis, mask in _groups(res):
        m = mask & inl
        ax.plot(np.degrees(angle[m]), res.residual_rad[m] * 1e6, ".", ms=1, alpha=0.4,
                label=f"station {lh} axis {axis}")
    ax.set_xlabel("measured angle (deg)")
    ax.set_ylabel("residual (urad)")
    ax.legend(fontsize=7, markerscale=8)
    ax.set_title("inliers (weight > 0.5)", fontsize=9)
    return fig


def sensor_figure(res: Residuals) -> Figure:
    """Inlier residual rms (urad) and hit count per sensor, per station/axis."""
    fig = Figure(figsize=(9, 3.2))
    ax = fig.add_subplot()
    inl = res.weight > 0.5
    sensors = np.unique(res.sensor)
    for lh, axis, mask in _groups(res):
        rms = [np.sqrt(np.mean(res.residual_rad[mask & inl & (res.sensor == s)] ** 2)) * 1e6
               if np.any(mask & inl & (res.sensor == s)) else np.nan for s in sensors]
        ax.plot(sensors, rms, "o-", ms=3, label=f"station {lh} axis {axis}")
    ax.set_xlabel("sensor id")
    ax.set_ylabel("inlier rms (urad)")
    ax.legend(fontsize=7)
    return fig


def convergence_figure(histories: dict[str, list[float]]) -> Figure | None:
    """Graph error per optimiser iteration (log scale); None when no method has one."""
    histories = {k: v for k, v in histories.items() if v}
    if not histories:
        return None
    fig = Figure(figsize=(6, 3))
    ax = fig.add_subplot()
    for name, h in histories.items():
        ax.semilogy(range(len(h)), h, "o-", label=name)
    ax.set_xlabel("iteration (0 = initial values)")
    ax.set_ylabel("graph error")
    ax.legend(fontsize=8)
    return fig


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>"
                   for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _num(v: float | None, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def _page(title: str, body: list[str]) -> str:
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
            f"</title><style>{STYLE}</style></head><body><h1>{html.escape(title)}</h1>"
            + "\n".join(body) + "</body></html>\n")


def _stations_table(summary: dict) -> str:
    rows = []
    for k, s in summary["stations"].items():
        sp, sr = s.get("sigma_position_mm"), s.get("sigma_rotation_deg")
        rows.append([k, *(f"{v * 1e3:.1f}" for v in s["position_m"]),
                     *(f"{v:.6f}" for v in s["quaternion_wxyz"]),
                     ", ".join(f"{v:.3f}" for v in sp) if sp else "-",
                     ", ".join(f"{v:.4f}" for v in sr) if sr else "-"])
    return _table(["station", "x mm", "y mm", "z mm", "qw", "qx", "qy", "qz",
                   "1-sigma x,y,z (mm, body)", "1-sigma rx,ry,rz (deg)"], rows)


def _errors_table(summary: dict) -> str:
    if not summary.get("errors"):
        return "<p>No truth given: no errors.</p>"
    rows = [[k, *(f"{v:.3f}" for v in e["position_mm"]), *(f"{v:.4f}" for v in e["euler_deg"]),
             f"{e['position_norm_mm']:.3f}", f"{e['rotation_deg']:.4f}"]
            for k, e in summary["errors"].items()]
    return _table(["station", "|X| mm", "|Y| mm", "|Z| mm", "|alpha| deg", "|beta| deg",
                   "|gamma| deg", "|p| mm", "angle deg"], rows)


def method_report(method: str, result: SolveResult, summary: dict[str, Any], angles: Angles,
                  truth: Stations | None) -> str:
    """The HTML report of one method's run: its result and its ``summary.json`` document."""
    s = summary
    body = [f"<p>method <b>{html.escape(method)}</b>: {html.escape(result.status)} after "
            f"{result.iterations} iterations; {s['hits']} hits; created {s['created']}.</p>"]
    body += [f"<p class='warn'>warning: {html.escape(w)}</p>" for w in result.warnings]
    body += ["<h2>Stations</h2>", _stations_table(s), "<h2>Errors against the truth</h2>",
             _errors_table(s), "<h2>Scene</h2>",
             png_tag(scene_figure({method: result}, truth), "scene")]
    if result.residuals is not None:
        r = s["residuals"]
        rows = [[k, str(v["hits"]), _num(v["rms_urad"], ".1f"), _num(v["median_abs_urad"], ".1f"),
                 _num(v["inlier_fraction"], ".3f")]
                for k, v in {"all": r, **r["per_station_axis"]}.items()]
        body += ["<h2>Residuals</h2>",
                 _table(["station/axis", "hits", "inlier rms urad", "median |r| urad",
                         "inlier fraction"], rows),
                 png_tag(histogram_figure(result.residuals), "residual histograms"),
                 png_tag(angle_figure(result.residuals, angles), "residual vs angle"),
                 png_tag(sensor_figure(result.residuals), "residual per sensor")]
    conv = convergence_figure({method: result.error_history})
    if conv is not None:
        body += ["<h2>Convergence</h2>", png_tag(conv, "convergence")]
    details = {k: s[k] for k in ("inputs", "options", "seed", "versions")}
    body += ["<h2>Timings</h2>", _table(["stage", "s"], [[k, f"{v:.3f}"] for k, v in
                                                        s["timings_s"].items()]),
             "<h2>Inputs, options, versions</h2>",
             f"<pre>{html.escape(json.dumps(details, indent=2))}</pre>"]
    if s["decode"]:
        body += ["<h2>Decoder</h2>", f"<pre>{html.escape(chr(10).join(s['decode']))}</pre>"]
    return _page(f"lhgraph run: {method}", body)


def comparison_report(results: dict[str, SolveResult], comparison: list[dict[str, Any]],
                      truth: Stations | None) -> str:
    """The HTML report comparing several methods' results on the same input.

    ``comparison``: one row per (method, station) as in the comparison ``summary.json``
    (``lhgraph.workflow.rundir.comparison_rows``).
    """
    rows = [[r["method"], str(r["station"]), _num(r["position_norm_mm"], ".3f"),
             _num(r["rotation_deg"], ".4f"),
             ", ".join(f"{v:.3f}" for v in r["position_mm"]) if r["position_mm"] else "-",
             ", ".join(f"{v:.4f}" for v in r["euler_deg"]) if r["euler_deg"] else "-",
             _num(r["rms_urad"], ".1f"), _num(r["seconds"], ".2f")]
            for r in comparison]
    body = ["<h2>Comparison</h2>",
            _table(["method", "station", "|p| mm", "angle deg", "|X|,|Y|,|Z| mm",
                    "|alpha|,|beta|,|gamma| deg", "rms urad", "solve s"], rows),
            "<p>Per-method reports: " + ", ".join(
                f"<a href='{m}/report.html'>{html.escape(m)}</a>" for m in results)
            + "</p>", "<h2>Scene</h2>",
            png_tag(scene_figure(results, truth), "scene")]
    conv = convergence_figure({m: r.error_history for m, r in results.items()})
    if conv is not None:
        body += ["<h2>Convergence</h2>", png_tag(conv, "convergence")]
    return _page("lhgraph run: method comparison", body)
