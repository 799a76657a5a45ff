"""`cosim verify SCENE`: what holds on any scene, checked on a run of it.

:func:`scene_checks` runs the scene under its scheme with the run's own
error estimate (:func:`cosim.studies.estimate.estimate_errors`: a companion
run with longer steps), the monolithic reference, and two copies whose
initial state is moved by +2 and -2 ulps
(:func:`cosim.studies.roundoff.perturbed`), and yields one
:class:`~cosim.studies.verify.Check` per claim:

- **energy ledger**: ``initial + supplied - final - dissipated`` is within
  what the run's estimate allows: the exit rates' and peaks' relative
  errors ``eps`` bound the energy a step may create to about ``2 eps`` of
  the energy scale (a kinetic energy ``m v^2 / 2`` off by ``2 dv / v``);
  and never below ten times the spread of the imbalance over the moved
  copies, nor one ulp of the energy scale per macro step (the run's own
  round-off).  A run whose estimate is not reliable
  is judged on round-off alone, and the line says so.
- **schemes agree**: each contact's peak penetration and each exit rate
  differ from the monolithic reference by at most :data:`SAFETY` times the
  run's estimate of its error (``relative_error``) plus the reference's own
  tolerance (``rtol``).  :data:`SAFETY` is 3, the agreement the estimate is
  held to on generated scenes (docs/accuracy.md).  An entry the estimate
  marks unreliable is not compared; the line names it and why.
- **counts robust**: every contact closes as many times in the moved copies
  as in the run.
- **estimate order confirmed**: where the estimate says it measured a
  quantity's order ``p`` on the run and its two companions (``kind``
  ``richardson``), the reference measures it again from the run's and the
  finer companion's actual errors, ``p_ref = log(e_run / e_finer) /
  log(r)``; the check fails where ``p_ref`` falls short of ``p`` by more
  than :data:`ORDER_SLACK` (the estimate then claims a faster convergence
  than the run has, and so too small an error), or where the finer
  companion is no closer to the reference than the run.  Errors within ten
  times the reference's tolerance cannot tell an order and are not judged;
  a quantity the estimate bounds (``kind`` ``bound``) claims no order and
  is listed as such.

A check that cannot be made (a monolithic scene: nothing to compare; no
reliable estimate; a scene without a nonzero initial value to move; no
order in the estimate) is *skipped*: it does not fail, and its line says
why (``SKIP``).
"""
from __future__ import annotations

import math
import warnings

from cosim.studies.verify import Check

__all__ = ["scene_checks", "SAFETY", "ORDER_SLACK", "ROUNDOFF_COPIES", "ROUNDOFF_MARGIN"]

#: how many times the run's own estimate the difference from the reference may be
SAFETY = 3.0

#: how far the order the reference measures may fall below the one the
#: estimate confirmed: over a factor sqrt(2) of the step, a relative noise of
#: 10 % on one of the two errors moves the measured order by 0.28, and an
#: order one too high makes a Richardson estimate sqrt(2) - 1 of the error
#: instead of 1: within :data:`SAFETY`
ORDER_SLACK = 1.0

#: the ulp offsets of the copies whose counts and imbalances are compared
ROUNDOFF_COPIES = (2, -2)

#: the ledger's tolerance is at least this many times the copies' spread
ROUNDOFF_MARGIN = 10.0


def _imbalance(summary) -> float:
    e = summary["energy"]
    return e["initial"] + e["supplied"] - e["final"] - e["dissipated"]


def _scale(summary) -> float:
    e = summary["energy"]
    return max(abs(e["initial"]), abs(e["initial"] + e["supplied"]), abs(e["final"]),
               abs(e["dissipated"]), 1e-300)


def _entries(acc: dict):
    """(label, entry) of every estimated peak and exit rate."""
    for name, c in acc.get("contacts", {}).items():
        if c["count"]["value"] > 0:
            yield f"peak of {name}", c["peak_penetration"], ("contacts", name)
    for joint, e in acc.get("exit", {}).items():
        if joint != "at":
            yield f"exit rate of {joint}", e, ("exit", joint)


def _run(scene, scheme=None):
    from cosim.scene.run import simulate
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(scene, scheme=scheme)


