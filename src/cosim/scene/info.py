"""What a run will meet, before it runs: `cosim info`.

A contact's reduced mass, and with it its frequency and contact time,
depends on the pose: a robot's arm stretched out at the start may strike
folded.  :func:`scene_info` therefore finds where each contact first closes
by running the scene, with its own scheme, until every contact has closed
once, and evaluates them there; the run stops at the end time or after
:data:`FIRST_TOUCH_BUDGET_S` of CPU time, whichever comes first, and a
contact it did not see close is evaluated at the initial pose.  Each contact
says which pose it used.  The largest stable steps are judged at the initial
pose: an integrator's as the build's check does; an explicit scheme's macro
step on the coupled system and confirmed by a run of the scene
(:mod:`cosim.scene.stable_step`), or marked a necessary bound only.

An FMU's code runs only when asked (``run_fmu``, ``cosim info --run-fmu``):
by default an FMU side is read from its model description alone
(:class:`~cosim.sides.fmu_description.DescribedFMU`), no run looks for the
first touch, and what only the FMU could tell (a port mass it reports when
it runs, and with it a contact's frequency, contact time and stable steps)
is listed under ``not_evaluated`` with the reason.  Every text taken from
a model description is escaped and capped (:func:`cosim.errors.shown`).
"""
from __future__ import annotations

import math
import time

from cosim.core import preflight
from cosim.core.preflight import contact_time, stiffest_normal
from cosim.core.schemes import COUPLING_SCHEMES
from cosim.errors import shown
from cosim.scene.stable_step import CONFIRM_STEPS, NECESSARY, RUNS, confirm, model_bound

__all__ = ["scene_info", "fmu_info", "first_touch", "contact_time", "FIRST_TOUCH_BUDGET_S"]

#: [s] CPU time the run that finds each contact's first touch may take
FIRST_TOUCH_BUDGET_S = 2.0

#: fewest samples in a contact's duration that draw it as a shape
SAMPLES_TO_DRAW = 4

#: longest text of a model description that info shows [characters]
FMU_TEXT_LIMIT = 200

#: why a scene with an FMU is not run to find where its contacts first close
NOT_RUN = ("finding where it closes would run the FMU's code; `cosim info --run-fmu` "
           "runs it")


def _sampling(system, c, scene, contact_time: float, name: str) -> dict:
    """How often the series will sample contact ``c`` while it is closed,
    against its duration ``contact_time`` [s].

    A co-simulation samples at each communication point: every
    ``contact_step`` while a contact the scheme exchanges (coupler or
    hosted) is closed, when step control is on, else every ``macro_step``;
    the monolithic scheme every ``output_interval`` (``t_end / 1000`` by
    default) plus the instants of its switch and peak events.  ``output.every``
    keeps one sample in that many."""
    opts, every = scene.scheme_options, scene.output_every
    monolithic = scene.scheme == "monolithic"
    if monolithic:
        dt, key = opts.get("output_interval") or scene.t_end / 1000.0, \
            "scheme.monolithic.output_interval"
    else:
        dt, key = opts.get("macro_step"), "scheme.macro_step"
        if dt is None:
            return {}
        step = opts.get("contact_step")
        if step is not None and c in set(int(r) for r in system.exchanged):
            dt, key = min(dt, step), "scheme.contact_step"
    dt *= every
    n = contact_time / dt
    out = {"sampling_interval_s": dt, "samples_per_contact": n}
    if n < SAMPLES_TO_DRAW:
        keys = f"`{key}`" + (" or `output.every`" if every > 1 else "")
        extra = (" (its switch and peak events are sampled too)" if monolithic else "")
        out["sampling_note"] = (
            f"the series sample contact `{name}` every {dt:.3g} s{extra}, {n:.3g} times in its "
            f"contact time of {contact_time:.3g} s: too coarse to draw it. `peak/{name}` in "
            f"the series and `peak_penetration` in the summary still hold its peak. To draw "
            f"it, sample at most every {contact_time / SAMPLES_TO_DRAW:.3g} s ({keys}).")
    return out


class _Touched(Exception):
    """Every contact sought has closed (or the budget is spent): the probe ends."""


