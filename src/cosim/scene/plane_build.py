"""The builder's part of a plane body (``type = "plane"``; the loader's is
:mod:`cosim.scene.plane`): the direction its ports move along, and the
static correction of its contacts with the pre-flight rules that go with
it.  It imports nothing of the scene package but its error.

A port of a plane body moves along the outward normal of the boundary
segment that holds it (its row is the normal displacement); the ports of
one body may lie on segments of different normals, for the structure side
and its compiled kernel take a direction per port.
"""
from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from cosim.scene.checks import SceneError

__all__ = ["port_direction", "corrected_law", "cached_basis", "mode_rules", "FLAMANT_WARNING"]

#: a point contact whose compliance grows by more than this share at every
#: halving of the mesh (Flamant) is warned as mesh-dependent
FLAMANT_WARNING = 1e-2
#: the warnings said in this process (a command builds a scene several times)
_SAID: set = set()


def _warn(message: str) -> None:
    if message not in _SAID:
        _SAID.add(message)
        warnings.warn(message, stacklevel=4)


def port_direction(structure, ports: dict, file, key: str) -> None:
    """Check that each port of the plane ``structure`` lies on a boundary
    chain, and give the structure the first one's outward normal as its
    ``direction`` (what reads one direction for the whole body: a port
    itself moves along its own segment's normal, ``port_direction``).

    Raises
    ------
    SceneError
        If a group is not one chain of boundary curves.
    """
    from fem.plane import MeshError

    normals = {}
    for name, (group, s) in ports.items():
        try:
            normals[name] = structure.boundary_point(group, s).normal
        except MeshError as exc:
            raise SceneError(file, f"{key}.points.{name}.boundary", str(exc)) from None
    structure.direction = np.array(next(iter(normals.values())), dtype=float)
    structure.direction.setflags(write=False)


def _contact_hz(k: float, subs: list, s: int, port: int, other: tuple, normal) -> float:
    """The frequency [Hz] of a spring ``k`` on the port mass of the side
    ``other`` (the plane body's own port when that side does not move)."""
    mob = subs[other[0]].port_mobility(other[1], normal)
    if not mob > 0.0:
        mob = subs[s].port_mobility(port, normal)
    return math.sqrt(k * mob) / (2.0 * math.pi)


def mode_rules(system, scene) -> dict:
    """Plane body -> for each of its contacts with a stiffness, the mode
    rule (:func:`fem.plane.reduce.mode_rule`): ``contact``,
    ``frequency_hz`` (its spring on the other side's port mass),
    ``kept_to_hz``, ``ratio``, ``verdict`` and ``static_correction``, with
    the static correction its ``dropped_share`` (``c_r k``, which turns an
    ``ok`` into a ``warn`` over 1e-2); for ``cosim info``."""
    from fem.plane.reduce import dropped_share_rule, mode_rule

    specs = {s.name: s for s in scene.subsystems}
    contacts = {c.name: c for c in scene.contacts}
    laws = {c.name: c.law for c in scene.contacts}
    subs, out = system.subsystems, {}
    for c, ln in enumerate(system.links):
        if c in system.circles:         # a spread penalty, in Pa/m: no one spring to judge
            continue
        k = getattr(laws.get(ln.contact.name), "contact_stiffness", None)
        ends = ((ln.sub_a, ln.port_a), (ln.sub_b, ln.port_b))
        for (s, port), other in zip(ends, ends[::-1]):
            spec = specs.get(subs[s].name)
            if getattr(spec, "type", None) != "plane" or k is None:
                continue
            f = _contact_hz(k, subs, s, port, other, ln.contact.normal)
            top = float(np.max(subs[s].natural_frequencies_hz))
            rule = {"contact": ln.contact.name, "frequency_hz": f, "kept_to_hz": top,
                    "ratio": top / f, "verdict": mode_rule(top, f)[0],
                    "static_correction": bool(spec.static_correction)}
            corr = getattr(subs[s], "static_correction", None)
            cspec = contacts[ln.contact.name]
            point = cspec.a[1] if s == ln.sub_a else cspec.b[1]
            if spec.static_correction and corr is not None:
                share = k * corr.compliance(spec.ports[point])
                rule["dropped_share"] = share
                if rule["verdict"] == "ok":
                    rule["verdict"] = dropped_share_rule(share)[0]
            out.setdefault(subs[s].name, []).append(rule)
    return out


