"""Checks shared by the modules of :mod:`cosim.scene`: the scene error, the
typed reading of one table of a scene file, and the limits a scene must keep.

:class:`Table` reads a table of the file with typed getters that refuse a
``bool`` where a number is expected, and takes from the table of keys
(:mod:`cosim.scene.keys`) which keys the table accepts, which are required
and what the others default to.
"""
from __future__ import annotations

import contextlib
import difflib
import math
import re

from cosim.errors import shown
from cosim.io.rundir import name_problem
from cosim.scene import keys as _keys
#: most integrator steps a run may take unless ``guard.max_steps`` raises it
from cosim.scene.keytable import MAX_STEPS

__all__ = ["SceneError", "Table", "check_name", "type_name", "build_model", "floats",
           "record_keys", "echo", "MAX_ELEMENTS", "MAX_STEPS", "parse_accuracy", "nearest"]

#: most elements (or masses) a structure may have: a mesh beyond it is refused
#: when the scene is read, before anything is assembled
MAX_ELEMENTS = 20_000
#: rule name -> (text, check)
_RULES = {">0": ("> 0", lambda v: v > 0), ">=0": (">= 0", lambda v: v >= 0)}
_MISSING = object()
#: the sets that :func:`record_keys` fills, innermost last
_RECORDERS: list[set] = []


#: longest text of a file's name that a scene error shows [characters]
FILE_SHOWN_LIMIT = 500


class SceneError(ValueError):
    """A scene file that cannot be used, with the file and key path.

    The key path is shown escaped and capped (``cosim.errors.shown``): a
    key is the file's text too.  A value the message echoes goes through
    ``cosim.scene.checks.echo``."""

    def __init__(self, file, key: str, message: str):
        self.file, self.key = str(file), key
        where = f"`{shown(key)}` " if key else ""
        # the file's name too is shown escaped and capped: a scene named on
        # the command line may hold a line break, or be 100 000 characters
        super().__init__((f"{shown(self.file, FILE_SHOWN_LIMIT)}: " if self.file else "")
                         + f"{where}{message}")


def echo(value) -> str:
    """A value read from a scene as an error shows it: its ``repr`` (a string
    quoted), control characters escaped and at most
    :data:`cosim.errors.SHOWN_LIMIT` characters (:func:`cosim.errors.shown`),
    so that a 100 KB string or a line break in the file cannot flood or
    forge the message.  Every scene error that echoes a value does so here."""
    return shown(repr(value) if isinstance(value, str) else value)


def nearest(word: str, known) -> str | None:
    """The one name of ``known`` closest to ``word`` (:func:`difflib.get_close_matches`,
    a ratio of at least 0.6), or None: what a misspelt key most likely meant
    (``tend`` -> ``t_end``, ``youngs_modulos`` -> ``youngs_modulus``).  Names in
    upper case (``NAME``, ``POINT``: a name the scene chooses) are not offered."""
    if not isinstance(word, str):
        return None
    names = [n for n in known if isinstance(n, str) and not n.isupper() and n != word]
    found = difflib.get_close_matches(word, names, n=1, cutoff=0.6)
    return found[0] if found else None


def check_name(file, key: str, name, what: str) -> None:
    """Refuse a name that becomes a path or a key (a run folder, an export
    file, a sweep point's folder, a ``series.npz`` member) unless it is a
    plain word (:data:`cosim.io.rundir.NAME_RULE`)."""
    problem = name_problem(name)
    if problem is not None:
        raise SceneError(file, key, " ".join(filter(None, (what, problem))))


def type_name(v) -> str:
    """What a TOML value is, for a message (``a boolean``, ``a table``...)."""
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "an array", dict: "a table"}.get(type(v), type(v).__name__)


@contextlib.contextmanager
def record_keys():
    """Collect what the loader accepts while inside: a set of
    ``(section id, key name in the table of keys, key path)``, one for every
    key of the file that a :class:`Table` with a section accepted (the test
    of the table of keys walks scenes with it)."""
    found: set = set()
    _RECORDERS.append(found)
    try:
        yield found
    finally:
        _RECORDERS.remove(found)


