"""An estimate of a finished run's error, its order measured on the run's own scene.

:func:`estimate_errors` runs the same scene and scheme twice more, with the
steps that set its accuracy ``r`` times shorter (the *finer companion*) and
``r`` times longer (the *coarser companion*): a geometric ladder ``h/r, h,
r h`` around the run's step.  Each quantity's order is measured on those
three runs (:func:`cosim.studies.ladder.observed_order`); where it is
confirmed, the run's error is Richardson's with that order; where it is
not, it is a bound at order 1 (:func:`cosim.studies.ladder.bound`), said
as such (``kind``).  The orders fitted once on the shipped scenes
(:data:`ORDERS`, :data:`HOSTED_ORDERS`) are a prior only (``order_prior``):
on a scene a user wrote (an arm striking a pinned beam whose exit velocity
converges at order 1) the fitted 2.6 put the estimate several times below
the error.

Why a ladder centred on the run, and not two coarser companions at ``r``
and ``r**2`` (cheaper: ``1/r + 1/r**2`` of the run's steps): where the
error is the sum of two powers of the step (``a h + b h**2``), the coarser
runs see the higher power and confirm it, and the estimate falls below the
error by the ratio of the two terms at the run's step; the finer companion
sees the power that rules at the run's step.  With ``r`` = sqrt(2)
(:data:`DEFAULT_FACTOR`) the two companions cost about ``r + 1/r`` = 2.1
times the run's steps, so that the run with its estimate stays near 3 times
the run's steps (``work_share``).

What it cannot see: an error whose size turns with the step near the run's
(a sum of terms of opposite signs: the peak of the damped contact in
``tests/test_estimate_order.py`` is off by 2.4e-3 at the run's step, 1.6e-3
at half of it and 1.1e-3 at twice it) looks like one power of the step on
three neighbouring runs, and its estimate can fall far below it (2.2e-4
there, measured); nor an error that comes from a step the companions keep.

Which steps (:func:`cosim.studies.companion.coarsened`): a co-simulation
scheme's ``macro_step`` and, where the scene gives one, its
``contact_step``, both times ``r`` (or ``1/r``); under interface error
control (``interface_tolerance``), the tolerance times ``r **
(extrapolation_order + 2)``, so that the controlled step scales alike.  The
``approach_horizon`` stays the run's.  The number of ``substeps`` stays.  A
side's own step (a multibody side's ``rk4`` ``max_step`` and
``free_step``, a structure's ``contact_step``) scales too, unless the
coarser companion's would take a contact it hosts past omega h =
:data:`~cosim.studies.companion.OMEGA_H_MAX`: it then stays in both
companions, and an error that comes from it is not seen.  The monolithic
scheme gets no companion (:data:`MONOLITHIC`).

Which companions (:func:`cosim.studies.companion.ladder_plan`): a contact
the sides exchange whose step in the coarser companion lies past omega h =
:data:`~cosim.studies.companion.ASYMPTOTIC_OMEGA_H` (where the schemes'
errors stop falling as one power of the step) is read from the finer
companion alone: a bound, ``|Q_h - Q_(h/r)| (2 r - 1) / (r - 1)``; where every
contact that closed is past it (or not seen), the coarser companion is not
run.  A contact
past the range at the run's own step is not estimated, nor are the exit
rates read at its release; where that leaves nothing to read, no companion
runs (:data:`BLIND`).  A coarser companion that the guard stops, or that
the pre-flight check refuses, leaves the finer one: bounds.

What is estimated: per contact, ``peak_penetration``, ``impulse``, the
first interval's ``t_on`` and ``t_off``, and ``count`` (robust when every
companion agrees); the exit state: each multibody joint's rate at the last
release of the last contact that releases (:func:`exit_rates`), after the
velocity jump where that contact is a rigid impact (its impulse law is
exact: the rates are read as the impact left them, not interpolated across
the jump), or the final rate when no contact releases.

Honest where it cannot: a quantity is ``reliable: false`` with a ``why``
when no companion finished, when the runs disagree on a contact's count
(that contact's quantities and the exit state), when the contact's step is
past the asymptotic range at the run's own step, when a side that keeps its
step in the companions resolves the contact coarsely, when the scheme is
monolithic, or when the estimate exceeds the quantity; its
``relative_error`` is then None and ``difference`` keeps ``|Q_h -
Q_companion|``.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from cosim.studies.accuracy_line import BLIND, accuracy_text
from cosim.studies.companion import (ASYMPTOTIC_OMEGA_H, OMEGA_H_MAX, UNSEEN_OMEGA_H, built,
                                     coarsened, exchanged_omega_h, ladder_plan)
from cosim.studies.ladder import judge

__all__ = ["ORDERS", "HOSTED_ORDERS", "DEFAULT_FACTOR", "BLIND", "coarsened", "estimate_errors",
           "accuracy_text", "counted_share", "exit_rates"]

#: the ratio of the ladder's steps: the companions run at ``h/r`` and ``r h``
DEFAULT_FACTOR = math.sqrt(2.0)

#: the prior: observed orders of the schemes fitted once on the shipped
#: scenes (the median slope of ``log(error)`` against ``log(omega h)``
#: between omega h = 0.1, 0.2 and 0.4 of C's peak penetration and the arm's
#: exit velocity against the bench's monolithic reference, three_mass f1 to
#: f1000 and beam_impact, ``benchmarks/results/accuracy_model``).  Not used
#: for a run's estimate (its order is measured on the run's own ladder);
#: :mod:`cosim.studies.accurate` reads it to size a refinement before it
#: runs, and the summary gives it as ``order_prior``.
ORDERS = {
    "gauss_seidel": {"contacts": 2.9, "exit": 2.6},
    "jacobi": {"contacts": 2.1, "exit": 1.9},
    "implicit": {"contacts": 4.2, "exit": 2.6},
}
#: the prior where a side's own RK4 step integrates the contact against a
#: rigid partner (spring_drop, ground_multicontact: ``host_rk4`` fit)
HOSTED_ORDERS = {"contacts": 4.6, "exit": 1.8}

#: why the monolithic scheme gets no companion: its cost hardly depends on
#: the tolerance (three_mass f100: 0.24 s of CPU at rtol 1e-5, 0.23 s at
#: 1e-9; locating every switch and the output samples make most of it), so a
#: companion at a coarser tolerance would cost about as much as the run
MONOLITHIC = ("not estimated for the monolithic scheme: a coarser tolerance saves its "
              "solver little, so a companion would cost about as much as the run")

#: per contact, the summary's quantities that are estimated
_CONTACT_QUANTITIES = ("peak_penetration", "impulse", "t_on", "t_off")

#: where the exit rates are read when no contact releases
END = "end of the run"


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
    [rad/s or m/s]), and what that instant is (``"release of C at T s"``,
    ``"after the impact of C at T s"`` or ``"end of the run"``);
    ``multibody``: the names of the multibody subsystems.

    Between samples the rate is read linearly (as
    :func:`cosim.studies.metrics.exit_velocity`); where the release is a
    rigid impact (the summary's ``impacts``), the impacted side's rates are
    the impact's ``dq_after``: the exact law's jump is not interpolated
    across."""
    t = result.series["t"]
    last = None
    for name, c in result.summary["contacts"].items():
        if contact is not None and name != contact:
            continue
        if c["intervals"] and c["intervals"][-1][1] < t[-1]:
            t_off = float(c["intervals"][-1][1])
            if last is None or t_off > last[1]:
                last = (name, t_off)
    impact = None
    if last is not None:
        hits = [i for i in result.summary.get("impacts", ()) if i["contact"] == last[0]
                and i["time"] <= last[1]]
        impact = hits[-1] if hits else None
    rates = {}
    for key in result.series:
        if not key.startswith("dq/"):
            continue
        name = key[3:]
        sub, joint = name.split("/", 1)
        if sub not in multibody:
            continue
        if impact is not None and joint in impact["dq_after"] and _impacted(result, impact,
                                                                            sub):
            rates[name] = float(impact["dq_after"][joint])
            continue
        dq = result.series[key]
        # (cosim.studies.metrics not imported: every run would load the bench's module)
        rates[name] = (float(np.interp(last[1], t, dq)) if last is not None
                       else float(dq[-1]))
    if last is None:
        return rates, END
    if impact is not None:
        return rates, f"after the impact of {last[0]} at {last[1]:.6g} s"
    return rates, f"release of {last[0]} at {last[1]:.6g} s"


