"""A plug-in structure's scene table: its keys from the fields of its
dataclass (:class:`fem.StructureModel`), read and checked as the built-in
structures' are.

:func:`fields_of` says which keys a class takes and what each must be (the
reference of keys renders it, :func:`cosim.scene.keys.structure_section`),
:func:`field_reader` how each is read; the loader reads them from the table
and builds the model (:mod:`cosim.scene.subsystems`), a ``ValueError`` of
the model's own checks becoming a scene error at the key it names.  A class whose fields cannot be read from a scene (an annotation
outside the module notes of :mod:`fem.structure_model`, no ``length``) is
refused as a plug-in, naming the field.
"""
from __future__ import annotations

import dataclasses
import typing

from cosim.errors import PluginError

__all__ = ["fields_of", "field_reader"]

#: annotation -> (how the field is read, the check its key's reference gives)
_KINDS = {float: ("number", "a finite number"), int: ("integer", "an integer"),
          bool: ("boolean", "true or false"), str: ("string", "a string"),
          tuple[float, float]: ("vec2", "two finite numbers"),
          tuple[float, ...]: ("numbers", "a non-empty array of numbers")}
_RULE_TEXT = {">0": "> 0", ">=0": ">= 0"}


def _kind(annotation):
    """(reader, check) of an annotation, ``X | None`` read as ``X``."""
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) in (typing.Union, type(int | None)) and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        annotation = rest[0] if len(rest) == 1 else annotation
    return _KINDS.get(annotation)


def fields_of(cls) -> list:
    """The scene keys of plug-in structure ``cls``: ``(field, check text)``
    pairs in the dataclass's order.

    Raises
    ------
    PluginError
        If ``cls`` is not a dataclass, has no ``length`` field, or a field's
        annotation is not one a scene value can give.
    """
    where = f"the plug-in structure {cls.__module__}.{cls.__qualname__}"
    if not dataclasses.is_dataclass(cls):
        raise PluginError(f"{where} is not a dataclass: its fields are the keys of its scene "
                          f"table (fem.StructureModel)")
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        kind = _kind(hints.get(f.name))
        if kind is None:
            raise PluginError(f"{where} has a field `{f.name}: {hints.get(f.name)}` that no "
                              f"scene value gives; a field is float, int, bool, str, "
                              f"tuple[float, float] or tuple[float, ...] (or one of these "
                              f"| None)")
        check = kind[1]
        meta = f.metadata
        if meta.get("rule") in _RULE_TEXT:
            check = _RULE_TEXT[meta["rule"]]
        if "low" in meta or "high" in meta:
            check += f" in [{meta.get('low', '-inf')}, {meta.get('high', 'inf')}]"
        if meta.get("choices"):
            check = "one of " + ", ".join(f'"{c}"' for c in meta["choices"])
        if meta.get("nonzero"):
            check += ", not both 0"
        out.append((f, check))
    if "length" not in {f.name for f, _ in out}:
        raise PluginError(f"{where} has no `length` field: its points are material "
                          f"coordinates in [0, length] m")
    return out


def field_reader(cls, name: str) -> str:
    """How field ``name`` of ``cls`` is read from a scene: ``number``,
    ``integer``, ``boolean``, ``string``, ``vec2`` or ``numbers``."""
    return _kind(typing.get_type_hints(cls)[name])[0]
