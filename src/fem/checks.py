"""Parameter checks shared by the modules of :mod:`fem`.

One place for the rules the structural models and integrators apply to their
parameters, so that every model refuses the same values with the same
message (backticked name, rule, value received).  A ``bool`` is never a
number here: ``True`` would otherwise pass as 1.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["positive", "count", "vector", "choice", "real"]


def positive(value, name: str, unit: str, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float > 0 (or >= 0), else raise."""
    if isinstance(value, bool):
        raise TypeError(f"`{name}` must be a number [{unit}], got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a number [{unit}], got {value!r}") from None
    ok = math.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        rule = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"`{name}` must be {rule} {unit}, got {value!r}")
    return v


def count(value, name: str, minimum: int = 1) -> int:
    """Return ``value`` as an int >= ``minimum``, else raise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"`{name}` must be an integer >= {minimum}, got {value!r}")
    if value < minimum:
        raise ValueError(f"`{name}` must be an integer >= {minimum}, got {value!r}")
    return int(value)


def vector(value, name: str, unit: bool) -> tuple[float, float]:
    """Return a finite 2-vector as a tuple; normalised when ``unit``.  A ``bool``
    is not a number here."""
    if isinstance(value, bool) or (isinstance(value, (list, tuple))
                                   and any(isinstance(x, bool) for x in value)):
        raise TypeError(f"`{name}` must be a 2-vector of numbers, got {value!r}")
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a 2-vector, got {value!r}") from None
    if v.shape != (2,) or not np.all(np.isfinite(v)):
        raise ValueError(f"`{name}` must be a finite 2-vector, got {value!r}")
    if unit:
        n = float(np.hypot(v[0], v[1]))
        if n == 0.0:
            raise ValueError(f"`{name}` must be a non-zero 2-vector, got {value!r}")
        v = v / n
    return (float(v[0]), float(v[1]))


def choice(value, name: str, allowed) -> str:
    """Return ``value`` if it is one of ``allowed``, else raise ValueError listing them."""
    if value not in allowed:
        valid = ", ".join(repr(a) for a in sorted(allowed))
        raise ValueError(f"`{name}` must be one of {valid}, got {value!r}")
    return value


def real(name, value, lo=-math.inf, hi=math.inf, rule=""):
    """``float(value)``; ValueError unless a finite real in ``[lo, hi]`` (``rule``)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not math.isfinite(value):
        raise ValueError(f"`{name}` must be a finite real number, got {value!r}")
    if not lo <= value <= hi:
        raise ValueError(f"`{name}` must be {rule}, got {value!r}")
    return float(value)
