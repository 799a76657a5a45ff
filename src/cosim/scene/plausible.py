"""Is a scene physically plausible?  What a unit slip looks like.

A number in the wrong unit (a Young's modulus of 210 for 210 GPa, a section
in millimetres) passes every check of the loader: it is finite and positive.
The run then finishes and reports numbers that are right for the scene as
written and useless for the one meant.  The checks here look at what such a
slip does and say so in the summary's ``warnings`` (and on the terminal),
naming the key to check and the likely slip; a warning never stops a run.

* :func:`structure_warnings`, once the system is built: a static deflection
  under gravity (and ``static_loads``) larger than :data:`SAG_RATIO` of the
  structure's length (one solve with the factorised stiffness, whether or
  not the run starts from that state); a lowest natural frequency (of the
  elastic modes) outside [:data:`LOW_HZ`, :data:`HIGH_HZ`]; a section larger
  than the structure's length.
* :func:`gap_warnings`, after the run: a declared contact that never
  closed while its smallest gap stayed more than :data:`GAP_RATIO` times the
  size of the scene (the span of its points in the reference state).

Each warning is a dict with ``kind`` (``static_deflection``, ``frequency``,
``section`` or ``contact_gap``), ``contact`` (None but for ``contact_gap``),
``key`` (the key path to check) and ``message``.  The thresholds are far
from any scene meant as written: the tests check that no shipped scene or
variant warns and that the slips do, under a few-ulp nudge of the numbers.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["structure_warnings", "gap_warnings", "section_problem", "scene_size",
           "SAG_RATIO", "LOW_HZ", "HIGH_HZ", "GAP_RATIO"]

#: a static deflection above this fraction of a structure's length warns
SAG_RATIO = 0.1
#: a lowest elastic natural frequency below this warns [Hz]
LOW_HZ = 0.1
#: a lowest natural frequency above this warns [Hz]
HIGH_HZ = 1e6
#: a contact that never closed warns when its smallest gap exceeds this many
#: times the size of the scene
GAP_RATIO = 100.0

#: the unit slips a stiffness key is checked for: (factor, what it would have been)
_SLIPS = {"Pa": ((1e6, "MPa written as Pa"), (1e9, "GPa written as Pa")),
          "N/m": ((1e3, "kN/m written as N/m"), (1e6, "kN/mm written as N/m")),
          "N": ((1e3, "kN written as N"),)}
#: unit -> the range a value of it has in a structure as meant: Young's moduli of
#: structural materials, polymers (about 1 GPa) to diamond (about 1.2e12 Pa)
_TYPICAL = {"Pa": (1e9, 1.2e12)}


def length_text(x: float) -> str:
    """A length [m] as a person reads it: ``573 km``, ``1 m``, ``0.57 mm``."""
    x = float(x)
    if abs(x) >= 1e3:
        return f"{x / 1e3:.3g} km"
    if abs(x) >= 1.0 or x == 0:
        return f"{x:.3g} m"
    if abs(x) >= 1e-3:
        return f"{x * 1e3:.3g} mm"
    return f"{x:.3g} m"


def _warning(kind: str, key: str, message: str, contact=None) -> dict:
    return {"kind": kind, "contact": contact, "key": key, "message": message}


def _data(scene, spec) -> dict:
    """The structure's table of the merged scene file."""
    node = scene.data.get("subsystems", {}).get(spec.name, {})
    return node if isinstance(node, dict) else {}


def _length(spec, structure) -> float:
    """A structure's length [m]: a line's, or a chain's span (its spacing for one mass)."""
    if spec.type == "chain":
        nodes = np.asarray(structure.nodes(), float)
        span = float(np.max(np.linalg.norm(nodes - nodes[0], axis=1))) if len(nodes) else 0.0
        return max(span, float(getattr(spec.model, "spacing", 0.0) or 0.0))
    return float(getattr(structure, "length", 0.0) or getattr(spec.model, "length", 0.0))


def _stiffness_key(spec, data) -> tuple[str, str] | None:
    """The key whose value sets a structure's stiffness, and its unit."""
    if spec.type in ("beam", "rod"):
        return "youngs_modulus", "Pa"
    if spec.type == "cable":      # tension or bending: the smaller stiffens the least
        e = data.get("youngs_modulus")
        return ("tension", "N") if isinstance(e, (int, float)) and e >= 1e6 else (
            "youngs_modulus", "Pa")
    if spec.type == "string":
        return "tension", "N"
    if spec.type == "chain":
        return "stiffnesses", "N/m"
    return None


