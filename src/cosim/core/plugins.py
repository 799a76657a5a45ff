"""Contact laws, coupling schemes, integrators and structures that installed packages
declare (entry points), found by the name a scene gives them.

A distribution declares its classes in its ``pyproject.toml``::

    [project.entry-points."cosim.laws"]
    sphere_on_flat = "sphere_law:SphereOnFlat"

and once it is installed (``pip install``), a scene's ``law = { type =
"sphere_on_flat", ... }`` finds the class, in `cosim run`, `cosim sweep` (each
worker process finds it the same way) and `cosim info` alike.  The groups:

- ``cosim.laws``: a :class:`couplers.ContactLaw` subclass, into
  :data:`couplers.CONTACT_LAWS`;
- ``cosim.schemes``: a :class:`cosim.core.schemes.CouplingScheme` subclass,
  into :data:`cosim.core.schemes.COUPLING_SCHEMES`;
- ``cosim.integrators``: a :class:`cosim.core.ode.TimeStepper` subclass (a
  robot's integrator, into :data:`cosim.core.ode.INTEGRATORS`) or a
  :class:`fem.StructuralIntegrator` subclass (a structure's, into
  :data:`fem.STRUCTURAL_INTEGRATORS`);
- ``cosim.structures``: a :class:`fem.StructureModel` subclass, a frozen
  dataclass whose fields are the keys of its scene table
  (:mod:`cosim.scene.plugin_structure`), into :data:`fem.STRUCTURE_MODELS`.

The entry point's name is the name a scene writes, and must be the class's
own ``name``.  Entry points are read only when a scene asks for a name that
is not registered: a run that uses built-in names reads no package metadata
and imports no plug-in.  A plug-in named like a built-in is never loaded;
a name that two distributions declare is refused when a scene names it,
the group's other names working.  A plug-in is refused, with the
distribution and the entry point named (:class:`~cosim.errors.PluginError`),
when its name clashes so, it fails to import (whatever it raises,
``SystemExit`` included), it is not a class of its group, or cosim cannot
read it (a scheme without ``macro_step``; a structure's fields, which the
scene loader judges as it asks for one).  Once loaded, what it returns and
raises is judged at the boundary (:mod:`cosim.core.plugin_guard`).

Trust: an installed package's code runs when a scene names it, as any
package the user installed; a scene names a registered name, never a module
to import.
"""
from __future__ import annotations

from cosim.errors import PluginError, shown

__all__ = ["GROUPS", "find", "provide", "declared"]

#: entry-point group -> what it holds, in words
GROUPS = {"cosim.laws": "contact law", "cosim.schemes": "coupling scheme",
          "cosim.integrators": "integrator", "cosim.structures": "structure"}

#: the packages whose classes are built in
_OURS = ("cosim", "couplers", "fem", "multibody")


#: entry-point group -> the (base class, registry) pairs a class of it may go
#: to, each named ``"module:attribute"`` as a registry names a class it has not
#: imported: the registries are looked up here, not imported, so that the
#: modules that hold them (and import :class:`~cosim.core.registry.Registry`,
#: which asks this module for a name it lacks) are not imported by it
_TARGETS = {
    "cosim.laws": [("couplers:ContactLaw", "couplers:CONTACT_LAWS")],
    "cosim.schemes": [("cosim.core.schemes:CouplingScheme",
                       "cosim.core.schemes:COUPLING_SCHEMES")],
    "cosim.integrators": [("cosim.core.ode:TimeStepper", "cosim.core.ode:INTEGRATORS"),
                          ("fem.integrator_base:StructuralIntegrator",
                           "fem.integrators:STRUCTURAL_INTEGRATORS")],
    "cosim.structures": [("fem:StructureModel", "fem:STRUCTURE_MODELS")],
}


def _named(ref: str):
    """The attribute ``"module:attribute"`` names (its module imported)."""
    module, _, attr = ref.partition(":")
    # the import statement's machinery, which `python -X importtime` reports
    return getattr(__import__(module, fromlist=[attr]), attr)


def _targets(group: str):
    """(base class, registry) pairs a class of ``group`` may go to."""
    if group not in _TARGETS:
        raise ValueError(f"unknown plug-in group {group!r}; the groups are {sorted(GROUPS)}")
    return [(_named(base), _named(registry)) for base, registry in _TARGETS[group]]


def _built_in(registry) -> set:
    """Names of ``registry`` whose class is defined in cosim's own packages
    (a lazy ``"module:Class"`` entry is judged by its module, not imported)."""
    entries = getattr(registry, "_entries", registry)
    out = set()
    for name, value in entries.items():
        module = value.partition(":")[0] if isinstance(value, str) else value.__module__
        if module.split(".")[0] in _OURS:
            out.add(name)
    return out


