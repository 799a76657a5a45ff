"""The order a run's error falls with, measured on the run's own ladder of steps.

A quantity ``Q`` computed at three steps ``h0 < h1 < h2`` in a geometric
ladder (``h1 = r h0``, ``h2 = r h1``) shows the order its error falls with
where the error is one power of the step (``Q_h = Q* + C h**p``)::

    p = log(|Q2 - Q1| / |Q1 - Q0|) / log(r)

:func:`observed_order` measures it and says whether it is *confirmed*: the
two differences of one sign (the three values monotone, as one power of the
step makes them), both above round-off (:data:`ROUNDOFF`) and ``p`` within
:data:`ORDER_BAND`.  Where it is, :func:`judge` gives the run's error by
Richardson's extrapolation with that ``p``: with ``Q* = Q0 - (Q1 - Q0) /
(r**p - 1)``, the run's error is ``|Q_run - Q*|`` (for the run at ``h1``,
``|Q1 - Q0| r**p / (r**p - 1)``; at ``h0``, ``|Q1 - Q0| / (r**p - 1)``).
Where the three are monotone but ``p`` lies above the band (the coarser
difference grows faster than any order the schemes have: the coarser
companion is past the range where the error is one power of the step), the
run's error is bounded from the finer pair alone at order 1, ``|Q_h -
Q_(h/r)| r / (r - 1)`` (the run's error at order 1; above it at any order
from 1 up, and within 3x of it up to order 5.5).  Otherwise, where the order
is not confirmed, :func:`judge` gives a bound at order 1 (:func:`bound`):
the difference between the run and its coarser companion times ``r / (r -
1)`` (the error at order 1 of the coarser of the two), or between the run
and its finer companion times ``(2 r - 1) / (r - 1)``, whichever is larger;
each is no smaller than the run's error wherever the error falls at least
as fast as the step to the power 0.74 (r = sqrt(2)) between the two runs.  The fitted orders of
:data:`cosim.studies.estimate.ORDERS` are a prior, never the answer.
"""
from __future__ import annotations

import math

__all__ = ["ORDER_BAND", "ROUNDOFF", "observed_order", "bound", "richardson", "judge"]

#: the orders accepted as measured: a slope below 0.5 or above 5 says the
#: three steps are not in the range where the error is one power of the step
#: (a difference dominated by another term, by a discrete event, or by noise).
#: 5 is one above the highest order of any step cosim's errors scale with
#: (RK4's 4; the coupling's extrapolation of order k gives k + 1 <= 3; the
#: structures' modal steps are exact, and DOP853, RK45, Radau and BDF follow
#: their tolerance, not the step): a steeper slope is two error terms
#: cancelling, as on three_mass f1, where three runs confirmed 6.2 on A's
#: peak while the monolithic reference measures 2.5 (`cosim verify
#: three_mass`)
ORDER_BAND = (0.5, 5.0)

#: a difference below this fraction of the quantity's size is round-off
#: (the integrators' tolerances, the float sums over a run): too small to
#: measure an order from
ROUNDOFF = 1e-10


def observed_order(values, r: float) -> tuple[float | None, str]:
    """The order measured from ``values`` = (Q at h0, h1, h2), ``h`` in a
    geometric ladder of ratio ``r`` > 1, finest first: ``(p, "")`` where it
    is confirmed, else ``(p or None, why)``."""
    q0, q1, q2 = (float(v) for v in values)
    d1, d2 = q1 - q0, q2 - q1
    size = max(abs(q0), abs(q1), abs(q2))
    if max(abs(d1), abs(d2)) <= ROUNDOFF * size:
        return None, "the three runs differ by round-off alone"
    if min(abs(d1), abs(d2)) <= ROUNDOFF * size:
        return None, ("one of the two differences is round-off: the three runs do not "
                      "show one power of the step")
    p = math.log(abs(d2) / abs(d1)) / math.log(r)
    if (d1 > 0) != (d2 > 0):
        return p, ("the three runs are not monotone in the step (the error is not one "
                   "power of it there)")
    lo, hi = ORDER_BAND
    if not lo <= p <= hi:
        return p, f"the measured order {p:.2g} lies outside [{lo:g}, {hi:g}]"
    return p, ""


def richardson(values, r: float, p: float, run: int) -> float:
    """The error of ``values[run]`` (0: the finest of the ladder, 1: the
    middle one) at order ``p``: its distance to the extrapolated value."""
    q0, q1 = float(values[0]), float(values[1])
    extrapolated = q0 - (q1 - q0) / (r ** p - 1.0)
    return abs(float(values[run]) - extrapolated)


def bound(value: float, finer: float | None, coarser: float | None, r: float) -> float:
    """The bound at order 1 of the run's error from its companions (either
    may be None): the largest of ``|Q_h - Q_(r h)| r / (r - 1)`` and
    ``|Q_h - Q_(h/r)| (2 r - 1) / (r - 1)``.

    The first is the error of the coarser companion at order 1; both are
    the run's error at the order ``q = log((2 r - 1) / r) / log(r)`` (0.74
    at r = sqrt(2), 0.58 at 2), so that either bounds it wherever the error
    falls between the two runs at least as fast as the step to that power
    (at order 1 they are ``r`` and ``(2 r - 1) / r`` times the error)."""
    out = []
    if coarser is not None:
        out.append(abs(value - coarser) * r / (r - 1.0))
    if finer is not None:
        out.append(abs(value - finer) * (2.0 * r - 1.0) / (r - 1.0))
    return max(out)


def judge(value: float, finer: float | None, coarser: float | None, r: float) -> dict:
    """The run's error estimate from its companions: ``finer`` at ``h/r``,
    ``coarser`` at ``r h`` (either may be None: not run, or not to be read).

    Returns
    -------
    dict
        ``kind`` (``"richardson"`` where the order is confirmed on the
        three runs, ``"bound"`` where it is not, or with two runs), ``order``
        (the measured order, or None), ``estimate`` (absolute), and
        ``order_why`` (why the order was not confirmed; absent where it was).
    """
    out: dict = {"order": None}
    if finer is not None and coarser is not None:
        values = (finer, value, coarser)
        p, why = observed_order(values, r)
        out["order"] = p
        if not why:
            out.update(kind="richardson", estimate=richardson(values, r, p, 1))
            return out
        out["order_why"] = why
        lo, hi = ORDER_BAND
        if p is not None and p > hi and (finer - value > 0) == (value - coarser > 0):
            # monotone, but the coarser difference grows faster than any order
            # the schemes have: the coarser companion is past the range where
            # the error is one power of the step; the finer pair at order 1
            out["order_why"] = (f"{why}: the coarser companion lies past the range where "
                                f"the error is one power of the step; the bound is the "
                                f"finer one's at order 1")
            out.update(kind="bound", estimate=abs(value - finer) * r / (r - 1.0))
            return out
    else:
        out["order_why"] = ("one companion alone: two runs do not tell an order"
                            if finer is not None or coarser is not None else "no companion")
    if finer is None and coarser is None:
        out.update(kind=None, estimate=None)
        return out
    out.update(kind="bound", estimate=bound(value, finer, coarser, r))
    return out
