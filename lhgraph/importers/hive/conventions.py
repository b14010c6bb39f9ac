"""Hive's conventions mapped to ours: the sweep axes and signs (:class:`AxisMapping`), the
angles table and the OOTX terms in our axis order. The mapping was verified on the data
(:mod:`lhgraph.importers.hive.mapping_check`, docs/hive.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.importers.hive.bag import HiveBag
from lhgraph.io.angles import Angles
from lhgraph.model.calibration import StationCalibration
from lhgraph.model.station import FactoryCalibration

Array = NDArray[np.float64]


@dataclass(frozen=True)
class AxisMapping:
    """How hive's ``(axis, angle)`` becomes ours: ``our_axis[hive_axis]``, ``sign[hive_axis]``.

    Hive's axis 0 is its "horizontal" sweep, axis 1 its "vertical" one.
    """

    our_axis: tuple[int, int] = (0, 1)
    sign: tuple[float, float] = (1.0, 1.0)

    @property
    def label(self) -> str:
        """Short name, e.g. ``az=+h el=+v`` (which hive axis, with which sign, feeds ours)."""
        names = "hv"
        parts = []
        for ours, tag in ((0, "az"), (1, "el")):
            hive = self.our_axis.index(ours)
            parts.append(f"{tag}={'+' if self.sign[hive] > 0 else '-'}{names[hive]}")
        return " ".join(parts)

    def apply(self, hive_axis: NDArray, angle: Array) -> tuple[NDArray[np.int64], Array]:
        """Our ``(axis, angle)`` of hive hits."""
        hive_axis = np.asarray(hive_axis, dtype=np.int64)
        axis = np.asarray(self.our_axis, dtype=np.int64)[hive_axis]
        return axis, np.asarray(self.sign)[hive_axis] * np.asarray(angle, dtype=float)


# Verified on data8.11.bag (docs/hive.md): hive's horizontal angle is our azimuth and its
# vertical angle our elevation, signs unchanged.
HIVE_MAPPING = AxisMapping((0, 1), (1.0, 1.0))

CANDIDATE_MAPPINGS = tuple(
    AxisMapping(axes, (s0, s1))
    for axes in ((0, 1), (1, 0))
    for s0 in (1.0, -1.0)
    for s1 in (1.0, -1.0)
)


def station_calibrations(bag: HiveBag, mapping: AxisMapping = HIVE_MAPPING
                         ) -> dict[int, StationCalibration]:
    """OOTX terms of each station in *our* axis order (hive's horizontal/vertical motor data
    goes to the axis its sweeps are mapped to). The bag carries no ``accel_dir``; it is
    written as zeros."""
    out = {}
    for index, cal in bag.hive_calibrations.items():
        order = [mapping.our_axis.index(k) for k in (0, 1)]
        values = {key: getattr(cal, key)[order] for key in
                  ("phase", "tilt", "curve", "gibphase", "gibmag")}
        out[index] = StationCalibration(FactoryCalibration(**values),
                                        int(bag.serials[index]) if bag.serials[index].isdigit()
                                        else index)
    return out


def hive_angles(bag: HiveBag, mapping: AxisMapping = HIVE_MAPPING) -> Angles:
    """The bag's sweep hits as an angles table in our convention, sorted by time.

    Extra columns: ``sweep`` (sweep message number) and ``length_us`` (pulse length).
    """
    L = bag.light
    axis, angle = mapping.apply(L["hive_axis"], L["angle"])
    order = np.lexsort((L["sensor"], L["time"]))
    return Angles(L["time"][order], L["station"][order], axis[order], L["sensor"][order],
                  angle[order], {"sweep": L["sweep"][order], "length_us": L["length_us"][order]})
