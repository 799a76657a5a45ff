"""Unpacking FMU files: bounded, once per process and content, and cleaned up.

An FMU is a zip archive from a supplier.  :func:`unpacked` extracts it into
``$TMPDIR/cosim-fmu-PID-RANDOM`` (``PID`` the process that owns the folder,
``RANDOM`` the letters :func:`tempfile.mkdtemp` chooses)
and refuses, before writing anything, an archive whose members declare more
than :func:`unpack_limit` bytes in all; it stops, and removes what it wrote,
when the bytes actually written pass the limit (a member's header can lie).
A member named with an absolute path, a drive, a backslash or a ``..`` is
refused; every member is written as a plain file (a symbolic link in the
archive becomes a file holding the link's text, as Python's ``zipfile``
writes it), created anew without following a link.

Each FMU content (by its SHA-256) is unpacked once per process: the FMU
subsystems of a sweep's points that one worker runs share the folder.  The
folders go when the process exits (however it exits, short of a kill);
:func:`remove_stale_unpacked`, run before each unpacking and by a sweep
after it kills a worker, removes the folders of this user whose owner
process is gone.
"""
from __future__ import annotations

import atexit
import hashlib
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path

__all__ = ["unpacked", "remove_stale_unpacked", "unpack_limit", "UNPACK_LIMIT_ENV",
           "DEFAULT_UNPACK_LIMIT", "MAX_MEMBERS", "PREFIX"]

#: the environment variable that sets the most an FMU may unpack to [bytes]
UNPACK_LIMIT_ENV = "COSIM_FMU_UNPACK_LIMIT"
#: the most an FMU may unpack to without it [bytes]: 1 GiB
DEFAULT_UNPACK_LIMIT = 1 << 30
#: the most members an FMU archive may hold
MAX_MEMBERS = 10_000
#: how an unpacked folder's name begins, before its owner's pid
PREFIX = "cosim-fmu-"
_OWNED = re.compile(re.escape(PREFIX) + r"(\d+)-[A-Za-z0-9_]+")
_SUFFIXES = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}
_CHUNK = 1 << 20

#: content digest -> folder, for this process (a forked child starts afresh)
_folders: dict[str, Path] = {}
_owner = [0]


def unpack_limit() -> int:
    """The most an FMU may unpack to [bytes]: ``$COSIM_FMU_UNPACK_LIMIT``
    (bytes, or with a binary suffix ``K``, ``M``, ``G``, ``T``: ``2G``), else
    :data:`DEFAULT_UNPACK_LIMIT`.

    Raises
    ------
    ValueError
        If the variable is set to anything but a positive size.
    """
    text = os.environ.get(UNPACK_LIMIT_ENV)
    if text is None or not text.strip():
        return DEFAULT_UNPACK_LIMIT
    m = re.fullmatch(r"\s*(\d+)\s*([kmgtKMGT]?)(i?[bB])?\s*", text)
    value = int(m.group(1)) * _SUFFIXES[m.group(2).lower()] if m else 0
    if value <= 0:
        from cosim.errors import shown
        raise ValueError(f"the environment variable {UNPACK_LIMIT_ENV} must be a positive "
                         f"size in bytes (e.g. 2147483648 or 2G), got {shown(text, 40)!r}")
    return value


def _size(n: int) -> str:
    for unit, k in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= k:
            return f"{n / k:.3g} {unit}"
    return f"{n} bytes"


def unpacked(path) -> Path:
    """The folder where the FMU at ``path`` is unpacked: made on the first
    call for its content in this process, the same folder afterwards.

    Raises
    ------
    ValueError
        If the archive is not a zip, is damaged, holds a member whose name
        leaves the folder, holds more than :data:`MAX_MEMBERS` members, or
        unpacks to more than :func:`unpack_limit` bytes; nothing is left then.
    OSError
        If the file cannot be read or the folder written.
    """
    if _owner[0] != os.getpid():           # a forked child owns none of its parent's
        _folders.clear()
        _owner[0] = os.getpid()
    limit = unpack_limit()
    with open(path, "rb") as fh:
        digest = hashlib.sha256()
        while chunk := fh.read(_CHUNK):
            digest.update(chunk)
        key = digest.hexdigest()
        folder = _folders.get(key)
        if folder is not None and folder.is_dir():
            return folder
        remove_stale_unpacked()
        fh.seek(0)
        folder = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-"))
        try:
            _extract(fh, folder, limit)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
    if not _folders:
        atexit.register(_remove_own)
    _folders[key] = folder
    return folder


