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

from cosim.errors import PluginError, shown

__all__ = ["fields_of", "field_reader", "model_class_problem", "SHARED_KEYS"]

#: the keys every structure's table has, read by cosim itself: no field may take one
#: (``rayleigh`` aside, which the model receives when it declares it)
SHARED_KEYS = ("type", "points", "modes", "integrator", "initial_velocity",
               "static_equilibrium", "static_loads")
#: metadata key -> the reader of the fields that may give it, and what it must be
_META = {"rule": ("number", '">0" or ">=0"'), "low": ("integer", "an integer"),
         "high": ("integer", "an integer"), "choices": ("string", "a non-empty list of strings"),
         "nonzero": ("vec2", "true or false"), "unit": (None, "a string"),
         "doc": (None, "a string")}

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
        meta = f.metadata              # as model_class_problem checked it when loaded
        if isinstance(meta.get("rule"), str) and meta["rule"] in _RULE_TEXT:
            check = _RULE_TEXT[meta["rule"]]
        if "low" in meta or "high" in meta:
            check += f" in [{meta.get('low', '-inf')}, {meta.get('high', 'inf')}]"
        if isinstance(meta.get("choices"), (list, tuple)) and meta["choices"]:
            check = "one of " + ", ".join(f'"{shown(c)}"' for c in meta["choices"])
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


def _plain(text) -> bool:
    """``text`` is a string without control characters (a line break, an
    escape), which a message could not print as it is."""
    return isinstance(text, str) and shown(text, len(text) + 1) == text


def _meta_ok(key: str, value) -> bool:
    if key in ("unit", "doc"):
        return _plain(value)
    if key == "rule":
        return value in _RULE_TEXT
    if key in ("low", "high"):
        return isinstance(value, int) and not isinstance(value, bool)
    if key == "choices":
        return (isinstance(value, (list, tuple)) and len(value) > 0
                and all(_plain(c) for c in value))
    return isinstance(value, bool)                  # nonzero


def model_class_problem(cls) -> str:
    """What cosim cannot read in plug-in structure ``cls`` (checked when it
    is loaded, so that a scene never meets it): its fields
    (:func:`fields_of`), a field named like a key every structure shares
    (:data:`SHARED_KEYS`), or metadata of the wrong kind (``rule``,
    ``low``/``high``, ``choices``, ``nonzero`` each for the annotation that
    takes it; ``unit`` and ``doc`` text without control characters).
    ``""`` when none."""
    try:
        fields = fields_of(cls)
    except PluginError as exc:
        return str(exc)
    except Exception as exc:              # an annotation typing cannot resolve
        return f"its fields cannot be read: {type(exc).__name__}: {shown(str(exc))}"
    for f, _ in fields:
        if f.name in SHARED_KEYS:
            return (f"it has a field `{f.name}`, a key every structure shares, which cosim "
                    f"reads itself (the shared keys: {', '.join(SHARED_KEYS)}): rename the field")
        reader = field_reader(cls, f.name)
        if f.name == "rayleigh" and reader != "numbers":
            return ("its field `rayleigh` is not `tuple[float, ...] | None`: cosim gives it "
                    "the scene's [a0, a1]")
        for key, value in f.metadata.items():
            if key not in _META:
                continue
            takes, want = _META[key]
            if takes is not None and reader != takes:
                return (f"its field `{f.name}` ({reader}) has metadata `{key}`, which only a "
                        f"{takes} field takes")
            if not _meta_ok(key, value):
                return (f"its field `{f.name}` has metadata `{key}` = {shown(repr(value))}, "
                        f"expected {want}" + (" without control characters"
                                              if want == "a string" or key == "choices" else ""))
        low, high = f.metadata.get("low"), f.metadata.get("high")
        if low is not None and high is not None and low > high:
            return f"its field `{f.name}` has metadata `low` = {low} > `high` = {high}"
    return ""
