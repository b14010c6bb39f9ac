"""Can a calibration be trusted without a truth file: where the board was seen in each
station's view (:func:`view_points`, :func:`coverage`), the residuals' statistics
(:func:`residual_statistics`) and a plain verdict from a run's summary (:func:`verdict`, of a
result: :func:`result_verdict`; of a track: :func:`track_verdict`).

A verdict is ``ok``, ``check`` or ``failed`` (:data:`VERDICT_STATUSES`). A calibration has
*failed* when the solver did not converge (stopped at ``max_iterations`` or stalled: its
answer is wherever the iterations stopped); it is to be *checked* when the solver warned
(e.g. a weak link between stations), more than :data:`MAX_OUTLIER_FRACTION` of the hits are
outliers, a station's position 1-sigma exceeds :data:`MAX_SIGMA_MM`, a station/axis's
residuals spread :data:`MAX_SPREAD_RATIO` times wider than the best one's (the solution does
not explain that view), or the board covered less than :data:`MIN_COVERAGE` of a station's
view. Each reason names what was measured and what it points to, from what the solve used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.estimation.spread import robust_sigma
from lhgraph.io.angles import Angles
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2

FOV_HALF_DEG = 60.0
COVERAGE_CELL_DEG = 5.0
PAIR_WINDOW_S = 0.02
"""A sensor's azimuth and elevation hits closer than this (s) form one view point (the
two sweeps of a cycle are 8.3 ms apart)."""
MAX_OUTLIER_FRACTION = 0.05
MAX_SIGMA_MM = 10.0
MIN_COVERAGE = 0.005
"""Below this the board stayed within ~10 deg of one direction (3 cells of 5 deg)."""
MAX_SPREAD_RATIO = 3.0


def view_points(angles: Angles, station: int) -> NDArray[np.float64]:
    """``(n, 2)`` (azimuth, elevation) in deg where ``station`` saw a sensor: each axis-0 hit
    paired with the same sensor's nearest axis-1 hit within :data:`PAIR_WINDOW_S`."""
    out = []
    sel = angles.lighthouse == station
    for sensor in np.unique(angles.sensor[sel]):
        mine = sel & (angles.sensor == sensor)
        t0, a0 = angles.time[mine & (angles.axis == 0)], angles.angle[mine & (angles.axis == 0)]
        t1, a1 = angles.time[mine & (angles.axis == 1)], angles.angle[mine & (angles.axis == 1)]
        if not len(t0) or not len(t1):
            continue
        order = np.argsort(t1)
        t1, a1 = t1[order], a1[order]
        j = np.searchsorted(t1, t0)
        lo, hi = np.clip(j - 1, 0, len(t1) - 1), np.clip(j, 0, len(t1) - 1)
        j = np.where(np.abs(t1[lo] - t0) <= np.abs(t1[hi] - t0), lo, hi)
        near = np.abs(t1[j] - t0) < PAIR_WINDOW_S
        out.append(np.c_[a0[near], a1[j[near]]])
    return np.degrees(np.vstack(out)) if out else np.empty((0, 2))


def coverage(points: NDArray[np.float64]) -> float:
    """Fraction of the station's view (+-60 deg, cells of 5 x 5 deg) holding a point."""
    edges = np.arange(-FOV_HALF_DEG, FOV_HALF_DEG + 1e-9, COVERAGE_CELL_DEG)
    if not len(points):
        return 0.0
    counts, _, _ = np.histogram2d(points[:, 0], points[:, 1], bins=(edges, edges))
    return float(np.mean(counts > 0))


