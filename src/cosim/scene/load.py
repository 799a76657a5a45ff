"""Scene files: TOML to validated objects.

A scene declares its subsystems, contacts, effects, coupling scheme, end
time and outputs; nothing undeclared is simulated.  Every value is checked
when the file is read, and a :class:`SceneError` names the file, the key path
and what was expected.  Variants (``[variants.NAME]``) are tables of
overrides merged into the scene; ``--set key.path=value`` applies after them.

:func:`load_scene` reads the file (:mod:`cosim.scene.read`), validates its
top-level tables here, its subsystems (:mod:`cosim.scene.subsystems`) and
contacts (:mod:`cosim.scene.contacts`) against the table of keys
(:mod:`cosim.scene.keys`), and returns a :class:`~cosim.scene.specs.Scene` of
typed specs (:mod:`cosim.scene.specs`).  It never imports the builder.
"""
from __future__ import annotations

from cosim.core.guard import GuardOptions
from cosim.scene.checks import (MAX_ELEMENTS, MAX_STEPS, SceneError, Table, check_name,
                                 echo, nearest)
from cosim.scene.contacts import check_conditions, contact_spec
from cosim.scene.read import parse_override, read_scene, read_toml_file
from cosim.scene.shipped import scene_file
from cosim.scene.specs import (STRUCTURE_TYPES, SUBSYSTEM_TYPES, Scene, StructureSpec,
                               resolve_scheme)
from cosim.scene.subsystems import subsystem_spec

__all__ = ["SceneError", "Scene", "load_scene", "parse_override", "read_toml_file",
           "SUBSYSTEM_TYPES", "STRUCTURE_TYPES", "structure_memory", "spec_memory", "MAX_ELEMENTS",
           "MAX_STEPS", "MAX_MEMORY"]

#: most memory the structures of a scene may need, as estimated before they
#: are built (:func:`structure_memory`) [bytes]
MAX_MEMORY = 4 * 2**30
#: the reader of a table, under the name a study file's reader imports
_Table = Table


def load_scene(path, variant: str | None = None, overrides=(), scheme: str | None = None
               ) -> Scene:
    """Read, merge and validate a scene file.

    Parameters
    ----------
    path : path-like
        The scene file, or the name of a scene cosim ships (``spring_drop``;
        :func:`cosim.scene.shipped.find_scene`): a file that exists wins.
    variant : str, optional
        Name of a ``[variants.NAME]`` table; the scene's ``default_variant``
        when omitted.
    overrides : iterable of str or (path list, value)
        ``key.path=value`` overrides, applied after the variant.
    scheme : str, optional
        Replace the scene's coupling scheme; the scene's options the new
        scheme does not take (those for other schemes) are dropped, no fault
        of the scene: one line at the log's info level names them.

    Returns
    -------
    Scene
        Its :meth:`~cosim.Scene.build` makes the coupled system.

    Raises
    ------
    SceneError
    """
    file = scene_file(path)             # an empty name, or none found, refused
    data, chosen = read_scene(file, variant, overrides, scheme)
    return _validate(data, file, chosen, scheme is not None)


