"""Building ``type = "fmu"`` subsystems (the builder's side of
:mod:`cosim.scene.fmu`): the FMU side of a validated
:class:`~cosim.scene.specs.FMUSpec`, after checking that the scheme can drive
it, and the contacts kept out of it.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

__all__ = ["build_fmu", "settle_fmu_contacts", "needs_rollback"]


def needs_rollback(scheme: str, opts: dict) -> str | None:
    """Why scheme ``scheme`` with options ``opts`` rolls subsystems back (a
    phrase for a message), or None if it never does."""
    if scheme == "implicit":
        return "the `implicit` scheme repeats each macro step from a saved state"
    if opts.get("contact_step") is not None:
        return (f"macro-step control (`scheme.contact_step`) of scheme `{scheme}` rolls back "
                f"steps that overrun a contact's onset")
    return None


def build_fmu(spec, scene, scheme: str, opts: dict, *, run: bool = True):
    """The :class:`~cosim.sides.fmu.FMUSubsystem` of a validated spec, after
    checking that scheme ``scheme`` (options ``opts``) can drive it; with
    ``run=False`` the :class:`~cosim.sides.fmu_description.DescribedFMU`
    that stands in for it, made from its model description alone, so that
    nothing of the FMU runs.

    A port mass the FMU reports (``port_mass`` naming a variable) is read
    once the FMU is initialised and held to the rule of a declared one
    (:func:`~cosim.sides.fmu_description.port_mass_problem`).

    Raises
    ------
    SceneError
        For the monolithic scheme (an FMU has no model-exchange face), for a
        scheme that rolls back an FMU that cannot get and set its state, for
        an FMU without an ``energy`` variable while the run guard checks
        energy, when the FMU cannot be instantiated, or when it reports an
        unfit port mass.
    """
    from cosim.errors import shown
    from cosim.scene.checks import SceneError
    from cosim.sides.fmu import FMUSubsystem
    from cosim.sides.fmu_description import DescribedFMU, port_mass_problem
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
    if not run:
        return DescribedFMU(spec["name"], spec["path"], spec["ports"], spec["coordinates"],
                            spec["energy"])
    try:
        sub = FMUSubsystem(spec["name"], spec["path"], spec["ports"], spec["parameters"],
                           spec["coordinates"], spec["energy"])
    except (RuntimeError, KeyError) as exc:
        raise SceneError(scene.path, f"{key}.path", str(exc)) from None
    for k, (pname, port) in enumerate(spec["ports"].items()):
        if not isinstance(port.mass, str):
            continue
        value = sub.port_mass(k)
        problem = port_mass_problem(value)
        if problem is not None:
            sub.close()
            raise SceneError(scene.path, f"{key}.ports.{pname}.port_mass",
                             f"names output `{shown(port.mass, limit=80)}` of FMU "
                             f"{shown(Path(spec['path']).name, limit=80)}, which reports "
                             f"{shown(value, limit=40)} kg after its initialisation: a port "
                             f"mass {problem}")
    return sub


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
    from cosim.scene.checks import SceneError
    from cosim.sides.fmu import FMUSubsystem
    from cosim.sides.fmu_description import DescribedFMU
    out = []
    specs = {c["name"]: c for c in scene.contacts}
    for ln in links:
        fmu = [s for s in (ln.sub_a, ln.sub_b)
               if isinstance(subs[s], (FMUSubsystem, DescribedFMU))]
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
