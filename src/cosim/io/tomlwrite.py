"""A small TOML writer for the tables a scene file holds.

The standard library reads TOML (``tomllib``) but does not write it.  A run
writes the scene it ran (variant and overrides applied) as ``scene.toml`` so
that the run can be drawn, or run again, from its directory; that needs only
what a scene holds: tables, arrays, strings, numbers and booleans.
"""
from __future__ import annotations

import json
import math
import re

__all__ = ["dumps", "value_text"]

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def _string(text: str) -> str:
    """A TOML basic string.  JSON's escapes are TOML's, but for characters
    beyond the BMP, which JSON writes as a surrogate pair (invalid in TOML):
    those stay as they are, and DEL, which TOML wants escaped."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def _key(k: str) -> str:
    if not isinstance(k, str):
        raise TypeError(f"TOML keys must be strings, got {type(k).__name__} {k!r}")
    return k if _BARE.fullmatch(k) else _string(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)                 # shortest round-tripping form, e.g. 1e-06, 0.5
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} {v!r} as TOML")


def value_text(v) -> str:
    """``v`` as a TOML value (``1.6e7``, ``"coupler"``, ``{type = "linear", ...}``): how
    a scene file would spell it, for messages and listings.  A float takes the
    shorter of its plain and its exponent form that reads back as the same
    float (``1.6e7``, not ``16000000.0``)."""
    if isinstance(v, float) and math.isfinite(v):
        plain = repr(v)
        for digits in range(17):
            sci = f"{v:.{digits}e}"
            if float(sci) == v:
                mantissa, exp = sci.split("e")
                sci = f"{mantissa}e{int(exp)}"
                break
        return sci if len(sci) + 2 < len(plain) else plain     # 200.0, not 2e2
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value_text(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {value_text(x)}" for k, x in v.items()) + "}"
    return _value(v)


def dumps(data: dict) -> str:
    """TOML text of a table of tables, arrays and scalars.

    Sub-tables become ``[a.b]`` sections; tables inside arrays are written
    inline.  ``tomllib.loads(dumps(d)) == d`` for what ``tomllib`` reads
    (dates and times aside).

    Raises
    ------
    TypeError
        If a key is not a string or a value has no TOML form.
    """
    lines: list[str] = []
    _section(data, (), lines)
    return "\n".join(lines).lstrip("\n") + "\n"


def _section(table: dict, path: tuple, lines: list) -> None:
    subs = [(k, v) for k, v in table.items() if isinstance(v, dict)]
    plain = [(k, v) for k, v in table.items() if not isinstance(v, dict)]
    if path and (plain or not subs):
        lines.append("")
        lines.append("[" + ".".join(_key(k) for k in path) + "]")
    for k, v in plain:
        lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in subs:
        _section(v, path + (k,), lines)
