"""The cache of ``cosim bench``'s reference: entries keyed on the content
of every input, checked before use.

An entry is a JSON table of the reference's ``key`` (cosim's version, the
SHA-256 of the scene file and of every file it names, of the scene's table
after variant and overrides, the reference's settings, the contact and the
joint), the ``reference`` itself, and a ``checksum`` over both.  An entry is
used only when its key is this run's, its fields have their types and are
finite where they must be, and its checksum matches; any other entry (a
damaged file, another version's, a number edited by hand, a link) is
recomputed with a warning.  The checksum detects damage and edits, not
intent: an entry rewritten with a matching checksum is its writer's own
doing, and is used.
"""
from __future__ import annotations

import hashlib
import json
import math

from cosim import __version__
from cosim.errors import OutputError, shown
from cosim.io.rundir import OutputFolder
from cosim.scene.inputs import input_digests

__all__ = ["REFERENCE", "CACHE_FORMAT", "CACHE_MAX_BYTES", "cache_key", "cache_entry",
           "entry_problem", "entry_name", "read_entry"]

#: the reference: monolithic DOP853, every switch located, tight tolerances
REFERENCE = {"method": "DOP853", "rtol": 1e-11, "atol": 1e-14}
#: the layout of a reference cache entry (part of its key)
CACHE_FORMAT = 1
#: the largest cache entry read [bytes]; an entry holds well under 2 KiB
CACHE_MAX_BYTES = 1 << 16
#: the reference's fields and what each holds: a count, a finite number, or
#: a finite number or NaN (no exit velocity: the contact never released; no
#: energy error: the initial energy is zero)
_FIELDS = {"count": "count", "peak": "finite", "exit_velocity": "nan", "energy": "nan",
           "cpu_time_s": "finite"}


def cache_key(scene, variant, contact: str, joint: str) -> dict:
    """What the reference of ``scene`` (loaded with ``variant``, the
    overrides and the monolithic scheme) depends on: the cache's format,
    cosim's version, the SHA-256 of every input file
    (:func:`cosim.scene.inputs.input_digests`), of the scene's table after
    variant and overrides, the reference's settings, the contact and the
    joint.

    Raises
    ------
    SceneError
        If an input file cannot be read any more.
    """
    table = json.dumps(scene.data, sort_keys=True, default=str)
    return {"format": CACHE_FORMAT, "cosim": __version__, "files": input_digests(scene),
            "table": hashlib.sha256(table.encode()).hexdigest(), "variant": variant,
            "reference": dict(REFERENCE), "contact": contact, "joint": joint}


def entry_name(scene, variant, key: dict) -> str:
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()
    return f"{scene.name}-{variant or 'default'}-{digest[:16]}.json"


def _checksum(key: dict, ref: dict) -> str:
    blob = json.dumps({"key": key, "reference": ref}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def cache_entry(key: dict, ref: dict) -> dict:
    """The cache entry of the reference ``ref`` computed for ``key``: both,
    and the SHA-256 of both (``checksum``)."""
    ref = {k: ref[k] for k in _FIELDS}
    return {"key": key, "reference": ref, "checksum": _checksum(key, ref)}


def _show(v, limit: int) -> str:
    """A value read from a cache entry, for a message (text quoted)."""
    return shown(repr(v) if isinstance(v, str) else v, limit)


def _field_problem(name: str, v, kind: str) -> str | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return f"`reference.{name}` is {type(v).__name__} {_show(v, 40)}, not a number"
    if kind == "count":
        if not isinstance(v, int) or v < 0:
            return f"`reference.{name}` is {_show(v, 40)}, not a count (a whole number >= 0)"
    elif math.isinf(v) or (kind == "finite" and math.isnan(v)):
        return f"`reference.{name}` is {v}, not a finite number"
    return None


def entry_problem(entry, key: dict) -> str | None:
    """What makes the cache entry ``entry`` (parsed JSON) unfit to use for
    ``key``, or ``None`` when it is fit: its shape (a table of ``key``,
    ``reference`` and ``checksum``; the reference's fields of their types,
    finite where they must be), its key, and its checksum."""
    if not isinstance(entry, dict):
        return f"holds {type(entry).__name__} {_show(entry, 60)}, not a cache entry (a table)"
    if set(entry) != {"key", "reference", "checksum"}:
        return (f"holds the keys {shown(sorted(map(str, entry)), 80)}, not `key`, `reference` "
                f"and `checksum`")
    stored, ref = entry["key"], entry["reference"]
    if stored != key:
        if not isinstance(stored, dict):
            return f"holds a `key` of {type(stored).__name__}, not a table"
        if stored.get("cosim") != key["cosim"]:
            return (f"was written by cosim {_show(stored.get('cosim'), 40)}, not by this "
                    f"version ({key['cosim']})")
        files = stored.get("files")
        changed = [k for k in key["files"] if not isinstance(files, dict)
                   or files.get(k) != key["files"][k]]
        if changed:
            return (f"was written for other content of {', '.join(changed)} (its SHA-256 "
                    f"differs)")
        other = sorted(k for k in set(key) | set(stored) if stored.get(k) != key.get(k))
        return f"was written for other inputs (its key differs in {shown(other, 80)})"
    if not isinstance(ref, dict):
        return f"holds a `reference` of {type(ref).__name__}, not a table"
    if set(ref) != set(_FIELDS):
        return (f"holds a `reference` of the fields {shown(sorted(map(str, ref)), 80)}, not "
                f"{sorted(_FIELDS)}")
    for name, kind in _FIELDS.items():
        problem = _field_problem(name, ref[name], kind)
        if problem is not None:
            return problem
    if entry["checksum"] != _checksum(key, ref):
        return "does not match its checksum (damaged, or a number edited)"
    return None


def read_entry(folder: OutputFolder, name: str):
    """The parsed cache entry ``name`` of ``folder``, ``None`` when there is
    none, or the text of why it cannot be read (a string).  The entry is
    opened without following a link and read only up to
    :data:`CACHE_MAX_BYTES` (:meth:`~cosim.io.rundir.OutputFolder.read`)."""
    try:
        data = folder.read(name, CACHE_MAX_BYTES)
    except OutputError as exc:
        return str(exc)
    if data is None:
        return None
    try:
        return {"entry": json.loads(data.decode("utf-8"))}
    except (ValueError, RecursionError) as exc:
        return f"is not JSON ({shown(str(exc), 80)})"


