"""A registry that imports a class when it is first looked up.

Extension points map a name to a class (STYLE.md).  A class whose module is
costly to import, and that most runs do not use, is registered as the string
``"package.module:Class"`` instead; the first lookup imports it and keeps the
class in its place.  Listing the names (``in``, ``sorted``, ``len``) imports
nothing; iterating over the classes (``values()``, ``items()``) imports them
all.

A registry given an entry-point ``group`` also finds, when looked up
(``registry[name]``) for a name it does not hold, a class an installed
package declares under that name (:mod:`cosim.core.plugins`); ``in`` does
not look (the scene loader asks :func:`cosim.core.plugins.provide` first
where a scene names a class), and a name it holds never reads package
metadata.
"""
from __future__ import annotations

from collections.abc import MutableMapping

__all__ = ["Registry"]


class Registry(MutableMapping):
    """A mapping of names to classes, some given as ``"module:Class"``.

    It behaves as the dict it replaces: a user registers a class of their own
    with ``registry[name] = cls``.  With ``group`` (``"cosim.schemes"``), a
    name it lacks is looked up among installed plug-ins
    (:func:`cosim.core.plugins.find`, which raises
    :class:`~cosim.errors.PluginError` for a plug-in that cannot be used).
    """

    def __init__(self, entries: dict, group: str | None = None):
        self._entries = dict(entries)
        self._group = group

    def _plugin(self, name) -> bool:
        if self._group is None:
            return False
        from cosim.core.plugins import find
        return find(self._group, name) and name in self._entries

    def __getitem__(self, name):
        if name not in self._entries:
            self._plugin(name)
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
