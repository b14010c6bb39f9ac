"""Can a calibration be trusted without a truth file: where the board was seen in each
station's view (:func:`view_points`, :func:`coverage`) and a plain verdict from a run's
summary (:func:`verdict`).

A station sees +-60 deg in azimuth and elevation (the rotors' sweep); a calibration is
checked when it did not converge, the solver warned (e.g. a weak link between stations),
more than :data:`MAX_OUTLIER_FRACTION` of the hits are outliers, a station's position
1-sigma exceeds :data:`MAX_SIGMA_MM`, a station/axis's residuals spread
:data:`MAX_SPREAD_RATIO` times wider than the best one's (the solution does not explain that
view), or the board covered less than :data:`MIN_COVERAGE` of a station's view.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.angles import Angles

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


@dataclass(frozen=True)
class Verdict:
    """``ok`` and the reasons to check (empty when ok)."""

    ok: bool
    reasons: list[str]

    def text(self) -> str:
        """``"OK"`` or ``"check: reason; reason"``."""
        return "OK" if self.ok else "check: " + "; ".join(self.reasons)


def verdict(summary: dict[str, Any], coverages: dict[int, float] | None = None) -> Verdict:
    """The verdict on one method's run from its ``summary.json`` document and the board's
    :func:`coverage` of each station's view."""
    reasons = []
    if summary["status"] != "converged":
        reasons.append(f"the solver stopped before converging ({summary['status']})")
    reasons += list(summary.get("warnings") or [])
    res = summary.get("residuals") or {}
    if res.get("inlier_fraction") is not None and \
            1 - res["inlier_fraction"] > MAX_OUTLIER_FRACTION:
        reasons.append(f"{100 * (1 - res['inlier_fraction']):.1f} % of the hits are outliers "
                       f"(more than {100 * MAX_OUTLIER_FRACTION:.0f} %: reflections?)")
    spreads = {k: v.get("robust_sigma_urad") for k, v in
               (res.get("per_station_axis") or {}).items() if v.get("robust_sigma_urad")}
    for k, v in spreads.items():
        if v > MAX_SPREAD_RATIO * min(spreads.values()):
            station, axis = k.split("/")
            reasons.append(f"station {station} {('azimuth', 'elevation')[int(axis)]} residuals "
                           f"spread {v:.0f} µrad, over {MAX_SPREAD_RATIO:g} x the best "
                           f"station/axis's {min(spreads.values()):.0f} µrad: its view is "
                           "not explained well")
    for k, s in summary["stations"].items():
        sp = s.get("sigma_position_mm")
        if sp and float(np.linalg.norm(sp)) > MAX_SIGMA_MM:
            reasons.append(f"station {k} poorly determined (position 1-sigma "
                           f"{np.linalg.norm(sp):.1f} mm)")
    for k, c in (coverages or {}).items():
        if c < MIN_COVERAGE:
            reasons.append(f"station {k}: the board covered only {100 * c:.0f} % of its view "
                           "(move it through more of the view)")
    return Verdict(not reasons, reasons)
