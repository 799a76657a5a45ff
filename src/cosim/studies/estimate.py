"""An estimate of a finished run's error, from one coarser companion run.

:func:`estimate_errors` runs the same scene and scheme again with the steps
that set its accuracy made ``factor`` times longer (the *companion*), and
turns the difference of each quantity into a Richardson estimate of the
run's own error::

    err(Q_h) ~ |Q_h - Q_rh| / (r**p - 1)

with ``r`` the factor and ``p`` the scheme's observed order (:data:`ORDERS`,
one for a contact's quantities, one for the exit rates), or, for a contact a
side's own RK4 step integrates against a rigid partner (and the exit rates
read at its release), that step's (:data:`HOSTED_ORDERS`).

Which steps (:func:`cosim.studies.companion.coarsened`): a co-simulation
scheme's ``macro_step`` and, where the scene gives one, its
``contact_step`` (the step while a contact is closed), both times ``r``;
under interface error control (``interface_tolerance``), the tolerance times
``r ** (extrapolation_order + 2)``, so that the controlled step is ``r``
times longer too.  The ``approach_horizon`` (how far ahead a predicted
onset shortens the step) stays the run's: the window before an onset is
stepped at ``r`` times the contact step, in ``r`` times fewer steps (with a
horizon ``r`` times longer too, the companion of three_mass f100 took more
approach steps than the run).  The number of ``substeps`` stays (each is
``r`` times longer).  A side's own step (a multibody side's ``rk4``
``max_step`` and ``free_step``, a structure's ``contact_step``) is ``r``
times longer too, unless that would take a contact it hosts past omega h =
:data:`~cosim.studies.companion.OMEGA_H_MAX`: such a step is set by the
contact's stability, not by accuracy (three_mass's robot, at 0.3, fails at
3x its step); it stays, and an error that comes from it is not seen.  The
monolithic scheme gets no companion (:data:`MONOLITHIC`): its cost hardly
falls with a coarser tolerance.

Which factor (:func:`cosim.studies.companion.fitting_factor`): ``r`` = 4,
shortened (not below 2) where the companion's step in a contact the sides
exchange would pass omega h =
:data:`~cosim.studies.companion.ASYMPTOTIC_OMEGA_H`, past which the
schemes' errors stop falling as one power of the step; a contact past it
even at 2x (three_mass f100 at its 30 us) is not estimated, nor are the exit
rates read at its release.  Where that leaves nothing to read (every contact
that closed past the range, or stepped by a side that keeps its step), no
companion runs (:data:`BLIND`).

The order: ``p`` is measured once per scheme (:data:`ORDERS`, with where),
not on every run.  Measuring it on every run needs a third run at ``r**2``
whose cost, added to the companion's, passes 30 % of the run at r = 4
(1/4 + 1/16 of its steps), and whose step lies 16 times past the run's, far
outside the range where the error is one power of the step.  A scheme
without a measured order gives differences, no estimate.

Cost: the companion takes about ``1/r`` of the run's macro steps where free
flight and contact are both stepped at the scheme's steps (spring_drop,
ground_multicontact: 1/4); step control adds steps aimed at each onset that
do not scale with ``r`` (three_mass f10: 0.27 of the run's macro steps).
A side's steps shrink with ``r`` only where its step is coarsened.  Both
shares are in the summary's ``work_share``.

What is estimated: per contact, ``peak_penetration``, ``impulse``, the
first interval's ``t_on`` and ``t_off``, and ``count`` (robust when both runs
agree); the exit state: each multibody joint's rate at the last release of
the last contact that releases (:func:`cosim.studies.metrics.exit_velocity`),
or its final rate when no contact releases.

Honest where it cannot: a quantity is ``reliable: false`` with a ``why``
when the companion stopped or failed, when the two runs disagree on a
contact's count (that contact's quantities and the exit state), when the
contact's step lies past the asymptotic range, when a side that keeps its
step in the companion resolves the contact coarsely, when the
scheme's order was not measured or the scheme is monolithic, or when the
estimate exceeds the quantity itself; its ``relative_error`` is then None
and ``difference`` keeps ``|Q_h - Q_rh|``.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from cosim.studies.companion import (ASYMPTOTIC_OMEGA_H, OMEGA_H_MAX, UNSEEN_OMEGA_H, built,
                                     coarsened, exchanged_omega_h, fitting_factor)

__all__ = ["ORDERS", "HOSTED_ORDERS", "DEFAULT_FACTOR", "BLIND", "coarsened", "estimate_errors",
           "accuracy_text", "counted_share"]

#: the factor by which the companion's steps are longer than the run's
DEFAULT_FACTOR = 4

#: observed orders of the schemes where their errors fall as one power of
#: the step, for a contact's quantities and for the exit rates, and where
#: they were measured: the median slope of ``log(error)`` against
#: ``log(omega h)`` between neighbouring points at omega h = 0.1, 0.2 and 0.4
#: (:data:`~cosim.studies.companion.ASYMPTOTIC_OMEGA_H`) of C's peak
#: penetration and the arm's exit velocity against the bench's monolithic
#: reference, on three_mass f1 to f1000 and beam_impact
#: (``benchmarks/results/accuracy_model``).  Gauss-Seidel's peak slopes lie
#: in 2.0-4.1, its exit slopes in 1.5-3.5, Jacobi's in 2.0-2.7 and 0.8-4.4.
#: The implicit scheme's peak error sits at its floor (2e-7) there: its
#: contact order is the slope of three_mass f100's peak between contact
#: steps 4e-5 and 1.6e-4 s; its exit slopes scatter from 0 to 5.2.
ORDERS = {
    "gauss_seidel": {"contacts": 2.9, "exit": 2.6},
    "jacobi": {"contacts": 2.1, "exit": 1.9},
    "implicit": {"contacts": 4.2, "exit": 2.6},
}
#: the orders where a side's own RK4 step integrates the contact against a
#: rigid partner (whatever the scheme), from the same run's ``host_rk4``
#: fit (spring_drop, ground_multicontact): the peak error falls as RK4's,
#: ``(omega h)**4.62``; the exit rate's, read linearly between the samples
#: around the release, as ``(omega h)**1.84`` (its sampling)
HOSTED_ORDERS = {"contacts": 4.6, "exit": 1.8}
ORDER_SOURCE = ("benchmarks/results/accuracy_model: median slopes of C's peak and the arm's "
                "exit velocity at omega h 0.1 to 0.4, three_mass f1-f1000 and beam_impact")

#: why the monolithic scheme gets no companion: its cost hardly depends on
#: the tolerance (three_mass f100: 0.24 s of CPU at rtol 1e-5, 0.23 s at
#: 1e-9; locating every switch and the output samples make most of it), so a
#: companion at a coarser tolerance would cost about as much as the run
MONOLITHIC = ("not estimated for the monolithic scheme: a coarser tolerance saves its "
              "solver little, so a companion would cost about as much as the run")

#: per contact, the summary's quantities that are estimated
_CONTACT_QUANTITIES = ("peak_penetration", "impulse", "t_on", "t_off")


def _order(scheme: str) -> dict:
    return ORDERS.get(scheme, {"contacts": None, "exit": None})


def _first(c: dict, i: int) -> float:
    return float(c["intervals"][0][i]) if c["intervals"] else math.nan


def _contact_values(summary: dict) -> dict:
    out = {}
    for name, c in summary["contacts"].items():
        out[name] = {"count": int(c["count"]),
                     "peak_penetration": float(c["peak_penetration"]),
                     "impulse": float(c["impulse"]), "t_on": _first(c, 0),
                     "t_off": _first(c, 1)}
    return out


#: where the exit rates are read when no contact releases
END = "end of the run"


def exit_rates(result, multibody, contact: str | None = None) -> tuple[dict, str]:
    """Each multibody joint's rate at the last release of ``contact`` (the
    strike the bench reads, :func:`cosim.studies.strike.find_strike`), or,
    without one, of the last contact that releases (``SUBSYSTEM/JOINT`` ->
    [rad/s or m/s]), and what that instant is (``"release of C at T s"`` or
    ``"end of the run"``); ``multibody``: the names of the multibody
    subsystems."""
    t = result.series["t"]
    last = None
    for name, c in result.summary["contacts"].items():
        if contact is not None and name != contact:
            continue
        if c["intervals"] and c["intervals"][-1][1] < t[-1]:
            t_off = float(c["intervals"][-1][1])
            if last is None or t_off > last[1]:
                last = (name, t_off)
    rates = {}
    for key in result.series:
        if not key.startswith("dq/"):
            continue
        name = key[3:]
        if name.split("/", 1)[0] not in multibody:
            continue
        dq = result.series[key]
        # linear between the samples around it, as cosim.studies.metrics.exit_velocity
        # (not imported: every run would load the bench's module)
        rates[name] = (float(np.interp(last[1], t, dq)) if last is not None
                       else float(dq[-1]))
    when = f"release of {last[0]} at {last[1]:.6g} s" if last is not None else END
    return rates, when


def _judge(value, other, r, p, why=None) -> dict:
    """One quantity: its value, the companion's, and the estimate."""
    def finite(x):                       # summary.json holds no NaN
        return x if math.isfinite(x) else None
    out = {"value": finite(value), "companion": finite(other), "difference": None,
           "relative_error": None, "reliable": False}
    if not (math.isfinite(value) and math.isfinite(other)):
        out["why"] = why or "not defined in both runs"
        return out
    diff = abs(value - other)
    out["difference"] = diff
    if why is not None:
        out["why"] = why
        return out
    if value == 0.0 == other:            # at rest in both (a joint that never moved)
        out.update(relative_error=0.0, reliable=True)
        return out
    if p is None:
        out["why"] = "the scheme's order is not measured"
        return out
    est = diff / (r ** p - 1.0)
    if value == 0.0:
        out["why"] = "the quantity is zero in the run, not in the companion"
        return out
    rel = est / abs(value)
    if rel > 1.0:
        out["why"] = "the estimate is larger than the quantity"
        return out
    out.update(relative_error=rel, reliable=True)
    return out


