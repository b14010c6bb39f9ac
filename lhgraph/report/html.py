"""Self-contained HTML reports of a run directory (figures embedded as base64 PNG).

Figures (matplotlib, no display needed): the 3-D scene (station axes, board path, position
covariance ellipsoids scaled up), residual histograms per station/axis, residual vs measured
angle, residual rms per sensor, where the board was seen in each station's view, and the
optimiser's convergence, the co-visibility graph of three stations or more
(:mod:`lhgraph.report.visibility`); a plain verdict (:mod:`lhgraph.report.assessment`) and the
stations' poses with their 1-sigma in the printed axes (:mod:`lhgraph.report.uncertainty`).
Frames: world = reference station (+x forward, +y left, +z up); residuals in µrad.
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
from lhgraph.estimation.visibility import co_visibility
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Stations
from lhgraph.report.assessment import FOV_HALF_DEG, coverage, verdict, view_points
from lhgraph.report.figures import png_bytes
from lhgraph.report.visibility import visibility_figure, visibility_rows

ELLIPSOID_SCALE = 100.0
AXIS_LENGTH_M = 0.3
AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")
AXIS_NAMES = ("azimuth", "elevation")
COVERAGE_COLUMNS = 4
"""Stations per row of the coverage figure (a 16-station room: 4 rows)."""
VISIBILITY_NOTE = ("<p class='note'>Stations that saw the board within 50 ms of each other "
                   "are linked (line width: sweeps seen together); a station's pose is tied "
                   "to the reference's through the chain of links shown as its hops.</p>")
STYLE = """body{font-family:sans-serif;max-width:1100px;margin:1em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0;font-size:0.85em}
td,th{border:1px solid #bbb;padding:2px 6px;text-align:right;white-space:nowrap}
th{background:#eee;white-space:normal}img{max-width:100%}pre{background:#f6f6f6;padding:0.5em}
.warn{color:#a40}.verdict{font-size:1.2em;padding:0.4em 0.8em;border-radius:4px}
.ok{background:#e3f4e1}.check{background:#fbeed5}.note{color:#555;font-size:0.9em}"""


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


def _draw_station_axes(ax, T: NDArray, style: str = "-", alpha: float = 1.0) -> None:
    o = T[:3, 3]
    for i, colour in enumerate(AXIS_COLOURS):
        e = o + AXIS_LENGTH_M * T[:3, i]
        ax.plot(*np.c_[o, e], style, color=colour, alpha=alpha, lw=2)


def _label_stations(ax, labels: dict[int, tuple[NDArray, list[str]]], rise_m: float) -> None:
    """One label per station (the methods that placed it there listed together), raised
    ``rise_m`` above it on a thin leader line so that labels and axes do not overlap."""
    for k, (o, names) in labels.items():
        top = o + np.array([0.0, 0.0, rise_m])
        ax.plot(*np.c_[o, top], color="0.5", lw=0.6)
        text = f"station {k}" + (f" ({', '.join(names)})" if any(names) else "")
        ax.text(*top, text, fontsize=8, ha="center", va="bottom",
                bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "0.7", "alpha": 0.8})


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
    labels: dict[int, tuple[NDArray, list[str]]] = {}
    for name, result in results.items():
        st = result.stations.relative_to_reference()
        for k in st.indices():
            T = st.pose(k)
            _draw_station_axes(ax, T)
            labels.setdefault(k, (T[:3, 3], []))[1].append(name if len(results) > 1 else "")
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
            _draw_station_axes(ax, t.pose(k), style="--", alpha=0.5)
        ax.plot([], [], "k--", alpha=0.5, label="truth")
    span = np.ptp(np.vstack([np.atleast_2d(p) for p in points]), axis=0).max()
    _label_stations(ax, labels, 0.15 * max(span, 1.0))
    _equal_aspect(ax, np.vstack([np.atleast_2d(p) for p in points]))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    ax.legend(unique.values(), unique.keys(), fontsize=7, loc="upper left")
    ax.set_title("Stations and board path (m); world = reference station;\n"
                 "station axes x red, y green, z blue", fontsize=9)
    return fig


def _groups(res: Residuals) -> list[tuple[int, int, NDArray[np.bool_]]]:
    return [(int(lh), ax, (res.lighthouse == lh) & (res.axis == ax))
            for lh in np.unique(res.lighthouse) for ax in (0, 1)]


def histogram_figure(res: Residuals) -> Figure:
    """Residual histograms (µrad) per station and axis; outliers (weight <= 0.5) stacked."""
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
        ax.set_title(f"station {lh}, {AXIS_NAMES[axis]}: {mask.sum()} hits", fontsize=9)
        ax.set_xlabel("residual (µrad)")
        if i % 2 == 0:
            ax.set_ylabel("hits")
        if i == 0:
            ax.legend(fontsize=7)
    fig.suptitle("Residuals, measured - predicted angle (µrad); clipped to +-5 sigma",
                 fontsize=10)
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
    """Residual (µrad) vs measured angle (deg) per station/axis, inliers."""
    angle = measured_angles(res, angles)
    fig = Figure(figsize=(9, 3.2))
    ax = fig.add_subplot()
    inl = res.weight > 0.5
    for lh, axis, mask in _groups(res):
        m = mask & inl
        ax.plot(np.degrees(angle[m]), res.residual_rad[m] * 1e6, ".", ms=1, alpha=0.4,
                label=f"station {lh} {AXIS_NAMES[axis]}")
    ax.set_xlabel("measured angle (deg)")
    ax.set_ylabel("residual (µrad)")
    ax.legend(fontsize=7, markerscale=8)
    ax.set_title("Residual vs measured angle, inliers (weight > 0.5)", fontsize=9)
    return fig


def sensor_figure(res: Residuals) -> Figure:
    """Inlier residual rms (µrad) and hit count per sensor, per station/axis."""
    fig = Figure(figsize=(9, 3.2))
    ax = fig.add_subplot()
    inl = res.weight > 0.5
    sensors = np.unique(res.sensor)
    for lh, axis, mask in _groups(res):
        rms = [np.sqrt(np.mean(res.residual_rad[mask & inl & (res.sensor == s)] ** 2)) * 1e6
               if np.any(mask & inl & (res.sensor == s)) else np.nan for s in sensors]
        ax.plot(sensors, rms, "o-", ms=3, label=f"station {lh} {AXIS_NAMES[axis]}")
    ax.set_xlabel("sensor id")
    ax.set_ylabel("inlier rms (µrad)")
    ax.set_title("Residual rms per sensor", fontsize=9)
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
    ax.set_ylabel("graph error (0.5 x whitened chi^2)")
    ax.set_title("Convergence of the factor graph", fontsize=9)
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


def coverage_figure(angles: Angles) -> Figure:
    """Where each station saw the board: 2-D histogram of the sensors' (azimuth, elevation)
    in 5-deg cells, the +-60 deg view outlined; azimuth + = the station's left."""
    stations = angles.stations()
    cols = min(len(stations), COVERAGE_COLUMNS)
    rows = -(-len(stations) // cols)
    fig = Figure(figsize=(4 * cols, 4 * rows))
    edges = np.arange(-FOV_HALF_DEG - 10, FOV_HALF_DEG + 10.1, 5.0)
    for i, k in enumerate(stations):
        ax = fig.add_subplot(rows, cols, i + 1)
        pts = view_points(angles, k)
        counts, _, _ = np.histogram2d(pts[:, 0], pts[:, 1], bins=(edges, edges))
        shown = np.ma.masked_equal(counts.T, 0)
        mesh = ax.pcolormesh(edges, edges, shown, cmap="viridis")
        fig.colorbar(mesh, ax=ax, shrink=0.8, label="sensor hits per cell")
        h = FOV_HALF_DEG
        ax.plot([h, -h, -h, h, h], [h, h, -h, -h, h], color="tab:red", lw=1,
                label="view (+-60 deg)")
        ax.set_xlim(edges[-1], edges[0])  # as seen from behind the station: left on the left
        ax.set_ylim(edges[0], edges[-1])
        ax.set_aspect("equal")
        ax.set_xlabel("azimuth (deg, + = left)")
        ax.set_ylabel("elevation (deg, + = up)")
        ax.set_title(f"station {k}: board in {100 * coverage(pts):.0f} % of the view",
                     fontsize=9)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig


def _pm(value: float, sigma: list[float] | None, i: int, fmt: str) -> str:
    return format(value, fmt) + (f" ± {format(sigma[i], fmt)}" if sigma else "")


def _stations_table(summary: dict) -> str:
    """Pose and 1-sigma of every station in the axes the CLI prints."""
    rows = []
    for k, s in summary["stations"].items():
        sp, se = s.get("sigma_position_world_mm"), s.get("sigma_euler_deg")
        sb = s.get("sigma_rotation_deg")
        if str(summary["reference"]) == k:  # the world's origin: fixed, no uncertainty
            sp = se = sb = None
        ref = " (reference)" if str(summary["reference"]) == k else ""
        rows.append([k + ref, *(_pm(v * 1e3, sp, i, ".2f") for i, v in
                                enumerate(s["position_m"])),
                     *(_pm(v, se, i, ".4f") for i, v in enumerate(s["euler_deg"])),
                     ", ".join(f"{v:.4f}" for v in sb) if sb else "-"])
    return _table(["station", "x mm", "y mm", "z mm", "roll deg", "pitch deg", "yaw deg",
                   "1σ about own x, y, z (deg)"], rows)


STATIONS_NOTE = ("<p class='note'>x, y, z: the station's position in the world frame (the "
                 "reference station's: +x forward, +y left, +z up, unless gravity-aligned); "
                 "roll, pitch, yaw: the ZYX Euler angles of the station's rotation, R = "
                 "Rz(yaw) Ry(pitch) Rx(roll), as <code>lhgraph solve</code> prints them. "
                 "± is the 1-sigma from the solver's covariance in these axes; the last "
                 "column is the rotation's 1-sigma about the station's own axes, the axes "
                 "of the errors' alpha, beta, gamma. No ± (paper method): no covariance."
                 "</p>")


def _verdict_html(summary: dict[str, Any], method: str = "") -> str:
    coverages = {int(k): v for k, v in (summary.get("coverage") or {}).items()}
    v = verdict(summary, coverages)
    label = f"{html.escape(method)}: " if method else ""
    return (f"<p class='verdict {'ok' if v.ok else 'check'}'><b>verdict</b> {label}"
            f"{html.escape(v.text())}</p>")


def _residuals_table(summary: dict[str, Any], method: str | None = None) -> str:
    r = summary["residuals"]
    rows = [([method] if method else []) + [
        k, str(v["hits"]), _num(v["rms_urad"], ".1f"), _num(v.get("robust_sigma_urad"), ".1f"),
        _num(v["median_abs_urad"], ".1f"), _num(v["inlier_fraction"], ".3f")]
        for k, v in {"all": r, **{_station_axis(k): v for k, v in
                                  r["per_station_axis"].items()}}.items()]
    return _table((["method"] if method else []) + [
        "station, axis", "hits", "inlier rms µrad", "robust spread µrad (1.4826 MAD)",
        "median |r| µrad", "inlier fraction"], rows)


def _station_axis(key: str) -> str:
    """``"1/0"`` -> ``"1 azimuth"``."""
    station, axis = key.split("/")
    return f"{station} {AXIS_NAMES[int(axis)]}"


def _errors_table(summary: dict) -> str:
    if not summary.get("errors"):
        return ("<p>No truth file given: no errors. The verdict, the 1-sigma and the "
                "residuals tell how far to trust the result.</p>")
    rows = [[k, *(f"{v:.3f}" for v in e["position_mm"]), *(f"{v:.4f}" for v in e["euler_deg"]),
             f"{e['position_norm_mm']:.3f}", f"{e['rotation_deg']:.4f}"]
            for k, e in summary["errors"].items()]
    return _table(["station", "|X| mm", "|Y| mm", "|Z| mm", "|alpha| deg", "|beta| deg",
                   "|gamma| deg", "|p| mm", "angle deg"], rows)


def method_report(method: str, result: SolveResult, summary: dict[str, Any], angles: Angles,
                  truth: Stations | None) -> str:
    """The HTML report of one method's run: its result and its ``summary.json`` document."""
    s = summary
    body = [_verdict_html(s),
            f"<p>method <b>{html.escape(method)}</b>: {html.escape(result.status)} after "
            f"{result.iterations} iterations; {s['hits']} hits; created {s['created']}.</p>"]
    body += [f"<p class='warn'>warning: {html.escape(w)}</p>" for w in result.warnings]
    body += ["<h2>Stations</h2>", _stations_table(s), STATIONS_NOTE,
             "<h2>Errors against the truth</h2>", _errors_table(s), "<h2>Scene</h2>",
             png_tag(scene_figure({method: result}, truth), "scene")]
    if result.residuals is not None:
        body += ["<h2>Residuals</h2>", _residuals_table(s),
                 png_tag(histogram_figure(result.residuals), "residual histograms"),
                 png_tag(angle_figure(result.residuals, angles), "residual vs angle"),
                 png_tag(sensor_figure(result.residuals), "residual per sensor")]
    body += ["<h2>Coverage</h2>", png_tag(coverage_figure(angles), "coverage")]
    if len(result.stations.stations) >= 3:
        body += _visibility_html(result, angles)
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


def _visibility_html(result: SolveResult, angles: Angles) -> list[str]:
    """The co-visibility section (:mod:`lhgraph.report.visibility`)."""
    vis = co_visibility(angles)
    ref = result.stations.reference
    positions = {k: result.stations.pose(k)[:3, 3] for k in result.stations.indices()}
    return ["<h2>Co-visibility</h2>", VISIBILITY_NOTE,
            png_tag(visibility_figure(vis, positions, ref), "co-visibility graph"),
            _table(["station", "hits", "captures", "seen together with",
                    f"links from station {ref}"], visibility_rows(vis, ref))]


def comparison_report(results: dict[str, SolveResult], comparison: list[dict[str, Any]],
                      truth: Stations | None, summaries: dict[str, dict[str, Any]],
                      angles: Angles) -> str:
    """The HTML report comparing several methods' results on the same input: verdicts,
    stations with 1-sigma, residuals and coverage, then the errors (with a truth).

    ``comparison``: one row per (method, station) as in the comparison ``summary.json``
    (``lhgraph.workflow.rundir.comparison_rows``); ``summaries``: each method's
    ``summary.json`` document.
    """
    body = [_verdict_html(s, m) for m, s in summaries.items()]
    body += ["<p>Per-method reports (all plots): " + ", ".join(
        f"<a href='{m}/report.html'>{html.escape(m)}</a>" for m in results) + "</p>"]
    for m, s in summaries.items():
        body += [f"<h2>Stations: {html.escape(m)}</h2>", _stations_table(s)]
    body += [STATIONS_NOTE, "<h2>Residuals</h2>"]
    body += [_residuals_table(s, m) for m, s in summaries.items() if s["residuals"]]
    body += [f"<p>Residual histograms of {html.escape(m)} (every method's in its report):</p>"
             + png_tag(histogram_figure(r.residuals), f"residual histograms {m}")
             for m, r in list(results.items())[:1] if r.residuals is not None]
    body += ["<h2>Coverage</h2>", png_tag(coverage_figure(angles), "coverage")]
    rows = [[r["method"], str(r["station"]), _num(r["position_norm_mm"], ".3f"),
             _num(r["rotation_deg"], ".4f"),
             ", ".join(f"{v:.3f}" for v in r["position_mm"]) if r["position_mm"] else "-",
             ", ".join(f"{v:.4f}" for v in r["euler_deg"]) if r["euler_deg"] else "-",
             _num(r["rms_urad"], ".1f"), _num(r["seconds"], ".2f")]
            for r in comparison]
    if truth is not None:
        body += ["<h2>Errors against the truth</h2>",
                 _table(["method", "station", "|p| mm", "angle deg", "|X|,|Y|,|Z| mm",
                         "|alpha|,|beta|,|gamma| deg", "rms µrad", "solve s"], rows)]
    else:
        body += ["<h2>Methods</h2>", _table(["method", "station", "rms µrad", "solve s"],
                                            [[r[0], r[1], r[6], r[7]] for r in rows]),
                 "<p>No truth file given: no errors.</p>"]
    body += ["<h2>Scene</h2>", png_tag(scene_figure(results, truth), "scene")]
    conv = convergence_figure({m: r.error_history for m, r in results.items()})
    if conv is not None:
        body += ["<h2>Convergence</h2>", png_tag(conv, "convergence")]
    return _page("lhgraph run: method comparison", body)
