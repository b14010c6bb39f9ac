"""The robust spread (1.4826 x MAD) against known answers."""

import numpy as np
import pytest

from lhgraph.estimation.spread import robust_sigma


def test_normal_sample_gives_its_sigma_despite_outliers() -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(5.0, 2.0, 200_000)
    x[:10_000] = 1e6  # 5 % gross outliers move it by only ~7 %
    assert robust_sigma(x) == pytest.approx(2.0 * 1.066, rel=0.02)
    assert robust_sigma(rng.normal(5.0, 2.0, 200_000)) == pytest.approx(2.0, rel=0.01)


def test_about_zero_and_per_axis() -> None:
    x = np.array([[1.0, -4.0], [2.0, 4.0], [3.0, 8.0]])
    # about the median: |x - 2| -> median 1; |x - 4| = 8, 0, 4 -> median 4
    assert np.allclose(robust_sigma(x, axis=0), 1.4826 * np.array([1.0, 4.0]))
    # about zero: median of |x| = 2 and 4
    assert np.allclose(robust_sigma(x, about_zero=True, axis=0), 1.4826 * np.array([2.0, 4.0]))
    assert robust_sigma([1.0, 2.0, 4.0]) == pytest.approx(1.4826)
    assert robust_sigma([-1.0, 2.0, -4.0], about_zero=True) == pytest.approx(2.0 * 1.4826)