def _origin(ep) -> str:
    dist = getattr(ep, "dist", None)
    # the metadata's text, shown escaped: a name cannot start a line of its own
    where = f"distribution `{shown(dist.name)}` {shown(dist.version)}" if dist is not None \
        else "an unnamed distribution"
    return f"{where}, entry point `{shown(ep.name)} = {shown(ep.value)}` in group `{ep.group}`"


def _scan(group: str) -> tuple[dict, dict]:
    """The entry points of ``group``: ``(usable, refused)``, each by name.

    A name that is a built-in one, or that two distributions declare, is
    refused (its message naming them) and never loaded; the other names of
    the group stay usable.
    """
    from importlib.metadata import entry_points

    built_in = set().union(*(_built_in(reg) for _, reg in _targets(group)))
    usable, refused, seen = {}, {}, {}
    for ep in entry_points(group=group):
        if ep.name in built_in:
            refused[ep.name] = (f"the plug-in {_origin(ep)} is named like the built-in "
                                f"{GROUPS[group]} `{ep.name}`, which it may not replace: "
                                f"rename it in that package's entry points")
            continue
        first = seen.setdefault(ep.name, ep)
        if first is not ep and first.value != ep.value:
            refused[ep.name] = (f"two plug-ins are named `{ep.name}`: {_origin(first)}, "
                                f"and {_origin(ep)}; uninstall or rename one")
        if ep.name not in refused:
            usable[ep.name] = ep
    for name in refused:
        usable.pop(name, None)
    return usable, refused


def declared(group: str) -> dict:
    """The usable entry points of ``group`` by name: those whose name is
    neither a built-in one nor declared by two distributions (:func:`_scan`)."""
    return _scan(group)[0]


def find(group: str, name) -> bool:
    """Register the class an installed distribution declares as ``name`` in
    ``group`` (see the module's notes) and say whether one does.

    Raises
    ------
    PluginError
        If ``name`` is declared twice, or the entry point fails to import
        (anything it raises, ``SystemExit`` included, Ctrl-C aside), is not
        a class of its group named ``name``, or (a scheme) declares what
        cosim cannot read.  Another name of the group is not concerned.
    """
    if not isinstance(name, str):
        return False
    usable, refused = _scan(group)
    if name in refused:
        raise PluginError(refused[name])
    ep = usable.get(name)
    if ep is None:
        return False
    try:
        cls = ep.load()
    except KeyboardInterrupt:
        raise
    except BaseException as exc:    # whatever the plug-in's import raised, sys.exit() too
        raise PluginError(f"the plug-in {_origin(ep)} cannot be imported: "
                          f"{type(exc).__name__}: {shown(str(exc))}") from None
    for base, registry in _targets(group):
        if isinstance(cls, type) and issubclass(cls, base):
            if getattr(cls, "name", None) != name:
                raise PluginError(f"the plug-in {_origin(ep)} loads {cls.__qualname__}, whose "
                                  f"`name` is {shown(repr(getattr(cls, 'name', None)))}, not "
                                  f"{name!r}: the two must agree")
            problem = _class_problem(group, cls)
            if problem:
                raise PluginError(f"the plug-in {_origin(ep)} is refused: {problem}")
            from cosim.core.plugin_guard import loaded
            loaded(cls, _origin(ep))
            registry[name] = cls
            return True
    bases = " or ".join(f"{b.__module__}.{b.__qualname__}" for b, _ in _targets(group))
    raise PluginError(f"the plug-in {_origin(ep)} loads {shown(cls)}, which is not a subclass "
                      f"of {bases}")


def _class_problem(group: str, cls) -> str:
    """What cosim cannot read in plug-in class ``cls`` of ``group`` (a
    scheme's options), or ``""``.  A structure's fields are the scene
    loader's to judge (:func:`cosim.scene.plugin_structure.model_class_problem`),
    as it provides one."""
    if group == "cosim.schemes":
        options = getattr(cls, "options", None)
        if not isinstance(options, dict):
            return f"its `options` is {shown(options)}, not a dict of option name -> Option"
        monolithic = any(k.__module__ == "cosim.core.schemes.monolithic" for k in cls.__mro__)
        if "macro_step" not in options and not monolithic:     # (its module left unloaded)
            return (f"its `options` ({shown(sorted(map(str, options)))}) has no "
                    f"`macro_step`: a co-simulation scheme takes its communication step as "
                    f"`macro_step` (or subclass cosim.core.schemes.Monolithic)")
    return ""


def provide(registry, group: str, name) -> None:
    """Make sure a plain dict ``registry`` (a :class:`~cosim.core.registry.Registry`
    does this itself) holds ``name`` if a plug-in of ``group`` declares it:
    for names read from a scene, before they are checked against it."""
    if isinstance(name, str) and name not in registry:
        find(group, name)
