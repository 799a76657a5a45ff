"""The scenes and studies cosim ships, and scenes named instead of a path.

The repository keeps the verification cases (and a few examples beyond
them, with the meshes of their plane bodies) in ``cases/`` and the studies
in ``studies/`` at its root; a built package carries a copy of both as
``cosim/_shipped/cases`` and ``cosim/_shipped/studies`` (``setup.py``'s
``build_py``).  :func:`shipped_folder` finds them in either place: the
package's copy when installed, the repository's when cosim is imported from
its source tree.

A scene is given by a path or by the name of a shipped scene
(:func:`find_scene`): ``spring_drop`` is ``cases/spring_drop.toml`` from any
folder.  A file that exists always wins over a name, and a relative path
``cases/NAME.toml`` (the form the documentation uses) that does not exist
where it is given names the shipped scene ``NAME``.  A folder is no scene:
a name that is a folder where it is given (the run folder of ``cosim run
spring_drop --out spring_drop``) names the shipped scene of that name too.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["shipped_folder", "shipped_scenes", "find_scene", "scene_file", "find_study",
           "describe", "not_found", "scene_variants", "shipped_list"]

#: the folders shipped, as the repository and the package name them
KINDS = ("cases", "studies")


def shipped_folder(kind: str) -> Path | None:
    """The folder of the shipped ``kind`` (``cases`` or ``studies``): the
    installed package's copy, else the repository's when cosim runs from its
    source tree; None when neither is there."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    package = Path(__file__).resolve().parents[1]          # .../cosim
    inside = package / "_shipped" / kind
    if inside.is_dir():
        return inside
    tree = package.parents[1] / kind                       # src/cosim -> the repository
    return tree if package.parent.name == "src" and tree.is_dir() else None


def _named(kind: str) -> dict[str, Path]:
    folder = shipped_folder(kind)
    if folder is None:
        return {}
    return {p.stem: p for p in sorted(folder.glob("*.toml"))}


def shipped_scenes() -> dict[str, Path]:
    """Name -> file of each shipped scene, by name."""
    return _named("cases")


def _as_name(text: str, kind: str) -> str | None:
    """The shipped name ``text`` stands for, when it is a bare name
    (``spring_drop``, ``spring_drop.toml``) or ``KIND/NAME.toml``."""
    p = Path(text)
    if p.is_absolute():
        return None
    parts = p.parts
    if len(parts) == 1:
        return p.stem if p.suffix == ".toml" else p.name
    if len(parts) == 2 and parts[0] == kind and p.suffix == ".toml":
        return p.stem
    return None


def _find(text, kind: str) -> Path:
    path = Path(text)
    folder = os.path.isdir(path)            # no scene: a shipped name it also is wins
    if os.path.lexists(path) and not folder:
        return path
    name = _as_name(str(text), kind)
    found = _named(kind).get(name) if name else None
    return found if found is not None else path


def scene_file(text) -> Path:
    """:func:`find_scene`, refusing a name that names nothing: the file a
    command reads, checked before any work.

    Raises
    ------
    SceneError
        If ``text`` is empty, or names neither a file nor a shipped scene (the
        shipped ones listed); ``text`` is shown escaped and capped.
    """
    from cosim.scene.checks import SceneError
    if not str(text):
        raise SceneError("", "", "the scene is an empty name: give a scene file or the name of "
                                 "a shipped scene (`cosim info --list` lists them)")
    file = find_scene(text)
    if not os.path.lexists(file):       # the shipped names, when it reads as a name
        raise SceneError(file, "", f"cannot be read: {not_found(text)}")
    return file


def find_scene(text) -> Path:
    """The scene file ``text`` names: the file itself when it exists, else
    the shipped scene of that name (``spring_drop``, ``spring_drop.toml`` or
    ``cases/spring_drop.toml``; also when ``text`` is a folder), else
    ``text`` as a path (whose reading then fails, naming it)."""
    return _find(text, "cases")


def find_study(text) -> Path:
    """The study file ``text`` names: the file itself, else
    ``studies/NAME.toml`` in the present folder, else the shipped study of
    that name, else ``text`` as a path."""
    path = Path(text)
    if os.path.lexists(path) and not os.path.isdir(path):
        return path
    name = _as_name(str(text), "studies")
    if name and os.path.lexists(Path("studies") / f"{name}.toml"):
        return Path("studies") / f"{name}.toml"
    return _find(text, "studies")


def describe(path) -> str:
    """A scene file's ``description`` (its ``name`` when it gives none;
    what keeps it from being read when it cannot be)."""
    from cosim.scene.checks import SceneError
    from cosim.scene.read import read_toml_file
    try:
        data = read_toml_file(path)
    except SceneError as exc:
        return str(exc)
    text = data.get("description")
    return text if isinstance(text, str) and text else str(data.get("name", Path(path).stem))


def not_found(text, kind: str = "cases") -> str:
    """Why ``text`` names no file: there is none, and, when ``text`` reads
    as a name, no shipped scene (or study) has it either (the shipped ones
    listed)."""
    names = ", ".join(_named(kind))
    if _as_name(str(text), kind) is None or not names:
        return "No such file or directory"
    what = "scene" if kind == "cases" else "study"
    return (f"No such file or directory, and no shipped {what} has that name (shipped: {names}"
            + ("; `cosim info --list` describes them)" if kind == "cases" else ")"))


def _flat(table: dict, prefix: str = "") -> dict:
    """A variant's table as ``{dotted.key: value}``; a table naming a ``type``
    (a law, a drive) replaces the one it overrides whole, so it stays one value."""
    out = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v and "type" not in v:
            out.update(_flat(v, key + "."))
        else:
            out[key] = v
    return out


def scene_variants(path) -> tuple[dict, str | None]:
    """The variants of the scene file ``path`` and its default.

    Returns
    -------
    variants : dict
        Variant name -> ``{dotted.key: value}`` it sets, in the file's order
        (empty for a scene without variants, or a file that cannot be read).
    default : str or None
        Its ``default_variant``.
    """
    from cosim.scene.checks import SceneError
    from cosim.scene.read import read_toml_file
    try:
        data = read_toml_file(path)
    except SceneError:
        return {}, None
    variants = data.get("variants")
    default = data.get("default_variant")
    if not isinstance(variants, dict):
        return {}, None
    return ({name: _flat(v) for name, v in variants.items() if isinstance(v, dict)},
            default if isinstance(default, str) else None)


def shipped_list() -> list[dict]:
    """One entry per shipped scene: ``name``, ``file``, ``description``,
    ``variants`` (their names) and ``default_variant``."""
    out = []
    for name, path in shipped_scenes().items():
        variants, default = scene_variants(path)
        out.append({"name": name, "file": str(path), "description": describe(path),
                    "variants": list(variants), "default_variant": default})
    return out