def _validate(data: dict, file, variant, scheme_chosen: bool = False) -> Scene:
    top = Table(data, (), file, "top")
    name = top.string("name", file.stem)
    check_name(file, "name", name, "(a run folder's default name; the file's name when the "
                                   "scene gives none)" if "name" not in data else "")
    top.string("description")
    t_end = top.number("t_end", rule=">0", unit="s")
    scheme_name, given, tables = _scheme_table(top.table("scheme", section="top"))

    out = top.table("output", section="output")
    every = out.integer("every", low=1)
    export = out.raw("export")
    if not isinstance(export, list) or not all(isinstance(x, str) for x in export):
        out.error("export", f"must be a list of structure names, got {echo(export)}")
    export_every = out.integer("export_every", low=1)
    estimate = out.boolean("estimate")
    out.finish()

    eff = top.table("effects", section="effects")
    gravity = None
    if eff.has("gravity"):
        g = eff.raw("gravity")
        if isinstance(g, list):
            gravity = eff.vec2("gravity", unit="m/s^2")
        else:
            gravity = (0.0, -eff.number("gravity", rule=">0", unit="m/s^2"))
    eff.finish()

    gd = top.table("guard", section="guard")
    guard = GuardOptions(energy_growth=gd.number("energy_growth", rule=">0"),
                         energy_check=gd.boolean("energy_check"),
                         energy_floor=gd.number("energy_floor", rule=">=0", unit="J"),
                         energy_warning=gd.number("energy_warning", rule=">0"),
                         coupling_warning=gd.number("coupling_warning", rule=">0"),
                         chatter_switches=gd.integer("chatter_switches", low=2, high=10 ** 9),
                         chatter_window=gd.number("chatter_window", rule=">=0", unit="s"))
    max_steps = gd.number("max_steps", rule=">0")
    gd.finish()

    subs = []
    for sname, st in top.tables("subsystems", section="subsystems", entries="subsystem"):
        check_name(file, "subsystems", sname, "names a subsystem that")
        if "." in sname:
            raise SceneError(file, "subsystems", f"names a subsystem {echo(sname)}: a subsystem's "
                                                 f"name holds no `.`, which separates it from "
                                                 f"the point in SUBSYSTEM.POINT")
        subs.append(subsystem_spec(sname, st))
    if not subs:
        top.error("subsystems", "must declare at least one subsystem")
    _check_memory(subs, file)
    structures = [s.name for s in subs if isinstance(s, StructureSpec)]
    for name_ in export:
        if name_ not in structures:
            raise SceneError(file, "output.export", f"names {echo(name_)}, which is not a "
                                                    f"structure of this scene; structures are "
                                                    f"{structures}")
    contacts = []
    for cname, ct in top.tables("contacts", section="contacts", entries="contact"):
        check_name(file, "contacts", cname, "names a contact that")
        contacts.append(contact_spec(cname, ct, subs))
    check_conditions(contacts, file)
    top.finish()
    # the work a run will do (macro steps, iterations, each side's steps), bounded
    spec = resolve_scheme(scheme_name, given, tables, file=file, t_end=t_end, stacklevel=3,
                          subsystems=subs, contacts=contacts, max_steps=max_steps,
                          chosen=scheme_chosen)
    return Scene(name=name, path=str(file), variant=variant, t_end=t_end, scheme=spec.name,
                 scheme_options=spec.options, output_every=every, subsystems=tuple(subs),
                 contacts=tuple(contacts), gravity=gravity, data=data,
                 export=tuple(export), export_every=export_every, scheme_tables=tables,
                 guard=guard, max_steps=max_steps, estimate=estimate)


def _scheme_table(sch: Table) -> tuple[str, dict, dict]:
    """The ``[scheme]`` table: the scheme's name, the options given (each
    checked against a scheme that takes it) and the ``[scheme.NAME]`` tables
    (checked against scheme NAME).  Which of them the run keeps is
    :func:`~cosim.scene.specs.resolve_scheme`'s choice.

    Its keys are the registry's (:data:`cosim.core.schemes.COUPLING_SCHEMES`):
    ``name``, the schemes' options and tables named after a scheme; and
    ``accuracy``, which :mod:`cosim.studies.choose` reads (checked here).
    """
    from cosim.core.plugins import provide
    from cosim.core.schemes import COUPLING_SCHEMES

    free = Table(sch.data, sch.path, sch.file)      # keys from the registry, not SECTIONS
    provide(COUPLING_SCHEMES, "cosim.schemes", free.data.get("name"))   # an installed plug-in
    name = free.string("name", choices=COUPLING_SCHEMES)
    cls = COUPLING_SCHEMES[name]
    given, tables = {}, {}
    if "accuracy" in free.data:
        from cosim.scene.checks import parse_accuracy
        try:
            parse_accuracy(free.raw("accuracy"), "accuracy")
        except ValueError as exc:
            free.error("accuracy", str(exc).replace("`accuracy` ", "", 1))
    for k in list(free.data):
        if k in ("name", "accuracy"):
            continue
        if k in COUPLING_SCHEMES and isinstance(free.data[k], dict):
            sub = free.table(k)
            other = COUPLING_SCHEMES[k]
            for ko in list(sub.data):
                if ko not in other.options:
                    near = nearest(ko, other.options)
                    sub.error(ko, f"is not an option of scheme `{k}`"
                                  + (f" (did you mean `{near}`?)" if near else "")
                                  + f"; its options are {sorted(other.options)}")
            tables[k] = {ko: _scheme_option(sub, ko, other.options[ko]) for ko in sub.data}
            sub.finish()
            continue
        free.used.add(k)
        if k not in cls.options and not any(k in c.options for c in COUPLING_SCHEMES.values()):
            known = {o for c in COUPLING_SCHEMES.values() for o in c.options} | {"accuracy"}
            near = nearest(k, known)
            free.error(k, f"is not an option of any scheme"
                          + (f" (did you mean `{near}`?)" if near else "")
                          + f"; options of `{name}` are {sorted(cls.options)}")
        owner = cls if k in cls.options else next(c for c in COUPLING_SCHEMES.values()
                                                  if k in c.options)
        given[k] = _scheme_option(free, k, owner.options[k])    # still a valid value
    free.finish()
    return name, given, tables


