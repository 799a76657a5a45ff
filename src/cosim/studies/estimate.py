"""An estimate of a finished run's error, from one coarser companion run.

:func:`estimate_errors` runs the same scene and scheme again with the steps
that set its accuracy made ``factor`` times longer (the *companion*), and
turns the difference of each quantity into a Richardson estimate of the
run's own error::

    err(Q_h) ~ |Q_h - Q_rh| / (r**p - 1)

with ``r`` the factor and ``p`` the scheme's observed order (:data:`ORDERS`).

Which steps: a co-simulation scheme's ``macro_step`` and, where the scene
gives one, its ``contact_step`` (the step while a contact is closed), both
times ``r``; under interface error control (``interface_tolerance``), the
tolerance times ``r ** (extrapolation_order + 2)``, so that the controlled
step is ``r`` times longer too.  The number of ``substeps`` stays (each is
``r`` times longer).  A side's own step (a multibody side's ``rk4``
``max_step`` and ``free_step``, a structure's ``contact_step``) is ``r``
times longer too, unless that would take a contact it hosts past omega h =
:data:`OMEGA_H_MAX` (:func:`_coarsenable_sides`): such a step is set by the
contact's stability, not by accuracy (three_mass's robot, at 0.3, fails at
3x its step); it stays, and an error that comes from it is not seen.  The monolithic scheme gets no companion (:data:`MONOLITHIC`): its
cost hardly falls with a coarser tolerance.

The order: ``p`` is measured once per scheme (:data:`ORDERS`, with where),
not on every run.  Measuring it on every run needs a third run at ``r**2``
whose cost, added to the companion's, passes 30 % of the run at r = 4
(1/4 + 1/16 of its steps); at r = 5 (1/5 + 1/25) the run at 25x the step
is far from the asymptotic range (three_mass f100 already closes C 8 times,
not 9, at 8x).  A scheme without a measured order gives
differences, no estimate.

Cost: the companion takes about ``1/r`` of the run's macro steps where free
flight and contact are both stepped at the scheme's steps (spring_drop,
ground_multicontact: 1/4); step control adds steps aimed at each onset that
do not scale with ``r`` (three_mass f100: 0.48 of the run's macro steps).
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
scheme's order was not measured or the scheme is monolithic, or when the
estimate exceeds the quantity itself; its ``relative_error`` is then None
and ``difference`` keeps ``|Q_h - Q_rh|``.
"""
from __future__ import annotations

import copy
import math
import warnings
from pathlib import Path

import numpy as np

__all__ = ["ORDERS", "DEFAULT_FACTOR", "coarsened", "estimate_errors", "accuracy_text",
           "counted_share"]

#: the factor by which the companion's steps are longer than the run's
DEFAULT_FACTOR = 4

#: observed orders of the schemes, and where they were measured: the slope
#: of ``log(error)`` against ``log(contact_step)`` (``np.polyfit``) of C's
#: peak penetration in three_mass f100 against the bench's monolithic
#: reference (DOP853, rtol 1e-11), at the steps named.  Gauss-Seidel's local
#: slope is 2.7 between 1e-5 and 2e-5 s and falls to 1.4 between 4e-5 and
#: 8e-5 s; the implicit scheme's error is at its floor (2e-7) below 4e-5 s.
ORDERS = {
    "gauss_seidel": (2.1, "three_mass f100, C's peak, contact_step 1e-5 to 8e-5 s"),
    "jacobi": (2.3, "three_mass f100, C's peak, contact_step 1e-5 to 8e-5 s"),
    "implicit": (4.2, "three_mass f100, C's peak, contact_step 4e-5 to 1.6e-4 s"),
}

#: why the monolithic scheme gets no companion: its cost hardly depends on
#: the tolerance (three_mass f100: 0.24 s of CPU at rtol 1e-5, 0.23 s at
#: 1e-9; locating every switch and the output samples make most of it), so a
#: companion at a coarser tolerance would cost about as much as the run
MONOLITHIC = ("not estimated for the monolithic scheme: a coarser tolerance saves its "
              "solver little, so a companion would cost about as much as the run")

#: per contact, the summary's quantities that are estimated
_CONTACT_QUANTITIES = ("peak_penetration", "impulse", "t_on", "t_off")