def first_touch(scene, budget_s: float = FIRST_TOUCH_BUDGET_S,
                contacts=None, built=None) -> tuple[dict, str | None]:
    """Where each contact (of ``contacts``, names, if given) first closes in
    a run of ``scene`` with its scheme.

    The run goes until every contact sought has closed once, the end time, or
    ``budget_s`` of CPU time; it writes nothing.  A contact closed at the
    start closes at t = 0.  It runs every side, an FMU's code included
    (:func:`scene_info` calls it for a scene with an FMU only when asked).
    ``built``: the scene's ``(system, scheme)``, built and not yet run, to
    run instead of a build of its own (it is run: read what the caller
    needs of its initial state before).

    Returns
    -------
    touches : dict
        Contact index -> ``(t, mobility)``: the time it closed [s] and its
        ports' mobility ``1 / reduced mass`` [1/kg] in the state the run
        had when it reported that (at the end of the step it closed in; the
        pose moves little within a step).
    why_not : str or None
        Why some contacts were not seen to close: the run ended, ran out of
        budget, or could not run (its message).
    """
    from cosim.core.recorder import Recorder
    from cosim.errors import SimulationError, UnsafeStepError

    system, sch = scene.build() if built is None else built
    sought = {c for c, ln in enumerate(system.links) if not ln.contact.law.rigid
              and (contacts is None or ln.contact.name in contacts)}
    touches: dict = {}
    if not sought:
        return touches, None
    if budget_s <= 0:
        return touches, "no run was made to find where it closes"
    cpu0 = time.process_time()

    class Probe(Recorder):
        reads_live_system = True        # the mobility at the touch, from the system

        def edge(self, c, t, on):
            if on and c in sought and c not in touches:
                touches[c] = (float(t), system.contact_mobility(c))
                if len(touches) == len(sought):
                    raise _Touched
            super().edge(c, t, on)

        def record(self, t, *args, **kw):
            if time.process_time() - cpu0 > budget_s:
                raise _Touched
            super().record(t, *args, **kw)

        def record_block(self, t, *args, **kw):     # the sampled path's samples
            if time.process_time() - cpu0 > budget_s:
                raise _Touched
            super().record_block(t, *args, **kw)

    mono = sch.name == "monolithic"
    auto = False if mono else [c not in system.embedded for c in range(system.n_contacts)]
    probe = Probe(system, scene.name, sch.name, scene.t_end, every=2**62, auto_edges=auto)
    why = None
    try:
        sch.preflight(system)
        sch.run(system, scene.t_end, probe)
        why = f"the run to t_end = {scene.t_end:g} s did not close it"
    except _Touched:
        if len(touches) < len(sought):
            why = f"not closed within {budget_s:g} s of CPU time"
    except UnsafeStepError:
        why = ("the pre-flight check refuses the scheme's step (below), so no run was made "
               "to find where it closes")
    except SimulationError as exc:
        why = f"the run stopped before it closed: {exc}"
    except Exception as exc:            # info must not fail where only the probe does
        why = f"the run stopped before it closed: {type(exc).__name__}: {exc}"
    return touches, why