#: why no companion runs where nothing it gives could be read
BLIND = ("no companion: every contact that closed (the strike among them) lies past the "
         "asymptotic range at the companion's step, or is stepped by a side that keeps its "
         "step in it, so nothing it gives could be read")


def _blind(result, strike, beyond: dict, kept: list) -> bool:
    """Whether every contact that closed, and the strike whose release the
    exit rates are read at, is past the asymptotic range or unseen: a
    companion would be run for nothing."""
    closed = {n for n, c in result.summary["contacts"].items() if c["count"] > 0}
    blind = set(beyond) | {c for c, _ in kept}
    return bool(closed) and closed <= blind and (strike is None or strike in blind)


def counted_share(result, companion) -> float:
    """The companion's macro steps (with their iterations, if the scheme
    iterates) over the run's: the counted share of its work."""
    def work(res):
        return max(res.n_windows, 1) + res.n_iterations
    return work(companion) / work(result)


def _embedded(scene) -> dict:
    """Embedded contact -> (the side whose integrator evaluates it: its
    ``host``, or the side that is not rigid; whether its partner is rigid)."""
    kinds = {s.name: s.type for s in scene.subsystems}
    out = {}
    for c in scene.contacts:
        if c.placement != "embedded":
            continue
        sides = (c.a[0], c.b[0])
        out[c.name] = (c.host or next((n for n in sides if kinds[n] != "rigid"), None),
                       any(kinds[n] == "rigid" for n in sides))
    return out


