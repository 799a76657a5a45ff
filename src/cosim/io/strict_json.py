"""JSON that every parser reads: no ``NaN``, no ``Infinity``.

Python's :mod:`json` writes a float that is not finite as the bare words
``NaN``, ``Infinity`` and ``-Infinity``, which are not JSON: a strict parser
(JavaScript's ``JSON.parse``, ``jq``, Go's, Rust's) refuses the whole file.
A file cosim writes as JSON goes through :func:`json_writer` instead: a
value that is not finite is written as ``null``, and when the top level is a
table its key :data:`NOTE_KEY` lists where each was and what it was, so
nothing is lost silently.  The writing itself is strict
(``allow_nan=False``): a non-finite value this module missed is refused, not
written.
"""
from __future__ import annotations

import json
import math

__all__ = ["NOTE_KEY", "finite_json", "json_writer", "dumps"]

#: the top-level key that lists the values written as null: ``{"energy.final": "inf"}``
NOTE_KEY = "not_finite"


def _text(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")


def finite_json(value):
    """``value`` with each float that is not finite replaced by None.

    Returns
    -------
    clean
        A copy of the tables (dicts) and lists of ``value``, other values
        kept as they are (a NumPy float is a float).
    where : dict
        Dotted key path (list items by their index) -> ``"nan"``, ``"inf"``
        or ``"-inf"``, in the order met.
    """
    where: dict[str, str] = {}

    def walk(v, path):
        if isinstance(v, float) and not math.isfinite(v):
            where[path or "."] = _text(v)
            return None
        if isinstance(v, dict):
            return {k: walk(x, f"{path}.{k}" if path else str(k)) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [walk(x, f"{path}.{i}" if path else str(i)) for i, x in enumerate(v)]
        return v

    return walk(value, ""), where


def _noted(value):
    clean, where = finite_json(value)
    if where and isinstance(clean, dict):
        clean[NOTE_KEY] = where
    return clean


def dumps(value, **kw) -> str:
    """:func:`json.dumps` of ``value`` with its non-finite values written as
    null and noted (:data:`NOTE_KEY`); strict (``allow_nan=False``)."""
    return json.dumps(_noted(value), allow_nan=False, **kw)


def json_writer(value, indent: int | None = 2):
    """A ``writer(fh)`` for :meth:`cosim.io.rundir.OutputFolder.write` (mode
    ``"w"``) that writes ``value`` as strict JSON (:func:`dumps`).

    The value is cleaned when the writer is made; the writer dumps it to the
    open file (``json.dump``, strict)."""
    clean = _noted(value)
    return lambda fh: json.dump(clean, fh, indent=indent, allow_nan=False)