def _impacted(result, impact, sub: str) -> bool:
    """Whether ``sub`` is the side whose velocities ``impact`` jumped: its
    ``dq_after`` names that side's joints (a rigid contact has one moving
    side); a scene with one multibody side needs no more."""
    sides = {k.split("/", 1)[0] for k in result.series if k.startswith("dq/")}
    if len(sides) == 1:
        return True
    own = {k.split("/", 1)[1] for k in result.series if k.startswith(f"dq/{sub}/")}
    return own == set(impact["dq_after"])


def _finite(x):                      # summary.json holds no NaN
    return x if x is not None and math.isfinite(x) else None


def _entry(value: float, finer, coarser, r: float, why: str | None = None,
           note: str | None = None) -> dict:
    """One quantity: its value, its companions' (None: not read) and the
    estimate (see :func:`cosim.studies.ladder.judge`); ``note``: why a
    companion is not read for it."""
    finer, coarser = _finite(finer), _finite(coarser)
    other = coarser if coarser is not None else finer
    out = {"value": _finite(value), "companion": other, "finer": finer, "difference": None,
           "relative_error": None, "reliable": False, "kind": None, "order": None}
    if not math.isfinite(value) or other is None:
        out["why"] = why or "not defined in the run and a companion"
        return out
    out["difference"] = abs(value - other)
    if why is not None:
        out["why"] = why
        return out
    j = judge(value, finer, coarser, r)
    out.update(kind=j["kind"], order=j["order"])
    if "order_why" in j:
        out["order_why"] = note or j["order_why"]
    if value == 0.0:
        if j["estimate"] == 0.0:          # at rest in every run (a joint that never moved)
            out.update(relative_error=0.0, reliable=True)
            return out
        out["why"] = "the quantity is zero in the run, not in a companion"
        return out
    rel = j["estimate"] / abs(value)
    if rel > 1.0:
        out["why"] = "the estimate is larger than the quantity"
        return out
    out.update(relative_error=rel, reliable=True)
    return out


