"""The run folder: names that become paths, the files a run may write, and
the lock a run holds on its folder.

A run writes only into its folder, and only under names it chose: every
path is made by :func:`inside`, which refuses anything but one plain file
name and checks that the file's parent resolves to the folder itself.  Names
that come from a scene file (its ``name``, subsystems, contacts, joints,
variants) become folder names, file names and ``series.npz`` member paths, so
the loader holds them to :data:`NAME_RULE` (:func:`name_problem`).

While a run goes, it holds an exclusive lock (``flock``) on ``.run.lock`` in
its folder; a second run into the same folder is refused
(:class:`~cosim.errors.OutputBusyError`) and leaves the folder alone.  The
lock dies with its process, so a run killed outright leaves no stale lock.
"""
from __future__ import annotations

import errno
import os
import re
import stat
from pathlib import Path

from cosim.errors import OutputBusyError, OutputError

__all__ = ["NAME_RULE", "NAME_MAX", "LOCK_NAME", "name_problem", "inside", "RunLock",
           "output_error"]

#: longest name a scene may give [characters]
NAME_MAX = 64
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*")
#: the rule, as messages state it
NAME_RULE = (f"a name is 1 to {NAME_MAX} of the characters A-Z a-z 0-9 _ . + -, does not "
             f"start with . + or -, and holds no `..`")
#: the lock file a run holds in its folder
LOCK_NAME = ".run.lock"


def name_problem(name) -> str | None:
    """What makes ``name`` unfit as a name that becomes a path or a key
    (``None`` when it fits :data:`NAME_RULE`)."""
    if not isinstance(name, str):
        return f"must be a string, got {type(name).__name__} {name!r}"
    if not name:
        return "must not be empty"
    if len(name) > NAME_MAX:
        return f"must be at most {NAME_MAX} characters, got {len(name)}: {name[:NAME_MAX]!r}..."
    if not _NAME.fullmatch(name) or ".." in name:
        return f"must be a plain name ({NAME_RULE}), got {name!r}"
    return None


def inside(folder, name: str) -> Path:
    """``folder / name``, after checking that ``name`` is one plain file name
    and that the file's parent resolves to ``folder``: the last check before
    a run writes a file.

    Raises
    ------
    OutputError
        If ``name`` holds a separator, is empty, ``.`` or ``..``, or holds a
        control character.
    """
    folder = Path(folder)
    bad = (not name or name in (".", "..") or "/" in name or "\0" in name
           or (os.altsep is not None and os.altsep in name) or os.sep in name
           or any(ord(ch) < 32 or ord(ch) == 127 for ch in name))
    path = folder / name
    if bad or os.path.realpath(path.parent) != os.path.realpath(folder):
        raise OutputError(f"refusing to write {name!r}: a run writes only plain file names "
                          f"inside its folder {folder}")
    return path


def output_error(exc: OSError, path, what: str = "cannot write") -> OutputError:
    """An :class:`OutputError` naming ``path`` and the system's reason."""
    if isinstance(exc, OutputError):
        return exc
    reason = exc.strerror or str(exc) or type(exc).__name__
    err = OutputError(f"{what} {path}: {reason}")
    err.errno, err.path = exc.errno, str(path)     # not `filename`: it would reword str(err)
    return err


class RunLock:
    """An exclusive lock on a run folder, held from :meth:`acquire` to
    :meth:`release`.

    :meth:`acquire` makes the folder (and its parents) when missing,
    remembered as :attr:`created`.  The lock file is opened without following
    links, holds the owner's process id, and is removed on release.
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.created = False
        self._fd = None

    def acquire(self) -> "RunLock":
        """Take the lock (a folder made for it is removed again when it fails).

        Raises
        ------
        OutputError
            If the folder cannot be made or the lock file not created (a
            read-only place, a file in the path, a link planted at the lock).
        OutputBusyError
            If another process holds the lock.
        """
        if os.path.lexists(self.folder) and not self.folder.is_dir():
            raise OutputError(f"cannot make the run folder {self.folder}: it exists and is "
                              f"not a folder")
        try:
            self.created = not self.folder.exists()
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise output_error(exc, self.folder, "cannot make the run folder") from None
        try:
            return self._lock()
        except BaseException:
            if self.created:            # a folder made just now holds nothing but the lock
                try:
                    self.path.unlink(missing_ok=True)
                    self.folder.rmdir()
                except OSError:
                    pass
            raise

    def _lock(self) -> "RunLock":
        import fcntl                    # POSIX; the rest of this module is not
        for _ in range(5):              # the file may be removed between open and lock
            fd = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                owner = _read_owner(fd)
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise OutputBusyError(
                        f"{self.folder} is in use by another run"
                        + (f" (process {owner})" if owner else "")
                        + "; wait for it to end, or choose another --out") from None
                raise output_error(exc, self.path, "cannot lock") from None
            st = os.fstat(fd)
            try:
                now = os.stat(self.path, follow_symlinks=False)
            except FileNotFoundError:
                now = None
            if now is not None and (now.st_ino, now.st_dev) == (st.st_ino, st.st_dev):
                break
            os.close(fd)                # locked a file its owner had just removed
        else:
            raise OutputError(f"cannot lock {self.path}: it keeps being replaced")
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError as exc:
            os.close(fd)
            raise output_error(exc, self.path) from None
        self._fd = fd
        return self

    def _open(self) -> int:
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        try:
            fd = os.open(inside(self.folder, LOCK_NAME), flags, 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise OutputError(f"cannot lock {self.path}: it is a symbolic link (a run "
                                  f"never follows one); remove it") from None
            raise output_error(exc, self.path, "cannot create") from None
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
            os.close(fd)
            raise OutputError(f"cannot lock {self.path}: it is not a plain file of its own "
                              f"(a link or a special file); remove it")
        return fd

    def release(self) -> None:
        """Remove the lock file and let the lock go (no-op when not held)."""
        if self._fd is None:
            return
        try:
            st = os.fstat(self._fd)
            now = os.stat(self.path, follow_symlinks=False)
            if (now.st_ino, now.st_dev) == (st.st_ino, st.st_dev):
                os.unlink(self.path)
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()


def _read_owner(fd: int) -> str:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return ""
    return text if text.isdigit() else ""
