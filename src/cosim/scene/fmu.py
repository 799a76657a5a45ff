"""Scene support of ``type = "fmu"`` subsystems: validate the table, build the side.

A scene declares an FMU side as::

    [subsystems.arm]
    type = "fmu"
    path = "arm2.fmu"                  # relative to the scene file
    parameters = { dq1_start = -3.0 }  # start values set before initialisation
    energy = "energy"                  # output variable [J] (optional, see below)
    coordinates = { q1 = ["q1", "dq1"] }   # named coordinates for the results (optional)

    [subsystems.arm.ports.tip]
    position = ["x", "y"]              # output variables [m]
    velocity = ["vx", "vy"]            # output variables [m/s]
    force = ["fx", "fy"]               # input variables [N]
    port_mass = 0.17                   # [kg], or the name of an output variable

Everything is checked when the scene is read: the file exists, is a
co-simulation FMU of FMI 2.0 or 3.0, and every variable named exists with
the right causality (outputs for positions, velocities, coordinates, energy
and a port mass given by name; inputs for forces; parameters for start
values).  :func:`fmu_spec` is the loader's single call; the builder's are in
:mod:`cosim.scene.fmu_build`.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["fmu_spec"]


def _names(t, k: str, n: int = 2) -> tuple:
    v = t.raw(k)
    if not (isinstance(v, list) and len(v) == n and all(isinstance(x, str) for x in v)):
        t.error(k, f"must be an array of {n} variable names, got {v!r}")
    return tuple(v)


def fmu_spec(name: str, t):
    """Validate the table ``t`` (a scene loader's table, section ``fmu``) of
    the ``type = "fmu"`` subsystem ``name``; return its
    :class:`~cosim.scene.specs.FMUSpec`.

    Raises
    ------
    SceneError
        Naming the file and the key path.
    """
    from cosim.sides.fmu import FMUPort
    from cosim.sides.fmu_description import read_fmu_variables
    rel = t.string("path")
    path = Path(rel)
    if not path.is_absolute():
        path = Path(t.file).resolve().parent / path
    if not path.is_file():
        t.error("path", f"must name an .fmu file (relative to the scene file), got {rel!r}: "
                        f"{path} does not exist")
    # the run folder's scene.toml records where the FMU was found, so that the
    # run can be rebuilt from there (`cosim plot --animate`)
    t.data["path"] = str(path)
    try:
        md, variables = read_fmu_variables(path)
    except ImportError as exc:
        t.error("type", str(exc))
    except ValueError as exc:
        t.error("path", f"{rel!r} {exc}")

    def check(table, k, name, causalities, what):
        v = variables.get(name)
        if v is None:
            close = sorted(n for n, x in variables.items() if x.causality in causalities)
            table.error(k, f"names no variable of {path.name}: {name!r}; its {what} are {close}")
        if v.causality not in causalities or not v.real:
            table.error(k, f"must name a real {what[:-1]} of {path.name}, got {name!r} "
                           f"({v.causality} {v.type})")

    ports = {}
    pt = t.table("ports", section="fmu.ports")
    for pname in list(pt.data):
        p = pt.table(pname, section="fmu.port")
        pos, vel, force = _names(p, "position"), _names(p, "velocity"), _names(p, "force")
        for k, names in (("position", pos), ("velocity", vel)):
            for n in names:
                check(p, k, n, ("output",), "outputs")
        for n in force:
            check(p, "force", n, ("input",), "inputs")
        m = p.raw("port_mass")
        if isinstance(m, str):
            check(p, "port_mass", m, ("output",), "outputs")
        else:
            m = p.number("port_mass", rule=">0", unit="kg")
        p.finish()
        ports[pname] = FMUPort(pos, vel, force, m)
    if not ports:
        t.error("ports", "must declare at least one port")
    pt.finish()
    params = {}
    pr = t.table("parameters", section="fmu.parameters")
    for k in list(pr.data):
        check(pr, k, k, ("parameter",), "parameters")
        params[k] = pr.number(k)
    pr.finish()
    coords = {}
    ct = t.table("coordinates", section="fmu.coordinates")
    for k in list(ct.data):
        names = _names(ct, k)
        for n in names:
            check(ct, k, n, ("output",), "outputs")
        coords[k] = names
    ct.finish()
    energy = t.string("energy")
    if energy is not None:
        check(t, "energy", energy, ("output",), "outputs")
    from cosim.sides.fmu_description import can_get_set_state
    from cosim.scene.specs import FMUSpec
    return FMUSpec(name=name, key=t.key(), path=str(path), ports=ports, parameters=params,
                   coordinates=coords, energy=energy, fmi_version=str(md.fmiVersion),
                   can_get_set_state=can_get_set_state(md))
