"""The grid of a sweep: ``--set key=v1,v2,...`` read into values, every
combination of variants and values as a :class:`Point` in grid order, and the
run directory's name of each point, made from its parameters alone.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import re
from dataclasses import dataclass

from cosim.scene.load import SceneError, parse_override

__all__ = ["Point", "split_values", "parse_grid_option", "point_name", "grid_points"]

_SAFE = re.compile(r"[^A-Za-z0-9._=+-]")
_NAME_MAX = 120

def split_values(text: str) -> list[str]:
    """Split ``v1,v2,...`` at the commas that lie outside brackets, braces and
    quotes, so that TOML arrays and strings pass whole: ``[1, 2],[3, 4]``
    gives ``["[1, 2]", "[3, 4]"]``.

    Raises
    ------
    ValueError
        If a bracket or a quote is left open, or a value is empty.
    """
    out, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            cur.append(ch)
            if ch == quote:
                quote = None
            continue
        if ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise ValueError(f"`{text}` closes a bracket it never opened")
        elif ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    if quote or depth:
        raise ValueError(f"`{text}` leaves a {'quote' if quote else 'bracket'} open")
    out.append("".join(cur).strip())
    if not all(out):
        raise ValueError(f"`{text}` has an empty value")
    return out


def parse_grid_option(text: str) -> tuple[str, list]:
    """Parse one ``--set key.path=v1,v2,...`` of a sweep into the key and its
    values, each read as a TOML value (else kept as a string), as ``cosim run
    --set`` reads one value.

    Raises
    ------
    SceneError
        If the text is not ``key.path=values``.
    ValueError
        If the values do not split (see :func:`split_values`).
    """
    if "=" not in text:
        raise SceneError("--set", "", f"sweep value {text!r} must read key.path=v1,v2,...")
    key, values = text.split("=", 1)
    parsed = [parse_override(f"{key}={v}")[1] for v in split_values(values)]
    return ".".join(parse_override(f"{key}=0")[0]), parsed


def _text(value) -> str:
    """A grid value as it appears in a point's name: strings bare, numbers as
    Python writes them (round trip), anything else as compact JSON."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value
    if isinstance(value, (int, float)):
        return repr(value)
    return json.dumps(value, separators=(",", ":"), sort_keys=True)


@dataclass(frozen=True)
class Point:
    """One point of a sweep.

    Attributes
    ----------
    index : int
        Its place in grid order (variants outermost, then the grid's keys in
        the order given, the last fastest).
    variant : str or None
        The scene variant (None: the scene's default).
    params : tuple of (str, value)
        The grid's keys and this point's values, in the grid's key order.
    name : str
        Its run directory's name, made from ``variant`` and ``params`` only.
    """

    index: int
    variant: str | None
    params: tuple
    name: str

    @property
    def overrides(self) -> list:
        """The ``--set`` overrides of this point, as (path list, value)."""
        return [(k.split("."), v) for k, v in self.params]


def point_name(variant: str | None, params) -> str:
    """The run directory's name of a point: ``VARIANT,KEY=VALUE,...`` with the
    keys in grid order.  When a character outside ``[A-Za-z0-9._=+-]`` or a
    leading ``.`` had to be replaced (no point is ``..``, ``.`` or hidden), or
    the name is long, a hash of the exact parameters is
    appended, so that two points never share a name."""
    parts = ([variant] if variant is not None else []) + [f"{k}={_text(v)}" for k, v in params]
    clean = [_SAFE.sub("_", part) for part in parts]
    clean = ["_" + c[1:] if c.startswith(".") or not c else c for c in clean]
    safe = ",".join(clean) if parts else "default"
    if clean != parts or len(safe) > _NAME_MAX:
        blob = json.dumps([variant, [[k, v] for k, v in params]], sort_keys=True)
        digest = hashlib.sha256(blob.encode()).hexdigest()[:10]
        safe = f"{safe[:_NAME_MAX]}-{digest}"
    return safe


def grid_points(variants=None, grid=None) -> list[Point]:
    """Every combination of ``variants`` and the values of ``grid``, in grid
    order.

    Parameters
    ----------
    variants : sequence of str, optional
        Scene variants; none: the scene's default variant alone.
    grid : mapping of str to sequence, optional
        ``key.path`` -> values (TOML values: numbers, strings, arrays...).

    Raises
    ------
    ValueError
        If a variant repeats, a key has no values, or two points would be
        the same.
    """
    variants = list(variants) if variants else [None]
    if len(set(variants)) != len(variants):
        raise ValueError(f"`variants` repeats a name: {variants}")
    grid = dict(grid or {})
    for k, vals in grid.items():
        if isinstance(vals, (str, bytes)) or not len(vals):
            raise ValueError(f"grid key `{k}` needs a list of values, got {vals!r}")
    keys = list(grid)
    points = []
    for i, (variant, *values) in enumerate(itertools.product(variants, *grid.values())):
        params = tuple(zip(keys, values))
        points.append(Point(i, variant, params, point_name(variant, params)))
    names = [p.name for p in points]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ValueError(f"two points of the grid are the same: {dup}")
    return points
