"""The grid of a sweep: ``--set key=v1,v2,...`` read into values, every
combination of variants and values as a :class:`Point` in grid order, and the
run directory's name of each point, made from its parameters alone.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import operator
import re
from collections.abc import Sequence
from dataclasses import dataclass

from cosim.errors import shown
from cosim.scene.load import SceneError, parse_override

__all__ = ["Point", "Grid", "split_values", "parse_grid_option", "point_name", "grid_points",
           "LARGE_GRID", "MAX_POINTS"]

_SAFE = re.compile(r"[^A-Za-z0-9._=+-]")
_NAME_MAX = 120

#: a grid of more points than this is large: ``cosim sweep`` runs it only with ``--yes``
LARGE_GRID = 10_000
#: most points a sweep runs (each gets a folder of its own)
MAX_POINTS = 10 ** 9


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


def _repeated(values):
    """The first value of ``values`` that repeats one before it (None when
    none does): the same value (``1`` and ``1.0`` too), or the same plain
    text in a point's name (``1`` and ``"1"``, which would share a folder)."""
    seen, names = set(), set()
    for v in values:
        if isinstance(v, (int, float)) and not isinstance(v, bool) and v == v:
            same = ("number", v)
        else:
            same = ("value", json.dumps(v, sort_keys=True, default=repr))
        text = _text(v)
        plain = text if _SAFE.sub("_", text) == text and not text.startswith(".") else None
        if same in seen or (plain is not None and plain in names):
            return v
        seen.add(same)
        if plain is not None:
            names.add(plain)
    return None


class Grid(Sequence):
    """The points of a sweep: every combination of its variants and of the
    values of its keys, in grid order, made one at a time when asked for.

    A grid is a product, so it is never built whole: its length is the
    product of the number of variants and of each key's values, and point
    ``i`` is made from ``i``'s digits in that mixed radix.  A grid of a
    million points takes no more memory than its values.

    Parameters
    ----------
    variants : sequence of str, optional
        Scene variants; none: the scene's default variant alone.
    grid : mapping of str to sequence, optional
        ``key.path`` -> values (TOML values: numbers, strings, arrays...).

    Raises
    ------
    ValueError
        If a variant repeats, a key has no values or repeats one (each point
        would run twice, into one folder), or the grid has more than
        :data:`MAX_POINTS` points.
    """

    def __init__(self, variants=None, grid=None):
        variants = list(variants) if variants else [None]
        seen = set()
        for v in variants:
            if v in seen:
                raise ValueError(f"`variants` repeats a name: {shown(repr(v), 80)}; give each "
                                 f"variant once")
            seen.add(v)
        values = {}
        for k, vals in dict(grid or {}).items():
            if (isinstance(vals, (str, bytes, dict)) or not hasattr(vals, "__len__")
                    or not len(vals)):
                raise ValueError(f"grid key `{shown(k, 80)}` needs a list of values, got "
                                 f"{shown(vals, 80)}")
            values[k] = tuple(vals)
            dup = _repeated(values[k])
            if dup is not None:
                raise ValueError(f"grid key `{shown(k, 80)}` repeats the value "
                                 f"{shown(_text(dup), 80)}: give each value once (each point "
                                 f"runs once, into a folder of its own)")
        self.variants = tuple(variants)
        self.keys = tuple(values)
        self.values = tuple(values.values())
        self._sizes = (len(self.variants), *map(len, self.values))
        self.size = math.prod(self._sizes)
        if self.size > MAX_POINTS:
            shape = " x ".join(map(str, self._sizes))
            raise ValueError(f"the grid has {self.size:.3g} points ({shape}): a sweep runs at "
                             f"most {MAX_POINTS:.0e}")

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(self.size))]
        i = operator.index(i)
        if i < 0:
            i += self.size
        if not 0 <= i < self.size:
            raise IndexError(f"point {i} of a grid of {self.size}")
        digits, rest = [], i
        for n in reversed(self._sizes):
            rest, d = divmod(rest, n)
            digits.append(d)
        digits.reverse()
        variant = self.variants[digits[0]]
        values = [vals[d] for vals, d in zip(self.values, digits[1:])]
        return self._point(i, variant, values)

    def __iter__(self):
        for i, (variant, *values) in enumerate(itertools.product(self.variants, *self.values)):
            yield self._point(i, variant, values)

    def _point(self, index: int, variant, values) -> Point:
        params = tuple(zip(self.keys, values))
        return Point(index, variant, params, point_name(variant, params))

    def __repr__(self) -> str:
        return f"Grid({len(self.variants)} variant(s), keys {list(self.keys)}: {self.size} points)"


def grid_points(variants=None, grid=None) -> Grid:
    """Every combination of ``variants`` and the values of ``grid``, in grid
    order: a :class:`Grid`, which makes each point when it is asked for.

    Parameters
    ----------
    variants : sequence of str, optional
        Scene variants; none: the scene's default variant alone.
    grid : mapping of str to sequence, optional
        ``key.path`` -> values (TOML values: numbers, strings, arrays...).

    Raises
    ------
    ValueError
        If a variant repeats, a key has no values or repeats a value, or the
        grid is larger than :data:`MAX_POINTS`.
    """
    return Grid(variants, grid)
