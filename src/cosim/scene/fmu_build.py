"""Building ``type = "fmu"`` subsystems (the builder's side of
:mod:`cosim.scene.fmu`): the FMU side of a validated
:class:`~cosim.scene.specs.FMUSpec`, after checking that the scheme can drive
it, and the contacts kept out of it.
"""
from __future__ import annotations

import dataclasses

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


def build_fmu(spec, scene, scheme: str, opts: dict):
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
    from cosim.scene.checks import SceneError
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
    from cosim.scene.checks import SceneError
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