VERDICT_STATUSES = ("ok", "check", "failed")
MAX_TRACK_SPREAD_MM = 1.0
"""A track fails when its residuals' robust spread, times the median station-board range,
exceeds this (mm): the angles do not fit the stations (the real deck logs through their own
calibrations: 0.2-0.3 mm)."""
MAX_IMU_TRACK_SPREAD_MM = 3.0
"""The same limit for a track with an IMU, whose path cannot bend to the light's noise as a
light-only one does on a few-diode deck: its residuals show the light's whole misfit. The
shared Crazyflie logs tracked with their IMU through their own light-only calibrations spread
0.30-1.44 mm, 1.3-7.2 x their light-only tracks' (benchmarks/track_verdicts.py); the ratio
to the calibration's spread, measured without an IMU, is not applied to them."""
MIN_TRACK_INLIERS = 0.5
"""A track fails when fewer of its hits than this fraction are inliers."""
MAX_GRAVITY_ERROR = 0.1
"""A track with an IMU fails when its estimated gravity is this fraction off 1 g."""
MAX_ACCEL_BIAS_MPS2 = 1.0
"""A track with an IMU fails when its estimated accelerometer bias exceeds this (m/s^2; a
MEMS accelerometer's is ~0.1; the real deck log's 0.017, the same log's accelerometer read
in g instead of m/s^2 9.5: the bias took up gravity's missing part)."""


def residual_statistics(res: Residuals) -> dict[str, Any]:
    """Counts, inlier rms, median |residual| and robust spread 1.4826 MAD (µrad), overall
    and per station/axis."""

    def stats(mask: np.ndarray) -> dict[str, Any]:
        r, w = res.residual_rad[mask], res.weight[mask]
        inl = r[w > 0.5]
        return {"hits": int(mask.sum()),
                "inlier_fraction": float(np.mean(w > 0.5)) if len(w) else None,
                "rms_urad": float(np.sqrt(np.mean(inl**2)) * 1e6) if len(inl) else None,
                "median_abs_urad": float(np.median(np.abs(r)) * 1e6) if len(r) else None,
                "robust_sigma_urad": robust_sigma(r) * 1e6 if len(r) else None,
                "max_abs_urad": float(np.max(np.abs(r)) * 1e6) if len(r) else None}

    out = stats(np.ones(len(res.residual_rad), dtype=bool))
    out["per_station_axis"] = {
        f"{lh}/{ax}": stats((res.lighthouse == lh) & (res.axis == ax))
        for lh in np.unique(res.lighthouse) for ax in (0, 1)
        if np.any((res.lighthouse == lh) & (res.axis == ax))}
    return out


@dataclass(frozen=True)
class Verdict:
    """``status`` (one of :data:`VERDICT_STATUSES`) and its reasons (empty when ok), each
    naming what was found and what it points to."""

    status: str
    reasons: list[str]
    residual_spread_urad: float | None = None
    """The robust spread (1.4826 MAD) of the result's residuals: what a later track through
    these stations is measured against (:func:`track_verdict`)."""

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def failed(self) -> bool:
        return self.status == "failed"

    def text(self) -> str:
        """``"OK"``, ``"check: reason; reason"`` or ``"FAILED: reason; reason"``."""
        if self.ok:
            return "OK"
        return ("FAILED: " if self.failed else "check: ") + "; ".join(self.reasons)

    def as_dict(self) -> dict[str, Any]:
        """The ``verdict`` table of summary.json and the result TOML (docs/workflow.md)."""
        table: dict[str, Any] = {"status": self.status, "text": self.text(),
                                 "reasons": list(self.reasons)}
        if self.residual_spread_urad is not None:
            table["residual_spread_urad"] = self.residual_spread_urad
        return table


def _not_converged(status: str, iterations: int | None) -> str:
    after = "" if iterations is None else f" after {iterations} iterations"
    if status == "max_iterations":
        return (f"the solver stopped at its iteration limit{after} before converging: the "
                "answer is wherever it stopped (raise graph.max_iterations, or give more "
                "motion of the board)")
    if status == "stalled":
        return (f"the solver stalled{after}: no step lowered the error before it converged "
                "(the data may not determine the answer)")
    return f"the solver stopped before converging ({status}{after})"


