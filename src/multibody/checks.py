"""Parameter checks shared by the modules of :mod:`multibody`.

One place for the rules the bodies, joints, joint effects and impact laws
apply to their parameters, so that every model refuses the same values with
the same message (backticked name, rule, value received).  A ``bool`` is
never a number here: ``True`` would otherwise pass as 1.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["finite", "nonnegative", "vec2", "unit_interval"]


def finite(value, name: str) -> float:
    """Return ``value`` as a float if it is a finite int or float, else raise
    ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"`{name}` must be a finite number, got {value!r}")
    return float(value)


def nonnegative(value, name: str, unit: str) -> float:
    """Return ``value`` as a finite float >= 0 [``unit``], else raise ValueError."""
    v = finite(value, name)
    if v < 0:
        raise ValueError(f"`{name}` must be >= 0 {unit}, got {value!r}")
    return v


def vec2(value, name: str) -> tuple[float, float]:
    """Return two finite numbers [m] as a tuple of floats, else raise ValueError."""
    if isinstance(value, bool) or (isinstance(value, (list, tuple))
                                   and any(isinstance(x, bool) for x in value)):
        raise ValueError(f"`{name}` must be two finite numbers [m], got {value!r}")
    arr = np.asarray(value, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be two finite numbers [m], got {value!r}")
    return (float(arr[0]), float(arr[1]))


def unit_interval(e, name: str) -> float:
    """Return ``e`` as a float in [0, 1] (a coefficient of restitution), else
    raise ValueError."""
    x = math.nan if isinstance(e, bool) else float(e)
    if not 0.0 <= x <= 1.0:
        raise ValueError(f"`{name}` must be in [0, 1], got {e if isinstance(e, bool) else x:g}")
    return x
