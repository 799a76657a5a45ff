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
and imports no plug-in.  A plug-in is refused, with the distribution and the
entry point named (:class:`~cosim.errors.PluginError`), when its name is a
built-in one, two distributions declare the same name, it fails to import,
or it is not a class of its group.

Trust: an installed package's code runs when a scene names it, as any
package the user installed; a scene names a registered name, never a module
to import.
"""
from __future__ import annotations

from cosim.errors import PluginError

__all__ = ["GROUPS", "find", "provide", "declared"]

#: entry-point group -> what it holds, in words
GROUPS = {"cosim.laws": "contact law", "cosim.schemes": "coupling scheme",
          "cosim.integrators": "integrator", "cosim.structures": "structure"}

#: the packages whose classes are built in
_OURS = ("cosim", "couplers", "fem", "multibody")


def _targets(group: str):
    """(base class, registry) pairs a class of ``group`` may go to."""
    if group == "cosim.laws":
        from couplers import CONTACT_LAWS, ContactLaw
        return [(ContactLaw, CONTACT_LAWS)]
    if group == "cosim.schemes":
        from cosim.core.schemes import COUPLING_SCHEMES, CouplingScheme
        return [(CouplingScheme, COUPLING_SCHEMES)]
    if group == "cosim.integrators":
        from cosim.core.ode import INTEGRATORS, TimeStepper
        from fem.integrator_base import StructuralIntegrator
        from fem.integrators import STRUCTURAL_INTEGRATORS
        return [(TimeStepper, INTEGRATORS), (StructuralIntegrator, STRUCTURAL_INTEGRATORS)]
    if group == "cosim.structures":
        from fem import STRUCTURE_MODELS, StructureModel
        return [(StructureModel, STRUCTURE_MODELS)]
    raise ValueError(f"unknown plug-in group {group!r}; the groups are {sorted(GROUPS)}")


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
    where = f"distribution `{dist.name}` {dist.version}" if dist is not None else \
        "an unnamed distribution"
    return f"{where}, entry point `{ep.name} = {ep.value}` in group `{ep.group}`"


def declared(group: str) -> dict:
    """The entry points of ``group`` by name, checked: none has a built-in
    name, and no two distributions declare the same name.

    Raises
    ------
    PluginError
        On such a clash, naming the distributions and entry points.
    """
    from importlib.metadata import entry_points

    built_in = set().union(*(_built_in(reg) for _, reg in _targets(group)))
    found = {}
    for ep in entry_points(group=group):
        if ep.name in built_in:
            raise PluginError(f"the plug-in {_origin(ep)} is named like the built-in "
                              f"{GROUPS[group]} `{ep.name}`, which it may not replace: "
                              f"rename it in that package's entry points")
        if ep.name in found and found[ep.name].value != ep.value:
            raise PluginError(f"two plug-ins are named `{ep.name}`: {_origin(found[ep.name])}, "
                              f"and {_origin(ep)}; uninstall or rename one")
        found[ep.name] = ep
    return found


def find(group: str, name) -> bool:
    """Register the class an installed distribution declares as ``name`` in
    ``group`` (see the module's notes) and say whether one does.

    Raises
    ------
    PluginError
        If the group has a clash (:func:`declared`), or the entry point
        fails to import or is not a class of its group named ``name``.
    """
    if not isinstance(name, str):
        return False
    ep = declared(group).get(name)
    if ep is None:
        return False
    try:
        cls = ep.load()
    except Exception as exc:                 # whatever the plug-in's import raised
        raise PluginError(f"the plug-in {_origin(ep)} cannot be imported: "
                          f"{type(exc).__name__}: {exc}") from exc
    for base, registry in _targets(group):
        if isinstance(cls, type) and issubclass(cls, base):
            if getattr(cls, "name", None) != name:
                raise PluginError(f"the plug-in {_origin(ep)} loads {cls.__qualname__}, whose "
                                  f"`name` is {getattr(cls, 'name', None)!r}, not {name!r}: "
                                  f"the two must agree")
            registry[name] = cls
            return True
    bases = " or ".join(f"{b.__module__}.{b.__qualname__}" for b, _ in _targets(group))
    raise PluginError(f"the plug-in {_origin(ep)} loads {cls!r}, which is not a subclass "
                      f"of {bases}")


def provide(registry, group: str, name) -> None:
    """Make sure a plain dict ``registry`` (a :class:`~cosim.core.registry.Registry`
    does this itself) holds ``name`` if a plug-in of ``group`` declares it:
    for names read from a scene, before they are checked against it."""
    if isinstance(name, str) and name not in registry:
        find(group, name)
