"""Reading a scene file: the TOML, its variants and the ``--set`` overrides.

The result is the merged scene table, not yet validated
(:mod:`cosim.scene.load` validates it).
"""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path

from cosim.io import tomlread
from cosim.scene.checks import SceneError, check_name, echo, type_name

__all__ = ["read_toml_file", "parse_override", "merge", "apply_override", "read_scene"]


def read_toml_file(file) -> dict:
    """Read a scene or a study file within the limits of :mod:`cosim.io.tomlread`
    (a regular file of at most 64 MiB, UTF-8, nested at most 32 levels, at
    most 10 000 keys).

    Raises
    ------
    SceneError
        Naming the file, if it cannot be read, passes a limit, or is not TOML.
    """
    try:
        return tomlread.read_toml(file)
    except OSError as exc:
        raise SceneError(file, "", f"cannot be read: {exc.strerror or exc}") from None
    except tomlread.TomlLimitError as exc:
        raise SceneError(file, exc.key, str(exc)) from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(file, "", f"is not valid TOML: {exc}") from None


def merge(base: dict, over: dict) -> dict:
    """Merge ``over`` into ``base`` key by key.  A table that names another
    ``type`` than the one it overrides (a law, a drive) replaces it whole."""
    for k, v in over.items():
        old = base.get(k)
        if (isinstance(v, dict) and isinstance(old, dict)
                and not ("type" in v and v["type"] != old.get("type"))):
            merge(old, v)
        else:
            base[k] = copy.deepcopy(v)
    return base


def parse_override(text: str, file="--set") -> tuple[list[str], object]:
    """Parse ``a.b.c=value``; the value is read as a TOML value, else a string."""
    if "=" not in text:
        raise SceneError(file, "", f"override {echo(text)} must read key.path=value")
    key, value = text.split("=", 1)
    if key.count(".") >= tomlread.MAX_DEPTH:
        raise SceneError(file, "", f"a --set key must have at most {tomlread.MAX_DEPTH} "
                                   f"parts (`cosim.io.tomlread.MAX_DEPTH`), got "
                                   f"{key.count('.') + 1}")
    path = [p.strip() for p in key.strip().split(".")]
    if not all(path):
        raise SceneError(file, key, f"override {echo(text)} has an empty key")
    try:
        parsed = tomlread.loads(f"v = {value.strip()}")["v"]
    except tomlread.TomlLimitError as exc:
        raise SceneError(file, key.strip(), f"given with --set {exc}") from None
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return path, parsed


def apply_override(data: dict, path: list[str], value, file) -> None:
    """Set ``data[path[0]][path[1]]... = value``, making the tables on the way."""
    if path[0] in ("variants", "default_variant"):
        raise SceneError(file, ".".join(path), "is chosen with --variant, not with --set")
    node = data
    for i, k in enumerate(path[:-1]):
        nxt = node.setdefault(k, {})
        if not isinstance(nxt, dict):
            raise SceneError(file, ".".join(path[:i + 1]),
                             f"is {type_name(nxt)}, so --set cannot reach "
                             f"`{'.'.join(path)}` inside it")
        node = nxt
    node[path[-1]] = value


def read_scene(path, variant: str | None = None, overrides=(), scheme: str | None = None
               ) -> tuple[dict, str | None]:
    """Read a scene file and merge its variant, the overrides and the scheme.

    Parameters are those of :func:`cosim.scene.load.load_scene`.

    Returns
    -------
    data : dict
        The merged scene table (``variants`` and ``default_variant`` taken out).
    chosen : str or None
        The variant applied.
    """
    file = Path(path)
    data = read_toml_file(file)
    variants = data.pop("variants", {})
    if not isinstance(variants, dict) or not all(isinstance(v, dict) for v in variants.values()):
        raise SceneError(file, "variants", "must be a table of tables")
    for vname in variants:
        check_name(file, "variants", vname, "names a variant that")
    default_variant = data.pop("default_variant", None)
    if default_variant is not None and not isinstance(default_variant, str):
        raise SceneError(file, "default_variant",
                         f"must be a string, got {type_name(default_variant)} "
                         f"{echo(default_variant)}")
    chosen = variant if variant is not None else default_variant
    if chosen is not None:
        if chosen not in variants:
            key = "default_variant" if variant is None else "variants"
            raise SceneError(file, key,
                             f"names no variant {echo(chosen)}; variants are "
                             f"{echo(sorted(variants))}")
        merge(data, variants[chosen])
    for ov in overrides:
        p, v = parse_override(ov, file) if isinstance(ov, str) else ov
        apply_override(data, list(p), v, file)
    if scheme is not None:
        sch = data.setdefault("scheme", {})
        if not isinstance(sch, dict):
            raise SceneError(file, "scheme", f"must be a table, got {type_name(sch)} {echo(sch)}")
        sch["name"] = scheme
    try:
        tomlread.check_depth(data)          # an override may reach deeper than the file
    except tomlread.TomlLimitError as exc:
        raise SceneError(file, exc.key, str(exc)) from None
    return data, chosen
