"""The geometry of a run's scene for its animation, rebuilt from
``scene.toml`` as data: no side that runs code is built.

A run folder's ``scene.toml`` may name an FMU, whose geometry is computed by
its own binary; building that side would load and run the binary, so an
animation would run code a run folder brought along.  Here only the sides
that cosim computes itself are built (rigid sides, multibody trees and
structures, through the scene loader's checks of their tables and
:func:`cosim.scene.build.build_side`); an FMU's table is not read beyond the
names of its ports, and its file is never opened.  Its recorded series (the
coordinates its scene names) hold no positions, so the animation leaves it
out and says so.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Link", "SceneGeometry", "scene_geometry", "CODE_SIDES"]

#: subsystem types whose geometry is computed by code the scene names
CODE_SIDES = ("fmu",)


@dataclass(frozen=True)
class Link:
    """A contact as the animation draws it.

    Attributes
    ----------
    name : str
    sub_a, sub_b : int
        Indices of its sides in :attr:`SceneGeometry.subsystems`.
    port_a, port_b : int or None
        Port indices on those sides (None on a side not built).
    normal : tuple of float
        Unit normal from b towards a.
    """

    name: str
    sub_a: int
    port_a: int | None
    sub_b: int
    port_b: int | None
    normal: tuple


@dataclass(frozen=True)
class SceneGeometry:
    """The sides and contacts of a scene, as far as cosim computes them.

    Attributes
    ----------
    names : tuple of str
        The subsystems, in the scene's order.
    subsystems : tuple
        The built side of each (a :class:`~cosim.core.subsystem.RigidReference`,
        a multibody or structure subsystem), or None for a side whose
        geometry only its own code computes (an FMU).
    links : tuple of Link
    not_drawn : tuple of str
        The names of the sides left as None.
    """

    names: tuple
    subsystems: tuple
    links: tuple
    not_drawn: tuple


@dataclass(frozen=True)
class _CodeSide:
    """What the contacts' checks need of a side that is not built: its
    name, type and port names."""

    name: str
    type: str
    ports: dict


class _Scene:
    """What the side builders read of a scene: its file and gravity."""

    def __init__(self, path, gravity):
        self.path, self.gravity = str(path), gravity


def scene_geometry(data: dict, file) -> SceneGeometry:
    """Build the geometry of the scene table ``data`` (read from ``file``).

    Raises
    ------
    SceneError
        If a table of a side that is built, or of a contact, does not pass
        the scene loader's checks, or a structure would need more memory
        than a scene may use.
    """
    from cosim.scene.build import build_side
    from cosim.scene.checks import Table
    from cosim.scene.contacts import contact_spec
    from cosim.scene.subsystems import subsystem_spec

    file = Path(file)
    top = Table(data, (), file, "top")
    t_end = top.number("t_end", rule=">0", unit="s")
    eff = top.table("effects", section="effects")
    gravity = None
    if eff.has("gravity"):
        g = eff.raw("gravity")
        gravity = (eff.vec2("gravity", unit="m/s^2") if isinstance(g, list)
                   else (0.0, -eff.number("gravity", rule=">0", unit="m/s^2")))
    specs = []
    for sname, st in top.tables("subsystems", section="subsystems", entries="subsystem"):
        kind = st.data.get("type")
        if kind in CODE_SIDES:          # its file is not opened: only its ports' names
            ports = st.data.get("ports")
            specs.append(_CodeSide(sname, kind, dict.fromkeys(
                ports if isinstance(ports, dict) else ())))
        else:
            specs.append(subsystem_spec(sname, st))
    _check_memory(specs, file)
    contacts = [contact_spec(cname, ct, specs)
                for cname, ct in top.tables("contacts", section="contacts", entries="contact")]
    scene = _Scene(file, gravity)
    subs = [None if isinstance(s, _CodeSide) else build_side(s, scene, t_end) for s in specs]
    names = tuple(s.name for s in specs)
    links = []
    for c in contacts:
        sa, sb = names.index(c.a[0]), names.index(c.b[0])
        pa = subs[sa].port_index(c.a[1]) if subs[sa] is not None else None
        pb = subs[sb].port_index(c.b[1]) if subs[sb] is not None else None
        links.append(Link(c.name, sa, pa, sb, pb, tuple(c.normal)))
    return SceneGeometry(names, tuple(subs), tuple(links),
                         tuple(n for n, s in zip(names, subs) if s is None))


def _check_memory(specs, file) -> None:
    """Refuse structures that would need more than the scene loader's
    :data:`~cosim.scene.load.MAX_MEMORY` to build."""
    from cosim.scene.checks import SceneError
    from cosim.scene.load import MAX_MEMORY, spec_memory
    from cosim.scene.specs import StructureSpec

    total = sum(spec_memory(spec)[1] for spec in specs if isinstance(spec, StructureSpec))
    if total > MAX_MEMORY:
        raise SceneError(file, "subsystems", f"hold structures that need about "
                                             f"{math.ceil(total / 2**20)} MiB to build, more "
                                             f"than the {MAX_MEMORY // 2**20} MiB a scene "
                                             f"may use")
