"""The lock a run holds on its folder: an exclusive ``flock`` on
``.run.lock`` (:data:`LOCK_NAME`), refused to a second run
(:class:`~cosim.errors.OutputBusyError`), dying with its process.  Part of
the run folder (:mod:`cosim.io.rundir`, which holds these names too)."""
from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from cosim.errors import OutputBusyError, OutputError
from cosim.io.folders import open_folder
from cosim.io.names import inside, output_error

__all__ = ["LOCK_NAME", "RunLock"]

#: the lock file a run holds in its folder
LOCK_NAME = ".run.lock"


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
        fd, self.created = open_folder(self.folder)     # never through a link
        os.close(fd)
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
        except OSError:
            # the lock is the flock, held; the process id only names the owner to a
            # second run.  A full disk here is said by the first file the run writes
            # (naming that file), and the lock file goes on release as always
            pass
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
