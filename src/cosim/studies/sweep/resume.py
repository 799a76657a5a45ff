"""Resuming a sweep: what a point's run directory must hold for the point to
count as done, so that a sweep run again skips it.

A point is keyed on everything its run read: the scene file and every file
the scene names (each FMU's ``path``), by content (SHA-256), cosim's
version, and the point's variant, overrides and scheme.  Its folder counts
as done when its ``point.json`` holds the same key and a status of
:data:`DONE`, and, if it ran, its ``summary.json`` and ``series.npz`` are
whole and of the shape a run writes.  Anything else -- another key, a file
cut short, doctored or not a file at all -- runs the point again, and
:func:`_load_done` says why.

The folder's files are read without following a link, each within a size
limit, and of ``series.npz`` only the members the table reads, each checked
against the bytes it occupies before it is read.
"""
from __future__ import annotations

import errno
import json
import os
import stat
import zipfile
from pathlib import Path

import numpy as np

from cosim.studies.sweep.grid import Point

__all__ = ["DONE", "MAX_JSON_BYTES"]

#: a point whose run ended in one of these is done: a sweep run again skips it
DONE = ("finished", "failed", "refused")
#: most bytes of a point's ``point.json`` or ``summary.json`` that a resume reads
MAX_JSON_BYTES = 64 * 2**20

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
_DIR = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | _NOFOLLOW
_FILE = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | _NOFOLLOW


class PointFolderError(OSError):
    """A point's folder is not a folder of its own (a link, a file): the
    sweep neither reads nor writes through it."""


class _Damaged(ValueError):
    """A file of a point's folder that is not what a run writes."""


# ------------------------------------------------------------- the key
def point_key(point: Point, scene_path: Path, scheme, scene_hash: str, inputs=()) -> dict:
    """What ``point.json`` records of a point besides its outcome: the scene
    file (name and content), the other ``inputs`` (label, SHA-256), cosim's
    version, the variant, the overrides and the scheme.  A point done with
    another key is run again."""
    return {"scene": scene_path.name, "scene_sha256": scene_hash,
            "inputs": [[label, digest] for label, digest in inputs], "cosim": _version(),
            "variant": point.variant, "set": [[k, v] for k, v in point.params],
            "scheme": scheme}


def _version() -> str:
    from cosim import __version__
    return __version__


def _key_change(done: dict, key: dict) -> str | None:
    """Why a point done with the key recorded in ``done`` must run again
    under ``key`` (None when the keys agree)."""
    from cosim.errors import shown
    if done.get("cosim") != key["cosim"]:
        old = done.get("cosim")
        return (f"it ran with cosim {shown(old, 40)}, this is {key['cosim']}"
                if isinstance(old, str) else "it ran with a cosim that did not record its "
                                             "inputs")
    if done.get("scene_sha256") != key["scene_sha256"] or done.get("scene") != key["scene"]:
        return "the scene file changed since it ran"
    old = done.get("inputs")
    if old != key["inputs"]:
        before = dict(x for x in old if isinstance(x, list) and len(x) == 2) \
            if isinstance(old, list) else {}
        changed = [label for label, digest in key["inputs"] if before.get(label) != digest]
        if changed:
            return f"{shown(changed[0], 160)} changed since it ran"
        return "the scene names other files than when it ran"
    for k in ("variant", "set", "scheme"):
        if done.get(k) != key[k]:
            return f"it ran with another {k}"
    return None


# ----------------------------------------------------- reading a folder
def open_point(out_fd: int, name: str) -> int | None:
    """The point folder ``name`` of the sweep folder ``out_fd``, opened
    without following a link (None when there is none yet).

    Raises
    ------
    PointFolderError
        If a link, a file or anything but a folder has the name.
    """
    try:
        return os.open(name, _DIR, dir_fd=out_fd)
    except FileNotFoundError:
        return None
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENOTDIR, errno.EMLINK):
            raise PointFolderError(exc.errno, "it is a symbolic link or not a folder (a sweep "
                                              "never reads or writes through one); remove it"
                                   ) from None
        raise


