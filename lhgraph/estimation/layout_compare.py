"""Two calibrations of one room compared station by station (``lhgraph compare``): did a
station move between them?

Both results are expressed in the frame of a station they share (the common reference:
results of different worlds compare alike). For each other common station the difference
``dT = T_ref_lhA^-1 T_ref_lhB`` gives a position difference (m, in the reference frame) and
a rotation angle. Each file's ``covariance`` is of ``T_world_lh`` in its own body-frame
tangent ``[rx, ry, rz, tx, ty, tz]`` (GTSAM's), which a change of world leaves unchanged
while the reference station is held fixed (as every solve holds it); to first order the
difference's covariance is the sum of the two, and each difference is also given in units of
that combined sigma along its own direction. Two results that both record a receiver-scale
share (``receiver_scale_sigma``: few-diode solves) are taken as one receiver's: that share
moves both alike and is taken out of their difference (docs/uncertainty.md). A station moved
when its difference exceeds both ``k_sigma`` combined sigmas and a floor (the repeatability
of real recordings, which the reported sigmas do not yet cover: docs/compare.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lhgraph.config import check_fields, option
from lhgraph.errors import InputError
from lhgraph.estimation.receiver_scale import receiver_scale_covariance, result_scale_sigma
from lhgraph.geometry.transforms import inverse, rotation_angle, so3_log
from lhgraph.io.stations import Stations


@dataclass(frozen=True)
class CompareOptions:
    """When a station counts as moved: a difference over ``k_sigma`` combined sigmas and
    over ``floor_mm`` (position) or ``floor_deg`` (rotation)."""

    k_sigma: float = option(3.0, gt=0, le=100)
    floor_mm: float = option(40.0, ge=0, le=10000)
    floor_deg: float = option(0.6, ge=0, le=180)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class StationDifference:
    """One station's difference B - A in the common reference frame: ``dp_m`` (3,) m, its
    norm ``position_m``, ``rotation_rad``, and the combined 1-sigma along the position
    difference ``sigma_position_m`` and about the rotation axis ``sigma_rotation_rad``
    (NaN when a file has no covariance); ``moved`` by the options' rule; the same sigmas of
    the files' white-noise covariances (``sigma_white_*``, NaN when a file has none)."""

    station: int
    dp_m: np.ndarray
    position_m: float
    rotation_rad: float
    sigma_position_m: float
    sigma_rotation_rad: float
    moved: bool
    sigma_white_position_m: float = float("nan")
    sigma_white_rotation_rad: float = float("nan")

    @property
    def position_sigmas(self) -> float:
        """The position difference in combined sigmas (NaN without covariances)."""
        return self.position_m / self.sigma_position_m

    @property
    def rotation_sigmas(self) -> float:
        """The rotation difference in combined sigmas (NaN without covariances)."""
        return self.rotation_rad / self.sigma_rotation_rad


@dataclass(frozen=True)
class LayoutComparison:
    """Every common station's difference, the reference they share and the verdict."""

    reference: int
    differences: list[StationDifference]
    options: CompareOptions
    only_in_a: list[int]
    only_in_b: list[int]

    @property
    def moved(self) -> list[StationDifference]:
        """The stations that moved."""
        return [d for d in self.differences if d.moved]

    def verdict(self) -> str:
        """``same layout`` or ``station N moved by X mm / Y deg (Z sigma)``, one per station."""
        if not self.moved:
            return "same layout"
        return "; ".join(
            f"station {d.station} moved by {d.position_m * 1e3:.1f} mm / "
            f"{np.degrees(d.rotation_rad):.2f} deg"
            + ("" if np.isnan(d.sigma_position_m) else
               f" ({d.position_sigmas:.1f} / {d.rotation_sigmas:.1f} sigma)")
            for d in self.moved)


def _sigma_along(cov: np.ndarray, direction: np.ndarray) -> float:
    """Standard deviation of ``cov`` (3x3) along ``direction`` (any length; NaN if zero)."""
    norm = np.linalg.norm(direction)
    if norm == 0 or not np.all(np.isfinite(cov)):
        return float("nan")
    u = direction / norm
    return float(np.sqrt(max(u @ cov @ u, 0.0)))