def _scheme_option(sch: Table, k, opt):
    v = sch.raw(k)
    if opt.kind is float:
        v = sch.number(k)
    elif opt.kind is int:
        v = sch.integer(k)
    elif opt.kind is bool:
        v = sch.boolean(k)
    elif opt.kind is str:
        v = sch.string(k)
    elif opt.kind is list and not isinstance(v, list):
        sch.error(k, f"must be an array, got {echo(v)}")
    if not opt.check(v):
        sch.error(k, f"must be {opt.rule}, got {echo(v)}")
    return v


def structure_memory(kind: str, size: int, n_modes: int | None, cutoff_hz: float | None
                     ) -> tuple[int, int, str]:
    """Estimate the memory that building a structure takes, before it is built.

    Parameters
    ----------
    kind : str
        ``chain``, ``beam``, ``cable``, ``string`` or ``rod``; ``dofs`` for a
        plug-in structure (:class:`fem.StructureModel`).
    size : int
        Masses of a chain, elements of the others, the DOFs of ``dofs``
        (the model's :meth:`~fem.StructureModel.dof_bound`).
    n_modes, cutoff_hz
        The structure's ``modes`` table (``count`` and ``cutoff_hz``).

    Returns
    -------
    n_dof : int
        Its degrees of freedom before constraints (an upper bound).
    bytes : int
        About the peak memory of its assembly and modal analysis [bytes]: a
        dense eigenproblem (every mode kept, or a structure of at most
        ``fem.modal.DENSE_LIMIT`` DOFs) holds about ten ``n x n`` arrays of
        doubles (9.4 measured for a chain of 2000 masses), and so does a
        chain, whose matrices are dense; a sparse one, a few ``n``-vectors per
        Lanczos vector (a lower bound with a cutoff alone, whose number of
        modes is found while solving).
    why : str
        What dominates, for the message.
    """
    from fem.modal import DENSE_LIMIT

    n = {"chain": size, "dofs": size, "beam": 2 * (size + 1),
         "cable": 2 * (size + 1)}.get(kind, size + 1)
    dense = (n <= DENSE_LIMIT or (n_modes is None and cutoff_hz is None)
             or (n_modes is not None and n_modes >= n - 3))
    if dense or kind == "chain":
        nbytes = 10 * 8 * n * n
        why = f"dense {n} x {n} matrices"
        if not dense:
            why += " (a chain's matrices are dense whatever modes it keeps)"
        else:
            why += (" (every mode is kept: give `modes.count` or `modes.cutoff_hz`)"
                    if kind != "chain" else "")
        return n, nbytes, why
    k = n_modes if n_modes is not None else 16
    nbytes = 8 * n * (3 * max(2 * k + 1, 20) + 60)
    return n, nbytes, f"{k} Lanczos vectors of {n} DOFs"


def spec_memory(spec) -> tuple[int, int, str, str]:
    """:func:`structure_memory` of a :class:`~cosim.scene.specs.StructureSpec`,
    and the key that sets its size: ``(n_dof, bytes, why, key)``."""
    model = spec.model
    if spec.type == "chain":
        kind, size, key = "chain", len(model.masses), ".masses"
    elif spec.type == "plane":                     # counted from the mesh's cells
        kind, size, key = "dofs", int(model.dof_bound()), ".mesh"
    elif spec.type in STRUCTURE_TYPES:
        kind, size, key = spec.type, model.n_elements, ".elements"
    else:                                          # a plug-in's bound
        kind, size, key = "dofs", _dof_bound(model), ""
    return (*structure_memory(kind, size, spec.n_modes, spec.cutoff_hz), spec.key + key)


def _dof_bound(model) -> int:
    """A plug-in structure's ``dof_bound()``: an integer >= 1, else a
    :class:`~cosim.errors.PluginError` naming the plug-in."""
    import numbers

    from cosim.core.plugin_guard import call, refuse
    n = call(model, "dof_bound")
    if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1:
        raise refuse(model, "dof_bound()", n, "an integer >= 1, the most degrees of freedom "
                                               "its assembled structure has")
    return int(n)


def _check_memory(subs: list, file) -> None:
    """Refuse a scene whose structures would need more than :data:`MAX_MEMORY`."""
    found = []
    for spec in subs:
        if isinstance(spec, StructureSpec):
            n, nbytes, why, key = spec_memory(spec)
            found.append((nbytes, key, n, why))
    total = sum(f[0] for f in found)
    if total > MAX_MEMORY:
        nbytes, key, n, why = max(found)
        others = (f"; with the other structures, {_size_text(total)}"
                  if total > nbytes else "")
        raise SceneError(file, key, f"makes a structure of {n} DOFs whose model and modes "
                                    f"need about {_size_text(nbytes)} ({why}){others}, more "
                                    f"than the {_size_text(MAX_MEMORY)} a scene may use "
                                    f"(`cosim.scene.load.MAX_MEMORY`)")


def _size_text(nbytes: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if nbytes < 1024 or unit == "GiB":
            return f"{nbytes:.3g} {unit}"
        nbytes /= 1024