def corrected_law(contact, scene, subs: list, sides: tuple, scheme: str | None = None):
    """The law contact ``contact`` (a :class:`ContactSpec`) runs with: its
    own, or, where a side is a plane body with ``modes.static_correction``,
    a linear spring in series with the static compliance of the modes that
    body dropped at the contact's point, ``k / (1 + k c_r)``.

    Warns when the kept modes reach less than 10 times the contact's
    frequency, and when the contact's compliance is mesh-dependent
    (Flamant: ``k x 2 ln 2 / (pi E t)`` over 1e-2); refuses the correction
    below 1 times the contact's frequency and with a law that is not the
    linear spring.  ``sides`` are ``(subsystem index, port index)`` of a and b.

    A contact that follows the plane body's boundary (``follow = true``)
    gets its own copy of the law, whose stiffness the body sets to
    ``k / (1 + k c_r)`` at the port's present point each time the port
    moves (:meth:`cosim.sides.plane.PlaneSubsystem.follow_stiffness`, per
    macro step of the scheme ``scheme``, which therefore must not be the
    monolithic one: it moves the port at every evaluation).  The rules
    above (mode rule, dropped share, Flamant) are evaluated at the first
    point.
    """
    from fem.plane.reduce import (StaticCorrection, dropped_share_rule, flamant_growth,
                                  mode_rule)

    law = contact.law
    specs = {s.name: s for s in scene.subsystems}
    for (s, port), (sub_name, point) in zip(sides, (contact.a, contact.b)):
        spec = specs[sub_name]
        if getattr(spec, "type", None) != "plane":
            continue
        model, key = spec.model, f"subsystems.{sub_name}"
        if contact.follow and point == contact.b[1]:
            _check_follow(contact, spec, subs[s], scene.path, scheme)
        k = getattr(law, "contact_stiffness", None)
        point_contact = spec.ports[point][1] is not None     # not a face's average
        if k is not None and not law.rigid and point_contact:
            growth = flamant_growth(k, model.youngs_modulus, model.thickness)
            if growth > FLAMANT_WARNING:
                _warn(f"{scene.path}: contact `{contact.name}` is a point contact on the plane "
                      f"body `{sub_name}` whose compliance grows by {growth:.2g} of the "
                      f"spring's at every halving of the mesh (Flamant): its result depends on "
                      f"the mesh; spread the contact or soften the spring")
        if not spec.static_correction:
            continue
        if law.name != "linear":
            raise SceneError(scene.path, f"{key}.modes.static_correction",
                             f"puts the dropped modes' compliance in series with a linear "
                             f"spring; contact `{contact.name}` has a `{law.name}` law: use "
                             f"`linear`, or turn the correction off")
        other = sides[1] if sides[0][0] == s else sides[0]
        f_contact = _contact_hz(k, subs, s, port, other, contact.normal)
        top = float(np.max(subs[s].natural_frequencies_hz))
        verdict, why = mode_rule(top, f_contact)
        if verdict == "refuse":
            raise SceneError(scene.path, f"{key}.modes.static_correction",
                             f"for contact `{contact.name}`: {why}")
        if verdict == "warn":
            _warn(f"{scene.path}: `{key}` with contact `{contact.name}`: {why}")
        sub = subs[s]
        corr = getattr(sub, "static_correction", None)
        if corr is None:
            corr = sub.static_correction = StaticCorrection(sub.structure, sub.basis)
        c_r = corr.compliance(spec.ports[point])
        share_verdict, why = dropped_share_rule(k * c_r)
        if verdict == "ok" and share_verdict == "warn":
            _warn(f"{scene.path}: `{key}` with contact `{contact.name}`: {why}")
        law = dataclasses.replace(law, contact_stiffness=k / (1.0 + k * c_r))
        if contact.follow and point == contact.b[1]:
            # its own copy, whose stiffness follows the port (per macro step)
            law = dataclasses.replace(law, contact_stiffness=k)
            sub.correct_following(port, law, corr)
    return law


def _check_follow(contact, spec, sub, file, scheme=None) -> None:
    """Refuse what a following contact on the plane body ``spec`` cannot
    do: a point without ``s`` (a face's average does not slide), the static
    correction under the monolithic scheme (the correction's stiffness is
    set per macro step, the monolithic scheme moves the port at every
    evaluation of its right-hand side, where the change of stiffness would
    go unbooked), a boundary that touches itself at a vertex, and a
    ``normal`` that is not the first point's outward normal (the contact
    reads along it until the first step turns it with the boundary).  The
    sliding loop is made here, once."""
    point = contact.b[1]
    group, s = spec.ports[point]
    if s is None:
        raise SceneError(file, f"{contact.key}.follow",
                         f"slides `{spec.name}.{point}` along the boundary, but that point is "
                         f"the average of the group `{group}` (it has no `s`): give it an arc "
                         f"length `s`, or set `follow = false`")
    if spec.static_correction and scheme == "monolithic":
        raise SceneError(file, f"{contact.key}.follow",
                         f"slides `{spec.name}.{point}` along the boundary with "
                         f"`subsystems.{spec.name}.modes.static_correction`, whose stiffness "
                         f"follows the port per macro step; the monolithic scheme moves the "
                         f"port at every evaluation of its right-hand side: use a co-simulation "
                         f"scheme (gauss_seidel, jacobi), or turn the correction off")
    from fem.plane import MeshError
    try:
        sub.sliding_loop(sub.port_index(point))
    except MeshError as exc:
        raise SceneError(file, f"{contact.key}.follow", str(exc)) from None
    n = np.asarray(sub.structure.port_direction((group, s)), float)
    if float(np.dot(n, contact.normal)) < 1.0 - 1e-9:
        raise SceneError(file, f"{contact.key}.normal",
                         f"must be the outward normal of the boundary at `{spec.name}.{point}`, "
                         f"[{n[0]:.6g}, {n[1]:.6g}], for a contact that follows a plane body "
                         f"(it turns with the deformed boundary from there), got "
                         f"[{contact.normal[0]:.6g}, {contact.normal[1]:.6g}]")


def cached_basis(structure, spec, file):
    """The modes of a plane body from its ``modes.cache`` folder when an
    entry there fits (:func:`fem.plane.cache.cached_modes`), else computed
    and written there through the checked writer.

    Raises
    ------
    SceneError
        If the folder cannot be made, read or written.
    """
    from cosim.errors import OutputError
    from cosim.io.rundir import OutputFolder
    from fem.plane.cache import cached_modes

    try:
        with OutputFolder(spec.modal_cache, lock=False) as folder:
            basis, _ = cached_modes(structure, folder, **spec.modes)
    except OutputError as exc:
        raise SceneError(file, f"{spec.key}.modes.cache", str(exc)) from None
    return basis