def scene_checks(scene, label: str | None = None):
    """Yield the :class:`~cosim.studies.verify.Check` s of ``scene`` (see
    the module).  ``label`` prefixes each check's name (the scene's name
    by default)."""
    from cosim.studies.estimate import estimate_errors
    from cosim.studies.roundoff import perturbed

    label = label or (scene.name + (f"/{scene.variant}" if scene.variant else "")
                      + f"/{scene.scheme}")
    res = _run(scene)
    if not res.success:
        yield Check(f"{label}: run", False,
                    f"the run did not finish ({res.status}): {' '.join(res.message.split())}")
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        acc = estimate_errors(scene, res)
    try:
        copies = [_run(perturbed(scene, k)) for k in ROUNDOFF_COPIES]
    except ValueError:                  # nothing to move
        copies = None
    yield _ledger(label, res, acc, copies)
    ref = None if scene.scheme == "monolithic" else _run(scene, "monolithic")
    yield _agreement(label, scene, res, acc, ref)
    yield _counts(label, res, copies)
    yield _order(label, scene, acc, ref)


def _ledger(label, res, acc, copies) -> Check:
    s = res.summary
    imb, scale = _imbalance(s), _scale(s)
    spread = (max(abs(_imbalance(c.summary) - imb) for c in copies if c.success)
              if copies and any(c.success for c in copies) else 0.0)
    # round-off: the copies' spread, and at least one ulp of the scale per step
    steps = max(1, int(s.get("macro_steps") or 1))
    floor = max(ROUNDOFF_MARGIN * spread, steps * 2.0 ** -52 * scale)
    eps = [e["relative_error"] for _, e, _ in _entries(acc)
           if e.get("reliable") and e.get("relative_error") is not None]
    if eps:
        tol, source = max(2.0 * max(eps) * scale, floor), (
            f"2 x the largest estimated relative error {max(eps):.3g} x the energy scale "
            f"{scale:.6g} J, or {ROUNDOFF_MARGIN:g} x round-off")
    else:
        why = "; ".join(acc.get("why", [])[:1]) or "no estimated quantity"
        tol, source = floor, (f"round-off only ({ROUNDOFF_MARGIN:g} x the moved copies' spread "
                              f"{spread:.3g} J, or an ulp of {scale:.6g} J per step): the "
                              f"estimate gives no error ({why})")
    ok = abs(imb) <= tol
    return Check(f"{label}: energy ledger", ok,
                 f"initial + supplied - final - dissipated = {imb:.3g} J, tolerance {tol:.3g} J "
                 f"({source})")


def _rtol(scene) -> float:
    """The monolithic reference's relative tolerance in ``scene``."""
    from cosim.core.schemes import COUPLING_SCHEMES
    table = scene.data.get("scheme", {}).get("monolithic", {})
    return (table.get("rtol") if isinstance(table, dict) else None) or \
        COUPLING_SCHEMES["monolithic"].options["rtol"].default


def _agreement(label, scene, res, acc, ref) -> Check:
    if scene.scheme == "monolithic":
        return Check(f"{label}: schemes agree", True,
                     "not applicable: the scene's scheme is the monolithic reference", True)
    if not ref.success:
        return Check(f"{label}: schemes agree", False,
                     f"the monolithic reference did not finish ({ref.status}): "
                     f"{' '.join(ref.message.split())[:200]}")
    rtol = _rtol(scene)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref_acc = _reference_values(scene, ref, acc)
    worst, skipped, compared = None, [], 0
    for what, e, key in _entries(acc):
        refv = ref_acc.get(key)
        if not e.get("reliable") or e.get("relative_error") is None:
            skipped.append(f"{what} ({e.get('why') or 'unreliable'})")
            continue
        if refv is None or not math.isfinite(refv) or refv == 0.0:
            skipped.append(f"{what} (no reference value)")
            continue
        actual = abs(e["value"] - refv) / abs(refv)
        allowed = SAFETY * e["relative_error"] + 10.0 * rtol
        compared += 1
        ratio = actual / allowed
        if worst is None or ratio > worst[0]:
            worst = (ratio, what, actual, allowed)
    if compared == 0:
        return Check(f"{label}: schemes agree", True,
                     "not checked: no reliable estimate to compare"
                     + (f" ({'; '.join(skipped)[:300]})" if skipped else ""), True)
    ratio, what, actual, allowed = worst
    detail = (f"{compared} compared; worst {what}: {actual:.3g} from the monolithic reference, "
              f"allowed {allowed:.3g} ({SAFETY:g} x its estimate + 10 x rtol)")
    if skipped:
        detail += f"; not compared: {'; '.join(skipped)[:300]}"
    return Check(f"{label}: schemes agree", ratio <= 1.0, detail)