def _sigma_reason(station: str, sigma_mm: float, scale: float,
                  position_m: list[float] | None) -> str:
    """The verdict's reason for a station whose position 1-sigma ``sigma_mm`` is over
    :data:`MAX_SIGMA_MM`, naming the receiver scale's share when it is most of it (relative
    spread ``scale`` times the station's distance from the world's origin, the reference)."""
    share = scale * float(np.linalg.norm(position_m)) * 1e3 if position_m else 0.0
    if share < 0.5 * sigma_mm:
        return f"station {station} poorly determined (position 1-sigma {sigma_mm:.1f} mm)"
    return (f"station {station} position 1-sigma {sigma_mm:.1f} mm, {share:.0f} mm of it the "
            f"receiver's size (receiver_scale_sigma {scale:g}: angles cannot see a scale and "
            "a few-diode receiver's centimetres set it; docs/uncertainty.md)")


def verdict(summary: dict[str, Any], coverages: dict[int, float] | None = None) -> Verdict:
    """The verdict on one method's run from its ``summary.json`` document (``status``,
    ``iterations``, ``warnings``, ``residuals``, ``stations``) and the board's
    :func:`coverage` of each station's view."""
    failures = []
    if summary["status"] != "converged":
        failures.append(_not_converged(summary["status"], summary.get("iterations")))
    reasons = list(summary.get("warnings") or [])
    res = summary.get("residuals") or {}
    if res.get("inlier_fraction") is not None and \
            1 - res["inlier_fraction"] > MAX_OUTLIER_FRACTION:
        reasons.append(f"{100 * (1 - res['inlier_fraction']):.1f} % of the hits are outliers "
                       f"(more than {100 * MAX_OUTLIER_FRACTION:.0f} %): reflections, or "
                       "board poses the light cannot tell from their mirror image")
    spreads = {k: v.get("robust_sigma_urad") for k, v in
               (res.get("per_station_axis") or {}).items() if v.get("robust_sigma_urad")}
    for k, v in spreads.items():
        if v > MAX_SPREAD_RATIO * min(spreads.values()):
            station, axis = k.split("/")
            reasons.append(f"station {station} {('azimuth', 'elevation')[int(axis)]} residuals "
                           f"spread {v:.0f} µrad, over {MAX_SPREAD_RATIO:g} x the best "
                           f"station/axis's {min(spreads.values()):.0f} µrad: its view is "
                           "not explained well")
    scale = ((summary.get("resolved_options") or {}).get("uncertainty") or {}).get(
        "receiver_scale_sigma") or 0.0
    for k, s in summary["stations"].items():
        sp = s.get("sigma_position_mm")
        if sp and float(np.linalg.norm(sp)) > MAX_SIGMA_MM:
            reasons.append(_sigma_reason(k, float(np.linalg.norm(sp)), scale,
                                         s.get("position_m")))
    for k, c in (coverages or {}).items():
        if c < MIN_COVERAGE:
            reasons.append(f"station {k}: the board covered only {100 * c:.0f} % of its view "
                           "(move it through more of the view)")
    status = "failed" if failures else "check" if reasons else "ok"
    return Verdict(status, failures + reasons, res.get("robust_sigma_urad"))


def result_verdict(result: SolveResult, angles: Angles) -> Verdict:
    """:func:`verdict` of a solve's result on its ``angles`` (what ``lhgraph solve`` prints
    and stores without a run directory)."""
    stations = {str(k): {"sigma_position_mm": None if s.covariance is None else
                         (np.sqrt(np.diag(s.covariance)[3:]) * 1e3).tolist(),
                         "position_m": s.T_world_lh[:3, 3].tolist()}
                for k, s in result.stations.stations.items()}
    summary = {"status": result.status, "iterations": result.iterations,
               "warnings": result.warnings, "stations": stations,
               "resolved_options": result.options,
               "residuals": residual_statistics(result.residuals) if result.residuals else None}
    return verdict(summary, {k: coverage(view_points(angles, k)) for k in angles.stations()})