def _blind(result, strike, beyond: dict, kept: list) -> bool:
    """Whether every contact that closed, and the strike whose release the
    exit rates are read at, is past the asymptotic range at the run's step
    or unseen: companions would be run for nothing."""
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
    """Embedded contact -> the side whose integrator evaluates it (its
    ``host``, or the side that is not rigid)."""
    kinds = {s.name: s.type for s in scene.subsystems}
    return {c.name: c.host or next((n for n in (c.a[0], c.b[0]) if kinds[n] != "rigid"),
                                   None)
            for c in scene.contacts if c.placement == "embedded"}


def _simulate(scene):
    from cosim.scene import run
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run.simulate(scene)


def _companion(role: str, factor: float, make, scene, result) -> tuple[dict, object]:
    """Run one companion (``make()`` gives its scene): its record (``role``,
    ``factor``, ``status``, ``message``, ``macro_steps``, ``cpu_time_s``,
    ``work_share``) and its result, None where it was refused or failed."""
    from cosim.errors import UnsafeStepError
    rec = {"role": role, "factor": factor}
    try:
        comp_scene = make()
        comp = _simulate(comp_scene)
    except Exception as exc:     # a refused or broken companion: said why
        rec.update(status="refused", message=f"{type(exc).__name__}: {exc}",
                   why=(f"the pre-flight check refuses {factor:.3g}x the step as unstable"
                        if isinstance(exc, UnsafeStepError) else
                        f"the {role} companion did not run ({type(exc).__name__})"))
        return rec, None
    rec.update(status=comp.status, message=comp.message, macro_steps=comp.n_windows,
               cpu_time_s=comp.summary["cpu_time_s"],
               work_share={"macro_steps": counted_share(result, comp),
                           "integrator_steps": comp_scene.work().steps / scene.work().steps})
    if not comp.success:          # the guard's reason (energy growth, chatter), short
        reason = comp.message.split(": ", 1)[-1].split(";")[0].split(" (")[0]
        rec["why"] = f"the {role} companion {comp.status}: {reason}"[:160]
        return rec, None
    return rec, comp


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
        The ladder's ratio ``r`` (> 1): the companions run at ``h/r`` and
        ``r h``.
    contact : str, optional
        The contact at whose last release the exit rates are read (default:
        the scene's strike, :func:`cosim.studies.strike.find_strike`, else
        the contact that releases last).

    Returns
    -------
    dict
        The summary's ``accuracy``: ``reliable`` (every quantity has an
        estimate), ``method``, ``factor``, ``order`` (the lowest confirmed
        order among the contacts' quantities and among the exit rates, None
        where none is), ``order_prior`` (:data:`ORDERS`, not used),
        ``order_source``, ``coarsened`` and ``refined`` (key path -> value in
        the coarser and the finer companion), ``companions`` (one record
        each, :func:`_companion`), ``companion`` (``status``: finished when
        every companion run did; ``message``, ``macro_steps``,
        ``cpu_time_s`` summed), ``work_share`` (summed over the companions:
        ``macro_steps``, :func:`counted_share`; ``integrator_steps``, the
        ratio of the integrator steps counted before the runs, upper
        bounds), ``contacts`` (name -> ``count`` {``value``, ``companion``,
        ``robust``} and one entry per quantity), ``exit`` (``at``, and
        ``SUBSYSTEM/JOINT`` -> entry) and ``why`` (what made the summary
        unreliable).  An entry holds ``value``, ``companion`` (the coarser
        companion's value, else the finer's), ``finer``, ``difference``
        (``|value - companion|``), ``reliable``, ``kind`` (``"richardson"``
        or ``"bound"``), ``order`` (measured, or None), ``order_why`` (why
        the order was not confirmed), and ``relative_error`` (the estimate
        over the value) or ``why``.
    """
    if contact is None:
        from cosim.studies.strike import find_strike
        found = find_strike(scene, required=False)
        contact = found[0] if found else None
    r = float(factor)
    acc = {"reliable": False, "method": "richardson with the order measured on h/r, h, r h; "
                                        "else a bound at order 1",
           "factor": factor, "order": {"contacts": None, "exit": None},
           "order_prior": ORDERS.get(scene.scheme),
           "order_source": "measured on this run and its companions at h/r and r h",
           "coarsened": {}, "refined": {}, "companions": [], "companion": {},
           "work_share": None, "contacts": {}, "exit": {}, "why": []}
    runs = {"finer": None, "coarser": None}
    kept: list = []                   # contacts the companions cannot see (coarsened fills it)
    beyond: dict = {}                 # exchanged contacts past the range at the run's step
    finer_only: dict = {}             # ... past it at the coarser companion's step only
    blind = False
    if scene.scheme == "monolithic":
        acc["companion"] = {"status": "not run", "message": MONOLITHIC}
        acc["why"].append(MONOLITHIC)
    else:
        try:
            system = built(scene)
            finer_only, beyond = ladder_plan(r, exchanged_omega_h(scene, system))
            coarse_scene, acc["coarsened"] = coarsened(scene, r, kept, system)
            acc["refined"] = coarsened(scene, 1.0 / r, None, system, judged_at=r)[1]
        except Exception as exc:      # the scene cannot be scaled: no estimate, said why
            blind = None
            acc["companion"] = {"status": "refused", "message": f"{type(exc).__name__}: {exc}"}
            acc["why"].append(f"the companion did not run ({type(exc).__name__})")
        if blind is not None:
            blind = _blind(result, contact, beyond, kept)
            # the coarser companion, where some contact that closed can be read from it
            coarse = not _blind(result, contact, {**beyond, **finer_only}, kept)
        if blind:
            acc["companion"] = {"status": "not run", "message": BLIND}
        elif blind is not None:
            plan = [("finer", 1.0 / r,
                     lambda: coarsened(scene, 1.0 / r, None, system, judged_at=r)[0])]
            if coarse:
                plan.append(("coarser", r, lambda: coarse_scene))
            for role, f, make in plan:
                rec, runs[role] = _companion(role, f, make, scene, result)
                acc["companions"].append(rec)
            _summarise(acc)
    _fill(acc, scene, result, contact, r, runs, kept, beyond, finer_only, blind)
    return acc


def _summarise(acc: dict) -> None:
    """``companion`` and ``work_share`` summed over the companions run, and
    why no companion gave anything, where none did."""
    recs = acc["companions"]
    bad = [c for c in recs if c["status"] != "finished"]
    acc["companion"] = {"status": bad[0]["status"] if bad else "finished",
                        "message": "; ".join(c["message"] for c in recs if c["message"]),
                        "macro_steps": sum(c.get("macro_steps", 0) for c in recs),
                        "cpu_time_s": sum(c.get("cpu_time_s", 0.0) for c in recs)}
    shares = [c["work_share"] for c in recs if "work_share" in c]
    if shares:
        acc["work_share"] = {k: sum(s[k] for s in shares) for k in shares[0]}
    if all("why" in c for c in recs):            # no companion to read
        acc["why"].append(recs[0]["why"])


def _unseen(scene, r, kept, beyond) -> dict:
    """Contact -> why its error cannot be read from the companions."""
    hosts = _embedded(scene)
    out = {c: (f"`{hosts.get(c)}` steps contact {c} at the same step in the companions "
               f"({r:.3g}x would take a contact it hosts past omega h = {OMEGA_H_MAX}), and "
               f"that step resolves {c} coarsely (omega h > {UNSEEN_OMEGA_H}): its error is "
               f"not seen"
               if math.isfinite(wh) else
               f"`{hosts.get(c)}` keeps its step in the companions, as {c}'s law has no "
               f"linear stiffness to tell the omega h of another one: {c}'s error is not seen")
           for c, wh in kept}
    out.update({c: f"the run steps contact {c} at omega h = {wh:.2g}, past "
                   f"{ASYMPTOTIC_OMEGA_H}, where the scheme's error stops falling as one power "
                   f"of the step: its companions' differences would not tell the run's error"
                for c, wh in beyond.items()})
    return out


def _fill(acc, scene, result, contact, r, runs, kept, beyond, finer_only, blind) -> None:
    """The entries of every contact and exit rate, and the summary's
    ``order``, ``why`` and ``reliable``."""
    from cosim.scene.specs import MultibodySpec

    done = {role: res for role, res in runs.items() if res is not None}
    unseen = _unseen(scene, r, kept, beyond)
    coarse_why = {c: f"the coarser companion steps contact {c} at omega h = {wh:.2g}, past "
                     f"{ASYMPTOTIC_OMEGA_H}: read from the finer companion alone"
                  for c, wh in finer_only.items()}
    stopped = None if done or blind else (acc["why"][0] if acc["why"] else
                                          "no companion finished")
    # why one companion gave nothing, said by each entry the other alone bounds
    lost = next((c["why"] for c in acc["companions"] if "why" in c), None) if done else None
    mine = _contact_values(result.summary)
    theirs = {role: _contact_values(res.summary) for role, res in done.items()}
    differ = []
    for name, v in mine.items():
        counts = {role: t[name]["count"] for role, t in theirs.items()}
        robust = all(n == v["count"] for n in counts.values()) if counts else None
        other = counts.get("coarser", counts.get("finer"))
        entry = {"count": {"value": v["count"], "companion": other, "robust": robust}}
        if "finer" in counts:
            entry["count"]["finer"] = counts["finer"]
        why = stopped
        if why is None and robust is False:
            bad = next(role for role, n in counts.items() if n != v["count"])
            why = (f"contact {name} closed {v['count']} times, {counts[bad]} in the "
                   f"{'' if len(counts) == 1 else bad + ' '}companion")
            differ.append(why)
        why = why or unseen.get(name)
        for q in _CONTACT_QUANTITIES:
            coarser = (None if name in coarse_why else
                       theirs.get("coarser", {}).get(name, {}).get(q))
            entry[q] = _entry(v[q], theirs.get("finer", {}).get(name, {}).get(q), coarser, r,
                              why, coarse_why.get(name) or lost)
        acc["contacts"][name] = entry
    multibody = {s.name for s in scene.subsystems if isinstance(s, MultibodySpec)}
    rates, at = exit_rates(result, multibody, contact)
    acc["exit"]["at"] = at
    crates, elsewhere = {}, []
    for role, res in done.items():
        crates[role], cat = exit_rates(res, multibody, contact)
        if (cat == END) != (at == END):      # one run's contact is still closed at the end
            elsewhere.append(f"the {role} companion reads the exit rates at {cat}, the run "
                             f"at {at}")
            crates[role] = {}
    for joint, value in rates.items():
        why = (stopped or (differ[0] if differ else None)
               or (elsewhere[0] if len(elsewhere) == len(done) and done else None)
               or unseen.get(contact) or (BLIND if blind else None))
        note = coarse_why.get(contact) or (elsewhere[0] if elsewhere else None) or lost
        coarser = None if contact in coarse_why else crates.get("coarser", {}).get(joint)
        acc["exit"][joint] = _entry(value, crates.get("finer", {}).get(joint), coarser, r,
                                    why, note)
    acc["why"] += differ
    entries = [e for c in acc["contacts"].values() for k, e in c.items() if k != "count"
               if c["count"]["value"] > 0] + [e for k, e in acc["exit"].items() if k != "at"]
    for e in entries:
        if not e["reliable"] and e.get("why") and e["why"] not in acc["why"]:
            acc["why"].append(e["why"])
    contact_entries = [e for c in acc["contacts"].values() for k, e in c.items()
                       if k != "count" and c["count"]["value"] > 0]
    exit_entries = [e for k, e in acc["exit"].items() if k != "at"]
    for key, group in (("contacts", contact_entries), ("exit", exit_entries)):
        measured = [e["order"] for e in group if e.get("kind") == "richardson"]
        acc["order"][key] = min(measured) if measured else None
    acc["reliable"] = (not acc["why"] and all(e["reliable"] for e in entries)
                       and all(c["count"]["robust"] for c in acc["contacts"].values()))