def coarsened(scene, factor: float, kept: list | None = None):
    """A copy of ``scene`` whose accuracy-setting steps are ``factor`` times
    longer (see the module), and the keys changed (key path -> new value).

    Parameters
    ----------
    scene : Scene
    factor : float
        > 1.
    kept : list, optional
        Filled with ``(contact, omega h)`` of the contacts whose error the
        companion does not see (omega h infinite: a law without a linear
        stiffness, which cannot be judged): a
        contact hosted by a side whose own step stays (a contact it hosts
        would pass omega h = :data:`OMEGA_H_MAX`), where that step resolves
        the contact itself coarsely (omega h > :data:`UNSEEN_OMEGA_H`).

    Returns
    -------
    (Scene, dict)
    """
    from cosim.scene.load import _validate
    from cosim.scene.specs import MultibodySpec

    if not (isinstance(factor, (int, float)) and factor > 1 and math.isfinite(factor)):
        raise ValueError(f"`factor` must be a finite number > 1, got {factor!r}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        spec = scene.scheme_spec()
    data = copy.deepcopy(scene.data)
    sch = data.setdefault("scheme", {})
    sch["name"] = spec.name
    own = sch.setdefault(spec.name, {})      # a [scheme.NAME] table wins over [scheme]
    if "macro_step" not in spec.options:
        raise ValueError(f"scheme `{spec.name}` has no macro step to coarsen")
    changed = {}
    for key in ("macro_step", "contact_step"):
        if spec.options.get(key):
            own[key] = spec.options[key] * factor
            changed[f"scheme.{spec.name}.{key}"] = own[key]
    tol = spec.options.get("interface_tolerance")
    if tol:           # the controller's step goes as tol ** (1 / (order + 2)): r times longer
        own["interface_tolerance"] = min(tol * factor ** (spec.options.get(
            "extrapolation_order", 0) + 2), 0.5)
        changed[f"scheme.{spec.name}.interface_tolerance"] = own["interface_tolerance"]
    omega_h: dict = {}
    for side, ok in _coarsenable_sides(scene, factor, omega_h).values():
        sd = data["subsystems"][side.name]
        integ = sd.get("integrator")
        integ = sd["integrator"] = dict(integ) if isinstance(integ, dict) else (
            {"method": integ} if isinstance(integ, str) else {})
        if not ok:
            if kept is not None:          # the contacts it resolves coarsely: not seen
                kept.extend((c, wh) for c, (host, wh) in omega_h.items()
                            if host == side.name and wh > UNSEEN_OMEGA_H)
            continue
        if isinstance(side, MultibodySpec):
            integ["max_step"] = (side.max_step or spec.default_step) * factor
            keys = ["max_step"] + (["free_step"] if "free_step" in side.integrator_options
                                   else [])
            for key in keys[1:]:
                integ[key] = side.integrator_options[key] * factor
        else:
            integ["contact_step"] = side.contact_step * factor
            keys = ["contact_step"]
        for key in keys:
            changed[f"subsystems.{side.name}.integrator.{key}"] = integ[key]
    return _validate(data, Path(scene.path), scene.variant, True), changed


#: the largest omega h [rad] of a contact that a side's own step may reach in
#: the companion: below it an RK4 step resolves the contact's oscillation
#: (an error of (omega h)**4 / 120 in a period's phase), so that the
#: companion is still in the asymptotic range; three_mass's robot runs at
#: 0.3 and fails at 4x that
OMEGA_H_MAX = 0.5


#: the omega h [rad] above which a contact's error from its host's RK4 step,
#: when that step stays in the companion, is not negligible: RK4's phase
#: error per period is about (omega h)**4 / 120, 1e-6 at 0.1
UNSEEN_OMEGA_H = 0.1


def _coarsenable_sides(scene, factor: float, omega_h: dict | None = None) -> dict:
    """The sides whose own step sets the accuracy of a contact they host
    (a multibody side under ``rk4``, a structure that steps its closed
    contacts with ``contact_step``): name -> (spec, whether ``factor`` times
    that step keeps omega h <= :data:`OMEGA_H_MAX` for every contact it
    hosts (omega of the contact's linearised stiffness and the sides'
    mobility at the initial pose)).  A side that hosts no contact is
    coarsened too (its step sets only its own accuracy)."""
    from cosim.core.preflight import stiffest_normal
    from cosim.scene.specs import MultibodySpec, StructureSpec
    from cosim.scene.work import _closed_form

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default_step = scene.scheme_spec().default_step
    steps = {}
    for side in scene.subsystems:
        if isinstance(side, MultibodySpec) and side.integrator == "rk4":
            steps[side.name] = (side, side.max_step or default_step)
        elif isinstance(side, StructureSpec) and not _closed_form(side, scene.contacts):
            steps[side.name] = (side, side.contact_step)
    if not steps:
        return {}
    with warnings.catch_warnings():      # what the run said of the scene, said once
        warnings.simplefilter("ignore")
        system, _ = scene.build()
    omega = {name: 0.0 for name in steps}
    for c, (own, _) in system.embedded.items():
        host = system.subsystems[own].name
        if host not in omega:
            continue
        ln = system.links[c]
        n = ln.contact.normal
        mob = (system.subsystems[ln.sub_a].port_mobility(ln.port_a, n)
               + system.subsystems[ln.sub_b].port_mobility(ln.port_b, n))
        k = stiffest_normal(ln)[0]
        w = math.sqrt(k * mob) if math.isfinite(k) and mob > 0 else math.inf
        omega[host] = max(omega[host], w)
        if omega_h is not None:           # the contact's own omega h at the run's step
            omega_h[ln.contact.name] = (host, w * steps[host][1])
    return {name: (side, omega[name] * factor * h <= OMEGA_H_MAX)
            for name, (side, h) in steps.items()}


def _order(scheme: str):
    return ORDERS.get(scheme, (None, ""))


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
    when = (f"release of {last[0]} at {last[1]:.6g} s" if last is not None
            else "end of the run")
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


def counted_share(result, companion) -> float:
    """The companion's macro steps (with their iterations, if the scheme
    iterates) over the run's: the counted share of its work."""
    def work(res):
        return max(res.n_windows, 1) + res.n_iterations
    return work(companion) / work(result)


def _hosts(scene) -> dict:
    """Contact -> the side whose integrator evaluates it (an embedded
    contact: its ``host``, or the side that is not rigid)."""
    kinds = {s.name: s.type for s in scene.subsystems}
    out = {}
    for c in scene.contacts:
        if c.placement != "embedded":
            continue
        sides = (c.a[0], c.b[0])
        out[c.name] = c.host or next((n for n in sides if kinds[n] != "rigid"), None)
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

    p, source = _order(scene.scheme)
    acc = {"reliable": False, "method": "richardson", "factor": factor, "order": p,
           "order_source": source, "coarsened": {}, "companion": {}, "work_share": None,
           "contacts": {}, "exit": {}, "why": []}
    comp = None
    kept: list = []                   # contacts the companion cannot see (coarsened fills it)
    if scene.scheme == "monolithic":
        acc["companion"] = {"status": "not run", "message": MONOLITHIC}
        acc["why"].append(MONOLITHIC)
    else:
        try:
            comp_scene, acc["coarsened"] = coarsened(scene, factor, kept)
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
    hosts = _hosts(scene)
    unseen = {c: (f"`{hosts.get(c)}` steps contact {c} at the same step in the companion (4x "
                  f"would take a contact it hosts past omega h = {OMEGA_H_MAX}), and that step "
                  f"resolves {c} coarsely (omega h > {UNSEEN_OMEGA_H}): its error is not seen"
                  if math.isfinite(wh) else
                  f"`{hosts.get(c)}` keeps its step in the companion, as {c}'s law has no "
                  f"linear stiffness to tell the omega h of a longer one: {c}'s error is not "
                  f"seen") for c, wh in kept}
    mine = _contact_values(result.summary)
    theirs = _contact_values(comp.summary) if comp is not None and comp.success else {}
    stopped = None if theirs else (acc["why"][0] if acc["why"] else
                                   "the companion did not finish")
    differ = []
    for name, v in mine.items():
        o = theirs.get(name, {})
        count = {"value": v["count"], "companion": o.get("count"),
                 "robust": o.get("count") == v["count"]}
        entry = {"count": count}
        why = stopped
        if why is None and not count["robust"]:
            why = f"contact {name} closed {v['count']} times, {o.get('count')} in the companion"
            differ.append(why)
        why = why or unseen.get(name)
        for q in _CONTACT_QUANTITIES:
            entry[q] = _judge(v[q], o.get(q, math.nan), factor, p, why)
        acc["contacts"][name] = entry
    from cosim.scene.specs import MultibodySpec
    multibody = {s.name for s in scene.subsystems if isinstance(s, MultibodySpec)}
    if contact is None:
        from cosim.studies.strike import find_strike
        found = find_strike(scene, required=False)
        contact = found[0] if found else None
    rates, at = exit_rates(result, multibody, contact)
    acc["exit"]["at"] = at
    if theirs:
        crates = exit_rates(comp, multibody, contact)[0]
    else:
        crates = {}
    for joint, value in rates.items():
        why = stopped or (differ[0] if differ else None) or unseen.get(contact)
        acc["exit"][joint] = _judge(value, crates.get(joint, math.nan), factor, p, why)
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
    steps = ", ".join(f"{k.rsplit('.', 1)[-1]} {v:.3g}" for k, v in acc["coarsened"].items())
    head = f"accuracy (companion at {acc['factor']:g}x the step: {steps})"
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