def _slip(value, unit: str, fits) -> str:
    """``; was it 210e9 (GPa written as Pa)?``: of the factors of
    :data:`_SLIPS` that ``fits(factor)`` accepts (the deflection or frequency
    it would give is plausible), the first that also puts ``value`` in the
    range of :data:`_TYPICAL` (a modulus of a structural material), else
    the first; a plain ``; check its unit (Pa)`` when none fits."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        fitting = [(f, what) for f, what in _SLIPS.get(unit, ()) if fits(f)]
        low, high = _TYPICAL.get(unit, (-math.inf, math.inf))
        typical = [(f, what) for f, what in fitting if low <= value * f <= high]
        for factor, what in typical or fitting:
            return f"; was it {value:g}e{round(math.log10(factor))} ({what})?"
    return f"; check its unit ({unit})" if unit else ""


def _value_text(value, unit: str) -> str:
    if isinstance(value, list):
        shown = ", ".join(f"{v:g}" for v in value[:3]) + (", ..." if len(value) > 3 else "")
        return f"[{shown}] {unit}"
    return f"{value:g} {unit}" if isinstance(value, (int, float)) else str(value)


def section_problem(scene, spec) -> dict | None:
    """The warning of a structure whose section is larger than its length
    (a section in millimetres read as metres), or None."""
    data = _data(scene, spec)
    length = float(getattr(spec.model, "length", 0.0) or 0.0)
    if spec.type not in ("beam", "cable", "rod", "string") or not length > 0:
        return None
    if spec.type in ("beam", "cable"):
        sec = data.get("section")
        if not isinstance(sec, dict):
            return None
        sizes = {k: v for k, v in sec.items() if k in ("diameter", "width", "height")
                 and isinstance(v, (int, float)) and not isinstance(v, bool)}
        if not sizes:
            return None
        k, v = max(sizes.items(), key=lambda kv: kv[1])
        if not v > length:
            return None
        key = f"{spec.key}.section.{k}"
        return _warning("section", key,
                        f"`{key}` = {v:g} m on a {length_text(length)} {spec.type}: the section "
                        f"is larger than the {spec.type}'s length; was it {v / 1e3:g} "
                        f"(millimetres written as metres)? A section in millimetres makes "
                        f"it about 1e6 times too stiff for its mass")
    area = data.get("area")
    if not isinstance(area, (int, float)) or isinstance(area, bool) or not (
            math.sqrt(area) > length):
        return None
    key = f"{spec.key}.area"
    return _warning("section", key,
                    f"`{key}` = {area:g} m^2 on a {length_text(length)} {spec.type}: the "
                    f"section is wider than the {spec.type} is long; was it {area / 1e6:g} "
                    f"(mm^2 written as m^2)?")


def _load(scene, spec, structure) -> np.ndarray | None:
    """Gravity's load on the structure plus its ``static_loads``, or None if nothing loads it."""
    f = np.zeros(structure.n_dof)
    if scene.gravity is not None:
        f = f + structure.gravity_load(np.asarray(scene.gravity, float))
    for port, force in (spec.static_loads or {}).items():
        f = f + structure.point_load(spec.ports[port], force)
    return f if np.any(f) else None


def _sag_warning(scene, spec, sub) -> dict | None:
    structure = sub.structure
    length = _length(spec, structure)
    f = _load(scene, spec, structure)
    if f is None or not length > 0:
        return None
    try:
        u = structure.static_displacement(f)
    except (ValueError, ArithmeticError):      # free to move: no static state to judge
        return None
    sag = float(np.max(np.abs(structure.nodal_displacement(u))))
    if not sag > SAG_RATIO * length:
        return None
    data = _data(scene, spec)
    found = _stiffness_key(spec, data)
    what = ("under gravity" if scene.gravity is not None else "under its loads") + (
        " and its `static_loads`" if scene.gravity is not None and spec.static_loads else "")
    head = (f"a static deflection of {length_text(sag)} {what} on a {length_text(length)} "
            f"{spec.type} (more than {SAG_RATIO:g} of its length)")
    if found is None:
        return _warning("static_deflection", spec.key,
                        f"`{spec.key}`: {head}; check the units of its stiffness")
    name, unit = found
    key = f"{spec.key}.{name}"
    value = data.get(name)
    # the deflection goes as 1 / stiffness: the smallest slip that brings it below the level
    slip = _slip(value, unit, lambda factor: sag / factor <= SAG_RATIO * length)
    return _warning("static_deflection", key,
                    f"`{key}` = {_value_text(value, unit)}: {head}{slip}")


