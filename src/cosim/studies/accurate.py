"""A run on request of an accuracy: choose, run, check the estimate, refine once.

``cosim run --accuracy 1%`` (or ``accuracy = 0.01`` in a scene's
``[scheme]``) asks for a relative accuracy of the impact a study reads: the
peak penetration of the contact :func:`cosim.studies.choose.choose` models
and the striker's exit velocity (:func:`cosim.studies.strike.find_strike`).

1. :func:`plan` asks the a-priori model (:mod:`cosim.studies.choose`) for
   the scheme and steps expected to meet it at the least CPU, and loads the
   scene with them;
2. the run goes as any other, and the companion run estimates its error
   (:mod:`cosim.studies.estimate`);
3. :func:`verdict` compares the estimate with the accuracy asked.  Where
   the estimate says it is not met, :func:`refined` shortens the steps the
   estimate depends on (those its companion coarsened, a side's step the
   companion kept excepted) by ``(estimate / (SAFETY X)) ** (1 / p)``, ``p``
   the model's lowest order for the scheme, and that run goes into a
   folder of its own: the finished first run is replaced only when the
   refined one finished with a lower estimate (a refined run whose estimate
   did not fall with its steps says that those steps are not what limits
   it).  A refinement counted at more than :data:`REFINE_WORK_LIMIT` times
   the first run's steps is not run unless asked (``--yes``).  Where the
   estimate is not reliable (a count that differs in the companion, the
   monolithic scheme's no companion), the request is unchecked, with why,
   and nothing is refined.

A request always ends in one of :data:`OUTCOMES`: ``met`` (the estimate is
at most the accuracy asked), ``not met`` (larger; ``cosim run`` exits with
status 3) or ``unchecked`` (no reliable estimate; exit 0 with a warning).
What was asked, chosen, estimated and decided is the summary's
``accuracy.request`` (:func:`request_record`).
"""
from __future__ import annotations

import warnings

__all__ = ["plan", "verdict", "judged", "refined", "request_record", "request_text", "asked",
           "conflicts", "OUTCOMES", "REFINE_WORK_LIMIT", "EXIT_NOT_MET"]

#: how a request ends
OUTCOMES = ("met", "not met", "unchecked")

#: the exit status of ``cosim run`` whose request was not met
EXIT_NOT_MET = 3

#: a refinement counted (:meth:`cosim.Scene.work`) at more than this many
#: times the first run's steps runs only when asked (``cosim run --yes``),
#: as a sweep of more than ``LARGE_GRID`` points does: the first run's cost
#: was accepted, ten times it was not
REFINE_WORK_LIMIT = 10.0


def asked(scene, flag) -> tuple[float | None, str]:
    """The accuracy a run is asked for: ``flag`` (``--accuracy``, a string
    or a number) wins over the scene's ``scheme.accuracy``; ``(None, "")``
    when neither gives one.  Returns ``(accuracy, where it came from)``."""
    from cosim.scene.checks import SceneError, parse_accuracy
    if flag is not None:
        return parse_accuracy(flag, "--accuracy"), "--accuracy"
    table = scene.data.get("scheme", {})
    if isinstance(table, dict) and "accuracy" in table:
        try:
            return parse_accuracy(table["accuracy"], "scheme.accuracy"), "scheme.accuracy"
        except ValueError as exc:
            raise SceneError(scene.path, "", str(exc)) from None
    return None, ""


#: the keys whose values an accuracy request chooses: the co-simulation
#: steps (``scheme.macro_step``, ``scheme.contact_step``, also under
#: ``[scheme.NAME]``), the monolithic tolerances, and a side's own steps
_CHOSEN = (r"scheme(\.[A-Za-z0-9_]+)?\.(macro_step|contact_step|rtol|atol)",
           r"subsystems\.[^.=]+\.integrator\.(max_step|free_step|contact_step)")


def conflicts(keys, source: str, no_estimate: str | None = None) -> str | None:
    """Why an accuracy asked by ``source`` cannot go with the keys the user
    set (``keys``: ``--set`` strings or key paths), or with ``no_estimate``
    (what turned the estimate off, e.g. ``--no-estimate``); None when it
    can.  The request chooses those steps itself and is checked against
    the estimate."""
    import re
    if no_estimate:
        return (f"{source} asks for an accuracy, which is checked against the run's error "
                f"estimate: it cannot go with {no_estimate}; give one of them")
    for text in keys:
        key = str(text).split("=", 1)[0].strip()
        if any(re.fullmatch(p, key) for p in _CHOSEN):
            return (f"{source} chooses the steps itself: it cannot go with `{key}` set "
                    f"(`{str(text).strip()}`); give one of them")
    return None