def _contact_info(system, c, scene, touch=None, why_not=None) -> dict:
    ln = system.links[c]
    law = ln.contact.law
    out = {"law": law.name, "placement": ln.placement,
           "between": [system.names[ln.sub_a], system.names[ln.sub_b]]}
    if law.rigid:
        out.update(restitution=law.restitution, friction=law.friction)
        return out
    if c in system.circles:          # a penalty spread over the boundary inside a circle
        circle = system.circles[c].embedded.circle
        out.update(host=system.names[system.embedded[c][0]], radius=circle.radius,
                   stiffness_pa_per_m=circle.stiffness,
                   not_evaluated="reduced mass, frequency, contact time and stable steps: a "
                                 "circle (`radius`) stiffens as its contact widens, so it has "
                                 "no one spring; its host's RK4 resolves it at the host's "
                                 "`integrator.contact_step`")
        return out
    n = ln.contact.normal
    mob = system.contact_mobility(c)
    k, cd = stiffest_normal(ln)      # a grasp stiffer than the law sets the frequency
    conn = ln.connection
    if conn is not None:
        out.update(grasp=conn.grasp is not None,
                   friction=None if conn.friction is None else conn.friction.coefficient)
    unknown = _unknown_mass(system, c)
    if unknown is not None:          # an FMU reports it only when it runs
        if c in system.hosted:
            out["host"] = system.names[system.embedded[c][0]]
        out.update(stiffness=k, damping=cd, pose={"at": "initial", "t": 0.0, "why": why_not},
                   not_evaluated=f"reduced mass, frequency, contact time and stable steps: "
                                 f"{unknown}; `cosim info --run-fmu` runs the FMU to "
                                 f"evaluate them")
        return out
    if not (math.isfinite(mob) and mob > 0 and (touch is None or (
            math.isfinite(touch[1]) and touch[1] > 0))):
        out.update(stiffness=k, damping=cd,
                   not_evaluated=f"reduced mass, frequency, contact time and stable steps: "
                                 f"the ports' mobility is {mob!r} 1/kg at the start"
                                 + ("" if touch is None else
                                    f" and {touch[1]!r} 1/kg at the first touch")
                                 + ", which gives no finite reduced mass")
        return out
    m0 = 1.0 / mob                   # at the initial pose: the pre-flight check's
    if touch is not None:
        pose = {"at": "first touch", "t": touch[0]}
        m = 1.0 / touch[1]
    else:
        pose = {"at": "initial", "t": 0.0, "why": why_not or "no run was made to find it"}
        m = m0
    out["pose"] = pose
    if not (math.isfinite(k) and math.isfinite(cd)):
        out.update(reduced_mass=m, frequency_hz=None, contact_time_s=None,
                   note="nonlinear law without `reference_penetration`: no linearisation")
        return out
    omega = math.sqrt(k / m)
    t_c = contact_time(m, k, cd)
    out.update(stiffness=k, damping=cd, reduced_mass=m, frequency_hz=omega / (2 * math.pi),
               contact_time_s=t_c)
    if touch is not None and touch[0] > 0:
        out["initial_pose"] = {"reduced_mass": m0,
                               "frequency_hz": math.sqrt(k / m0) / (2 * math.pi),
                               "contact_time_s": contact_time(m0, k, cd)}
    out.update(_sampling(system, c, scene, t_c, ln.contact.name))
    m, omega = m0, math.sqrt(k / m0)  # the stable steps: at the initial pose
    opts = scene.scheme_options
    order, gain = opts.get("extrapolation_order", 0), opts.get("max_energy_gain", 0.01)
    steps, checks = {}, {}
    for name, cls in COUPLING_SCHEMES.items():
        first = preflight.partner_first(system, c, name, order)
        steps[name] = model_bound(system, c, cls, order, gain, scene.t_end, first,
                                  opts.get("sequence"))
        if ln.placement == "coupler" and cls.explicit:   # what the pre-flight check refuses
            checks[name] = preflight.largest_safe_step(m, k, cd, 10 * math.pi / omega, order,
                                                       gain, first)
    out["max_macro_step_s"] = steps
    out["max_macro_step_kind"] = {n: None for n in steps}    # scene_info confirms them
    if checks:
        out["preflight_step_s"] = checks
    if ln.placement == "embedded":
        host = system.embedded[c][0]
        if c in system.hosted:   # the host's spring runs against a prescribed point
            out["host"] = system.names[host]
            own = ln.port_a if host == ln.sub_a else ln.port_b
            omega = math.sqrt(k * system.subsystems[host].port_mobility(own, n))
        closed_form = system.subsystems[host].closed_form_contacts
        from cosim.scene.build import embedded_step_limit
        found = None if closed_form else embedded_step_limit(system, c)
        # an adaptive integrator (DOP853, RK45, ...): its error control sets the step
        method = getattr(getattr(system.subsystems[host], "integrator", None), "name", None)
        out["max_integrator_step_s"] = ({"closed_form": None} if closed_form else
                                       {"rk4": found[0]} if found is not None else
                                       {method: None} if method else {})
    return out


