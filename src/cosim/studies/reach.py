"""What an accuracy request can reach, and the frequency its check reads.

:func:`reachable` is the smallest relative accuracy a request may ask of a
scene's contact: the schemes' error floors (:data:`cosim.studies.choose.MODEL`),
the monolithic scheme's error at the finest tolerance its solvers honour
(:data:`MIN_RTOL`), and never below :data:`DOUBLE_PRECISION_FLOOR`.  A
request below it is refused before anything runs (:func:`refusal` names the
flag or key that asked).

:func:`check_omega` is the frequency the run's error estimate judges a
contact's step with: :func:`cosim.studies.companion.contact_omega`, the
companion's own function, so that a step the choice caps to be checkable is
one the companion checks.
"""
from __future__ import annotations

import math

from cosim.core.schemes.base import MIN_SOLVER_RTOL
from cosim.studies.companion import contact_omega
from cosim.studies.error_model import MONOLITHIC_MODEL, SAFETY, _bound, _params

__all__ = ["DOUBLE_PRECISION_FLOOR", "MIN_RTOL", "reachable", "refusal", "check_omega"]

#: the smallest relative accuracy a request may ask of any scene.  A double
#: holds a number to eps = 2.2e-16 relative; each step of a run rounds its
#: state at least once, and the shortest runs the model was measured on take
#: about 1e4 steps: their quantities carry up to 1e4 eps = 2.2e-12 of
#: rounding (a random walk of the roundings, sqrt(1e4) eps = 2e-14, is the
#: least of it), and a companion's difference, which the estimate reads, as
#: much again.  Below 1e-12 what a run and its estimate report is round-off,
#: not the method's error, whatever the step.
DOUBLE_PRECISION_FLOOR = 1e-12

#: the smallest ``rtol`` the monolithic scheme's solvers honour: scipy's
#: ``solve_ivp`` raises a smaller one to ``100 eps`` (2.2e-14) and runs
#: at that; the scene refuses one below it
#: (:data:`cosim.core.schemes.base.MIN_SOLVER_RTOL`)
MIN_RTOL = MIN_SOLVER_RTOL


def reachable(k, schemes) -> float:
    """The smallest relative accuracy a request may ask of a contact
    (``k``, :func:`cosim.studies.choose.knob`) with ``schemes``: the least,
    over the schemes the model covers, of the largest error it predicts at
    the finest step or tolerance the scheme can be given (a co-simulation
    scheme's error ``floor`` in :data:`~cosim.studies.choose.MODEL`; the
    monolithic scheme's error at :data:`MIN_RTOL`), over
    :data:`~cosim.studies.choose.SAFETY`, and never below
    :data:`DOUBLE_PRECISION_FLOOR`.  A step's cost (``guard.max_steps``) is
    not counted here: the pre-flight check refuses a step too short for it."""
    best = math.inf
    for s in schemes:
        if s == "monolithic":
            e = max(_bound(v, MIN_RTOL) for v in MONOLITHIC_MODEL.values())
        else:
            par = _params(k.regime, s)
            if par is None:
                continue
            e = max(floor for _, _, floor in par.values())
        best = min(best, e / SAFETY)
    return max(DOUBLE_PRECISION_FLOOR, best)


def refusal(scene, source: str, text: str):
    """A :class:`~cosim.scene.checks.SceneError` about an accuracy asked by
    ``source`` (``--accuracy``, ``scheme.accuracy``, or a Python argument
    such as ``accuracy``): at that key of the scene, or naming the flag or
    argument, which is not a key of it."""
    from cosim.scene.checks import SceneError
    if source == "scheme.accuracy":
        return SceneError(scene.path, source, text)
    return SceneError(scene.path, "", f"{source} {text}")


def _hosted(system, c: int) -> bool:
    """Whether contact ``c`` is stepped by a side's own integrator against a
    rigid partner (else the sides exchange it)."""
    ln = system.links[c]
    return ln.placement == "embedded" and any(
        system.subsystems[s].rigid for s in (ln.sub_a, ln.sub_b))


def check_omega(system, c: int, omegas: dict | None = None) -> float:
    """The frequency [rad/s] the companion judges contact ``c``'s step with
    (:func:`~cosim.studies.companion.contact_omega`, the system at its
    initial pose): the largest over the contacts the sides exchange where
    ``c`` is one (their largest omega h sets the companion's factor), else
    over the contacts ``c``'s host steps (the largest sets whether the host's
    step is coarsened); nan where none has a linear stiffness.  ``omegas``:
    contact index -> that frequency, read before (at the initial pose) by
    a caller that runs the system meanwhile."""
    if _hosted(system, c):
        own = system.embedded[c][0]
        group = [d for d, (host, _) in system.embedded.items() if host == own]
    else:
        group = [d for d in range(len(system.links)) if not _hosted(system, d)]
    ws = [w for d in group if not system.links[d].contact.law.rigid
          for w in [contact_omega(system, d) if omegas is None else omegas[d]]
          if math.isfinite(w)]
    return max(ws) if ws else math.nan
