"""The largest macro step ``cosim info`` calls stable: a step that runs.

Two stages.  The *model bound* of a contact an explicit scheme exchanges
(``coupler``) or hands to a host (hosted) is the largest step safe on its
coupled linearisation (:mod:`cosim.core.stability`: both sides' port modes,
a structure's kept modes included), and for a coupler contact no larger than
the pre-flight check's own bound (:mod:`cosim.core.preflight`), which a run
would refuse.  The model cannot see everything a run meets: the force that
is never tensile, the contact seen closed only at the first communication
point after it closed (its penetration and the dashpot's force then appear
at once), a sustained contact's slow drift, a nonlinear law's stiffness
growing with the penetration, a hosted contact's motion extrapolated inside
its host.  A 1 kg pendulum on a tensioned cable (Kelvin-Voigt, damping ratio
0.5 against the cable's local mass) that the model judges safe under
Gauss-Seidel can be stopped by the guard at that step when it rests on the
cable long enough; a few halvings later it runs (``tests/test_stable_step.py``
runs such scenes at 0.9 times the step confirmed).

So the bound is then *confirmed*: the scene runs to ``t_end`` with that
scheme and every step equal to the smallest model bound of its contacts
(``scheme.macro_step`` and, if the scene gives one, ``scheme.contact_step``),
writing nothing, under its own guard; a run the guard (or anything) stops is
tried again at half the step, as long as the runs' integrator steps, counted
before each starts (:meth:`cosim.Scene.work`, an upper bound), stay within
:data:`CONFIRM_STEPS`.  A budget in counted steps, not in CPU time, makes the
verdict the same on every machine.
A confirmed step is the one ``cosim info`` prints as ``runs``; otherwise it
prints the model bound as a *necessary bound only* and says why (the budget
would be passed, the run could not be made).
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from cosim.core import preflight, stability
from cosim.core.preflight import stiffest_normal

__all__ = ["model_bound", "second_side", "confirm", "CONFIRM_STEPS", "HALVINGS", "RUNS",
           "NECESSARY"]

#: integrator steps (counted before each run, :meth:`cosim.Scene.work`) the
#: runs that confirm one scheme's step may make together: a few seconds of
#: CPU (60 to 260 us a step on the shipped and test scenes)
CONFIRM_STEPS = 5e4

#: most times a step the run refuses is halved
HALVINGS = 8

#: the kinds of a printed step
RUNS, NECESSARY = "runs", "necessary bound only"


def second_side(system, c: int, scheme_cls, sequence=None) -> np.ndarray | None:
    """Under Gauss-Seidel, the coupled modes (:func:`cosim.core.stability.
    side_mask`) of the side of contact ``c`` that steps after its partner
    (``sequence``: the scheme's order of subsystem names, else their order
    in the scene; a rigid partner has always stepped); None otherwise."""
    if scheme_cls.name != "gauss_seidel":
        return None
    ln = system.links[c]
    b = stability.side_mask(system, c)
    subs = system.subsystems
    if subs[ln.sub_a].rigid or subs[ln.sub_b].rigid:
        return np.ones(len(b), bool)
    names = list(sequence) if sequence else [system.names[s] for s in range(len(subs))
                                               if not subs[s].rigid]
    rank = {n: i for i, n in enumerate(names)}
    ra = rank.get(system.names[ln.sub_a], math.inf)
    rb = rank.get(system.names[ln.sub_b], math.inf)
    return b if ra < rb else ~b


def model_bound(system, c: int, scheme_cls, order: int, gain: float, t_end: float,
                partner_first: bool, sequence=None) -> float | None:
    """Contact ``c``'s model bound [s] under an explicit scheme (module
    docstring), or None when the scheme does not limit the contact: an
    implicit scheme, or a contact its moving side resolves against a rigid
    partner inside its own integrator.  A hosted contact is judged as if
    exchanged by Jacobi."""
    ln = system.links[c]
    if not scheme_cls.explicit:
        return None
    if c not in set(int(r) for r in system.coupler) and c not in system.hosted:
        return None
    k, cd = stiffest_normal(ln)
    w, d, p = stability.coupled_modes(system, c)
    if not len(p) or not float(p @ p) > 0:
        return None
    second = None if c in system.hosted else second_side(system, c, scheme_cls, sequence)
    if second is not None and order == 0 and not (~second).any():
        second = None                      # held against a rigid partner: as Jacobi
    bound = stability.largest_safe_step_coupled(w, d, p, k, cd, order, gain,
                                                False, t_end, second)
    if c not in system.hosted:             # the pre-flight check refuses above its own
        m = 1.0 / float(p @ p)
        bound = min(bound, preflight.largest_safe_step(
            m, k, cd, 10.0 * math.pi / math.sqrt(k / m), order, gain, partner_first))
    return bound


def _at_step(scene, scheme: str, step: float):
    """The scene under ``scheme`` with every step ``step`` [s], validated as
    a file would be (:func:`cosim.scene.load._validate`)."""
    from cosim.scene.load import _validate

    data = copy.deepcopy(scene.data)
    sch = data.setdefault("scheme", {})
    sch["name"] = scheme
    sch["macro_step"] = float(step)
    if "contact_step" in sch:
        sch["contact_step"] = float(step)
    return _validate(data, Path(scene.path), scene.variant, True)


def _run(scene) -> tuple[str, str]:
    """Run ``scene`` to its end under its guard, writing nothing: ``("ran",
    "")`` or ``("stopped", message)``."""
    from cosim.core.guard import Guard
    from cosim.core.recorder import Recorder
    from cosim.errors import SimulationError, UnsafeStepError
    from cosim.scene.load import SceneError

    try:
        system, sch = scene.build()
        auto = False if sch.name == "monolithic" else [
            c not in system.embedded for c in range(system.n_contacts)]
        rec = Recorder(system, scene.name, sch.name, scene.t_end, every=scene.output_every,
                       auto_edges=auto, guard=Guard(system, scene.guard))
        sch.run(system, scene.t_end, rec)
    except (SimulationError, UnsafeStepError, SceneError) as exc:
        return "stopped", " ".join(str(exc).split())
    return "ran", ""


def confirm(scene, scheme: str, step: float,
            budget: float = CONFIRM_STEPS) -> tuple[float | None, str]:
    """The largest of ``step``, ``step / 2``, ... (at most :data:`HALVINGS`
    halvings) at which ``scene`` runs to its end under ``scheme`` without a
    stop, its runs making at most ``budget`` integrator steps together (as
    counted before each starts).

    Returns
    -------
    step : float or None
        The step that ran, or None.
    why : str
        Why none was confirmed ("" when one was).
    """
    spent = 0.0
    h = step
    last = ""
    for _ in range(HALVINGS + 1):
        try:
            trial = _at_step(scene, scheme, h)
            work = float(trial.work().steps)
        except Exception as exc:         # a step the scene's checks refuse (work cap)
            return None, f"the scene at {h:.3g} s cannot run: {' '.join(str(exc).split())}"
        if spent + work > budget:
            return None, ((last + "; ") if last else "") + (
                f"a run at {h:.3g} s would make up to {work:.3g} integrator steps, past the "
                f"{budget - spent:.3g} left of the {budget:.3g} that confirm a step")
        spent += work
        outcome, message = _run(trial)
        if outcome == "ran":
            return h, ""
        last = f"a run at {h:.3g} s was stopped: {message[:300]}"
        h *= 0.5
    return None, last