def _unknown_mass(system, c) -> str | None:
    """Why contact ``c``'s reduced mass is unknown without running an FMU
    (a side built from its model description alone), or None."""
    ln = system.links[c]
    for s, port in ((ln.sub_a, ln.port_a), (ln.sub_b, ln.port_b)):
        why = system.subsystems[s].unknown_port_mass(port)
        if why is not None:
            return why
    return None


def fmu_info(sub) -> dict:
    """What ``cosim info`` tells of an FMU side (an
    :class:`~cosim.sides.fmu.FMUSubsystem`, or a
    :class:`~cosim.sides.fmu_description.DescribedFMU`): its file, model
    name, description and generation tool, FMI version, whether it can get
    and set its state (rollback) and interpolate its inputs, its ports'
    masses as far as known, and every variable of its model description
    (name, causality, variability, type, start, unit, description).  Every
    text from the description is escaped and capped at
    :data:`FMU_TEXT_LIMIT` characters (:func:`cosim.errors.shown`).
    ``dofs`` of an FMU counts its named ``coordinates``."""
    def text(v):
        return None if v is None else shown(v, limit=FMU_TEXT_LIMIT)

    md = sub.model_description
    masses = {}
    for k, (pname, port) in enumerate(sub.ports.items()):
        m = sub.port_mass(k)
        masses[pname] = {"kg": m, "variable": None if not isinstance(port.mass, str)
                         else text(port.mass)}
    return {"file": text(sub.path.name), "model_name": text(md.modelName),
            "description": text(md.description), "generation_tool": text(md.generationTool),
            "fmi_version": text(md.fmiVersion), "can_get_set_state": sub.can_get_set_state,
            "interpolates_inputs": sub.interpolates_inputs, "port_mass": masses,
            "variables": [{"name": text(v.name), "causality": text(v.causality),
                           "variability": text(v.variability), "type": text(v.type),
                           "start": text(v.start), "unit": text(v.unit),
                           "description": text(v.description)}
                          for v in sub.variables.values()]}