def estimate_errors(scene, result, factor: float = DEFAULT_FACTOR,
                    contact: str | None = None) -> dict:
    """Estimate the errors of ``result``, a finished run of ``scene``.

    Parameters
    ----------
    scene : Scene
        The scene as run (:func:`cosim.scene.load.load_scene`).
    result : SimulationResult
        The run's result (its ``series`` are read).
    factor : float
        How many times longer the companion's steps are (> 1).
    contact : str, optional
        The contact at whose last release the exit rates are read (default:
        the scene's strike, :func:`cosim.studies.strike.find_strike`, else
        the contact that releases last).

    Returns
    -------
    dict
        The summary's ``accuracy``: ``reliable`` (every quantity is),
        ``method``, ``factor``, ``order`` and ``order_source``,
        ``coarsened`` (key path -> value in the companion), ``companion``
        (``status``, ``message``, ``macro_steps``, ``cpu_time_s``),
        ``work_share`` (``macro_steps``: :func:`counted_share`;
        ``integrator_steps``: the ratio of the integrator steps counted
        before the two runs, :meth:`~cosim.Scene.work`, upper bounds), ``contacts`` (name ->
        ``count`` {``value``, ``companion``, ``robust``} and one entry per
        quantity), ``exit`` (``at``, and ``SUBSYSTEM/JOINT`` -> entry) and
        ``why`` (what made the summary unreliable).  An entry holds
        ``value``, ``companion``, ``difference`` (absolute), ``reliable``,
        and ``relative_error`` (the estimate over the value) or ``why``.
    """
    from cosim.scene import run

    if contact is None:
        from cosim.studies.strike import find_strike
        found = find_strike(scene, required=False)
        contact = found[0] if found else None
    order = _order(scene.scheme)
    acc = {"reliable": False, "method": "richardson", "factor": factor, "order": order,
           "order_source": ORDER_SOURCE if scene.scheme in ORDERS else "",
           "coarsened": {}, "companion": {}, "work_share": None,
           "contacts": {}, "exit": {}, "why": []}
    comp = None
    kept: list = []                   # contacts the companion cannot see (coarsened fills it)
    beyond: dict = {}                 # exchanged contacts past the asymptotic range
    blind = False                     # no companion: nothing it gives could be read
    if scene.scheme == "monolithic":
        acc["companion"] = {"status": "not run", "message": MONOLITHIC}
        acc["why"].append(MONOLITHIC)
    else:
        try:
            system = built(scene)
            factor, beyond = fitting_factor(factor, exchanged_omega_h(scene, system))
            acc["factor"] = factor
            comp_scene, acc["coarsened"] = coarsened(scene, factor, kept, system)
            blind = _blind(result, contact, beyond, kept)
            if blind:
                acc["companion"] = {"status": "not run", "message": BLIND}
            else:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    comp = run.simulate(comp_scene)
        except Exception as exc:   # a refused or broken companion: no estimate, said why
            from cosim.errors import UnsafeStepError
            acc["companion"] = {"status": "refused", "message": f"{type(exc).__name__}: {exc}"}
            acc["why"].append(
                f"the pre-flight check refuses {factor:g}x the step as unstable"
                if isinstance(exc, UnsafeStepError) else
                f"the companion did not run ({type(exc).__name__})")
    if comp is not None:
        acc["companion"] = {"status": comp.status, "message": comp.message,
                            "macro_steps": comp.n_windows,
                            "cpu_time_s": comp.summary["cpu_time_s"]}
        acc["work_share"] = {"macro_steps": counted_share(result, comp),
                             "integrator_steps": comp_scene.work().steps / scene.work().steps}
        if not comp.success:         # the guard's reason (energy growth, chatter), short
            reason = comp.message.split(": ", 1)[-1].split(";")[0].split(" (")[0]
            acc["why"].append(f"the companion {comp.status}: {reason}"[:160])
    # what a side whose step stayed integrates: the companion does not see its error
    embedded = _embedded(scene)
    hosts = {c: host for c, (host, _) in embedded.items()}
    unseen = {c: (f"`{hosts.get(c)}` steps contact {c} at the same step in the companion "
                  f"({factor:g}x "
                  f"would take a contact it hosts past omega h = {OMEGA_H_MAX}), and that step "
                  f"resolves {c} coarsely (omega h > {UNSEEN_OMEGA_H}): its error is not seen"
                  if math.isfinite(wh) else
                  f"`{hosts.get(c)}` keeps its step in the companion, as {c}'s law has no "
                  f"linear stiffness to tell the omega h of a longer one: {c}'s error is not "
                  f"seen") for c, wh in kept}
    unseen.update({c: f"a companion at {factor:g}x the run's step would step contact {c} at "
                      f"omega h = {wh:.2g}, past {ASYMPTOTIC_OMEGA_H}, where the scheme's error "
                      f"stops falling as one power of the step: the two runs' difference would "
                      f"not tell the run's error" for c, wh in beyond.items()})
    hosted = ({c for c, (_, rigid) in embedded.items() if rigid}
              if order["contacts"] is not None else set())

    def orders(c):                   # the contact's (the exit's: at its release)
        return HOSTED_ORDERS if c in hosted else order
    if hosted:
        acc["order_hosted"] = HOSTED_ORDERS
    mine = _contact_values(result.summary)
    theirs = _contact_values(comp.summary) if comp is not None and comp.success else {}
    stopped = None if theirs or blind else (
        acc["why"][0] if acc["why"] else "the companion did not finish")
    differ = []
    for name, v in mine.items():
        o = theirs.get(name, {})
        count = {"value": v["count"], "companion": o.get("count"),
                 "robust": o.get("count") == v["count"] if theirs else None}
        entry = {"count": count}
        why = stopped
        if why is None and count["robust"] is False:
            why = f"contact {name} closed {v['count']} times, {o.get('count')} in the companion"
            differ.append(why)
        why = why or unseen.get(name)
        for q in _CONTACT_QUANTITIES:
            entry[q] = _judge(v[q], o.get(q, math.nan), factor, orders(name)["contacts"],
                              why)
        acc["contacts"][name] = entry
    from cosim.scene.specs import MultibodySpec
    multibody = {s.name for s in scene.subsystems if isinstance(s, MultibodySpec)}
    rates, at = exit_rates(result, multibody, contact)
    acc["exit"]["at"] = at
    crates, elsewhere = {}, None
    if theirs:
        crates, cat = exit_rates(comp, multibody, contact)
        if (cat == END) != (at == END):      # one run's contact is still closed at the end
            elsewhere = f"the companion reads the exit rates at {cat}, the run at {at}"
    for joint, value in rates.items():
        why = (stopped or (differ[0] if differ else None) or elsewhere
               or unseen.get(contact) or (BLIND if blind else None))
        acc["exit"][joint] = _judge(value, crates.get(joint, math.nan), factor,
                                    orders(contact)["exit"], why)
    acc["why"] += differ
    entries = [e for c in acc["contacts"].values() for k, e in c.items() if k != "count"
               if c["count"]["value"] > 0] + [e for k, e in acc["exit"].items() if k != "at"]
    for e in entries:
        if not e["reliable"] and e.get("why") and e["why"] not in acc["why"]:
            acc["why"].append(e["why"])
    acc["reliable"] = (not acc["why"] and all(e["reliable"] for e in entries)
                       and all(c["count"]["robust"] for c in acc["contacts"].values()))
    return acc


