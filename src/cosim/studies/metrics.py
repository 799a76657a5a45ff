"""What a user compares between two runs of one scene.

The impact scenes are judged by three numbers of a contact (CASES.md
sections 5-6): how many times it closes, its peak penetration, and the
velocity a joint leaves with at its last release.  :func:`impact_metrics`
reads them from a :class:`~cosim.core.result.SimulationResult`;
:func:`relative_errors` compares two such readings.  :func:`impact_regime`
tells which way the striker went by the end of its first contact (CASES.md
section 5), from a run's summary and series as a sweep keeps them.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["exit_velocity", "impact_regime", "impact_metrics", "relative_errors"]


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


def _impact_at(summary: dict, series, contact: str, joint: str, at: float) -> dict | None:
    """The rigid impact of ``contact`` at the instant ``at`` that jumped the
    rates of ``joint``'s side (the run's record of it, with ``dq_before`` and
    ``dq_after``), or None.

    A rigid impact jumps the rates within an instant, which a series sampled
    at macro steps straddles: a rate read there by interpolation would mix
    the rates before and after.  The run records both (``summary["impacts"]``)."""
    sub, name = joint.split("/", 1)
    own = {k.split("/", 2)[2] for k in series.keys() if k.startswith(f"dq/{sub}/")}
    for hit in reversed(summary.get("impacts") or ()):
        if hit["contact"] == contact and math.isclose(hit["time"], at, rel_tol=1e-12) \
                and name in hit["dq_after"] and set(hit["dq_after"]) == own:
            return hit
    return None


def _rate(summary: dict, series, contact: str, joint: str, at: float, when: str) -> float:
    """``joint``'s rate at ``at``: the rigid impact's rate ``when``
    (``before`` or ``after``) where ``contact`` has one at that instant
    (:func:`_impact_at`), else :func:`exit_velocity`'s reading."""
    hit = _impact_at(summary, series, contact, joint, at)
    if hit is not None:
        return float(hit[f"dq_{when}"][joint.split("/", 1)[1]])
    return exit_velocity(series["t"], series[f"dq/{joint}"], at)


def impact_regime(summary: dict, series, contact: str, joint: str) -> dict:
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
        The contact struck (a key of ``summary["contacts"]``).
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
    c = summary["contacts"][contact]
    iv = c["intervals"]
    out = {"regime": "none", "rate_at_touch": math.nan, "rate_at_release": math.nan,
           "exit_velocity": math.nan}
    if not iv:
        return out
    t = np.asarray(series["t"])
    (t_on, t_off), t_last = iv[0], iv[-1][1]
    out["rate_at_touch"] = _rate(summary, series, contact, joint, t_on, "before")
    if t_off >= t[-1]:
        out["regime"] = "open-ended"
        return out
    out["rate_at_release"] = _rate(summary, series, contact, joint, t_off, "after")
    if t_last < t[-1]:
        out["exit_velocity"] = _rate(summary, series, contact, joint, t_last, "after")
    turned = out["rate_at_touch"] * out["rate_at_release"] < 0
    out["regime"] = ("forward" if not turned else "backward" if len(iv) == 1 else "backward+")
    return out


def impact_metrics(result, contact: str, joint: str) -> dict:
    """Contact count, peak penetration [m], and the exit velocity of ``joint``
    (``"SUBSYSTEM/JOINT"``) at the contact's last release: where that release
    is a rigid impact's instant, the rate the impact left (its record's
    ``dq_after``), not a reading across the jump.

    The exit velocity is NaN when the contact never closed or never released.
    """
    c = result.summary["contacts"][contact]
    out = {"count": int(c["count"]), "peak": float(c["peak_penetration"]),
           "exit_velocity": math.nan}
    if c["intervals"]:
        t_off = c["intervals"][-1][1]
        t = result.series["t"]
        if t_off < t[-1]:
            out["exit_velocity"] = _rate(result.summary, result.series, contact, joint, t_off,
                                         "after")
    return out


def relative_errors(run: dict, reference: dict) -> dict:
    """Errors of :func:`impact_metrics` ``run`` against ``reference``: the
    absolute difference in count, relative errors in peak and exit velocity.

    A quantity whose reference is zero (a rigid contact's peak penetration)
    has no relative error: its error is 0 where the run's is zero too, else
    NaN (not a number: no error to compare, never "within" a tolerance)."""
    def rel(k):
        if reference[k] == 0:
            return 0.0 if run[k] == 0 else math.nan
        return abs(run[k] - reference[k]) / abs(reference[k])
    return {"count": abs(run["count"] - reference["count"]), "peak": rel("peak"),
            "exit_velocity": rel("exit_velocity")}
