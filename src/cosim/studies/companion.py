"""The companion runs of an error estimate: which steps they take.

:func:`coarsened` makes a companion's scene: the run's steps that set its
accuracy ``factor`` times longer (``factor`` > 1, a coarser companion) or
shorter (``factor`` < 1, a finer one; see :mod:`cosim.studies.estimate`), a
side's own step only where a contact it hosts stays below omega h =
:data:`OMEGA_H_MAX` at the coarsest step of the ladder.  :func:`ladder_plan`
says which companions can tell the run's error: the coarser one only where
the companion's step in every exchanged contact stays in the range in which
the schemes' errors fall as one power of the step
(:data:`ASYMPTOTIC_OMEGA_H`); a contact past it at the coarser step but
within it at the run's is read from the finer companion alone; one past it
at the run's own step is not read.  omega is a contact's frequency from its
linearised stiffness and the two sides' mobility along its normal at the
initial pose.
"""
from __future__ import annotations

import copy
import math
import warnings
from pathlib import Path

__all__ = ["coarsened", "ladder_plan", "exchanged_omega_h", "contact_omega",
           "OMEGA_H_MAX", "UNSEEN_OMEGA_H", "ASYMPTOTIC_OMEGA_H", "MIN_FACTOR"]

#: the largest omega h [rad] of an exchanged contact's step at which the
#: schemes' errors still fall as one power of the step, from
#: ``benchmarks/results/accuracy_model`` (C's peak and the arm's exit
#: velocity against the bench's reference at omega h = 0.1, 0.2, 0.4, 0.8):
#: from 0.1 to 0.4 Gauss-Seidel's peak error falls with slopes 2.0 to 4.1 on
#: three_mass f1 to f1000 and beam_impact; from 0.4 to 0.8 the slope drops to
#: 1.4, 0.4 and 1.6 on three_mass f10, f100 and f1000, where C closes 8 or
#: 9 times (one impact's error moves another's onset)
ASYMPTOTIC_OMEGA_H = 0.4

#: the margin below :data:`ASYMPTOTIC_OMEGA_H` that the a-priori choice of
#: a step keeps (:data:`cosim.studies.choose.CHECKABLE`): a run at omega h
#: up to 0.4 / 2 has its coarser companion within the range at the default
#: ladder ratio sqrt(2), and at the ratio 2 that ``cosim run --accuracy``
#: tries where the first estimate gave no number
MIN_FACTOR = 2.0


