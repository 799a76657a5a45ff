"""A plane body in a scene (``type = "plane"``): its model and points read
from the scene's table (the builder's part: :mod:`cosim.scene.plane_build`).

The mesh is read (and checked, :func:`fem.plane.read_mesh`) when the scene
loads, so a trap of the mesh is refused at the ``mesh`` key before anything
is assembled; a point's group and arc length are checked against it there
too.  A port of a plane body moves along the outward normal of the boundary
segment that holds it (its row is the normal displacement), each port its
own.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cosim.scene.checks import Table, build_model, echo

__all__ = ["plane_model"]


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


def plane_model(t: Table, rayleigh=None):
    """The :class:`fem.plane.Plane` of table ``t`` (section ``plane``) and its
    ports ``{name: (group, s)}``; the mesh read and checked.  ``rayleigh``
    (read by the caller, as every structure's) goes to the model."""
    from fem.plane import PLANE_ELEMENTS, PLANE_MODELS, MeshError, Plane

    name = t.string("mesh")
    path = Path(name) if Path(name).is_absolute() else Path(t.file).resolve().parent / name
    t.data["mesh"] = str(path)      # the scene a run writes names it wherever it is read
    kw = dict(scale=t.number("scale", rule=">0", unit="m"),
              model=t.string("model", choices=PLANE_MODELS),
              thickness=t.number("thickness", rule=">0", unit="m"),
              youngs_modulus=t.number("youngs_modulus", rule=">0", unit="Pa"),
              poisson_ratio=t.number("poisson_ratio", rule=">=0"),
              density=t.number("density", rule=">0", unit="kg/m^3"),
              element=t.string("element", choices=PLANE_ELEMENTS),
              origin=t.vec2("origin"), angle=t.number("angle", unit="rad"))
    if rayleigh is not None:
        kw["rayleigh"] = rayleigh
    sup = t.table("supports", section="plane.supports")
    held = {key: _groups(sup, key) for key in ("fixed", "fixed_x", "fixed_y")}
    sup.finish()
    model = build_model(t, Plane, mesh=str(path), **held, **kw)
    try:
        mesh = model.read()
    except MeshError as exc:
        t.error("mesh", str(exc))
    except ImportError as exc:          # meshio is an optional extra
        t.error("type", f"`plane` needs {exc.name or 'a missing package'}, which is not "
                        f"installed: pip install \"cosim[fem]\"")
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
        if s is not None and not 0.0 <= s <= length * (1 + 1e-12):
            pt.error("s", f"must be an arc length in [0, {length:.6g}] m along `{group}`, got "
                          f"{echo(s)}")
        pt.finish()
        ports[p] = (group, None if s is None else min(s, length))
    pts.finish()
    if not ports:
        t.error("points", "must name at least one point")
    return model, ports