def _frequency_warning(scene, spec, sub) -> dict | None:
    omega = np.asarray(sub.omega, float)[int(getattr(sub.basis, "n_rigid", 0)):]
    if not omega.size:
        return None
    f1 = float(omega[0]) / (2.0 * math.pi)
    if LOW_HZ <= f1 <= HIGH_HZ:
        return None
    data = _data(scene, spec)
    found = _stiffness_key(spec, data)
    side = "below" if f1 < LOW_HZ else "above"
    head = (f"the lowest natural frequency of `{spec.name}` is {f1:.3g} Hz ({side} "
            f"{LOW_HZ if f1 < LOW_HZ else HIGH_HZ:g} Hz)")
    if f1 > HIGH_HZ:
        rho = data.get("density")
        if isinstance(rho, (int, float)) and not isinstance(rho, bool) and rho < 100.0:
            key = f"{spec.key}.density"
            return _warning("frequency", key, f"`{key}` = {rho:g} kg/m^3: {head}; was it "
                                              f"{rho * 1e3:g} (g/cm^3 written as kg/m^3)?")
    if found is None:
        return _warning("frequency", spec.key,
                        f"`{spec.key}`: {head}; check the units of its numbers")
    name, unit = found
    key = f"{spec.key}.{name}"
    value = data.get(name)
    if f1 < LOW_HZ:     # the frequency goes as the square root of the stiffness
        slip = _slip(value, unit, lambda factor: f1 * math.sqrt(factor) >= LOW_HZ)
    else:
        slip = f"; check its unit ({unit}), the density and the section"
    return _warning("frequency", key, f"`{key}` = {_value_text(value, unit)}: {head}{slip}")


def structure_warnings(scene, system) -> list[dict]:
    """The plausibility warnings of ``scene``'s structures, as built in
    ``system``: a section larger than the length, a static deflection
    larger than :data:`SAG_RATIO` of the length, a lowest natural frequency
    outside [:data:`LOW_HZ`, :data:`HIGH_HZ`] (one warning per key: a
    frequency warning that names the key a deflection warning named is
    left out, being the same slip)."""
    subs = {sub.name: sub for sub in system.subsystems}
    out = []
    for spec in scene.subsystems:
        sub = subs.get(spec.name)
        if sub is None or not hasattr(spec, "model") or "modes" not in sub.capabilities:
            continue
        found = [w for w in (section_problem(scene, spec), _sag_warning(scene, spec, sub))
                 if w is not None]
        freq = _frequency_warning(scene, spec, sub)
        if freq is not None and freq["key"] not in {w["key"] for w in found}:
            found.append(freq)
        out += found
    return out


def scene_size(system) -> float:
    """The size of a scene [m]: the largest distance between two of its
    points in the reference state (the structures undeformed, their ends
    included; the other sides at their start)."""
    pts = []
    for sub in system.subsystems:
        structure = sub.structure if "modes" in sub.capabilities else None
        if structure is not None:
            pts += [structure.reference_position(s) for s in sub.port_coordinates]
            nodes = np.asarray(structure.nodes(), float)
            if len(nodes):
                pts += [nodes[0], nodes[-1]]
            continue
        try:
            pos = np.asarray(sub.outputs(sub.t, sub.x)[0], float).reshape(-1, 2)
        except Exception:            # a side that cannot say where it is: no size from it
            continue
        pts += list(pos)
    if len(pts) < 2:
        return 0.0
    p = np.asarray(pts, float)
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) < 2:
        return 0.0
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


def gap_warnings(summary: dict, series, size: float) -> list[dict]:
    """The contacts of a finished run's ``summary`` that never closed while
    their smallest gap (``gap/NAME`` of ``series``) stayed above
    :data:`GAP_RATIO` times the scene's ``size`` [m] (:func:`scene_size`):
    whatever moves, it moves nowhere near that contact; a unit slip (a
    structure sagging kilometres under its weight) is the likely cause."""
    out = []
    if not size > 0:
        return out
    for name, c in summary.get("contacts", {}).items():
        if c.get("count", 0) or c.get("peak_penetration", 0.0) > 0:
            continue
        try:
            gap = np.asarray(series[f"gap/{name}"], float)
        except KeyError:
            continue
        if not gap.size or not np.all(np.isfinite(gap)):
            continue
        low = float(np.min(gap))
        if not low > GAP_RATIO * size:
            continue
        out.append(_warning(
            "contact_gap", f"contacts.{name}",
            f"contact `{name}` never closed: its gap stayed above {length_text(low)}, more "
            f"than {GAP_RATIO:g} times the size of the scene ({length_text(size)}); check the "
            f"units of its sides (a structure's stiffness or section, the points of "
            f"`contacts.{name}.a` and `.b`)", contact=name))
    return out
