"""Robust spread: the standard deviation of normally distributed data from its median absolute
deviation, insensitive to outliers."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

MAD_TO_SIGMA = 1.4826
"""1 / Phi^-1(3/4): the median absolute deviation of a normal distribution times this is its
standard deviation."""


def robust_sigma(x: ArrayLike, about_zero: bool = False, axis: int | None = None
                 ) -> float | NDArray[np.float64]:
    """``1.4826 x MAD`` of ``x`` (same unit as ``x``): about its median, or about zero with
    ``about_zero`` (residuals whose mean is zero by construction); over all values, or per
    slice along ``axis`` (an array then)."""
    a = np.asarray(x, dtype=float)
    centre = 0.0 if about_zero else np.median(a, axis=axis, keepdims=axis is not None)
    mad = np.median(np.abs(a - centre), axis=axis)
    return MAD_TO_SIGMA * (float(mad) if axis is None else mad)
