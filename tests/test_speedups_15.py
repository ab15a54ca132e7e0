"""Issue 13, eighth session: faster paths that must give the former results bit for bit."""

import numpy as np
import pytest

from stablemarks.planes import median


@pytest.mark.parametrize("n", [1, 2, 3, 8, 101, 1000, 8000, 8001])
def test_median_is_numpys_bit_for_bit(n):
    rng = np.random.default_rng(n)
    cases = [
        np.abs(rng.standard_t(3, n)),  # heavy-tailed: most values in a few buckets
        np.round(rng.normal(size=n), 1),  # many ties
        rng.normal(size=n) * 1e-300,  # a span too small for buckets
        np.full(n, 2.5),  # all equal
        np.concatenate([rng.normal(size=n - 1), [1e300]]) if n > 1 else np.array([-1e300]),  # one huge outlier
    ]
    for x in cases:
        assert median(x) == np.median(x)
    assert median(np.float32([3, 1, 2, 7])) == np.median(np.float32([3, 1, 2, 7]))


def test_median_of_a_2d_array_is_numpys():
    x = np.random.default_rng(0).normal(size=(7, 5))
    assert median(x) == np.median(x) and median(x.astype(np.float32)) == np.median(x.astype(np.float32))
