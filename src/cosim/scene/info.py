"""What a run will meet, before it runs: `cosim info`."""
from __future__ import annotations

import math

from cosim.core import preflight
from cosim.core.preflight import stiffest_normal
from cosim.core.schemes import COUPLING_SCHEMES

__all__ = ["scene_info", "fmu_info"]

#: RK4's stability limit on an undamped oscillator, omega * dt.
RK4_LIMIT = 2.0 * math.sqrt(2.0)

#: fewest samples in a contact's duration that draw it as a shape
SAMPLES_TO_DRAW = 4


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


def _contact_info(system, c, scene) -> dict:
    ln = system.links[c]
    law = ln.contact.law
    out = {"law": law.name, "placement": ln.placement,
           "between": [system.names[ln.sub_a], system.names[ln.sub_b]]}
    if law.rigid:
        out.update(restitution=law.restitution, friction=law.friction)
        return out
    n = ln.contact.normal
    mob = (system.subsystems[ln.sub_a].port_mobility(ln.port_a, n)
           + system.subsystems[ln.sub_b].port_mobility(ln.port_b, n))
    k, cd = stiffest_normal(ln)      # a grasp stiffer than the law sets the frequency
    conn = ln.connection
    if conn is not None:
        out.update(grasp=conn.grasp is not None,
                   friction=None if conn.friction is None else conn.friction.coefficient)
    m = 1.0 / mob
    if not (math.isfinite(k) and math.isfinite(cd)):
        out.update(reduced_mass=m, frequency_hz=None, contact_time_s=None,
                   note="nonlinear law without `reference_penetration`: no linearisation")
        return out
    omega = math.sqrt(k / m)
    out.update(stiffness=k, damping=cd, reduced_mass=m, frequency_hz=omega / (2 * math.pi),
               contact_time_s=math.pi / omega)
    out.update(_sampling(system, c, scene, math.pi / omega, ln.contact.name))
    opts = scene.scheme_options
    order, gain = opts.get("extrapolation_order", 0), opts.get("max_energy_gain", 0.01)
    steps = {}
    for name, cls in COUPLING_SCHEMES.items():
        if ln.placement == "embedded" or not cls.explicit:
            steps[name] = None       # not limited by this contact
        else:
            steps[name] = preflight.largest_safe_step(
                m, k, cd, 10 * math.pi / omega, order, gain,
                preflight.partner_first(system, c, name, order))
    out["max_macro_step_s"] = steps
    if ln.placement == "embedded":
        host = system.embedded[c][0]
        if c in system.hosted:   # the host's spring runs against a prescribed point
            out["host"] = system.names[host]
            own = ln.port_a if host == ln.sub_a else ln.port_b
            omega = math.sqrt(k * system.subsystems[host].port_mobility(own, n))
        closed_form = getattr(system.subsystems[host], "_closed_form", False)
        out["max_integrator_step_s"] = ({"closed_form": None} if closed_form
                                       else {"rk4": RK4_LIMIT / omega})
    return out


def fmu_info(sub) -> dict:
    """What ``cosim info`` tells of an FMU side (:class:`cosim.sides.fmu.FMUSubsystem`):
    its file, FMI version, whether it can get and set its state (rollback)
    and interpolate its inputs, and every variable of its model
    description (name, causality, variability, type, start, unit,
    description).  ``dofs`` of an FMU counts its named ``coordinates``."""
    return {"file": sub.path.name, "fmi_version": sub.model_description.fmiVersion,
            "can_get_set_state": sub.can_get_set_state,
            "interpolates_inputs": sub.interpolates_inputs,
            "variables": [{"name": v.name, "causality": v.causality,
                           "variability": v.variability, "type": v.type,
                           "start": v.start, "unit": v.unit, "description": v.description}
                          for v in sub.variables.values()]}


def scene_info(scene) -> dict:
    """DOFs and natural frequencies of each subsystem, and each contact's
    frequency, contact time, largest stable macro step per scheme, and how
    often the series will sample it (``sampling_interval_s``,
    ``samples_per_contact``, and a ``sampling_note`` when that is fewer than
    :data:`SAMPLES_TO_DRAW`).

    Frequencies are in Hz, times in s.  The reduced mass of a contact is
    that of its two ports at the initial state, ``1 / (n^T J M^-1 J^T n)``
    summed over both sides."""
    system, _ = scene.build()
    subs = {}
    for sub in system.subsystems:
        entry = {"type": "rigid" if sub.rigid else type(sub).__name__, "dofs": sub.n_states // 2,
                 "ports": list(sub.port_names)}
        coords = sub.coordinates()
        if coords:
            entry["coordinates"] = list(coords)
        if hasattr(sub, "model_description"):    # an FMU: cosim.sides.fmu
            entry["dofs"] = len(coords)
            entry["fmu"] = fmu_info(sub)
        freqs = getattr(sub, "natural_frequencies_hz", None)
        if freqs is not None:       # a structure: physical DOFs, kept and dropped modes
            entry["dofs"] = sub.structure.n_dof
            entry["modes_kept"] = int(sub.basis.kept)
            entry["modes_dropped"] = int(sub.basis.dropped)
            entry["mode_cutoff_hz"] = sub.basis.cutoff_hz
            entry["natural_frequencies_hz"] = [float(f) for f in freqs]
        subs[sub.name] = entry
    return {
        "scene": scene.name, "variant": scene.variant, "scheme": scene.scheme,
        "scheme_options": dict(scene.scheme_options), "t_end": scene.t_end,
        "subsystems": subs,
        "contacts": {name: _contact_info(system, c, scene)
                     for c, name in enumerate(system.contact_names)},
    }