def plan(path, variant, overrides, accuracy: float, scheme=None, first=None,
         source: str = "accuracy"):
    """The scene loaded with the scheme and steps :func:`choose` picks for
    ``accuracy``: ``(scene, choice)``; ``scheme``, when given, is the only
    candidate; ``first``: the scene as given, when the caller loaded it;
    ``source``: where the accuracy was asked (what a refusal names)."""
    from cosim.scene.load import load_scene
    from cosim.studies.choose import choose

    if first is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")      # shown again when the chosen scene loads
            first = load_scene(path, variant, list(overrides), scheme)
    choice = choose(first, accuracy, schemes=[scheme] if scheme else None, source=source)
    # the scene the choice loaded and checked: ``first``'s table (the file, its variant and
    # ``overrides``) with the choice's overrides, as a load of the file with them all
    return (choice.scene if choice.scene is not None else
            _load(path, variant, overrides, choice)), choice


def _load(path, variant, overrides, choice):
    from cosim.scene.load import load_scene
    return load_scene(path, variant, list(overrides) + list(choice.overrides), choice.scheme)


def judged(choice, scene) -> str:
    """What a request is judged on, in words: the contact's peak and the
    striker's exit velocity (:func:`cosim.studies.strike.find_strike`)."""
    from cosim.studies.strike import find_strike
    contact = choice.knob.contact
    found = find_strike(scene, contact, None, required=False) if scene is not None else None
    joint = found[1] if found else None
    return f"{contact}'s peak and " + (f"{joint}'s exit velocity" if joint else
                                       "the joints' exit velocities")


def verdict(acc: dict, choice, scene) -> tuple[float | None, str]:
    """The estimated error of what was asked (the larger of the contact's
    peak and the striker's exit velocity, :func:`judged`) and, when there is
    none, why: ``(error, "")`` or ``(None, why)``."""
    from cosim.studies.strike import find_strike

    if choice.knob.grasp:
        return None, (f"`{choice.knob.contact}` is a grasp, whose estimate was not validated: "
                      f"on brachiation the runs and their companions close it 2 or 3 times "
                      f"between neighbouring steps, the fine reference 3 (docs/performance.md)")
    contact = choice.knob.contact
    if contact not in acc.get("contacts", {}):
        return None, "; ".join(acc.get("why") or ["the estimate is not reliable"])
    found = find_strike(scene, contact, None, required=False)
    joint = found[1] if found else None
    entries = [acc["contacts"][contact]["peak_penetration"]]
    exits = {k: e for k, e in acc["exit"].items() if k != "at"}
    entries += [exits[joint]] if joint in exits else list(exits.values())
    # only what was asked: another contact's estimate (one the companion cannot see) does
    # not decide the request
    bad = [e.get("why") or "not estimated" for e in entries if not e.get("reliable")]
    if bad or not entries:
        return None, bad[0] if bad else "no quantity of the impact was estimated"
    return max(e["relative_error"] for e in entries), ""


#: a run whose estimate lies above this fraction of the accuracy asked is
#: refined, though "met" stays "the estimate is at most X": where Richardson's
#: order is confirmed its estimate lies within 1.3x of the error on the
#: generated scenes (benchmarks/results/generated_validation), so an estimate
#: just under X can hide an error just over it
CHECK_MARGIN = 0.75


def limiting_order(acc: dict, choice, scene) -> float | None:
    """The order the refinement may count on: the confirmed order of the
    quantity whose estimate :func:`verdict` reads as the largest; None
    where that is a bound (which lies above the error already: the model's
    order goes with it) or nothing was estimated."""
    from cosim.studies.ladder import ORDER_BAND
    from cosim.studies.strike import find_strike

    contact = choice.knob.contact
    if contact not in acc.get("contacts", {}):
        return None
    found = find_strike(scene, contact, None, required=False)
    joint = found[1] if found else None
    entries = [acc["contacts"][contact]["peak_penetration"]]
    exits = {k: e for k, e in acc["exit"].items() if k != "at"}
    entries += [exits[joint]] if joint in exits else list(exits.values())
    entries = [e for e in entries if e.get("reliable")]
    if not entries:
        return None
    worst = max(entries, key=lambda e: e["relative_error"])
    if worst.get("kind") == "richardson" and worst.get("order") is not None:
        return max(float(worst["order"]), ORDER_BAND[0])
    return None


def _order(choice) -> float:
    """The lowest order ``p`` the model gives the chosen scheme in the
    contact's regime (the errors fall as the step to that power)."""
    from cosim.studies.choose import MODEL, _params
    par = _params(choice.knob.regime, choice.scheme, MODEL) or {}
    return min((p for _, p, _ in par.values()), default=1.0)


