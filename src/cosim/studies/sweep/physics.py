"""What a sweep reads from a run's physics: the impact regime of CASES.md
section 5 (which way the striker goes by the end of its first contact).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["impact_regime"]


def impact_regime(summary: dict, series, contact: str = "C", joint: str = "robot/arm") -> dict:
    """The impact regime of CASES.md section 5, read from a run.

    A striker (the side whose ``joint`` drives the contact point) comes down
    on a structure.  What it does by the end of its *first* contact decides
    the regime, because that is where the mass ratio shows: a heavy structure
    throws the striker back within one contact, a light one is pushed ahead
    of it.

    - ``backward``: one contact, and the striker's rate at the release has
      the opposite sign to its rate at the touch (it turned back);
    - ``backward+``: it turned back within the first contact, as above, but
      the contact closes again: the structure, moving faster, catches it;
    - ``forward``: it is still moving on (rate of the same sign) when the
      first contact releases, so it strikes again: a train of contacts
      before it turns back.

    Parameters
    ----------
    summary : dict
        The run's ``summary.json``: the contact's ``intervals`` and ``count``.
    series : mapping
        The run's series: ``t`` and ``dq/JOINT``.
    contact : str
    joint : str
        ``SUBSYSTEM/JOINT`` of the striker.

    Returns
    -------
    dict
        ``regime`` (one of the three, or ``none`` when the contact never
        closed, ``open-ended`` when its first contact lasts to the end of the
        run), ``rate_at_touch`` and ``rate_at_release`` (the joint's rate at
        the first contact's touch and release) and ``exit_velocity`` (its rate
        at the last release, NaN if that is the end of the run).
    """
    from cosim.studies.metrics import exit_velocity

    c = summary["contacts"][contact]
    iv = c["intervals"]
    out = {"regime": "none", "rate_at_touch": math.nan, "rate_at_release": math.nan,
           "exit_velocity": math.nan}
    if not iv:
        return out
    t, dq = np.asarray(series["t"]), np.asarray(series[f"dq/{joint}"])
    (t_on, t_off), t_last = iv[0], iv[-1][1]
    out["rate_at_touch"] = exit_velocity(t, dq, t_on)
    if t_off >= t[-1]:
        out["regime"] = "open-ended"
        return out
    out["rate_at_release"] = exit_velocity(t, dq, t_off)
    if t_last < t[-1]:
        out["exit_velocity"] = exit_velocity(t, dq, t_last)
    turned = out["rate_at_touch"] * out["rate_at_release"] < 0
    out["regime"] = ("forward" if not turned else "backward" if len(iv) == 1 else "backward+")
    return out