def track_verdict(status: str, iterations: int, residuals: Residuals, range_m: float,
                  gravity_mps2: float | None = None,
                  calibration_spread_urad: float | None = None,
                  accel_bias_mps2: float | None = None) -> Verdict:
    """The verdict on a track with the stations held fixed: failed when the optimiser did
    not converge, when the residuals' robust spread times the median station-board range
    ``range_m`` exceeds :data:`MAX_TRACK_SPREAD_MM` (with an IMU
    :data:`MAX_IMU_TRACK_SPREAD_MM`), when the spread of a track without an IMU exceeds
    :data:`MAX_SPREAD_RATIO` times the stations' own calibration's
    (``calibration_spread_urad``, from the stations TOML's ``verdict``), or fewer than
    :data:`MIN_TRACK_INLIERS` of the hits are inliers (the angles do not fit these
    stations), or, with an IMU (``gravity_mps2``, ``accel_bias_mps2``: the magnitudes of
    the gravity and the accelerometer bias the track estimated), when that gravity is
    :data:`MAX_GRAVITY_ERROR` off 1 g or the bias exceeds :data:`MAX_ACCEL_BIAS_MPS2` (the
    accelerometer's unit or scale is wrong); to be checked when more than
    :data:`MAX_OUTLIER_FRACTION` of the hits are outliers."""
    failures, checks = [], []
    if status != "converged":
        failures.append(_not_converged(status, iterations))
    spread_urad = robust_sigma(residuals.residual_rad) * 1e6
    spread_mm = spread_urad * range_m * 1e-3
    inliers = residuals.inlier_fraction()
    light_only = gravity_mps2 is None
    imu = "" if light_only else ", or the IMU pulled the path off the light"
    over = (light_only and calibration_spread_urad is not None
            and spread_urad > MAX_SPREAD_RATIO * calibration_spread_urad)
    limit_mm = MAX_TRACK_SPREAD_MM if light_only else MAX_IMU_TRACK_SPREAD_MM
    if spread_mm > limit_mm or inliers < MIN_TRACK_INLIERS or over:
        against = ("" if calibration_spread_urad is None or not light_only else
                   f", {spread_urad / calibration_spread_urad:.1f} x the calibration's "
                   f"{calibration_spread_urad:.0f} µrad")
        failures.append(
            f"the angles do not fit these stations: residuals spread {spread_urad:.0f} µrad "
            f"({spread_mm:.2f} mm at the median range {range_m:.1f} m{against}), "
            f"{100 * inliers:.0f} % inliers: stations of another room or moved since their "
            f"calibration, or a factory calibration of other stations{imu}")
    elif 1 - inliers > MAX_OUTLIER_FRACTION:
        checks.append(f"{100 * (1 - inliers):.1f} % of the hits are outliers (more than "
                      f"{100 * MAX_OUTLIER_FRACTION:.0f} %): reflections, or board poses the "
                      "light cannot tell from their mirror image")
    unit = "the accelerometer's unit or scale is wrong (imu.csv must be in m/s^2, not g)"
    if gravity_mps2 is not None and abs(gravity_mps2 / STANDARD_GRAVITY_MPS2 - 1) > (
            MAX_GRAVITY_ERROR):
        failures.append(f"the track's gravity is {gravity_mps2:.2f} m/s^2, not "
                        f"{STANDARD_GRAVITY_MPS2:.2f}: {unit}")
    if accel_bias_mps2 is not None and accel_bias_mps2 > MAX_ACCEL_BIAS_MPS2:
        failures.append(f"the track's accelerometer bias is {accel_bias_mps2:.2f} m/s^2 "
                        f"(more than {MAX_ACCEL_BIAS_MPS2:g}): {unit}")
    status_out = "failed" if failures else "check" if checks else "ok"
    return Verdict(status_out, failures + checks)