def _reference_values(scene, ref, acc) -> dict:
    """The reference's peak of each contact and exit rate of each joint the
    estimate reads, read the same way (at the same contact's release)."""
    from cosim.scene.specs import MultibodySpec
    from cosim.studies.estimate import exit_rates
    out = {("contacts", n): c["peak_penetration"] for n, c in ref.summary["contacts"].items()}
    multibody = {s.name for s in scene.subsystems if isinstance(s, MultibodySpec)}
    from cosim.studies.strike import find_strike
    found = find_strike(scene, required=False)
    rates, _ = exit_rates(ref, multibody, found[0] if found else None)
    out.update({("exit", j): v for j, v in rates.items()})
    return out


def _counts(label, res, copies) -> Check:
    if copies is None:
        return Check(f"{label}: counts robust to round-off", True,
                     "not available: the scene has no nonzero initial value to move", True)
    mine = {n: c["count"] for n, c in res.summary["contacts"].items()}
    bad = []
    for k, c in zip(ROUNDOFF_COPIES, copies):
        if not c.success:
            bad.append(f"{k:+d} ulps: the run {c.status}")
            continue
        theirs = {n: v["count"] for n, v in c.summary["contacts"].items()}
        bad += [f"{n}: {mine[n]} vs {theirs.get(n)} at {k:+d} ulps"
                for n in mine if theirs.get(n) != mine[n]]
    counts = ", ".join(f"{n} {v}" for n, v in mine.items())
    return Check(f"{label}: counts robust to round-off", not bad,
                 (f"counts {counts} at " + ", ".join(f"{k:+d}" for k in ROUNDOFF_COPIES)
                  + " ulps too") if not bad else "; ".join(bad)[:400])


def _order(label, scene, acc, ref) -> Check:
    name = f"{label}: estimate order confirmed"
    entries = list(_entries(acc))
    bounds = [what for what, e, _ in entries if e.get("kind") == "bound"]
    claimed = [(what, e, key) for what, e, key in entries
               if e.get("kind") == "richardson" and e.get("order") is not None
               and e.get("finer") is not None]
    if not claimed:
        why = ("every quantity is a bound at order 1" if bounds else
               "the estimate measured no order" if entries else "no estimated quantity")
        return Check(name, True, f"not applicable: {why}", True)
    if ref is None or not ref.success:
        return Check(name, True, "not checked: no monolithic reference to measure it against",
                     True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        refs = _reference_values(scene, ref, acc)
    r, noise = float(acc["factor"]), 10.0 * _rtol(scene)
    judged, bad, unseen = [], [], []
    for what, e, key in claimed:
        refv = refs.get(key)
        if refv is None or not math.isfinite(refv) or refv == 0.0:
            unseen.append(what)
            continue
        e_run = abs(e["value"] - refv) / abs(refv)
        e_fine = abs(e["finer"] - refv) / abs(refv)
        if min(e_run, e_fine) <= noise:
            unseen.append(what)
            continue
        p_ref = math.log(e_run / e_fine) / math.log(r)
        judged.append(f"{what} {e['order']:.2g} (reference {p_ref:.2g})")
        if not p_ref >= e["order"] - ORDER_SLACK:
            bad.append(f"{what}: the estimate confirmed order {e['order']:.3g}, the reference "
                       f"measures {p_ref:.3g} (errors {e_run:.3g} at the run's step, "
                       f"{e_fine:.3g} at {1 / r:.2g} of it)")
    tail = ""
    if unseen:
        tail += f"; within the reference's tolerance, not judged: {', '.join(unseen)}"
    if bounds:
        tail += f"; bounds at order 1 (no order claimed): {', '.join(bounds)}"
    if bad:
        return Check(name, False, "; ".join(bad)[:400] + tail[:200])
    if not judged:
        return Check(name, True, "not judged: every error claimed lies within the "
                     "reference's tolerance" + tail[:300], True)
    return Check(name, True, "orders " + ", ".join(judged)[:300] + tail[:300])