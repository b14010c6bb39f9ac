"""A graph linearised at a point as one sparse least-squares system, and the solver of its
normal equations: :func:`linear_system`, :func:`normal_solver` (used by the honest covariance,
:mod:`.block_covariance`, and the factory terms' information, :mod:`.factory_information`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from lhgraph.estimation.graph.variables import VariableLayout

Array = NDArray[np.float64]
SYMBOL_SHIFT = 56
"""A GTSAM symbol key holds its character in the top byte, the index below it."""


@dataclass(frozen=True)
class LinearSystem:
    """A graph linearised at a point: whitened Jacobian ``A`` (rows x columns, sparse),
    right-hand side ``b`` (``A dx ~ b``), the first column of each key (``column``) and
    its dimension (``dim``), and the board state each row belongs to (``row_state``, -1 for
    rows of no state)."""

    A: sp.csr_matrix
    b: Array
    column: dict[int, int]
    dim: dict[int, int]
    row_state: NDArray[np.int64]

    def columns(self, keys: list[int]) -> NDArray[np.int64]:
        """The columns of ``keys``, in order."""
        return np.concatenate([np.arange(self.column[k], self.column[k] + self.dim[k])
                               for k in keys]).astype(np.int64)

    def elimination_columns(self, layout: VariableLayout) -> NDArray[np.int64]:
        """Every column, in ``layout``'s elimination order (a permutation with little fill
        for :func:`normal_solver`)."""
        ordering = layout.elimination_ordering()
        return self.columns([k for k in (ordering.at(i) for i in range(ordering.size()))
                             if k in self.column])


def linear_system(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                  layout: VariableLayout) -> LinearSystem:
    """``graph`` linearised at ``values`` as a sparse system (GTSAM's sparse Jacobian: the
    keys in ascending order, the right-hand side as last column); each row's board state is
    the lowest state index among its factor's keys of the chain and leaf families."""
    linear = graph.linearize(values)
    i, j, s = linear.sparseJacobian_()
    rows, cols = i.astype(np.int64) - 1, j.astype(np.int64) - 1
    n_cols = int(cols.max())
    n_rows = int(rows.max()) + 1
    rhs = cols == n_cols
    b = np.zeros(n_rows)
    b[rows[rhs]] = s[rhs]
    A = sp.csr_matrix((s[~rhs], (rows[~rhs], cols[~rhs])), shape=(n_rows, n_cols))
    zero = values.zeroVectors()
    column, dim, c = {}, {}, 0
    for key in sorted(linear.keys()):
        column[key], dim[key] = c, zero.at(key).shape[0]
        c += dim[key]
    if c != n_cols:
        raise RuntimeError(f"the linearised graph has {n_cols} columns, its keys {c}")
    per_state = {ord(f.symbol) for f in layout.families if f.elimination in ("chain", "leaf")}
    row_state = np.full(n_rows, -1, dtype=np.int64)
    r = 0
    for f in range(linear.size()):
        factor = linear.at(f)
        if factor is None:
            continue
        n = factor.rows() if hasattr(factor, "rows") else factor.jacobian()[1].shape[0]
        states = [k & ((1 << SYMBOL_SHIFT) - 1) for k in factor.keys()
                  if k >> SYMBOL_SHIFT in per_state]
        if states:
            row_state[r:r + n] = min(states)
        r += n
    return LinearSystem(A, b, column, dim, row_state)


def normal_solver(A: sp.csr_matrix, order: NDArray[np.int64] | None = None
                  ) -> Callable[[Array], Array]:
    """``rhs -> H^-1 rhs`` for ``H = A^T A`` (``rhs``: columns x k), ``H`` factorised once
    with its columns in ``order`` (a permutation with little fill; default: as given)."""
    order = np.arange(A.shape[1]) if order is None else order
    H = (A.T @ A).tocsc()[order][:, order]
    lu = spla.splu(H.tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})

    def solve(rhs: Array) -> Array:
        out = np.empty_like(rhs)
        out[order] = lu.solve(rhs[order])
        return out

    return solve
