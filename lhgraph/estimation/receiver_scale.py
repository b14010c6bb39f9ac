"""The receiver's scale as an uncertainty of the solved stations.

Angles cannot see a scale: a receiver a fraction ``k`` larger than its board file, in a world
``k`` larger, gives the same angles, so the board file's size error scales the whole solved
world about the reference station. A solve adds this share to its honest covariance
(``[graph] receiver_scale_sigma``, :mod:`lhgraph.estimation.graph.block_covariance`) and
records the spread in the result (the stations TOML's top-level ``receiver_scale_sigma``);
two results of one receiver share the error, which :mod:`lhgraph.estimation.layout_compare`
then takes out of their difference (docs/uncertainty.md).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.stations import Stations

Array = NDArray[np.float64]
RESULT_KEY = "receiver_scale_sigma"
"""The stations TOML's top-level key of the spread a result's honest covariance carries."""


def receiver_scale_covariance(T_ref_lh: Array, sigma: float) -> Array:
    """The covariance (6x6, tangent ``[rotation, translation]``) a receiver-scale uncertainty
    of relative spread ``sigma`` gives a station at ``T_ref_lh`` (the reference station's
    frame, m): the world scaled by ``1 + k`` about the reference moves the station's position
    ``p`` by ``k p`` and turns nothing, ``k R^T p`` in its own translation tangent."""
    v = T_ref_lh[:3, :3].T @ T_ref_lh[:3, 3]
    C = np.zeros((6, 6))
    C[3:, 3:] = sigma**2 * np.outer(v, v)
    return C


def result_scale_sigma(stations: Stations) -> float:
    """The receiver-scale spread a result's honest covariances carry (0 when it records
    none)."""
    value = stations.extra.get(RESULT_KEY, 0.0)
    return float(value) if isinstance(value, (int, float)) and value > 0 else 0.0