def built(scene):
    """``scene`` built, its warnings (said by the run) not said again."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return scene.build()[0]


def contact_omega(system, c: int) -> float:
    """Contact ``c``'s angular frequency [rad/s] from its linearised normal
    stiffness (:func:`cosim.core.preflight.stiffest_normal`) and the two
    sides' mobility along its normal at the system's present pose; inf for a
    law without a linear stiffness or sides without mobility."""
    from cosim.core.preflight import stiffest_normal
    mob = system.contact_mobility(c)
    k = stiffest_normal(system.links[c])[0]
    return math.sqrt(k * mob) if math.isfinite(k) and mob > 0 else math.inf


def exchanged_omega_h(scene, system) -> dict:
    """Contact name -> omega h at the run's step in contact, for each
    contact that the sides exchange each macro step (placed ``coupler``, or
    embedded in a side against a moving partner) and whose law has a linear
    stiffness: the step is the scheme's ``contact_step`` where the scene
    sets one, else its ``macro_step`` (as :func:`cosim.studies.choose.knob`
    takes it)."""
    opts = scene.scheme_options
    h = opts.get("contact_step") or opts.get("macro_step")
    if not h:
        return {}
    out = {}
    for c, ln in enumerate(system.links):
        if ln.contact.law.rigid:
            continue
        sides = (system.subsystems[ln.sub_a], system.subsystems[ln.sub_b])
        if ln.placement == "embedded" and any(s.rigid for s in sides):
            continue                      # a side's integrator steps it: its own step
        if c in system.circles:           # a spread penalty: no one spring's omega
            continue
        w = contact_omega(system, c)
        if math.isfinite(w):
            out[ln.contact.name] = w * h
    return out


def ladder_plan(r: float, omega_h: dict) -> tuple[dict, dict]:
    """Which exchanged contacts the companions of a ladder ``h/r, h, r h``
    can tell the error of, from each one's omega h at the run's step
    (:func:`exchanged_omega_h`).

    Returns
    -------
    (dict, dict)
        The contacts to be read from the finer companion alone (name ->
        omega h at ``r h``: past :data:`ASYMPTOTIC_OMEGA_H` there, not at the
        run's step), and those past it at the run's own step (name -> omega
        h there: not read at all).
    """
    run_past = {c: w for c, w in omega_h.items() if w > ASYMPTOTIC_OMEGA_H}
    finer_only = {c: w * r for c, w in omega_h.items()
                  if w * r > ASYMPTOTIC_OMEGA_H and c not in run_past}
    return finer_only, run_past


def coarsened(scene, factor: float, kept: list | None = None, system=None,
              judged_at: float | None = None):
    """A copy of ``scene`` whose accuracy-setting steps are ``factor`` times
    longer (see the module), and the keys changed (key path -> new value).

    Parameters
    ----------
    scene : Scene
    factor : float
        > 0 and not 1: > 1 for a coarser companion, < 1 for a finer one.
    judged_at : float, optional
        The factor at which a side's own step is judged (whether a contact
        it hosts stays below :data:`OMEGA_H_MAX`): the coarsest of the
        ladder, so that every companion scales the same steps (default:
        ``max(factor, 1)``).
    system : CoupledSystem, optional
        ``scene`` built (built here if not given; only read).
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

    if not (isinstance(factor, (int, float)) and factor > 0 and factor != 1
            and math.isfinite(factor)):
        raise ValueError(f"`factor` must be a finite number > 0 other than 1, got {factor!r}")
    judged_at = max(factor, 1.0) if judged_at is None else judged_at
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
    if spec.options.get("contact_step"):
        # the window before a predicted onset that is stepped at contact_step stays as
        # long as the run's: its steps are r times longer, so there are r times fewer
        # (at r times the macro step as horizon there would be as many as in the run)
        own["approach_horizon"] = (spec.options.get("approach_horizon")
                                   or spec.options["macro_step"])
        changed[f"scheme.{spec.name}.approach_horizon"] = own["approach_horizon"]
    tol = spec.options.get("interface_tolerance")
    if tol:           # the controller's step goes as tol ** (1 / (order + 2)): r times longer
        own["interface_tolerance"] = min(tol * factor ** (spec.options.get(
            "extrapolation_order", 0) + 2), 0.5)
        changed[f"scheme.{spec.name}.interface_tolerance"] = own["interface_tolerance"]
    omega_h: dict = {}
    for side, ok in _coarsenable_sides(scene, judged_at, omega_h, system).values():
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


def _coarsenable_sides(scene, factor: float, omega_h: dict | None = None,
                       system=None) -> dict:
    """The sides whose own step sets the accuracy of a contact they host
    (a multibody side under ``rk4``, a structure that steps its closed
    contacts with ``contact_step``): name -> (spec, whether ``factor`` times
    that step keeps omega h <= :data:`OMEGA_H_MAX` for every contact it
    hosts (omega of the contact's linearised stiffness and the sides'
    mobility at the initial pose)).  A side that hosts no contact is
    coarsened too (its step sets only its own accuracy)."""
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
    system = system if system is not None else built(scene)
    omega = {name: 0.0 for name in steps}
    for c, (own, _) in system.embedded.items():
        host = system.subsystems[own].name
        if host not in omega:
            continue
        w = contact_omega(system, c)
        omega[host] = max(omega[host], w)
        if omega_h is not None:           # the contact's own omega h at the run's step
            omega_h[system.links[c].contact.name] = (host, w * steps[host][1])
    return {name: (side, omega[name] * factor * h <= OMEGA_H_MAX)
            for name, (side, h) in steps.items()}
