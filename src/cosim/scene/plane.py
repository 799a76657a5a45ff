"""A plane body in a scene (``type = "plane"``): its model and points read
from the scene's table, the direction its ports move along, and the static
correction of its contacts with the pre-flight rules that go with it.

The mesh is read (and checked, :func:`fem.plane.read_mesh`) when the scene
loads, so a trap of the mesh is refused at the ``mesh`` key before anything
is assembled; a point's group and arc length are checked against it there
too.  A port of a plane body moves along the outward normal of the boundary
segment that holds it (its row is the normal displacement): the ports of
one body must share that normal, which is then the structure's
``direction`` (the compiled kernels take it as they take a beam's).
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np

from cosim.scene.checks import SceneError, Table, build_model, echo

__all__ = ["plane_model", "port_direction", "corrected_law", "FLAMANT_WARNING"]

#: a point contact whose compliance grows by more than this share at every
#: halving of the mesh (Flamant) is warned as mesh-dependent
FLAMANT_WARNING = 1e-2


def _group_length(mesh, group: str) -> float:
    p = mesh.points
    pairs = mesh.group(group)
    return float(np.sum(np.hypot(*(p[pairs[:, 1]] - p[pairs[:, 0]]).T)))


def _groups(sup: Table, key: str) -> tuple:
    value = sup.raw(key)
    if value is None:
        return ()
    if isinstance(value, str):
        return (value,)
    if isinstance(value, list) and value and all(isinstance(g, str) for g in value):
        return tuple(value)
    sup.error(key, f"must be a group's name or an array of them, got {echo(value)}")


def plane_model(t: Table):
    """The :class:`fem.plane.Plane` of table ``t`` (section ``plane``) and its
    ports ``{name: (group, s)}``; the mesh read and checked."""
    from fem.plane import PLANE_ELEMENTS, PLANE_MODELS, MeshError, Plane

    name = t.string("mesh")
    path = Path(name) if Path(name).is_absolute() else Path(t.file).parent / name
    kw = dict(scale=t.number("scale", rule=">0", unit="m"),
              model=t.string("model", choices=PLANE_MODELS),
              thickness=t.number("thickness", rule=">0", unit="m"),
              youngs_modulus=t.number("youngs_modulus", rule=">0", unit="Pa"),
              poisson_ratio=t.number("poisson_ratio", rule=">=0"),
              density=t.number("density", rule=">0", unit="kg/m^3"),
              element=t.string("element", choices=PLANE_ELEMENTS),
              origin=t.vec2("origin"), angle=t.number("angle", unit="rad"))
    if t.has("rayleigh"):
        from cosim.scene.subsystems import _rayleigh
        kw["rayleigh"] = _rayleigh(t)
    sup = t.table("supports", section="plane.supports")
    held = {key: _groups(sup, key) for key in ("fixed", "fixed_x", "fixed_y")}
    sup.finish()
    model = build_model(t, Plane, mesh=str(path), **held, **kw)
    try:
        mesh = model.read()
    except MeshError as exc:
        t.error("mesh", str(exc))
    for key, groups in held.items():
        for group in groups:
            try:
                mesh.vertices(group)
            except MeshError as exc:
                sup.error(key, str(exc))
    pts = t.table("points", section="plane.points")
    ports = {}
    for p in list(pts.data):
        pt = pts.table(p, section="plane.point")
        group = pt.string("boundary")
        try:
            length = _group_length(mesh, group)
        except MeshError as exc:
            pt.error("boundary", str(exc))
        s = pt.number("s", unit="m")
        if not 0.0 <= s <= length * (1 + 1e-12):
            pt.error("s", f"must be an arc length in [0, {length:.6g}] m along `{group}`, got "
                          f"{echo(s)}")
        pt.finish()
        ports[p] = (group, min(s, length))
    pts.finish()
    if not ports:
        t.error("points", "must name at least one point")
    return model, ports


def port_direction(structure, ports: dict, file, key: str) -> None:
    """Give the plane ``structure`` the direction its ports move along: the
    outward normal their boundary segments share.

    Raises
    ------
    SceneError
        If two ports lie on segments of different normals, or a group is
        not one chain of boundary curves.
    """
    from fem.plane import MeshError

    normals = {}
    for name, (group, s) in ports.items():
        try:
            normals[name] = structure.boundary_point(group, s).normal
        except MeshError as exc:
            raise SceneError(file, f"{key}.points.{name}.boundary", str(exc)) from None
    first = next(iter(normals))
    for name, n in normals.items():
        if float(n @ normals[first]) < 1.0 - 1e-9:
            raise SceneError(file, f"{key}.points.{name}",
                             f"lies on a boundary segment of outward normal "
                             f"[{n[0]:.6g}, {n[1]:.6g}], and `{first}` on one of "
                             f"[{normals[first][0]:.6g}, {normals[first][1]:.6g}]: the points "
                             f"of one plane body must share their normal (each moves along "
                             f"it); put them on parallel faces, or in bodies of their own")
    structure.direction = np.array(normals[first], dtype=float)
    structure.direction.setflags(write=False)


def corrected_law(contact, scene, subs: list, sides: tuple):
    """The law contact ``contact`` (a :class:`ContactSpec`) runs with: its
    own, or, where a side is a plane body with ``modes.static_correction``,
    a linear spring in series with the static compliance of the modes that
    body dropped at the contact's point, ``k / (1 + k c_r)``.

    Warns when the kept modes reach less than 10 times the contact's
    frequency, and when the contact's compliance is mesh-dependent
    (Flamant: ``k x 2 ln 2 / (pi E t)`` over 1e-2); refuses the correction
    below 1 times the contact's frequency and with a law that is not the
    linear spring.  ``sides`` are ``(subsystem index, port index)`` of a and b.
    """
    from fem.plane.reduce import StaticCorrection, flamant_growth, mode_rule

    law = contact.law
    specs = {s.name: s for s in scene.subsystems}
    for (s, port), (sub_name, point) in zip(sides, (contact.a, contact.b)):
        spec = specs[sub_name]
        if getattr(spec, "type", None) != "plane":
            continue
        model, key = spec.model, f"subsystems.{sub_name}"
        k = getattr(law, "contact_stiffness", None)
        if k is not None and not law.rigid:
            growth = flamant_growth(k, model.youngs_modulus, model.thickness)
            if growth > FLAMANT_WARNING:
                warnings.warn(f"{scene.path}: contact `{contact.name}` is a point contact on "
                              f"the plane body `{sub_name}` whose compliance grows by "
                              f"{growth:.2g} of the spring's at every halving of the mesh "
                              f"(Flamant): its result depends on the mesh; spread the contact "
                              f"or soften the spring", stacklevel=3)
        if not spec.static_correction:
            continue
        if law.name != "linear":
            raise SceneError(scene.path, f"{key}.modes.static_correction",
                             f"puts the dropped modes' compliance in series with a linear "
                             f"spring; contact `{contact.name}` has a `{law.name}` law: use "
                             f"`linear`, or turn the correction off")
        other = sides[1] if sides[0][0] == s else sides[0]
        mob = subs[other[0]].port_mobility(other[1], contact.normal)
        if not mob > 0.0:
            mob = subs[s].port_mobility(port, contact.normal)
        f_contact = math.sqrt(k * mob) / (2.0 * math.pi)
        top = float(np.max(subs[s].natural_frequencies_hz))
        verdict, why = mode_rule(top, f_contact)
        if verdict == "refuse":
            raise SceneError(scene.path, f"{key}.modes.static_correction",
                             f"for contact `{contact.name}`: {why}")
        if verdict == "warn":
            warnings.warn(f"{scene.path}: `{key}` with contact `{contact.name}`: {why}",
                          stacklevel=3)
        sub = subs[s]
        corr = getattr(sub, "static_correction", None)
        if corr is None:
            corr = sub.static_correction = StaticCorrection(sub.structure, sub.basis)
        c_r = corr.compliance(spec.ports[point])
        law = dataclasses.replace(law, contact_stiffness=k / (1.0 + k * c_r))
    return law