def refined(path, variant, overrides, choice, scene, estimated: float, factor: float = 4.0,
            order: float | None = None):
    """The scene and choice of the one refinement, or ``(None, None, why)``.

    Every step the run's estimate depends on -- the steps its companion
    made ``factor`` times longer (:func:`cosim.studies.companion.coarsened`:
    the scheme's macro and contact steps, a side's own step unless the
    companion kept it) -- is made ``f = (estimated / (SAFETY CHECK_MARGIN
    X)) ** (1 / p)`` times shorter, ``p`` the model's lowest order for the
    scheme (:func:`_order`) or ``order``, the order the run measured
    (:func:`limiting_order`), whichever is lower, rounded down to two
    digits; a step the companion did
    not change is not one the estimate depends on, and stays.  The
    pre-flight check and the scene's work limit are the run's.

    Returns
    -------
    (Scene, Choice, str)
        The scene, its choice (the step in contact and the predicted errors
        at it), and "" -- or None, None and why it cannot be refined.
    """
    import dataclasses

    from cosim.errors import UnsafeStepError
    from cosim.scene.checks import SceneError
    from cosim.studies.choose import SAFETY, _floor2, predicted_error
    from cosim.studies.companion import coarsened

    p = _order(choice) if order is None else min(_order(choice), order)
    f = (estimated / (SAFETY * CHECK_MARGIN * choice.accuracy)) ** (1.0 / p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, changed = coarsened(scene, factor)
    ov = [f"{key}={_floor2(v / factor / f)!r}" for key, v in changed.items()
          if not key.endswith((".approach_horizon", ".interface_tolerance"))]
    step = _floor2(choice.step / f)
    pred = predicted_error(choice.knob.regime, choice.scheme, choice.knob.omega * step)
    again = dataclasses.replace(
        choice, scene=None, overrides=tuple(choice.overrides) + tuple(ov), step=step,
        predicted_error=pred or dict(choice.predicted_error),
        why=f"{choice.why}; refined: its steps {f:.3g} times shorter, as the first run's "
            f"estimate asks")
    shorter = f"its steps {f:.3g} times shorter"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # counted first without the scene's limit, so that a refusal says it in its words
            counted = _load(path, variant, list(overrides) + ["guard.max_steps=1e300"], again)
            work = counted.work().steps
            if work > scene.max_steps:
                return None, None, (f"{shorter} would take {work:.3g} integrator steps, more "
                                    f"than the {scene.max_steps:.3g} a run may take "
                                    f"(`guard.max_steps`)")
            s = _load(path, variant, overrides, again)
            system, sch = s.build()
            sch.preflight(system)
    except (SceneError, UnsafeStepError) as exc:
        return None, None, f"{shorter} are refused: {exc}"
    return s, again, ""


def request_record(accuracy: float, source: str, choice, estimated, why: str,
                   first=None, scene=None, note: str = "") -> dict:
    """The summary's ``accuracy.request``.

    ``first`` is ``(choice, estimated)`` of the run a refinement replaced.
    ``outcome`` is one of :data:`OUTCOMES`; ``met`` is True or False when
    the estimate was reliable, else None (``unchecked`` says why);
    ``note`` says what became of a refinement (not run, stopped, or not
    kept)."""
    met = None if estimated is None else bool(estimated <= accuracy)
    out = {"accuracy": accuracy, "from": source, "scheme": choice.scheme,
           "overrides": list(choice.overrides), "step": choice.step,
           "contact": choice.knob.contact, "judged_on": judged(choice, scene),
           "predicted_error": dict(choice.predicted_error),
           "why": choice.why, "caveat": choice.caveat, "estimated_error": estimated,
           "outcome": "unchecked" if met is None else "met" if met else "not met",
           "met": met, "unchecked": why or None, "refined": first is not None,
           "note": note or None}
    if first is not None:
        out["first"] = {"overrides": list(first[0].overrides), "step": first[0].step,
                        "estimated_error": first[1]}
    return out


def request_text(req: dict) -> list[str]:
    """The terminal's lines of a request; the last says its outcome."""
    pct = f"{100 * req['accuracy']:.3g} %"

    def step(x):
        return f"rtol {x:.3g}" if req["scheme"] == "monolithic" else f"{x:.3g} s in contact"
    lines = [f"accuracy asked {pct} ({req['from']}): {req['why']}"]
    if req["refined"]:
        f = req["first"]
        lines.append(f"  the first run, at {step(f['step'])}, was estimated at "
                     f"{100 * f['estimated_error']:.2g} %: refined once, to {step(req['step'])}")
    if req.get("note"):
        lines.append(f"  {req['note']}")
    if req["caveat"]:
        lines.append(f"  caveat: {req['caveat']}")
    outcome = req.get("outcome") or ("unchecked" if req["met"] is None else
                                     "met" if req["met"] else "not met")
    if outcome == "unchecked":
        lines.append(f"  unchecked: {req['unchecked']}")
    else:
        lines.append(f"  estimated {percent(req['estimated_error'], req['accuracy'])} on "
                     f"{req['judged_on']}, asked {pct}: {outcome}")
    return lines


def percent(x: float, asked: float) -> str:
    """``x`` in percent at two digits, or more where two would show it equal
    to ``asked`` (an estimate just past the accuracy asked)."""
    for digits in (2, 3, 4, 6):
        text = f"{100 * x:.{digits}g}"
        if x == asked or text != f"{100 * asked:.{digits}g}":
            return f"{text} %"
    return f"{100 * x:.8g} %"
