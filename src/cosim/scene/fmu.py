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
values).  Variables that must differ do, by name and by value reference:
the two of a position, velocity, force or coordinate, a port's position and
velocity, and every input and parameter cosim sets (each by one key).  A
coordinate's name becomes a key of the series, so it is held to the rule of
names (:func:`cosim.scene.checks.check_name`).  Only the model description
is read (:mod:`cosim.sides.fmu_description`): nothing of the FMU runs while
a scene loads.  :func:`fmu_spec` is the loader's single call; the builder's
are in :mod:`cosim.scene.fmu_build`.
"""
from __future__ import annotations

from pathlib import Path

from cosim.errors import shown
from cosim.scene.checks import check_name

__all__ = ["fmu_spec"]


#: most variable names a message lists
NAMES_SHOWN = 20


def _names(t, k: str, n: int = 2) -> tuple:
    v = t.raw(k)
    if not (isinstance(v, list) and len(v) == n and all(isinstance(x, str) for x in v)):
        t.error(k, f"must be an array of {n} variable names, got {shown(v)}")
    if len(set(v)) < n:
        t.error(k, f"must name {n} different variables, got {shown(v)}")
    return tuple(v)


def _listed(names) -> str:
    """Variable names of an FMU for a message: escaped, at most
    :data:`NAMES_SHOWN` of them."""
    names = sorted(names)
    more = f", ... ({len(names)} in all)" if len(names) > NAMES_SHOWN else ""
    return "[" + ", ".join(shown(repr(n), limit=60) for n in names[:NAMES_SHOWN]) + more + "]"


def fmu_spec(name: str, t):
    """Validate the table ``t`` (a scene loader's table, section ``fmu``) of
    the ``type = "fmu"`` subsystem ``name``; return its
    :class:`~cosim.scene.specs.FMUSpec`.

    Only the FMU's model description is read; nothing of the FMU runs.

    Raises
    ------
    SceneError
        Naming the file and the key path.
    """
    from cosim.sides.fmu import FMUPort
    from cosim.sides.fmu_description import port_mass_problem, read_fmu_variables
    rel = t.string("path")
    path = Path(rel)
    if not path.is_absolute():
        path = Path(t.file).resolve().parent / path
    if path.is_dir():
        t.error("path", f"must name an .fmu file (relative to the scene file), got "
                        f"{shown(repr(rel))}: {shown(str(path))} is a directory")
    if not path.is_file():
        t.error("path", f"must name an .fmu file (relative to the scene file), got "
                        f"{shown(repr(rel))}: {shown(str(path))} does not exist")
    # the run folder's scene.toml records where the FMU was found, so that the
    # run can be rebuilt from there (`cosim plot --animate`)
    t.data["path"] = str(path)
    try:
        md, variables = read_fmu_variables(path)
    except ImportError as exc:
        t.error("type", str(exc))
    except ValueError as exc:
        t.error("path", f"{shown(repr(rel))} {exc}")
    fmu = shown(path.name, limit=80)

    def check(table, k, name, causalities, what):
        v = variables.get(name)
        if v is None:
            close = [n for n, x in variables.items() if x.causality in causalities]
            table.error(k, f"names no variable of {fmu}: {shown(repr(name))}; its {what} are "
                           f"{_listed(close)}")
        if v.causality not in causalities or not v.real:
            table.error(k, f"must name a real {what[:-1]} of {fmu}, got {shown(repr(name))} "
                           f"({shown(v.causality, limit=40)} {shown(v.type, limit=40)})")

    #: variables cosim sets, each once: value reference -> (key, name)
    written = {}

    def sets(table, k, name):
        """Record that cosim sets variable ``name`` (key ``k`` of ``table``):
        no other key may set it, nor a variable of the same value reference."""
        vr = variables[name].value_reference
        if vr in written:
            other, first = written[vr]
            alias = "" if first == name else (f" (its value reference {vr} is that of "
                                              f"{shown(repr(first))})")
            table.error(k, f"sets {fmu}'s variable {shown(repr(name))}{alias}, which "
                           f"`{other}` sets already; each input and parameter is set by one "
                           f"key")
        written[vr] = (table.key(k), name)

    def distinct(table, k, names, others, what):
        """Refuse ``names`` that share a variable or a value reference with ``others``."""
        refs = {variables[n].value_reference: n for n in others}
        for n in names:
            hit = refs.get(variables[n].value_reference)
            if hit is not None:
                table.error(k, f"names {shown(repr(n))}, the same variable of {fmu} as "
                               f"{shown(repr(hit))} of {what}; they must differ")

    ports = {}
    pt = t.table("ports", section="fmu.ports")
    for pname in list(pt.data):
        p = pt.table(pname, section="fmu.port")
        pos, vel, force = _names(p, "position"), _names(p, "velocity"), _names(p, "force")
        for k, names in (("position", pos), ("velocity", vel)):
            for n in names:
                check(p, k, n, ("output",), "outputs")
            distinct(p, k, names[1:], names[:1], f"`{p.key(k)}`")
        distinct(p, "velocity", vel, pos, f"`{p.key('position')}`")
        for n in force:
            check(p, "force", n, ("input",), "inputs")
            sets(p, "force", n)
        m = p.raw("port_mass")
        if isinstance(m, str):
            check(p, "port_mass", m, ("output",), "outputs")
        else:
            m = p.number("port_mass", rule=">0", unit="kg")
            problem = port_mass_problem(m)
            if problem is not None:
                p.error("port_mass", problem)
        p.finish()
        ports[pname] = FMUPort(pos, vel, force, m)
    if not ports:
        t.error("ports", "must declare at least one port")
    pt.finish()
    params = {}
    pr = t.table("parameters", section="fmu.parameters")
    for k in list(pr.data):
        check(pr, k, k, ("parameter",), "parameters")
        sets(pr, k, k)
        params[k] = pr.number(k)
    pr.finish()
    coords = {}
    ct = t.table("coordinates", section="fmu.coordinates")
    for k in list(ct.data):
        # a coordinate's name becomes a key of the series (`q/SUBSYSTEM/NAME`)
        check_name(t.file, ct.key(), k, "names a coordinate that")
        names = _names(ct, k)
        for n in names:
            check(ct, k, n, ("output",), "outputs")
        distinct(ct, k, names[1:], names[:1], f"`{ct.key(k)}`")
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
