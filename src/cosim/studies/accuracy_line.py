"""The terminal's line of a run's error estimate (:mod:`cosim.studies.estimate`),
and the estimate's word for a run where no companion runs (:data:`BLIND`, which
the estimate writes and this line reads: ``cosim.studies.estimate.BLIND``)."""
from __future__ import annotations

__all__ = ["accuracy_text", "number", "BLIND"]

#: why no companion runs where nothing it gives could be read
BLIND = ("no companion: every contact that closed (the strike among them) lies past the "
         "asymptotic range at the run's own step, or is stepped by a side that keeps its "
         "step in the companions, so nothing they give could be read")


def _pct(x: float) -> str:
    """A relative error in percent; below 1e-8 (round-off) as such."""
    return "< 1e-6 %" if x < 1e-8 else f"{100 * x:.2g} %"


def number(e: dict) -> str:
    """One reliable entry's estimate: ``0.19 % (order 1.1)`` where its order
    was measured, ``<= 0.2 % (bound)`` where it was not (a bound at order
    1), ``< 1e-6 %`` at round-off."""
    rel = e["relative_error"]
    if rel < 1e-8:
        return _pct(rel)
    if e.get("kind") == "bound":
        return f"<= {_pct(rel)} (bound)"
    return f"{_pct(rel)} (order {e['order']:.2g})" if e.get("order") is not None else _pct(rel)


def _head(acc: dict) -> str:
    keys = []
    for k in list(acc.get("refined", {})) + list(acc.get("coarsened", {})):
        name = k.rsplit(".", 1)[-1]
        if name != "approach_horizon" and name not in keys:      # kept, not scaled
            keys.append(name)
    factors = [c["factor"] for c in acc.get("companions", ())]
    at = " and ".join(f"{f:.3g}x" for f in sorted(factors))
    return (f"accuracy (companion{'s' if len(factors) > 1 else ''} at {at} the step: "
            f"{', '.join(keys)})")


def accuracy_text(acc: dict) -> str:
    """The terminal's line: the estimates that are reliable (each with its
    measured order, or said to be a bound), no number for one that is not,
    and what was left out and why (the first reason, the rest in
    summary.json)."""
    if acc["companion"].get("message") == BLIND:
        why = [w for w in acc["why"] if w != BLIND] or [BLIND]
        more = f"; {len(why) - 1} more in summary.json" if len(why) > 1 else ""
        return f"accuracy: not reliable, no companion run ({why[0]}{more})"
    if acc.get("skipped"):                 # a signal stopped the companions
        return f"accuracy: {acc['skipped']}"
    if acc["companion"].get("status") == "not run":
        return f"accuracy: {acc['companion']['message']}"
    parts, missing, reasons = [], [], []
    for name, c in acc["contacts"].items():
        if c["count"]["value"] == 0:
            continue
        pk, im = c["peak_penetration"], c["impulse"]
        if pk["reliable"] and im["reliable"]:
            parts.append(f"{name} peak {number(pk)}, impulse {number(im)}")
        else:
            missing.append(name)
            reasons.append((pk if not pk["reliable"] else im).get("why"))
    joints = [(k, e) for k, e in acc["exit"].items() if k != "at"]
    exits = [(k, e) for k, e in joints if e["reliable"]]
    if exits:
        k, e = max(exits, key=lambda ke: ke[1]["relative_error"])
        parts.append(f"exit {k} {number(e)}" + (
            f" (worst of {len(exits)} joints)" if len(exits) > 1 else ""))
    left = [(k, e) for k, e in joints if not e["reliable"]]
    if left:
        missing.append("exit" if not exits else "exit " + ", ".join(k for k, _ in left))
        reasons.append(left[0][1].get("why"))
    counts = [c["count"]["robust"] for c in acc["contacts"].values()]
    if not all(counts):
        missing.append("counts")
    reasons = [w for w in reasons if w] + list(acc["why"])
    why = reasons[0] if reasons else "see summary.json"
    if not parts:
        return f"accuracy: not reliable ({'; '.join(acc['why']) or why})"
    if not missing:
        return f"{_head(acc)}: {'; '.join(parts)}; counts robust"
    return f"{_head(acc)}: {'; '.join(parts)}; not estimated: {', '.join(missing)} ({why})"
