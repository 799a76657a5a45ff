"""The helper that bounds two computations' difference in ulps (tests/ulps.py)."""
import math

import numpy as np
import pytest

from ulps import after_product, assert_within, assert_within_ulps, ulp


def test_the_bound_is_counted_in_ulps_of_the_larger_value():
    assert_within_ulps(1.0, 1.0 + 2.0 ** -52, 1, "one step above 1")
    assert_within_ulps(1.0, 1.0 - 2.0 ** -53, 1, "one step below 1: half the ulp of 1")
    with pytest.raises(AssertionError, match=r"1 of 1 differ .*\(1 ulps: two steps\)"):
        assert_within_ulps(1.0, 1.0 + 2.0 ** -51, 1, "two steps")
    assert_within_ulps([0.0, math.nan, math.inf], [-0.0, math.nan, math.inf], 0, "the same")
    with pytest.raises(AssertionError):
        assert_within_ulps(math.inf, 1e308, 1e6, "an infinity is no number of ulps away")
    assert ulp(-3.0) == ulp(3.0) == math.ulp(3.0) and ulp(0.0) == 5e-324
    assert_within([1.0, 2.0], [1.5, 2.0], [0.5, 0.0], "an absolute bound per element")


def test_a_product_turns_n_ulps_into_at_most_2n_plus_1():
    """The rule the bounds of the tests are derived from, on random factors
    and values: the bound holds, and 2 n is reached (it is not loose)."""
    rng = np.random.default_rng(5)
    x = rng.uniform(1.0, 2.0, 200_000) * 2.0 ** rng.integers(-40, 40, 200_000)
    k = rng.uniform(1.0, 2.0, x.size) * 2.0 ** rng.integers(-20, 20, x.size)
    for n in (1, 2, 3):
        y = x + n * np.spacing(x)                      # n ulps above x
        a, b = k * x, k * y
        assert_within_ulps(a, b, after_product(n), f"{n} ulps times a number")
        worst = np.max(np.abs(a - b) / ulp(np.maximum(a, b)))
        assert worst >= 2 * n, worst
    assert after_product(1) == 3 and after_product(1, 2) == 7
