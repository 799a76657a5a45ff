"""A registry that imports a class when it is first looked up.

Extension points map a name to a class (STYLE.md).  A class whose module is
costly to import, and that most runs do not use, is registered as the string
``"package.module:Class"`` instead; the first lookup imports it and keeps the
class in its place.  Listing the names (``in``, ``sorted``, ``len``) imports
nothing; iterating over the classes (``values()``, ``items()``) imports them
all.
"""
from __future__ import annotations

from collections.abc import MutableMapping

__all__ = ["Registry"]


class Registry(MutableMapping):
    """A mapping of names to classes, some given as ``"module:Class"``.

    It behaves as the dict it replaces: a user registers a class of their own
    with ``registry[name] = cls``.
    """

    def __init__(self, entries: dict):
        self._entries = dict(entries)

    def __getitem__(self, name):
        value = self._entries[name]
        if isinstance(value, str):
            module, _, attr = value.partition(":")
            # the import statement's machinery, which `python -X importtime` reports
            value = self._entries[name] = getattr(__import__(module, fromlist=[attr]), attr)
        return value

    def __setitem__(self, name, cls) -> None:
        self._entries[name] = cls

    def __delitem__(self, name) -> None:
        del self._entries[name]

    def __iter__(self):
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, name) -> bool:
        return name in self._entries

    def __repr__(self) -> str:
        return f"{type(self).__name__}({list(self._entries)})"
