"""Weighted Kabsch superposition: the rigid transform that best maps one point set onto another."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.geometry.transforms import make_pose


def weighted_kabsch(src: ArrayLike, dst: ArrayLike, weights: ArrayLike | None = None
                    ) -> NDArray[np.float64]:
    """Proper rigid transform ``T_dst_src`` (4x4) minimising ``sum w_i |R src_i + t - dst_i|^2``.

    ``src`` and ``dst`` are corresponding points ``(N, 3)`` (any unit; the translation comes
    out in the same unit), ``weights`` ``(N,)`` non-negative (default all 1). The rotation is
    always proper: when the best orthogonal fit is a reflection (det < 0), the axis of the
    smallest singular value is flipped (Kabsch 1976 / Umeyama 1991). Needs at least three
    non-collinear points with positive weight for a unique rotation.
    """
    src = np.asarray(src, dtype=float).reshape(-1, 3)
    dst = np.asarray(dst, dtype=float).reshape(-1, 3)
    if src.shape != dst.shape:
        raise ValueError(f"point sets differ in shape: {src.shape} vs {dst.shape}")
    w = np.ones(len(src)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if len(w) != len(src) or np.any(w < 0) or not np.any(w > 0):
        raise ValueError("weights must be non-negative, one per point, not all zero")
    w = w / w.sum()
    c_src = w @ src
    c_dst = w @ dst
    H = (src - c_src).T @ (w[:, None] * (dst - c_dst))
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return make_pose(R, c_dst - R @ c_src)