def _combined_sigmas(covs: list[np.ndarray | None], dp: np.ndarray, rotvec: np.ndarray
                     ) -> tuple[float, float]:
    """The 1-sigma of the sum of two covariances ``covs`` (6x6, NaN when one is missing) along
    the position difference ``dp`` and about the rotation axis ``rotvec``."""
    if any(c is None for c in covs):
        return float("nan"), float("nan")
    cov = covs[0] + covs[1]
    return _sigma_along(cov[3:, 3:], dp), _sigma_along(cov[:3, :3], rotvec)


def _without_common_scale(results: list[Stations], k: int, sigma: float,
                          dp_local: np.ndarray) -> list[np.ndarray | None]:
    """Station ``k``'s honest covariances of ``results`` with their receiver-scale share of
    spread ``sigma`` taken out, the share's effect on the difference itself (``dp_local``,
    in the first result's station frame) put back once: two results of one receiver share
    its scale error, which moves both alike (:mod:`lhgraph.estimation.receiver_scale`)."""
    covs = [r.stations[k].covariance for r in results]
    if sigma <= 0 or any(c is None for c in covs):
        return covs
    out = [c - receiver_scale_covariance(inverse(r.pose(r.reference)) @ r.pose(k), sigma)
           for c, r in zip(covs, results, strict=True)]
    out[0] = out[0].copy()
    out[0][3:, 3:] += sigma**2 * np.outer(dp_local, dp_local)
    return out


def compare_layouts(a: Stations, b: Stations, reference: int | None = None,
                    options: CompareOptions | None = None) -> LayoutComparison:
    """Compare calibration ``b`` with ``a`` in the frame of a common station (``reference``,
    default: ``a``'s reference if ``b`` has it, else the lowest common index); InputError
    when they share fewer than two stations or ``reference`` is not in both."""
    options = options or CompareOptions()
    common = sorted(set(a.stations) & set(b.stations))
    if len(common) < 2:
        raise InputError(f"the two results share {len(common)} station(s): nothing to "
                         "compare (at least 2, one of them the common reference)")
    if reference is None:
        reference = a.reference if a.reference in common else common[0]
    elif reference not in common:
        raise InputError(f"station {reference} is not in both results (common: "
                         f"{', '.join(map(str, common))})")
    T_ref_a, T_ref_b = (inverse(s.pose(reference)) for s in (a, b))
    common_scale = min(result_scale_sigma(a), result_scale_sigma(b))
    diffs = []
    for k in common:
        if k == reference:
            continue
        A, B = T_ref_a @ a.pose(k), T_ref_b @ b.pose(k)
        dp = B[:3, 3] - A[:3, 3]
        dR = A[:3, :3].T @ B[:3, :3]
        # the position difference in A's station frame, where the covariance's translation is
        along = (A[:3, :3].T @ dp, so3_log(dR))
        covs = _without_common_scale([a, b], k, common_scale, along[0])
        sigma_p, sigma_r = _combined_sigmas(covs, *along)
        white = _combined_sigmas([s.stations[k].covariance_white for s in (a, b)], *along)
        position, rotation = float(np.linalg.norm(dp)), float(rotation_angle(dR))
        limit_p = max(options.floor_mm * 1e-3,
                      0.0 if np.isnan(sigma_p) else options.k_sigma * sigma_p)
        limit_r = max(np.radians(options.floor_deg),
                      0.0 if np.isnan(sigma_r) else options.k_sigma * sigma_r)
        diffs.append(StationDifference(k, dp, position, rotation, sigma_p, sigma_r,
                                       bool(position > limit_p or rotation > limit_r), *white))
    return LayoutComparison(reference, diffs, options,
                            sorted(set(a.stations) - set(b.stations)),
                            sorted(set(b.stations) - set(a.stations)))