def _read(folder_fd: int, name: str, limit: int = MAX_JSON_BYTES) -> bytes:
    try:
        fd = os.open(name, _FILE, dir_fd=folder_fd)
    except OSError as exc:
        if exc.errno == errno.ENOENT:
            raise
        raise _Damaged(f"its {name} cannot be read ({exc.strerror or exc})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise _Damaged(f"its {name} is not a plain file")
        data = b""
        while len(data) <= limit and (chunk := os.read(fd, 1 << 20)):
            data += chunk
        if len(data) > limit:
            raise _Damaged(f"its {name} is larger than {limit // 2**20} MiB")
        return data
    finally:
        os.close(fd)


def _json(folder_fd: int, name: str) -> dict:
    try:
        value = json.loads(_read(folder_fd, name))
    except (ValueError, RecursionError) as exc:
        raise _Damaged(f"its {name} is not whole JSON ({type(exc).__name__})") from None
    if not isinstance(value, dict):
        raise _Damaged(f"its {name} holds {type(value).__name__}, not a table")
    return value


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_summary(summary: dict, status: str) -> None:
    """Refuse a ``summary.json`` other than a run of ``status`` writes, in
    what the table and the figure read of it."""
    if summary.get("status") != status:
        raise _Damaged("its summary.json says another status than its point.json")
    if not isinstance(summary.get("message", ""), (str, type(None))):
        raise _Damaged("its summary.json has a `message` that is not text")
    contacts = summary.get("contacts", {})
    if not isinstance(contacts, dict):
        raise _Damaged("its summary.json has `contacts` that are not a table")
    for name, c in contacts.items():
        ok = (isinstance(c, dict) and isinstance(c.get("count"), int)
              and not isinstance(c.get("count"), bool) and c["count"] >= 0
              and _number(c.get("in_touch_time")) and isinstance(c.get("intervals"), list)
              and all(isinstance(iv, list) and len(iv) == 2 and all(map(_number, iv))
                      for iv in c["intervals"]))
        if not ok:
            raise _Damaged("its summary.json has a contact that is not what a run writes")


def _members(folder_fd: int, wanted) -> dict:
    """The members ``wanted`` (those present) of ``series.npz``: 1-D float
    arrays of one length, each stored whole as cosim writes them, and read
    only after its header's size is checked against the bytes it holds."""
    try:
        fd = os.open("series.npz", _FILE, dir_fd=folder_fd)
    except OSError as exc:
        if exc.errno == errno.ENOENT:
            raise
        raise _Damaged(f"its series.npz cannot be read ({exc.strerror or exc})") from None
    out = {}
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
            raise _Damaged("its series.npz is not a plain file")
        try:
            with zipfile.ZipFile(fh) as zf:
                infos = {i.filename: i for i in zf.infolist()}
                for key in wanted:
                    info = infos.get(f"{key}.npy")
                    if info is None:
                        continue
                    if info.compress_type != zipfile.ZIP_STORED:
                        raise _Damaged("its series.npz was not written by cosim (a member "
                                       "is compressed)")
                    with zf.open(info) as member:
                        out[key] = _array(member, info.file_size)
        except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError,
                NotImplementedError) as exc:
            raise _Damaged(f"its series.npz is not a whole npz ({type(exc).__name__})") \
                from None
    if len({a.shape for a in out.values()}) > 1:
        raise _Damaged("its series.npz holds series of different lengths")
    return out


def _array(member, size: int) -> np.ndarray:
    fmt = np.lib.format
    try:
        version = fmt.read_magic(member)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(member)
        elif version == (2, 0):
            shape, fortran, dtype = fmt.read_array_header_2_0(member)
        else:
            raise ValueError(f"npy version {version}")
    except (ValueError, SyntaxError, TypeError) as exc:
        raise _Damaged(f"its series.npz has a member with a bad header ({exc})") from None
    if len(shape) != 1 or dtype != np.dtype(float) or fortran:
        raise _Damaged("its series.npz has a member that is not a 1-D float series")
    nbytes = shape[0] * dtype.itemsize
    if nbytes > size:
        raise _Damaged("its series.npz has a member shorter than its header says")
    data = member.read(nbytes)
    if len(data) != nbytes:
        raise _Damaged("its series.npz has a member cut short")
    return np.frombuffer(data, dtype=dtype)


def _load_done(out_fd: int, name: str, key: dict, retry_failed: bool, wanted=()):
    """Whether the point ``name`` of the sweep folder ``out_fd`` was done
    before under ``key``.

    Returns
    -------
    done : tuple or None
        ``(point, summary, series)`` read back (``summary`` and ``series``
        None for a refused point; ``series`` holds the members ``wanted``
        that it has), or None when the point must run.
    note : str or None
        Why a point that was done must run again (its key changed, or its
        folder is damaged); None when it had not ended, or is asked to run
        again (``retry_failed``), or is done.

    Raises
    ------
    PointFolderError
        If a link or a file has the point folder's name.
    """
    folder = open_point(out_fd, name)
    if folder is None:
        return None, None
    try:
        try:
            done = _json(folder, "point.json")
        except FileNotFoundError:
            return None, None
        status = done.get("status")
        if status not in DONE:
            return None, None                    # interrupted, timed out, its worker died
        if not isinstance(done.get("message"), (str, type(None))):
            raise _Damaged("its point.json has a `message` that is not text")
        change = _key_change(done, key)
        if change is not None:
            return None, change
        if retry_failed and status != "finished":
            return None, None
        if status == "refused":
            return (done, None, None), None
        try:
            summary = _json(folder, "summary.json")
            _check_summary(summary, status)
            series = _members(folder, ("t", *wanted))
        except FileNotFoundError as exc:
            raise _Damaged(f"its {Path(exc.filename or 'run').name} is missing") from None
        return (done, summary, series), None
    except _Damaged as exc:
        return None, f"{exc}"
    finally:
        os.close(folder)