def scene_info(scene, *, budget_s: float = FIRST_TOUCH_BUDGET_S, run_fmu: bool = False,
               confirm_steps: float = CONFIRM_STEPS) -> dict:
    """DOFs and natural frequencies of each subsystem, and each contact's
    frequency, contact time, largest stable macro step per scheme, and how
    often the series will sample it (``sampling_interval_s``,
    ``samples_per_contact``, and a ``sampling_note`` when that is fewer than
    :data:`SAMPLES_TO_DRAW`).

    Frequencies are in Hz, times in s.  The reduced mass of a contact is
    that of its two ports, ``1 / (n^T J M^-1 J^T n)`` summed over both
    sides, in the pose where the contact first closes (:func:`first_touch`,
    a run of at most ``budget_s`` of CPU time; 0: no run); ``pose`` says
    which (``at``: ``"first touch"`` or ``"initial"``, ``t`` [s], and
    ``why`` the initial pose was used), and ``initial_pose`` holds the
    values at the start when they differ.  The contact time is that of the
    linearised spring and dashpot (:func:`contact_time`).  The largest
    stable steps are judged at the initial pose.  ``max_macro_step_s`` of
    an explicit scheme is the largest step safe on the contact's coupled
    system (:func:`cosim.scene.stable_step.model_bound`), confirmed by a run
    of the scene at the smallest of its contacts' steps, halved while the
    run is stopped, its runs making at most ``confirm_steps`` integrator
    steps per scheme, as counted before they start (0: no run): ``max_macro_step_kind`` is ``"runs"`` (the step a run
    confirmed) or ``"necessary bound only"`` (the model's, with
    ``max_macro_step_why``); None where the scheme does not limit the
    contact.  ``preflight_step_s`` of an exchanged contact is the step the
    pre-flight check refuses above (its one-mass model).  ``work`` is the
    count of the run's integrator steps
    made before it starts (:func:`cosim.scene.work.estimate_work`:
    ``steps``, ``bound``, ``how`` and the ``key`` that makes most of it).

    ``variant`` is the variant applied (None: the scene has none),
    ``variants`` each variant of the scene's file with the keys it sets
    (``{dotted.key: value}``) and ``default_variant`` the one applied when
    none is named.

    A scene with an FMU side is built from its model descriptions alone and
    not run, unless ``run_fmu``: ``fmu_code_run`` says which, and a
    contact's ``not_evaluated`` what the FMU's code would have told."""
    has_fmu = any(side.type == "fmu" for side in scene.subsystems)
    if has_fmu and not run_fmu:
        touches, why_not = {}, NOT_RUN
    else:
        touches, why_not = first_touch(scene, budget_s)
    system, _ = scene.build(run_fmu=run_fmu)
    rules = {}
    if any(side.type == "plane" for side in scene.subsystems):
        from cosim.scene.plane_build import mode_rules
        rules = mode_rules(system, scene)
    subs = {}
    for sub in system.subsystems:
        entry = {"type": "rigid" if sub.rigid else type(sub).__name__, "dofs": sub.n_states // 2,
                 "ports": list(sub.port_names)}
        coords = sub.coordinates()
        if coords:
            entry["coordinates"] = list(coords)
        if "fmi" in sub.capabilities:            # an FMU: cosim.sides.fmu(_description)
            entry["type"] = "FMUSubsystem"       # as the run builds it
            entry["dofs"] = len(coords)
            entry["fmu"] = fmu_info(sub)
        if "modes" in sub.capabilities:       # a structure: physical DOFs, kept and dropped modes
            entry["dofs"] = sub.structure.n_dof
            entry["modes_kept"] = int(sub.basis.kept)
            entry["modes_dropped"] = int(sub.basis.dropped)
            entry["mode_cutoff_hz"] = sub.basis.cutoff_hz
            entry["natural_frequencies_hz"] = [float(f) for f in sub.natural_frequencies_hz]
        if sub.name in rules:                 # a plane body: modes against its contacts
            entry["mode_rule"] = rules[sub.name]
        subs[sub.name] = entry
    from cosim.scene.shipped import scene_variants

    variants, default = scene_variants(scene.path)
    contacts = {name: _contact_info(system, c, scene, touches.get(c), why_not)
                for c, name in enumerate(system.contact_names)}
    _confirm_steps(scene, contacts, confirm_steps if not has_fmu or run_fmu else 0.0)
    return {
        "scene": scene.name, "variant": scene.variant, "default_variant": default,
        "variants": variants, "scheme": scene.scheme,
        "scheme_options": dict(scene.scheme_options), "t_end": scene.t_end,
        "fmu_code_run": bool(has_fmu and run_fmu),
        "subsystems": subs,
        "work": scene.work(system=system).as_dict(),
        "contacts": contacts,
        "warnings": _plausibility(scene, system),
    }


def _plausibility(scene, system) -> list[dict]:
    """What looks like a unit slip in the scene's structures, as a run's
    summary lists it (:func:`cosim.scene.plausible.structure_warnings`)."""
    from cosim.scene.plausible import structure_warnings
    return structure_warnings(scene, system)


def _confirm_steps(scene, contacts: dict, budget: float) -> None:
    """Turn each explicit scheme's model bounds into a step that runs
    (:func:`cosim.scene.stable_step.confirm`): the scene at the smallest
    bound of its contacts, halved while a run is stopped.  A contact with a
    bound then gets the confirmed step, kind ``runs``; without one, its
    model bound stays, kind ``necessary bound only``, with ``why``."""
    for name, cls in COUPLING_SCHEMES.items():
        bounds = {n: c["max_macro_step_s"][name] for n, c in contacts.items()
                  if c.get("max_macro_step_s", {}).get(name) is not None}
        if not bounds or not cls.explicit:
            continue
        least = min(bounds.values())
        if budget <= 0:
            step, why = None, "no run was made to confirm it"
        elif least <= 0:
            step, why = None, "no step is safe on the contact's coupled model"
        else:
            step, why = confirm(scene, name, least, budget)
        for n in bounds:
            c = contacts[n]
            if step is not None:
                c["max_macro_step_s"][name] = step
                c["max_macro_step_kind"][name] = RUNS
            else:
                c["max_macro_step_kind"][name] = NECESSARY
                c.setdefault("max_macro_step_why", {})[name] = why
