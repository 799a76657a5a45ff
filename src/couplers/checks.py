"""Parameter checks shared by the modules of :mod:`couplers`.

One place for the rules a law, a grasp or a friction model applies to its
parameters, so that every model refuses the same values with the same
message (backticked name, rule, value received).  A ``bool`` is never a
number here: ``True`` would otherwise pass as 1.
"""
from __future__ import annotations

import math

__all__ = ["positive"]


def positive(value, name: str, unit: str, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float > 0 (or >= 0 with ``allow_zero``).

    Parameters
    ----------
    value
        The parameter as given.
    name : str
        Its name, for the message.
    unit : str
        Its unit, for the message (e.g. ``"N/m"``).
    allow_zero : bool
        Accept 0.

    Raises
    ------
    TypeError
        If ``value`` is not a number (a ``bool`` included).
    ValueError
        If it is not finite or breaks the sign rule.
    """
    if isinstance(value, bool):
        raise TypeError(f"`{name}` must be a number [{unit}], got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a number [{unit}], got {value!r}") from None
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        rule = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"`{name}` must be {rule} {unit}, got {value!r}")
    return v
