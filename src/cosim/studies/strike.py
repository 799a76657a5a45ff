"""Which contact of a scene is the strike, and which joint strikes.

The studies read an impact from a run: the benchmark compares a contact's
count, peak and the exit velocity of a joint, the sweep classifies the impact
regime of a contact from a joint's rate (:mod:`cosim.studies.metrics`).
:func:`find_strike` names the contact and the joint of a scene for them, so
that no function of the studies carries the names of one scene as defaults:
what the caller names is checked against the scene, what it leaves out is
read from the scene when the scene leaves one choice only.
"""
from __future__ import annotations

import warnings
from pathlib import Path

from cosim.scene.load import Scene, SceneError, load_scene

__all__ = ["find_strike"]

#: subsystem types that carry joints (the striker's side of a strike)
_MULTIBODY = ("multibody",)

#: subsystem types that do not vibrate (the struck side of a strike is any other)
_RIGID = ("rigid",)


def _listed(names) -> str:
    return ", ".join(f"`{n}`" for n in names) or "none"


def _joints(scene: Scene) -> dict:
    """``SUBSYSTEM/JOINT`` -> None for every joint of every multibody."""
    return {f"{s['name']}/{j['name']}": None for s in scene.subsystems
            if s["type"] in _MULTIBODY for j in s["joints"]}


def _striker_joint(scene: Scene, contact: dict) -> str | None:
    """The joint of the body that carries the contact's point on a multibody
    (its point ``a`` first, then ``b``), as ``SUBSYSTEM/JOINT``; None when
    neither point lies on a multibody."""
    by_name = {s["name"]: s for s in scene.subsystems}
    for sub_name, port in (contact["a"], contact["b"]):
        sub = by_name.get(sub_name)
        if sub is None or sub["type"] not in _MULTIBODY:
            continue
        body = sub["ports"][port][0]
        return f"{sub_name}/{sub['joints'][body]['name']}"
    return None


def _strikes_a_structure(scene: Scene, contact: dict) -> bool:
    """One point on a multibody, the other on a structure that vibrates."""
    kinds = {s["name"]: s["type"] for s in scene.subsystems}
    a, b = kinds.get(contact["a"][0]), kinds.get(contact["b"][0])
    return any(x in _MULTIBODY and y not in _MULTIBODY + _RIGID
               for x, y in ((a, b), (b, a)))


def find_strike(scene, contact: str | None = None, joint: str | None = None, *,
                variant: str | None = None, required: bool = True) -> tuple | None:
    """The contact whose impact a study reads, and the striker's joint.

    Parameters
    ----------
    scene : Scene or path-like
        A loaded scene, or a scene file (loaded with ``variant``).
    contact : str, optional
        The contact's name.  Left out: the scene's only contact, else the
        only contact that joins a multibody to a structure that vibrates
        (neither a multibody nor ``rigid``).
    joint : str, optional
        ``SUBSYSTEM/JOINT`` of the striker.  Left out: the joint of the body
        that carries the contact's point on a multibody (the joint that moves
        that body on its parent).
    variant : str, optional
        The variant to load when ``scene`` is a file.
    required : bool
        Whether a scene that leaves no single choice is an error (True) or
        gives None (False).  A name given that the scene lacks is an error
        either way.

    Returns
    -------
    (str, str) or None
        The contact's name and the joint's ``SUBSYSTEM/JOINT``.

    Raises
    ------
    SceneError
        Naming the scene file: a ``contact`` or ``joint`` given that the scene
        does not have (with the names it has), or, when ``required``, a scene
        whose contact or joint cannot be chosen (with the choices).

    Examples
    --------
    >>> find_strike("cases/three_mass.toml")       # doctest: +SKIP
    ('C', 'robot/arm')
    """
    if not isinstance(scene, Scene):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")     # the caller's own load shows them
            scene = load_scene(Path(scene), variant)
    contacts = {c["name"]: c for c in scene.contacts}
    joints = _joints(scene)
    if joint is not None and joint not in joints:
        raise SceneError(scene.path, "", f"`joint` must be SUBSYSTEM/JOINT of a multibody "
                                         f"of the scene ({_listed(joints)}), got {joint!r}")
    if contact is not None:
        if contact not in contacts:
            raise SceneError(scene.path, "", f"`contact` must be one of the scene's "
                                             f"[contacts] ({_listed(contacts)}), got {contact!r}")
        chosen = contacts[contact]
    elif len(contacts) == 1:
        chosen = next(iter(contacts.values()))
    else:
        strikes = [c for c in contacts.values() if _strikes_a_structure(scene, c)]
        if len(strikes) != 1:
            if not required:
                return None
            raise SceneError(scene.path, "", f"`contact` must be given: of the scene's "
                                             f"[contacts] ({_listed(contacts)}), "
                                             f"{len(strikes)} join a multibody to a "
                                             f"structure, not one")
        chosen = strikes[0]
    if joint is None:
        joint = _striker_joint(scene, chosen)
        if joint is None:
            if not required:
                return None
            raise SceneError(scene.path, "", f"`joint` must be given: contact "
                                             f"`{chosen['name']}` joins `{chosen['a'][0]}` and "
                                             f"`{chosen['b'][0]}`, neither a multibody (joints "
                                             f"of the scene: {_listed(joints)})")
    return chosen["name"], joint
