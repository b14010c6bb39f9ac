"""How well a capture determines each station's factory-calibration terms, and how they trade
off against the poses: :func:`factory_information` (the identifiability study of the
station self-calibration).

The graph holds the factory terms (LH1: ``phase``, ``tilt``, ``curve``, ``gibphase``,
``gibmag`` per axis; LH2 also ``ogeephase``, ``ogeemag``) fixed at their OOTX values. Here
they are added as if they were variables, at a point of the graph (a solve's result, or the
truth of a simulation), without a prior:

1. the graph's whitened linear system ``A dx ~ b`` at the point
   (:func:`~.block_covariance.linear_system`);
2. each term's column ``J`` of the bearing rows: the central difference of the shared
   measurement model (:func:`lhgraph.estimation.residuals.bearing_residuals`) in the term,
   whitened like its row (the row's entry at the sweep offset, whose Jacobian is 1);
3. the Gauss-Newton information of the terms with every graph variable free: the Schur
   complement ``I = J^T J - C^T H^-1 C`` (``C = A^T J``, ``H = A^T A``); its inverse is the
   terms' Cramer-Rao covariance from this capture;
4. what the poses take from them: each term's sigma with the graph's variables held
   (``1 / sqrt((J^T J)_jj)``) against free (``1 / sqrt(I_jj)``), its largest correlation with
   a station-pose coordinate, and the stations' shift per unit error of the term left
   unmodelled (``-(H^-1 C)`` at the station columns: what an OOTX error does to the result).

Sigmas are of the white noise model (the graph's noise levels and robust weights at the
point); on real data the same factor as the stations' honest-to-white ratio applies
(docs/uncertainty.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.families.factory import STEP_RAD, with_term_deltas
from lhgraph.estimation.graph.linear_system import linear_system, normal_solver
from lhgraph.estimation.graph.variables import STATION_POSE, SWEEP_OFFSET
from lhgraph.estimation.residuals import bearing_residuals
from lhgraph.model.factory import CALIBRATION_KEYS, LH2_CALIBRATION_KEYS
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]
POSE_COORDINATES = ("rx", "ry", "rz", "tx", "ty", "tz")
PARTICIPATION = 0.01
"""A term takes part in an undetermined direction of the information when its component in
that (unit) eigenvector exceeds this."""


@dataclass(frozen=True)
class FactoryTerm:
    """One factory term of one station: ``station`` index, ``key`` (``phase``, ...),
    ``axis`` (0, 1)."""

    station: int
    key: str
    axis: int

    @property
    def name(self) -> str:
        """``station 1 phase[0]``."""
        return f"station {self.station} {self.key}[{self.axis}]"


@dataclass(frozen=True)
class FactoryInformation:
    """The terms' identifiability at a point of the graph (module docstring), per term in
    ``terms``' order: ``sigma_alone_rad`` (every graph variable held), ``sigma_free_rad``
    (the graph's variables free, the other terms held), ``covariance`` (P x P, every term
    and variable free; inf variance for the terms the capture cannot tell apart from the
    others or the poses, :func:`joint_covariance`), ``pose_correlation``
    (largest |correlation| with a station-pose coordinate, ``pose_coordinate`` which:
    ``station 1 tz``), and ``station_shift`` ``(6 S, P)``: the stations' tangent shift
    ``[rx, ry, rz, tx, ty, tz]`` per station slot but the reference's (their indices:
    ``shifted``), per rad of the term's error. ``unused``: the terms no residual depends on
    at the point (those the measurement model does not apply, such as LH2's curve and ogee,
    and a gib phase whose magnitude is zero), left out of the rest."""

    terms: list[FactoryTerm]
    sigma_alone_rad: Array
    sigma_free_rad: Array
    covariance: Array
    pose_correlation: Array
    pose_coordinate: list[str]
    station_shift: Array
    unused: list[FactoryTerm]
    shifted: list[int]

    @property
    def sigma_joint_rad(self) -> Array:
        """Each term's sigma with every term and variable free (inf: not identifiable)."""
        return np.sqrt(np.diag(self.covariance))

    def station_shift_mm_per_mrad(self) -> Array:
        """Per term, the largest station's position shift (mm) per mrad of its error."""
        pos = self.station_shift.reshape(-1, 6, len(self.terms))[:, 3:]
        return np.max(np.linalg.norm(pos, axis=1), axis=0) if len(pos) else np.zeros(
            len(self.terms))

    def as_dict(self) -> dict[str, Any]:
        """Per term (``terms``: their names) the sigmas (rad), the largest pose correlation
        and its coordinate, the largest station shift (mm per mrad), and by station index
        its tangent shift per rad of each term (``station_shift_per_rad``: 6 rows, one
        column per term): a result's ``factory_information``."""
        return {"terms": [t.name for t in self.terms],
                "sigma_alone_rad": self.sigma_alone_rad.tolist(),
                "sigma_free_rad": self.sigma_free_rad.tolist(),
                "sigma_joint_rad": self.sigma_joint_rad.tolist(),
                "pose_correlation": self.pose_correlation.tolist(),
                "pose_coordinate": list(self.pose_coordinate),
                "station_shift_mm_per_mrad": self.station_shift_mm_per_mrad().tolist(),
                "station_shift_per_rad": {
                    sid: self.station_shift[6 * i:6 * i + 6].tolist()
                    for i, sid in enumerate(self.shifted)},
                "unused": [t.name for t in self.unused]}


