"""The moved-station watch's options (:mod:`lhgraph.estimation.station_watch`), apart so
that the command line reads their defaults without loading the solver."""

from __future__ import annotations

from dataclasses import dataclass

from lhgraph.config import check_fields, option


@dataclass(frozen=True)
class WatchOptions:
    """The watch's windows (``window_s`` long every ``step_s``; s), how many earlier
    windows a test needs (``min_history``), and when a station moved: ``sustain`` windows
    in a row over ``k_sigma`` of the history's spread and over ``floor_mm`` or
    ``floor_deg``; a station is tested in a window (and joins its history) only when the
    window's white sigma of it is within ``max_sigma_mm`` and ``max_sigma_deg`` (a window
    that barely determines the station), and a window is solved only when the board moves
    in ``min_moving_fraction`` of it (0.25 s bins whose median angle rate exceeds
    ``motion_threshold_rad_s``, :func:`lhgraph.estimation.rests.motion_rate`: a still
    board leaves the window's solve where it started, and the change from rest to motion
    reads as a move on real recordings)."""

    window_s: float = option(3.0, gt=0, le=60)
    step_s: float = option(0.5, gt=0, le=60)
    min_history: int = option(10, ge=2, le=1000)
    k_sigma: float = option(10.0, gt=0, le=100)
    floor_mm: float = option(4.0, ge=0, le=1000)
    floor_deg: float = option(0.08, ge=0, le=180)
    sustain: int = option(2, ge=1, le=100)
    max_sigma_mm: float = option(50.0, gt=0, le=10000)
    max_sigma_deg: float = option(1.0, gt=0, le=180)
    min_moving_fraction: float = option(0.9, ge=0, le=1)
    motion_threshold_rad_s: float = option(0.01, gt=0)

    def __post_init__(self) -> None:
        check_fields(self)
