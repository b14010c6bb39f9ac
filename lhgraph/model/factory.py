"""A station's factory calibration terms (what it broadcasts over OOTX, in our convention:
docs/model.md) and the signs of the LH1 gib and curve terms, below the measurement models
that read them (:mod:`lhgraph.model.lh1`, :mod:`lhgraph.model.lh2`,
:mod:`lhgraph.model.station`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

CALIBRATION_KEYS = ("phase", "tilt", "curve", "gibphase", "gibmag")
"""The factory-calibration terms of both generations (``[axis0, axis1]`` each, rad)."""
LH2_CALIBRATION_KEYS = ("ogeephase", "ogeemag")
"""The terms only LH2 stations have (zero on LH1)."""


@dataclass(frozen=True)
class Convention:
    """Signs of the LH1 gib and curve terms. Public implementations disagree; the default
    (gib -1, curve +1) fits two real recordings best (docs/model.md)."""

    gib_sign: float = -1.0
    curve_sign: float = 1.0


@dataclass(frozen=True)
class FactoryCalibration:
    """Per-axis factory calibration of one station, each field ``[axis0, axis1]`` (rad; the
    ogee terms LH2 only)."""

    phase: Array = field(default_factory=lambda: np.zeros(2))
    tilt: Array = field(default_factory=lambda: np.zeros(2))
    curve: Array = field(default_factory=lambda: np.zeros(2))
    gibphase: Array = field(default_factory=lambda: np.zeros(2))
    gibmag: Array = field(default_factory=lambda: np.zeros(2))
    ogeephase: Array = field(default_factory=lambda: np.zeros(2))
    ogeemag: Array = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        for key in CALIBRATION_KEYS + LH2_CALIBRATION_KEYS:
            value = np.asarray(getattr(self, key), dtype=float).reshape(2)
            object.__setattr__(self, key, value)

    def as_dict(self, generation: int = 1) -> dict[str, list[float]]:
        """Plain ``{key: [axis0, axis1]}`` for files: the terms of ``generation``."""
        keys = CALIBRATION_KEYS + (LH2_CALIBRATION_KEYS if generation == 2 else ())
        return {key: [float(x) for x in getattr(self, key)] for key in keys}

    def is_zero(self) -> bool:
        """True when every term is zero (the ideal station)."""
        return all(not np.any(getattr(self, key))
                   for key in CALIBRATION_KEYS + LH2_CALIBRATION_KEYS)
