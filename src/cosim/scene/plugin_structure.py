"""A plug-in structure's scene table: its keys from the fields of its
dataclass (:class:`fem.StructureModel`), read and checked as the built-in
structures' are.

:func:`fields_of` says which keys a class takes and what each must be (the
reference of keys renders it, :func:`cosim.scene.keys.structure_section`);
:func:`read_model` reads them from the table and builds the model, a
``ValueError`` of the model's own checks becoming a scene error at the key
it names.  A class whose fields cannot be read from a scene (an annotation
outside the module notes of :mod:`fem.structure_model`, no ``length``) is
refused as a plug-in, naming the field.
"""
from __future__ import annotations

import dataclasses
import typing

from cosim.errors import PluginError
from cosim.scene.checks import Table, build_model, floats

__all__ = ["fields_of", "read_model"]

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


def read_model(t: Table, cls, rayleigh=None):
    """The model of plug-in structure ``cls`` from its scene table ``t``
    (whose section is the class's, :func:`cosim.scene.keys.structure_section`).

    ``rayleigh`` (read by the caller, as every structure's) goes to the
    model when given; a model without a ``rayleigh`` field refuses it at
    its key.
    """
    hints = typing.get_type_hints(cls)
    kw = {}
    for f, _ in fields_of(cls):
        if f.name == "rayleigh":
            continue
        meta = f.metadata
        if not t.has(f.name) and f.default is not dataclasses.MISSING:
            t.raw(f.name)                       # optional and not given: the class's default
            continue
        reader = _kind(hints[f.name])[0]
        unit = meta.get("unit", "")
        if reader == "number":
            kw[f.name] = t.number(f.name, rule=meta.get("rule"), unit=unit)
        elif reader == "integer":
            kw[f.name] = t.integer(f.name, low=meta.get("low"), high=meta.get("high"))
        elif reader == "boolean":
            kw[f.name] = t.boolean(f.name)
        elif reader == "string":
            kw[f.name] = t.string(f.name, choices=meta.get("choices"))
        elif reader == "vec2":
            kw[f.name] = t.vec2(f.name, unit=unit or "1", nonzero=bool(meta.get("nonzero")))
        else:
            kw[f.name] = floats(t, f.name)
    if rayleigh is not None:
        if "rayleigh" not in {f.name for f in dataclasses.fields(cls)}:
            t.error("rayleigh", f"is not taken by the structure `{cls.name}`, whose model has "
                                f"no `rayleigh` field")
        kw["rayleigh"] = rayleigh
    return build_model(t, cls, **kw)

