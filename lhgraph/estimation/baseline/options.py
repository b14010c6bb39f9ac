"""Settings of the paper pipeline (:class:`PaperOptions`), declared and checked by
:mod:`lhgraph.config`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from lhgraph.config import check_fields, option
from lhgraph.estimation.reconstruct import VARIANTS

Progress = Callable[[str, int, int], None]
"""``progress(stage, done, total)``: called as work advances (stage is a short label)."""

KABSCH_POINTS = ("board", "sensors")


@dataclass(frozen=True)
class PaperOptions:
    """Settings of the paper pipeline; defaults follow the paper (docs/baseline.md).

    - ``reconstruction``: ``"full"`` | ``"half"`` | ``"merge"``.
    - ``max_gap_periods``: no interpolation (angles, paths) across gaps longer than this many
      periods of the interpolated series.
    - ``warm_start``: start each measurement's Nelder-Mead from the previous measurement's
      pose (faster, not the paper's; the first one and any after a gap start cold).
    - ``mirror_check``: also refine the planar-board mirror of each fitted pose, keep the
      better fit (warm starts included: without it they can follow the wrong branch).
    - ``min_sensors``: a measurement needs this many sensors with both angles.
    - ``min_measurements``: a station needs this many usable measurements.
    - ``outlier_mads``: a board pose whose rms angle residual ``sqrt(K1 / (2 n_sensors))``
      exceeds the median of its station's by more than this many robust standard deviations
      (1.4826 x MAD) is dropped from the paths, the superposition and K2; K2 drops its own
      outlier measurements likewise and is fitted again (``inf``: keep all, the paper).
    - ``kabsch_points``: ``"board"`` superposes the board centres (paper), ``"sensors"``
      every sensor position of every matched board pose.
    - ``weight_floor``: Kabsch weight ``w = 1 / (eps + e_master + e_slave)`` with ``e`` the
      mean squared angle residual of a pose fit and ``eps = weight_floor * median(e_m + e_s)``.
    - ``pose_xatol`` (rad, m), ``pose_fatol`` (rad^2), ``pose_maxfev``: Nelder-Mead on K1.
    - ``refine``: run the final K2 refinement; ``refine_*``: its Nelder-Mead settings.
    - ``n_jobs``: processes for the cold-start board-pose fits (0 = every core, 1 = this
      process only); the fits are independent, the results the same for any value. Warm
      starts run one after the other.

    Every field declares its allowed values; a bad one raises
    :class:`~lhgraph.errors.InputError` naming the field.
    """

    reconstruction: str = option("full", choices=VARIANTS)
    max_gap_periods: float = option(2.5, gt=0)
    warm_start: bool = option(False)
    mirror_check: bool = option(True)
    min_sensors: int = option(6, ge=4)
    min_measurements: int = option(10, ge=3)
    outlier_mads: float = option(5.0, gt=0, finite=False)  # inf: no outlier rejection
    kabsch_points: str = option("board", choices=KABSCH_POINTS)
    weight_floor: float = option(0.1, ge=0)
    pose_xatol: float = option(1e-6, gt=0)
    pose_fatol: float = option(1e-14, gt=0)
    pose_maxfev: int = option(6000, gt=0)
    refine: bool = option(True)
    refine_xatol: float = option(1e-9, gt=0)
    refine_fatol: float = option(1e-15, gt=0)
    refine_maxfev: int = option(6000, gt=0)
    n_jobs: int = option(0, ge=0)

    def __post_init__(self) -> None:
        check_fields(self)
