"""Bounds in ulps: how far apart two computations of one quantity may be.

Two different computations of the same formula (a scalar ``x ** n`` and
numpy's array power, compiled code and the numpy reference) need not agree
bit for bit: numpy's AVX-512 power differs from the C library's ``pow`` by
an ulp for some arguments, and a C compiler may contract ``a * b + c`` into
one fused multiply-add.  A test of such a pair bounds the difference in ulps
and says where the bound comes from; bit identity is asserted only for the
same computation run twice (determinism).

The rules the bounds are derived from (``u = 2**-53``, round to nearest):

* a faithful function (``pow``: within one ulp of the exact value) returns
  one of the two floats around the exact value, so two faithful results
  differ by at most **1 ulp**;
* multiplying or dividing two results that differ by ``n`` ulps by the same
  number gives results at most ``2 n + 1`` ulps apart: the exact products
  are at most ``2 n`` ulps of the result apart (an ulp is between ``u`` and
  ``2 u`` times the value, so the count can double), and the two roundings
  add at most half an ulp each (:func:`after_product`);
* +, -, *, / and sqrt are correctly rounded on every IEEE 754 machine: the
  same operations on the same operands in the same order give the same bits
  everywhere (unless a compiler fuses them: see setup.py).
"""
from __future__ import annotations

import numpy as np

__all__ = ["ulp", "after_product", "assert_within", "assert_within_ulps"]


def ulp(x) -> np.ndarray:
    """The spacing of the floats at ``|x|`` (elementwise; 5e-324 at 0)."""
    return np.spacing(np.abs(np.asarray(x, dtype=float)))


def after_product(n: float, times: int = 1) -> float:
    """The ulps two results ``n`` ulps apart can be apart after ``times``
    products (or quotients) by the same number: ``n -> 2 n + 1`` each."""
    for _ in range(times):
        n = 2 * n + 1
    return n


def assert_within(a, b, bound, why: str) -> None:
    """Assert ``|a - b| <= bound`` elementwise (equal infinities and NaNs
    pass); the message names the worst element and ``why`` the bound holds."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    bound = np.broadcast_to(np.asarray(bound, dtype=float), a.shape)
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    with np.errstate(invalid="ignore"):
        excess = np.where(same, 0.0, np.abs(a - b) - bound)
    excess = np.where(np.isnan(excess), np.inf, excess)
    if np.any(excess > 0):
        i = np.unravel_index(int(np.argmax(excess)), a.shape)
        raise AssertionError(
            f"{np.count_nonzero(excess > 0)} of {a.size} differ by more than the bound: "
            f"worst at {i if a.ndim else ()}: {a[i]!r} vs {b[i]!r}, "
            f"|difference| {abs(a[i] - b[i]):.3g} > {bound[i]:.3g} ({why})")


def assert_within_ulps(a, b, n, why: str, *, of=None) -> None:
    """Assert that ``a`` and ``b`` are at most ``n`` ulps apart, the ulp
    taken of ``of`` (default: the larger of ``|a|`` and ``|b|``)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    scale = np.maximum(np.abs(a), np.abs(b)) if of is None else of
    assert_within(a, b, n * ulp(scale), f"{n} ulps: {why}")
