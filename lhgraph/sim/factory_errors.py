"""Decoded factory calibrations that are off the truth: what a solver is given when a
station's OOTX values are wrong (:func:`with_factory_errors`; the station self-calibration's
simulated checks, docs/self_calibration.md)."""

from __future__ import annotations

import dataclasses

import numpy as np

from lhgraph.model.station import StationModel


def with_factory_errors(models: dict[int, StationModel], keys: tuple[str, ...] | list[str],
                        sigma_rad: float, rng: np.random.Generator) -> dict[int, StationModel]:
    """``models`` (by station index) with each factory term of ``keys`` moved, per axis, by
    a Gaussian of ``sigma_rad`` (rad) drawn from ``rng`` (stations in the dict's order, then
    the keys, then the axes)."""
    out = {}
    for k, m in models.items():
        cal = m.calibration
        moved = {key: getattr(cal, key) + rng.normal(0.0, sigma_rad, 2) for key in keys}
        out[k] = dataclasses.replace(m, calibration=dataclasses.replace(cal, **moved))
    return out
