"""Station covariances that cover what repeats: the time-block sandwich
(:func:`station_covariances`).

The marginal covariance of the graph (GTSAM's, the *white* one) holds if every residual is
independent noise of its model's spread. On real captures they are not: a diode's residual
stays alike for the tenths of a second the board spends in one part of a station's view (the
station model's and the board geometry's errors seen from there), and the white covariance
of a real recording is 13-42x narrower than the spread between recordings of unmoved
stations (``docs/results/compare_pairs.md``). The time-block sandwich (the cluster-robust
covariance of econometrics, the linearised block bootstrap) lets the data say how much the
stations' estimate moves with the part of the path it was seen from:

1. the graph linearised at the result, whitened, robust weights included: ``A``, ``b``
   (:func:`~.linear_system.linear_system`);
2. ``H = A^T A`` factorised once, in the graph's elimination order (the chain state by state,
   the stations last: little fill); ``Y = H^-1 E`` for the station columns ``E``;
3. each row's influence on the stations' estimate, ``(A Y)_r b_r``, summed over the rows of
   each time block of the capture (the rows of a board state's factors belong to its block,
   the priors of variables of no state to none): the block scores ``g_c``;
4. by default (``block_estimator = "jackknife"``) each score is first scaled up by its
   block's leverage, ``g_c <- (I - L_c)^-1 g_c`` with ``L_c = M_c W^-1``, ``M_c`` the sum
   over the block's rows of ``(A Y)_r^T (A Y)_r`` and ``W`` the white covariance: the
   change of the estimate when the block is left out (the stations' problem with the path
   partialled out; the CV3 estimator of cluster-robust inference, which does not read low
   by the block's share of the information as the plain one does);
   ``sandwich = (C - 1) / C sum_c (g_c - mean g)(g_c - mean g)^T`` over the ``C`` blocks
   (plain: the unscaled scores, ``C / (C - 1)``; :func:`block_sandwich`), plus, for the
   rows of an earlier result's station priors (``lhgraph solve --prior``: information from
   outside this capture, weighed by its white covariance), their expected share
   ``(A Y)_p^T C_p (A Y)_p`` with ``C_p`` the covariance of the whitened prior residual its
   honest covariance implies;
5. the *honest* covariance is the sandwich, never narrower than the white one in any
   direction (:func:`floor_at`): with white residuals the two agree up to the sandwich's own
   scatter, with correlated ones the sandwich is the wider;
6. with ``receiver_scale_sigma`` (resolved on few-diode data), plus the receiver scale's
   share (:mod:`lhgraph.estimation.receiver_scale`): angles cannot see a scale, so the
   receiver file's size error scales the whole solved world about the reference station.

The blocks are ``capture length / covariance_blocks`` long, at least ``min_block_s``
(:class:`~lhgraph.estimation.graph.options.UncertaintyOptions`); docs/uncertainty.md gives
the method, the choice of block length and what it predicts on the shared recordings.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.factory_information import FactoryInformation, factory_information
from lhgraph.estimation.graph.families.station_prior import StationPriorFactors
from lhgraph.estimation.graph.linear_system import linear_system, normal_solver
from lhgraph.estimation.graph.optimizer import OptimizerResult
from lhgraph.estimation.graph.options import UncertaintyOptions
from lhgraph.estimation.graph.variables import BOARD_SCALE, FACTORY_TERMS, STATION_POSE
from lhgraph.estimation.receiver_scale import receiver_scale_covariance

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StationCovariances:
    """The stations' 6x6 covariances by slot (tangent order ``[rotation, translation]``):
    ``white`` the graph's marginals, ``honest`` the block sandwich floored at them (equal to
    ``white`` with ``covariance = "white"``); ``method`` the one ``honest`` is,
    ``block_s`` the block length (s) and ``n_blocks`` their number (0 without blocks);
    ``factory``: the factory terms' information when asked (``factory_information``);
    ``calibration_white`` / ``calibration_honest``: by GTSAM key, the covariance of each
    solved calibration variable the result reports (a station slot's factory-term
    corrections, rad^2, key-major; the board scale), the same two ways (both None when the
    graph solves none)."""

    white: dict[int, Array]
    honest: dict[int, Array]
    method: str
    block_s: float
    n_blocks: int
    factory: FactoryInformation | None = None
    calibration_white: dict[int, Array] | None = None
    calibration_honest: dict[int, Array] | None = None

    def summary(self) -> dict[str, float]:
        """The blocks as diagnostics figures."""
        return {"covariance_block_s": self.block_s, "covariance_blocks": float(self.n_blocks)}


MAX_BLOCK_LEVERAGE = 0.9
"""The largest share of the information in one direction a block's jackknife scaling counts
(its score scaled at most ``1 / (1 - 0.9)`` = 10x): a block that alone determines a
direction (a station seen in it only) has no leave-it-out estimate."""


def block_sandwich(A: sp.csr_matrix, b: Array, row_block: NDArray[np.int64],
                   columns: NDArray[np.int64], order: NDArray[np.int64] | None = None,
                   expected: NDArray[np.bool_] | None = None,
                   expected_cov: Array | None = None,
                   estimator: str = "jackknife") -> tuple[Array, Array, int]:
    """The white covariance ``[H^-1]`` and the block sandwich of the parameters ``columns``
    of the least-squares problem ``A x ~ b`` (whitened), and the number of blocks.

    ``row_block``: each row's block (-1: no block, e.g. a prior); ``order``: a column
    permutation that factorises ``H = A^T A`` with little fill (default: as given);
    ``expected``: rows (of no block) whose share is added at its model's value,
    ``(A Y)_e^T C (A Y)_e`` with ``C`` = ``expected_cov`` (the covariance of those whitened
    rows; default the identity), instead of from their residuals; ``estimator``:
    ``"jackknife"`` (each block's score scaled by its leverage, :func:`jackknife_scores`)
    or ``"plain"``."""
    E = np.zeros((A.shape[1], len(columns)))
    E[columns, np.arange(len(columns))] = 1.0
    Y = normal_solver(A, order)(E)
    white = 0.5 * (Y[columns] + Y[columns].T)
    used = np.flatnonzero(row_block >= 0)
    blocks, which = np.unique(row_block[used], return_inverse=True)
    n = len(blocks)
    # each block's score, the sum over its rows of b_r (A Y)_r, as (its rows' b^T A) Y: one
    # sparse gradient row per block times Y, not a dense row of A Y per row of A
    gradients = sp.csr_matrix((b[used], (which, used)), shape=(n, A.shape[0])) @ A
    scores = np.asarray(gradients @ Y)
    if estimator == "jackknife":
        scores = jackknife_scores(scores, A, used, which, Y, white)
        factor = (n - 1) / max(n, 1)
    else:
        factor = n / max(n - 1, 1)
    scores -= scores.mean(axis=0)
    sandwich = scores.T @ scores * factor
    if expected is not None and np.any(expected):
        AY = A[np.flatnonzero(expected)] @ Y
        C = np.eye(len(AY)) if expected_cov is None else expected_cov
        sandwich = sandwich + AY.T @ C @ AY
    return white, sandwich, n


def jackknife_scores(scores: Array, A: sp.csr_matrix, used: NDArray[np.int64],
                     which: NDArray[np.int64], Y: Array, white: Array) -> Array:
    """Block scores ``scores`` (C, k: each block's influence on the parameters) scaled to
    the change of the estimate when the block is left out: ``(I - L_c)^-1 g_c``, ``L_c =
    M_c W^-1`` with ``M_c = (A_c Y)^T (A_c Y)`` over the block's rows ``A_c`` of ``A``
    (rows ``used``, ``which``: each one's block) and ``W`` = ``white``. Computed in ``W``'s whitened
    coordinates (directions of ``W`` below 1e-12 of its largest left as they are), each
    block's leverage capped at :data:`MAX_BLOCK_LEVERAGE`."""
    w, V = np.linalg.eigh(white)
    keep = w > w.max() * 1e-12
    R = V[:, keep] / np.sqrt(w[keep])  # x -> R^T x whitens
    root = V[:, keep] * np.sqrt(w[keep])  # and root @ back
    order = np.argsort(which, kind="stable")
    starts = np.searchsorted(which[order], np.arange(len(scores) + 1))
    out = scores.copy()
    for c in range(len(scores)):
        rows = used[order[starts[c]:starts[c + 1]]]
        AYR = np.asarray(A[rows] @ Y) @ R
        lev, U = np.linalg.eigh(AYR.T @ AYR)
        s = R.T @ scores[c]
        scaled = U @ ((U.T @ s) / (1.0 - np.clip(lev, 0.0, MAX_BLOCK_LEVERAGE)))
        out[c] = scores[c] + root @ (scaled - s)
    return out


def floor_at(floor: Array, C: Array) -> Array:
    """``C`` widened to ``floor`` in every direction where it is narrower (symmetric positive
    definite ``floor``): its eigenvalues in ``floor``'s whitened coordinates clipped at 1."""
    w, V = np.linalg.eigh(floor)
    w = np.maximum(w, 1e-300)
    root, inv_root = V @ np.diag(np.sqrt(w)) @ V.T, V @ np.diag(1.0 / np.sqrt(w)) @ V.T
    m, U = np.linalg.eigh(inv_root @ C @ inv_root)
    out = root @ U @ np.diag(np.maximum(m, 1.0)) @ U.T @ root
    return 0.5 * (out + out.T)


def block_length_s(duration_s: float, options: UncertaintyOptions) -> float:
    """The block length (s) of a capture of ``duration_s``: ``duration_s /
    covariance_blocks``, at least ``min_block_s``."""
    return max(duration_s / options.covariance_blocks, options.min_block_s)


def station_covariances(fit: OptimizerResult, ev: FactorEvaluator,
                        options: UncertaintyOptions | None = None) -> StationCovariances:
    """The stations' white and honest covariances by slot at the optimiser's result ``fit``
    (the graph's ``build_and_optimise`` marginals: see the module docstring)."""
    options = options or UncertaintyOptions()
    found = station_covariances_only(fit, ev, options)
    sigma = options.receiver_scale_sigma or 0.0
    if sigma > 0:
        poses = ev.station_poses()
        found = replace(found, honest={slot: C + receiver_scale_covariance(poses[slot], sigma)
                                       for slot, C in found.honest.items()})
    if not options.factory_information:
        return found
    return replace(found, factory=factory_information(fit.graph, fit.values, ev))


def station_covariances_only(fit: OptimizerResult, ev: FactorEvaluator,
                             options: UncertaintyOptions) -> StationCovariances:
    """:func:`station_covariances` without the factory terms' information (with solved
    factory terms, their covariances too, the stations' and theirs from one sandwich)."""
    slots = list(ev.layout.indices(STATION_POSE))
    white = {slot: fit.covariance(STATION_POSE.key(slot)) for slot in slots}
    extra = calibration_keys(ev)
    extra_white = {key: fit.covariance(key) for key in extra} or None
    t = ev.problem.state_time
    block_s = block_length_s(float(t[-1] - t[0]), options) if len(t) else 0.0
    if options.covariance == "white" or not slots:
        return StationCovariances(white, dict(white), "white", 0.0, 0, None, extra_white,
                                  extra_white)
    system = linear_system(fit.graph, fit.values, ev.layout)
    columns = system.columns([STATION_POSE.key(slot) for slot in slots])
    last = max(int(np.ceil((t[-1] - t[0]) / block_s)) - 1, 0)
    block = np.where(system.row_state >= 0, np.minimum(
        np.floor((t[np.maximum(system.row_state, 0)] - t[0]) / block_s), last), -1)
    on_stations = np.zeros(system.A.shape[1])
    on_stations[columns] = 1.0
    magnitude = abs(system.A)
    station_only = (magnitude @ on_stations > 0) & np.isclose(
        magnitude @ on_stations, np.asarray(magnitude.sum(axis=1)).ravel())
    priors = next((f for f in ev.families if isinstance(f, StationPriorFactors)), None)
    prior_rows = (system.row_state < 0) & station_only
    expected_cov = None if priors is None else sp.block_diag(priors.whitened_errors()).toarray()
    if expected_cov is not None and expected_cov.shape[0] != int(prior_rows.sum()):
        raise RuntimeError("the station priors' rows do not match their factors")
    wanted = np.concatenate([columns] + ([system.columns(extra)] if extra else []))
    _, sandwich, n = block_sandwich(system.A, system.b, block.astype(np.int64), wanted,
                                    system.elimination_columns(ev.layout), prior_rows,
                                    expected_cov, options.block_estimator)
    if n < 2:
        return StationCovariances(white, dict(white), "white", block_s, n, None, extra_white,
                                  extra_white)
    honest = {slot: floor_at(white[slot], sandwich[6 * i:6 * i + 6, 6 * i:6 * i + 6])
              for i, slot in enumerate(slots)}
    extra_honest, first = {}, len(columns)
    for key in extra:
        d = system.dim[key]
        extra_honest[key] = floor_at(extra_white[key],
                                     sandwich[first:first + d, first:first + d])
        first += d
    return StationCovariances(white, honest, "blocks", block_s, n, None, extra_white,
                              extra_honest if extra else None)


def calibration_keys(ev: FactorEvaluator) -> list[int]:
    """The keys of the calibration variables a result reports with their covariance: every
    station slot's factory-term corrections, then the board scale (those the graph has)."""
    factory = ev.layout.family(FACTORY_TERMS)
    keys = [] if factory is None else list(ev.layout.keys(factory))
    return keys + ([BOARD_SCALE.key(0)] if ev.layout.holds(BOARD_SCALE, 0) else [])
