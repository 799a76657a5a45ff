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
   the estimate says it is not met, :func:`refined` asks the model once
   more for the accuracy scaled by how far the estimate missed (``X * X /
   estimate``, times the model's safety factor), and that run is the one
   kept.  Where the estimate is not reliable (a count that differs in the
   companion, the monolithic scheme's no companion), the request is said
   to be unchecked, with why, and nothing is refined.

What was asked, chosen, estimated and decided is the summary's
``accuracy.request`` (:func:`request_record`).
"""
from __future__ import annotations

import warnings

__all__ = ["plan", "verdict", "judged", "refined", "request_record", "request_text", "asked"]


def asked(scene, flag) -> tuple[float | None, str]:
    """The accuracy a run is asked for: ``flag`` (``--accuracy``, a string
    or a number) wins over the scene's ``scheme.accuracy``; ``(None, "")``
    when neither gives one.  Returns ``(accuracy, where it came from)``."""
    from cosim.scene.checks import parse_accuracy
    if flag is not None:
        return parse_accuracy(flag, "--accuracy"), "--accuracy"
    table = scene.data.get("scheme", {})
    if isinstance(table, dict) and "accuracy" in table:
        return parse_accuracy(table["accuracy"], "scheme.accuracy"), "scheme.accuracy"
    return None, ""


def plan(path, variant, overrides, accuracy: float, scheme=None, first=None):
    """The scene loaded with the scheme and steps :func:`choose` picks for
    ``accuracy``: ``(scene, choice)``; ``scheme``, when given, is the only
    candidate; ``first``: the scene as given, when the caller loaded it."""
    from cosim.scene.load import load_scene
    from cosim.studies.choose import choose

    if first is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")      # shown again when the chosen scene loads
            first = load_scene(path, variant, list(overrides), scheme)
    choice = choose(first, accuracy, schemes=[scheme] if scheme else None)
    return _load(path, variant, overrides, choice), choice


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


def refined(path, variant, overrides, choice, estimated: float):
    """The scene and choice of the one refinement: the model asked for
    ``X * X / estimated`` (what it must aim at for the run to land on X,
    when its prediction missed by ``estimated / X``), the scheme kept, and
    the step no longer than the first times ``(SAFETY X / estimated) **
    (1 / p)``, ``p`` the scheme's lower order in
    :data:`cosim.studies.estimate.ORDERS` (the error falls as the step to
    that power)."""
    from cosim.scene.load import load_scene
    from cosim.studies.choose import choose

    from cosim.studies.choose import SAFETY
    from cosim.studies.estimate import ORDERS

    target = choice.accuracy * min(1.0, choice.accuracy / estimated)
    # the estimate's own order says how much shorter the step must be (the
    # model's step may be capped at the first one, so asking it alone may not
    # shorten it)
    p = min(ORDERS[choice.scheme].values())   # a scheme with an estimate has orders
    at_most = choice.step * (SAFETY * choice.accuracy / estimated) ** (1.0 / p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        first = load_scene(path, variant, list(overrides), choice.scheme)
    again = choose(first, target, choice.knob.contact, schemes=[choice.scheme],
                   at_most=at_most)
    return _load(path, variant, overrides, again), again


def request_record(accuracy: float, source: str, choice, estimated, why: str,
                   first=None, scene=None) -> dict:
    """The summary's ``accuracy.request``.

    ``first`` is ``(choice, estimated)`` of the run a refinement replaced.
    ``met`` is True or False when the estimate was reliable, else None
    (``unchecked`` says why)."""
    out = {"accuracy": accuracy, "from": source, "scheme": choice.scheme,
           "overrides": list(choice.overrides), "step": choice.step,
           "contact": choice.knob.contact, "judged_on": judged(choice, scene),
           "predicted_error": dict(choice.predicted_error),
           "why": choice.why, "caveat": choice.caveat, "estimated_error": estimated,
           "met": None if estimated is None else bool(estimated <= accuracy),
           "unchecked": why or None, "refined": first is not None}
    if first is not None:
        out["first"] = {"overrides": list(first[0].overrides), "step": first[0].step,
                        "estimated_error": first[1]}
    return out


def request_text(req: dict) -> list[str]:
    """The terminal's lines of a request."""
    pct = f"{100 * req['accuracy']:.3g} %"

    def step(x):
        return f"rtol {x:.3g}" if req["scheme"] == "monolithic" else f"{x:.3g} s in contact"
    lines = [f"accuracy asked {pct} ({req['from']}): {req['why']}"]
    if req["refined"]:
        f = req["first"]
        lines.append(f"  the first run, at {step(f['step'])}, was estimated at "
                     f"{100 * f['estimated_error']:.2g} %: refined once, to {step(req['step'])}")
    if req["estimated_error"] is None:
        lines.append(f"  not checked: {req['unchecked']}")
    else:
        verdict_ = "met" if req["met"] else "NOT met after one refinement" if req["refined"] \
            else "NOT met"
        lines.append(f"  estimated {100 * req['estimated_error']:.2g} % on {req['judged_on']}: "
                     f"{verdict_}")
    if req["caveat"]:
        lines.append(f"  caveat: {req['caveat']}")
    return lines
