"""What a user compares between two runs of one scene.

The impact scenes are judged by three numbers of a contact (CASES.md
sections 5-6): how many times it closes, its peak penetration, and the
velocity a joint leaves with at its last release.  :func:`impact_metrics`
reads them from a :class:`~cosim.core.result.SimulationResult`;
:func:`relative_errors` compares two such readings.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["exit_velocity", "impact_metrics", "relative_errors"]


def exit_velocity(t, dq, t_release: float) -> float:
    """A joint's rate at ``t_release``, linear between the samples around it.

    Parameters
    ----------
    t : (n,) array
        Sample times [s], increasing.
    dq : (n,) array
        The joint's rate at those times [rad/s or m/s].
    t_release : float
        The instant of the last release [s].

    Raises
    ------
    ValueError
        If ``t_release`` lies outside the samples.
    """
    t, dq = np.asarray(t, float), np.asarray(dq, float)
    if not t[0] <= t_release <= t[-1]:
        raise ValueError(f"`t_release` = {t_release!r} s lies outside the samples "
                         f"[{t[0]}, {t[-1]}] s")
    return float(np.interp(t_release, t, dq))


def impact_metrics(result, contact: str, joint: str) -> dict:
    """Contact count, peak penetration [m], and the exit velocity of ``joint``
    (``"SUBSYSTEM/JOINT"``) at the contact's last release.

    The exit velocity is NaN when the contact never closed or never released.
    """
    c = result.summary["contacts"][contact]
    out = {"count": int(c["count"]), "peak": float(c["peak_penetration"]),
           "exit_velocity": math.nan}
    if c["intervals"]:
        t_off = c["intervals"][-1][1]
        t = result.series["t"]
        if t_off < t[-1]:
            out["exit_velocity"] = exit_velocity(t, result.series[f"dq/{joint}"], t_off)
    return out


def relative_errors(run: dict, reference: dict) -> dict:
    """Errors of :func:`impact_metrics` ``run`` against ``reference``: the
    absolute difference in count, relative errors in peak and exit velocity."""
    def rel(k):
        return abs(run[k] - reference[k]) / abs(reference[k])
    return {"count": abs(run["count"] - reference["count"]), "peak": rel("peak"),
            "exit_velocity": rel("exit_velocity")}