def _pct(x: float) -> str:
    """A relative error in percent; below 1e-8 (round-off) as such."""
    return "< 1e-6 %" if x < 1e-8 else f"{100 * x:.2g} %"


def accuracy_text(acc: dict) -> str:
    """The terminal's line: the estimates that are reliable, no number for
    one that is not, and why (the first reason, the rest in summary.json)."""
    steps = ", ".join(f"{k.rsplit('.', 1)[-1]} {v:.3g}" for k, v in acc["coarsened"].items()
                      if not k.endswith(".approach_horizon"))      # kept, not coarsened
    head = f"accuracy (companion at {acc['factor']:g}x the step: {steps})"
    if acc["companion"].get("message") == BLIND:
        why = [w for w in acc["why"] if w != BLIND] or [BLIND]
        more = f"; {len(why) - 1} more in summary.json" if len(why) > 1 else ""
        return f"accuracy: not reliable, no companion run ({why[0]}{more})"
    if acc["companion"].get("status") == "not run":
        return f"accuracy: {acc['companion']['message']}"
    parts, missing = [], []
    for name, c in acc["contacts"].items():
        if c["count"]["value"] == 0:
            continue
        pk, im = c["peak_penetration"], c["impulse"]
        if pk["reliable"] and im["reliable"]:
            parts.append(f"{name} peak {_pct(pk['relative_error'])}, "
                         f"impulse {_pct(im['relative_error'])}")
        else:
            missing.append(name)
    exits = [(k, e) for k, e in acc["exit"].items() if k != "at" and e["reliable"]]
    if exits:
        k, e = max(exits, key=lambda ke: ke[1]["relative_error"])
        parts.append(f"exit {k} {_pct(e['relative_error'])}" + (
            f" (worst of {len(exits)} joints)" if len(exits) > 1 else ""))
    elif any(k != "at" for k in acc["exit"]):
        missing.append("exit")
    why = "; ".join(acc["why"]) or "see summary.json"
    if not parts:
        return f"accuracy: not reliable ({why})"
    if acc["reliable"]:
        return f"{head}: {'; '.join(parts)}; counts robust"
    return (f"{head}: {'; '.join(parts)}; not estimated: {', '.join(missing) or 'counts'} "
            f"({acc['why'][0] if acc['why'] else 'see summary.json'})")