class Table:
    """A table of the scene being read: typed getters that record what was
    used, so that :meth:`finish` can reject unknown keys.

    Parameters
    ----------
    data : dict
    path : tuple of str
        Its key path in the file.
    file : path-like
        For the messages.
    section : str, optional
        Its id in :data:`cosim.scene.keys.SECTIONS` (``"law.NAME"`` for a
        law): the keys it accepts, and the defaults of the getters.  Without
        it (a study file) a key is known when a getter read it and defaults
        are the getters' own.
    """

    def __init__(self, data, path: tuple, file, section: str | None = None):
        self.data, self.path, self.file = data, path, file
        self.section_id = section
        self.section = None if section is None else _keys.section(section)
        self.used: set[str] = set()

    def use(self, section: str) -> None:
        """Read the rest of the table as section ``section`` (once its
        ``type`` is known)."""
        self.section_id, self.section = section, _keys.section(section)

    def key(self, k: str = "") -> str:
        return ".".join(self.path + ((k,) if k else ()))

    def error(self, k: str, message: str):
        raise SceneError(self.file, self.key(k), message)

    def has(self, k: str) -> bool:
        return k in self.data

    def _default(self, k: str, default):
        """The default of ``k``: the table of keys' (a caller gives one only
        where it depends on the scene, :class:`~cosim.scene.keys.Varies`)."""
        if self.section is None:
            return default
        row = self.section.find(k)
        if row is None:
            raise RuntimeError(f"the loader reads `{self.key(k)}`, which the table of keys "
                               f"(cosim.scene.keys) does not list under {self.section.title}")
        if isinstance(row.default, _keys.Varies):
            return default
        if default is not _MISSING:
            raise RuntimeError(f"the default of `{self.key(k)}` is the table of keys' "
                               f"(cosim.scene.keys), not the loader's")
        if row.default is _keys.REQUIRED:
            return _MISSING
        return (type(row.default)(row.default) if isinstance(row.default, (dict, list))
                else row.default)

    def raw(self, k: str, default=_MISSING):
        default = self._default(k, default)
        self.used.add(k)
        if k not in self.data:
            if default is _MISSING:
                self.error(k, "is required but missing" + self.misspelt(k))
            return default
        return self.data[k]

    def misspelt(self, k: str) -> str:
        """`` (found `KEY`: a misspelling?)`` when the table holds a key it does
        not accept that is close to the missing key ``k`` (:func:`nearest`),
        else ``""``: a misspelt required key is reported with the spelling the
        file has."""
        if self.section is not None:
            strangers = [x for x in self.data if self.section.find(x) is None]
        else:
            strangers = [x for x in self.data if x not in self.used]
        near = nearest(k, strangers)
        return "" if near is None else f" (found `{shown(near)}`: a misspelling?)"

    def _did_you_mean(self, k: str, known) -> str:
        near = nearest(k, known)
        return "" if near is None else f" (did you mean `{near}`?)"

    def _present(self, k, default):
        """(value, True) if ``k`` is given, else (its default, False)."""
        if k in self.data:
            return self.raw(k), True
        return self.raw(k, default), False

    def number(self, k, default=_MISSING, *, rule: str | None = None, unit: str = ""):
        v, given = self._present(k, default)
        if not given:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.error(k, f"must be a number{' [' + unit + ']' if unit else ''}, "
                          f"got {type_name(v)} {echo(v)}")
        try:
            v = float(v)
        except OverflowError:
            v = math.inf
        if not math.isfinite(v):
            self.error(k, f"must be finite, got {echo(v)}")
        if rule is not None and not _RULES[rule][1](v):
            self.error(k, f"must be {_RULES[rule][0]}{' ' + unit if unit else ''}, got {echo(v)}")
        return v

    def integer(self, k, default=_MISSING, *, low: int | None = None,
                high: int | None = None):
        v, given = self._present(k, default)
        if not given:
            return v
        if isinstance(v, bool) or not isinstance(v, int):
            self.error(k, f"must be an integer, got {type_name(v)} {echo(v)}")
        if low is not None and v < low:
            self.error(k, f"must be >= {low}, got {echo(v)}")
        if high is not None and v > high:
            self.error(k, f"must be <= {high}, got {echo(v)}")
        return v

    def string(self, k, default=_MISSING, *, choices=None):
        v, given = self._present(k, default)
        if not given:
            return v
        if not isinstance(v, str):
            self.error(k, f"must be a string, got {type_name(v)} {echo(v)}")
        if choices is not None and v not in choices:
            self.error(k, f"must be one of {sorted(choices)}, got {echo(v)}")
        return v

    def boolean(self, k, default=_MISSING):
        v, _ = self._present(k, default)
        if not isinstance(v, bool):
            self.error(k, f"must be true or false, got {type_name(v)} {echo(v)}")
        return v

    def vec2(self, k, default=_MISSING, *, unit="m", nonzero=False):
        v, given = self._present(k, default)
        if not given:
            return v
        if (not isinstance(v, list) or len(v) != 2
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            self.error(k, f"must be an array of two numbers [{unit}], got {echo(v)}")
        try:
            v = [float(x) for x in v]
        except OverflowError:
            v = [math.inf]
        if not all(math.isfinite(x) for x in v):
            self.error(k, f"must be finite, got {echo(self.data[k])}")
        if nonzero and v[0] == 0 and v[1] == 0:
            self.error(k, f"must be a non-zero vector, got {echo(v)}")
        return (float(v[0]), float(v[1]))

    def table(self, k, default=_MISSING, *, section: str | None = None) -> "Table":
        """The table ``k``, read as section ``section``."""
        if self.section is not None and section is None:
            raise RuntimeError(f"the loader reads the table `{self.key(k)}` without its "
                               f"section of the table of keys")
        if self.section is None:
            v = self.raw(k, {} if default is not _MISSING else _MISSING)
        else:
            v, _ = self._present(k, default)
        if not isinstance(v, dict):
            self.error(k, f"must be a table, got {type_name(v)} {echo(v)}")
        return Table(v, self.path + (k,), self.file, section)

    def tables(self, k, default=_MISSING, *, section: str | None = None,
               entries: str | None = None) -> list[tuple[str, "Table"]]:
        """The tables held in table ``k`` (read as ``section``), each read as
        ``entries``."""
        t = self.table(k, default, section=section)
        out = []
        for name in t.data:
            out.append((name, t.table(name, section=entries)))
        if t.section is not None:
            t.finish()
        return out

    def finish(self) -> None:
        """Refuse a key the table does not accept (or, without a section,
        that no getter read)."""
        for k in self.data:
            row = None if self.section is None else self.section.find(k)
            if self.section is not None and row is None:
                where = self.key() or "the top level"
                self.error(k, f"is not a known key of {where}"
                              f"{self._did_you_mean(k, self.section.names)}; known keys are "
                              f"{sorted(self.section.names)}")
            if k not in self.used:
                where = self.key() or "the top level"
                if self.section is None:
                    self.error(k, f"is not a known key of {where}"
                                  f"{self._did_you_mean(k, self.used)}; known keys are "
                                  f"{sorted(self.used)}")
                self.error(k, f"does not apply with the other keys of {where}, which uses "
                              f"{sorted(self.used)}")
            for found in _RECORDERS:
                found.add((self.section_id, row.name if row is not None else k, self.key(k)))


def build_model(t: Table, cls, **kw):
    """Construct a model object, turning its ValueError into a SceneError at
    the key of the parameter it names (or the table's)."""
    try:
        return cls(**kw)
    except (TypeError, ValueError) as exc:
        raise model_error(t, exc) from None


def model_error(t: Table, exc: Exception) -> SceneError:
    """``exc`` of a model as a SceneError at the key it names."""
    msg = str(exc)
    m = re.match(r"`(\w+)(\[\d+\])?` (.*)", msg, re.S)
    if m and m.group(1) in t.data:
        return SceneError(t.file, t.key(m.group(1)) + (m.group(2) or ""), m.group(3))
    return SceneError(t.file, t.key(), msg)


def floats(t: Table, k: str) -> tuple:
    """A non-empty array of finite numbers (``bool`` refused) as a tuple of
    floats; a value that is not names its index (``times[3]``)."""
    v = t.raw(k)
    if not isinstance(v, list) or not v or any(
            isinstance(x, bool) or not isinstance(x, (int, float)) for x in v):
        t.error(k, f"must be a non-empty array of numbers, got {echo(v)}")
    out = []
    for i, x in enumerate(v):
        try:
            x = float(x)
        except OverflowError:           # an integer beyond a double
            x = math.inf
        if not math.isfinite(x):
            t.error(f"{k}[{i}]", f"must be finite, got {echo(v[i])}")
        out.append(x)
    return tuple(out)


#: a number as --accuracy takes it: ASCII digits, a point, an exponent
_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)


def parse_accuracy(text, name: str = "--accuracy") -> float:
    """A relative accuracy from ``"1%"``, ``"0.5 %"``, ``"0.01"`` or a number.

    Raises
    ------
    ValueError
        Naming ``name``, if it is no number, or not in (0, 1).
    """
    raw = text
    scale = 1.0
    if isinstance(text, str):
        s = text.strip()
        if s.endswith("%"):
            s, scale = s[:-1].strip(), 0.01
        try:        # ASCII digits in the usual syntax: no `٥`, no `1_0` (float() takes both)
            if not _DECIMAL.fullmatch(s):
                raise ValueError(s)
            value = float(s) * scale
        except ValueError:
            raise ValueError(f"`{name}` must be a relative accuracy such as 1%, 0.5 % or 0.01, "
                             f"got {raw!r}") from None
    elif isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text)
    else:
        raise ValueError(f"`{name}` must be a relative accuracy such as 1%, 0.5 % or 0.01, "
                         f"got {raw!r}")
    if not (0.0 < value < 1.0):
        raise ValueError(f"`{name}` must be a relative accuracy above 0 and below 1 (100 %), "
                         f"got {raw!r}")
    return value
