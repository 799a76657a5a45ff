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
values).  :func:`fmu_spec` is the loader's single call, :func:`build_fmu`
and :func:`settle_fmu_contacts` the builder's.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

__all__ = ["fmu_spec", "build_fmu", "settle_fmu_contacts", "needs_rollback"]


def _names(t, k: str, n: int = 2) -> tuple:
    v = t.raw(k)
    if not (isinstance(v, list) and len(v) == n and all(isinstance(x, str) for x in v)):
        t.error(k, f"must be an array of {n} variable names, got {v!r}")
    return tuple(v)


def fmu_spec(t) -> dict:
    """Validate the table ``t`` (a scene loader's table) of a ``type = "fmu"``
    subsystem; return the spec entries ``path``, ``ports``, ``parameters``,
    ``coordinates``, ``energy`` and ``fmi_version``, ``can_get_set_state``.

    Raises
    ------
    SceneError
        Naming the file and the key path.
    """
    from cosim.sides.fmu import FMUPort, read_fmu_variables
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
    pt = t.table("ports")
    for pname in list(pt.data):
        p = pt.table(pname)
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
    pr = t.table("parameters", {})
    for k in list(pr.data):
        check(pr, k, k, ("parameter",), "parameters")
        params[k] = pr.number(k)
    pr.finish()
    coords = {}
    ct = t.table("coordinates", {})
    for k in list(ct.data):
        names = _names(ct, k)
        for n in names:
            check(ct, k, n, ("output",), "outputs")
        coords[k] = names
    ct.finish()
    energy = t.string("energy", None)
    if energy is not None:
        check(t, "energy", energy, ("output",), "outputs")
    from cosim.sides.fmu import can_get_set_state
    return {"path": str(path), "ports": ports, "parameters": params, "coordinates": coords,
            "energy": energy, "fmi_version": str(md.fmiVersion),
            "can_get_set_state": can_get_set_state(md)}


def needs_rollback(scheme: str, opts: dict) -> str | None:
    """Why scheme ``scheme`` with options ``opts`` rolls subsystems back (a
    phrase for a message), or None if it never does."""
    if scheme == "implicit":
        return "the `implicit` scheme repeats each macro step from a saved state"
    if opts.get("contact_step") is not None:
        return (f"macro-step control (`scheme.contact_step`) of scheme `{scheme}` rolls back "
                f"steps that overrun a contact's onset")
    return None


def build_fmu(spec: dict, scene, scheme: str, opts: dict):
    """The :class:`~cosim.sides.fmu.FMUSubsystem` of a validated spec, after
    checking that scheme ``scheme`` (options ``opts``) can drive it.

    Raises
    ------
    SceneError
        For the monolithic scheme (an FMU has no model-exchange face), for a
        scheme that rolls back an FMU that cannot get and set its state, for
        an FMU without an ``energy`` variable while the run guard checks
        energy, or when the FMU cannot be instantiated.
    """
    from cosim.scene.load import SceneError
    from cosim.sides.fmu import FMUSubsystem
    key = spec["key"]
    if scheme == "monolithic":
        raise SceneError(scene.path, "scheme.name",
                         f"is `monolithic`, which stacks every subsystem into one ODE; "
                         f"subsystem `{spec['name']}` is a co-simulation FMU with no "
                         f"model-exchange face; use `jacobi`, `gauss_seidel` or `implicit`")
    why = needs_rollback(scheme, opts)
    if why is not None and not spec["can_get_set_state"]:
        flag = ("canGetAndSetFMUState" if spec["fmi_version"].startswith("3")
                else "canGetAndSetFMUstate")
        raise SceneError(scene.path, f"{key}.path",
                         f"names an FMU that cannot get and set its state (`{flag}` is "
                         f"false), and {why}; use `jacobi` or `gauss_seidel` without "
                         f"`contact_step`")
    if spec["energy"] is None and scene.guard.energy_check:
        raise SceneError(scene.path, f"{key}.energy",
                         "is required while the run guard checks energy: name the FMU's "
                         "output variable of its mechanical energy [J], or set "
                         "`guard.energy_check = false`")
    try:
        return FMUSubsystem(spec["name"], spec["path"], spec["ports"], spec["parameters"],
                            spec["coordinates"], spec["energy"])
    except (RuntimeError, KeyError) as exc:
        raise SceneError(scene.path, f"{key}.path", str(exc)) from None


def settle_fmu_contacts(scene, subs: list, links: list) -> list:
    """Keep contacts out of FMU sides: an FMU cannot evaluate a contact law.

    A contact between an FMU and a moving side that the scene embeds without
    naming a host is hosted by the other side; one that names the FMU as
    host, or embeds a contact between an FMU and a rigid side, is refused.

    Raises
    ------
    SceneError
        At ``contacts.NAME.placement`` or ``contacts.NAME.host``.
    """
    from cosim.scene.load import SceneError
    from cosim.sides.fmu import FMUSubsystem
    out = []
    specs = {c["name"]: c for c in scene.contacts}
    for ln in links:
        fmu = [s for s in (ln.sub_a, ln.sub_b) if isinstance(subs[s], FMUSubsystem)]
        if not fmu or ln.placement != "embedded":
            out.append(ln)
            continue
        spec = specs[ln.contact.name]
        other = ln.sub_b if fmu[0] == ln.sub_a else ln.sub_a
        why = (f"subsystem `{subs[fmu[0]].name}` is an FMU, a black box that cannot evaluate "
               f"a contact law")
        if subs[other].rigid or len(fmu) == 2:
            raise SceneError(scene.path, f"{spec['key']}.placement",
                             f"is `embedded`, but {why}; set `placement = \"coupler\"`")
        if spec["host"] is not None and ln.host in fmu:
            raise SceneError(scene.path, f"{spec['key']}.host",
                             f"names `{subs[ln.host].name}`, but {why}; let "
                             f"`{subs[other].name}` host it or set `placement = \"coupler\"`")
        out.append(dataclasses.replace(ln, host=other))
    return out