def factory_terms(ev: FactorEvaluator) -> list[FactoryTerm]:
    """Every factory term of every station of ``ev``'s problem (its generation's keys)."""
    p = ev.problem
    return [FactoryTerm(int(sid), key, axis)
            for sid, model in zip(p.station_ids, p.models, strict=True)
            for key in CALIBRATION_KEYS + (LH2_CALIBRATION_KEYS if model.generation == 2 else ())
            for axis in (0, 1)]


def _with_term(model: StationModel, term: FactoryTerm, delta: float) -> StationModel:
    step = np.zeros(2)
    step[term.axis] = delta
    return with_term_deltas(model, (term.key,), step)


def term_jacobian(ev: FactorEvaluator, terms: list[FactoryTerm]) -> Array:
    """``d residual / d term`` ``(hits, P)`` of every bearing hit at ``ev``'s evaluated point
    (central differences of the measurement model)."""
    p, pt, hits = ev.problem, ev.point, ev.corrections.hits
    slot_of = {int(sid): slot for slot, sid in enumerate(p.station_ids)}
    J = np.zeros((len(hits.angle), len(terms)))
    for j, term in enumerate(terms):
        slot = slot_of[term.station]
        sides = []
        for delta in (STEP_RAD, -STEP_RAD):
            models = list(p.models)
            models[slot] = _with_term(models[slot], term, delta)
            sides.append(bearing_residuals(hits, pt.X, pt.W, pt.L, models, False)[0])
        J[:, j] = (sides[0] - sides[1]) / (2 * STEP_RAD)
    return J


def factory_information(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                        ev: FactorEvaluator) -> FactoryInformation:
    """The factory terms' information from ``graph`` at ``values`` (``ev`` its evaluator):
    see the module docstring."""
    ev.evaluate(values)
    system = linear_system(graph, values, ev.layout)
    terms = factory_terms(ev)
    state = ev.problem.hits.state
    n_hits = len(state)
    # the whitening of each bearing row: its entry at the sweep offset (Jacobian 1)
    offset_columns = np.array([system.column[SWEEP_OFFSET.key(int(k))] for k in state])
    scale = np.asarray(system.A[np.arange(n_hits), offset_columns]).ravel()
    dr = term_jacobian(ev, terms)
    used = np.any(dr != 0, axis=0)
    unused = [t for t, u in zip(terms, used, strict=True) if not u]
    terms = [t for t, u in zip(terms, used, strict=True) if u]
    J = np.zeros((system.A.shape[0], len(terms)))
    J[:n_hits] = dr[:, used] * scale[:, None]
    if not np.array_equal(system.row_state[:n_hits], state) or np.any(scale <= 0):
        raise RuntimeError("the graph's first rows are not its bearing hits")
    C = system.A.T @ J
    solve = normal_solver(system.A, system.elimination_columns(ev.layout))
    Z = solve(C)
    D = J.T @ J
    info = D - C.T @ Z
    info = 0.5 * (info + info.T)
    cov = joint_covariance(info)
    slots = list(ev.layout.indices(STATION_POSE))
    stations = system.columns([STATION_POSE.key(s) for s in slots])
    shift = -Z[stations]
    # the stations' covariance with the terms free, and their cross-covariance with them
    E = np.zeros((system.A.shape[1], len(stations)))
    E[stations, np.arange(len(stations))] = 1.0
    cov_s = solve(E)[stations]
    # correlations over the identifiable terms (the others held at their values)
    known = np.isfinite(np.diag(cov))
    held = np.where(known[:, None] & known[None, :], cov, 0.0)
    cov_s = cov_s + shift @ held @ shift.T
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = (shift @ held) / np.sqrt(np.outer(np.diag(cov_s), np.diag(held)))
    best = np.argmax(np.abs(np.nan_to_num(corr)), axis=0)
    correlation = np.where(known, np.abs(corr[best, np.arange(len(terms))]), np.nan)
    ids = [ev.problem.station_ids[s] for s in slots]
    coordinate = [f"station {ids[b // 6]} {POSE_COORDINATES[b % 6]}" if ok else "-"
                  for b, ok in zip(best, known, strict=True)]
    with np.errstate(divide="ignore"):
        alone, free = (1.0 / np.sqrt(np.maximum(np.diag(M), 0.0)) for M in (D, info))
    return FactoryInformation(terms, alone, free, cov, correlation, coordinate, shift, unused,
                              [int(i) for i in ids])


def joint_covariance(info: Array, rtol: float = 1e-10) -> Array:
    """The inverse of the information ``info`` (P x P) where it is determined: along
    directions of eigenvalue below ``rtol`` times the largest the terms they involve (a
    component over :data:`PARTICIPATION`) get infinite variance and no covariance with the
    rest (inf, 0), the others the inverse of their own information."""
    w, V = np.linalg.eigh(0.5 * (info + info.T))
    good = w > rtol * max(w[-1], 1e-300)
    cov = (V[:, good] / w[good]) @ V[:, good].T
    lost = np.any(np.abs(V[:, ~good]) > PARTICIPATION, axis=1)
    if np.any(lost):
        keep = ~lost
        sub = info[np.ix_(keep, keep)]
        cov = np.zeros_like(info)
        if np.any(keep):
            cov[np.ix_(keep, keep)] = joint_covariance(sub, rtol)
        cov[lost, lost] = np.inf
    return cov
