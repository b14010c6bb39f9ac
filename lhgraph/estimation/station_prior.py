"""An earlier calibration as a prior on the stations (``lhgraph solve --prior``):
:func:`station_priors` re-expresses its poses and covariances in the new solve's world.

The new solve's world is its reference station's frame, so the earlier result must hold
that station: station ``k``'s prior is ``T_ref_k = T_w_ref^-1 T_w_k`` with covariance
``Sigma_k + Ad(T_ref_k^-1) Sigma_ref Ad(T_ref_k^-1)^T`` (right perturbations ``[omega, v]``,
the two stations' errors taken as independent: a results file keeps no cross-covariance;
for a result solved in the reference's frame ``Sigma_ref`` is zero and the prior is the
file's own).

Two covariances serve: the prior factor *weighs* the earlier result by its white-noise
covariance (``covariance_white``, the file's ``covariance`` when it has none), the weight
the graph gives this capture's own sweeps, so that a capture with a prior weighs the two
captures as their joint solve would; the honest covariance (``covariance``) is what the
earlier estimate's error really is, and enters the new result's honest covariance
(:mod:`lhgraph.estimation.graph.block_covariance`). docs/solve.md says when this equals a
joint solve of both captures.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.estimation.residuals import adjoint
from lhgraph.geometry.transforms import inverse
from lhgraph.io.stations import Stations

Array = NDArray[np.float64]
MIN_PRIOR_EIGENVALUE = 1e-16
"""A prior covariance must be positive definite: its smallest eigenvalue above this."""


@dataclass(frozen=True)
class StationPriors:
    """The prior of every station of the earlier result in the new solve's world, by
    station index: ``T_ref_k``, the white 6x6 covariance that weighs it and the honest one
    (its error's), and what was left out (``notes``)."""

    reference: int
    priors: dict[int, tuple[Array, Array, Array]]
    notes: tuple[str, ...] = field(default=())


def station_priors(earlier: Stations, reference: int, source: str | Path | None = None
                   ) -> StationPriors:
    """``earlier``'s stations (with covariance) as priors in the frame of station
    ``reference`` (module docstring). InputError naming ``source`` when ``earlier`` lacks
    the reference station or has no station with a usable covariance."""
    if reference not in earlier.stations:
        raise InputError(f"the prior has no station {reference}, the solve's reference: give "
                         "a prior that holds it, or --reference one the prior has", source)
    ref = earlier.stations[reference]
    priors, notes = {}, []
    for k in earlier.indices():
        if k == reference:
            continue
        station = earlier.stations[k]
        if station.covariance is None:
            notes.append(f"station {k} of the prior has no covariance: not used")
            continue
        T = inverse(ref.T_world_lh) @ station.T_world_lh
        Ad = adjoint(inverse(T))
        pair = []
        for own, of_ref in ((station.covariance_white, ref.covariance_white),
                            (station.covariance, ref.covariance)):
            own = station.covariance if own is None else own
            of_ref = (ref.covariance if of_ref is None else of_ref)
            cov = own + (0.0 if of_ref is None else Ad @ of_ref @ Ad.T)
            pair.append(0.5 * (cov + cov.T))
        if min(np.min(np.linalg.eigvalsh(c)) for c in pair) <= MIN_PRIOR_EIGENVALUE:
            notes.append(f"station {k} of the prior has a singular covariance: not used")
            continue
        priors[k] = (T, pair[0], pair[1])
    if not priors:
        raise InputError("no station of the prior has a covariance to serve as a prior", source)
    return StationPriors(reference, priors, tuple(notes))