def _remove_own() -> None:
    """Remove this process's unpacked folders (at exit)."""
    if _owner[0] != os.getpid():
        return
    while _folders:
        shutil.rmtree(_folders.popitem()[1], ignore_errors=True)


def _member_parts(name: str) -> list[str]:
    """The path parts of a member's name, or ValueError if it leaves the folder."""
    from cosim.errors import shown
    parts = [p for p in name.split("/") if p not in ("", ".")]
    if (not parts or name.startswith("/") or "\\" in name or ":" in name or "\0" in name
            or ".." in parts):
        raise ValueError(f"holds a member named {shown(name, 120)!r}, which would be written "
                         f"outside the folder it unpacks to (an absolute path, a drive, a "
                         f"backslash or `..`)")
    return parts


def _extract(fh, folder: Path, limit: int) -> None:
    """Unpack the zip ``fh`` into the empty folder ``folder``, at most ``limit`` bytes."""
    import zipfile
    import zlib
    from cosim.errors import shown
    try:
        archive = zipfile.ZipFile(fh)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError) as exc:
        raise ValueError(f"is not a zip archive that can be unpacked ({exc})") from None
    with archive:
        members = archive.infolist()
        if len(members) > MAX_MEMBERS:
            raise ValueError(f"holds {len(members)} members, more than the {MAX_MEMBERS} an "
                             f"FMU may hold")
        declared = sum(m.file_size for m in members)
        hint = f"(set the environment variable {UNPACK_LIMIT_ENV} to raise the limit)"
        if declared > limit:
            raise ValueError(f"unpacks to {_size(declared)} (its members' declared sizes), "
                             f"more than the limit of {_size(limit)} {hint}")
        written = 0
        for m in members:
            parts = _member_parts(m.filename)
            target = folder.joinpath(*parts)
            if m.is_dir():
                target.mkdir(parents=True, exist_ok=True, mode=0o700)
                continue
            target.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            try:
                fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                             | getattr(os, "O_CLOEXEC", 0), 0o600)
            except FileExistsError:
                raise ValueError(f"holds the member {shown(m.filename, 120)!r} twice "
                                 f"(or as a file and a folder)") from None
            try:
                with archive.open(m) as src:
                    while chunk := src.read(_CHUNK):
                        written += len(chunk)
                        if written > limit:
                            raise ValueError(f"unpacks to more than the limit of "
                                             f"{_size(limit)} (its member "
                                             f"{shown(m.filename, 120)!r} holds more than it "
                                             f"declares) {hint}")
                        view = memoryview(chunk)
                        while view:
                            view = view[os.write(fd, view):]
            except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError,
                    RuntimeError) as exc:
                raise ValueError(f"holds the member {shown(m.filename, 120)!r}, which cannot "
                                 f"be unpacked ({shown(str(exc), 200)})") from None
            finally:
                os.close(fd)


def _alive(pid: int) -> bool:
    """Whether process ``pid`` may be running (a pid no process can have
    counts as running: its folder is not one of ours to judge)."""
    if pid <= 0:
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):   # another user's process; no pid at all
        return True
    return True


def remove_stale_unpacked() -> list[Path]:
    """Remove the unpacked FMU folders (``$TMPDIR/cosim-fmu-PID-*``) of this
    user whose owner process ``PID`` is gone (a run killed outright, a
    sweep's worker killed on its time limit).  Folders of other users, of
    live processes, links and anything not named so are left alone.

    Returns
    -------
    list of Path
        The folders removed.
    """
    base = Path(tempfile.gettempdir())
    uid = os.getuid()
    removed = []
    try:
        entries = list(os.scandir(base))
    except OSError:
        return removed
    for entry in entries:
        m = _OWNED.fullmatch(entry.name)
        if m is None:
            continue
        try:
            st = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        pid = int(m.group(1))
        if (not stat.S_ISDIR(st.st_mode) or st.st_uid != uid or pid == os.getpid()
                or _alive(pid)):
            continue
        shutil.rmtree(entry.path, ignore_errors=True)
        removed.append(Path(entry.path))
    return removed
