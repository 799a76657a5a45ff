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

Every file cosim writes -- a run's series and summary, figures, animations,
sweep tables and point folders, bench tables and caches, exports -- goes
through one writer, :class:`OutputFolder`: the folder is opened once by a
file descriptor that refuses a symbolic link at its place, every name is
checked (:func:`check_name`), a file is written under a new temporary name
created exclusively in the folder and renamed over its name (a link planted
there is replaced, never followed), and subfolders are made and opened the
same way.  The folder is reached one name at a time from the working folder
(or ``/``), each opened without following a link (:func:`open_folder`): a
link anywhere in the path as written, at its place or above it (a ``runs``
that is a link, ``--out link/sub``), is refused with the path it leads to.
Whatever stops the writing, the name holds its old content or the whole new
one.

The names and their checks live in :mod:`cosim.io.names`, the reaching of a
folder in :mod:`cosim.io.folders` and the lock in :mod:`cosim.io.runlock`;
every public name of theirs is importable from here as well.
"""
from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from cosim.errors import OutputError
from cosim.io.folders import (_DIR_FLAGS, _NOFOLLOW, MAX_RERUNS, _is_root, _remove_tree,
                              fresh_folder, open_folder)
from cosim.io.names import NAME_MAX, NAME_RULE, check_name, inside, name_problem, output_error
from cosim.io.runlock import LOCK_NAME, RunLock

__all__ = ["NAME_RULE", "NAME_MAX", "LOCK_NAME", "name_problem", "inside", "RunLock",
           "output_error", "check_name", "OutputFolder", "atomic_write", "run_folder_name",
           "fresh_folder", "MAX_RERUNS", "open_folder"]


class OutputFolder:
    """A folder cosim writes into, and the one way it writes there.

    Parameters
    ----------
    path : path-like
        The folder; made with its parents when missing.  A symbolic link
        at its place or above it (:func:`open_folder`), a file or a
        filesystem root at its place is refused.
    lock : bool
        Hold the folder's run lock (:class:`RunLock`) while open, so that no
        other cosim process writes there meanwhile.

    Use it as a context manager (or :meth:`open` / :meth:`close`)::

        with OutputFolder(out) as folder:
            folder.write("table.csv", lambda fh: fh.write(text), "w")
            point = folder.folder("k=1")      # a subfolder, never through a link

    Attributes
    ----------
    path : Path
    created : bool
        Whether :meth:`open` made the folder (a caller may remove it again
        when it wrote nothing there).
    """

    def __init__(self, path, *, lock: bool = True):
        self.path = Path(path)
        self.lock = lock
        self.created = False
        self._fd = None
        self._lock = None

    # ------------------------------------------------------------ opening
    def open(self) -> "OutputFolder":
        """Make (when missing) and open the folder, and take its lock.

        Raises
        ------
        OutputError
            If the folder is a link, a file, a filesystem root, or cannot be
            made or opened.
        OutputBusyError
            If another process holds its lock.
        """
        path = self.path
        if _is_root(path) and not os.path.islink(path):
            raise OutputError(f"refusing to write into {path}: it is a filesystem root; "
                              f"name a folder of its own")
        fd, self.created = open_folder(path)
        return self._adopt(fd)

    def _adopt(self, fd: int) -> "OutputFolder":
        if not stat.S_ISDIR(os.fstat(fd).st_mode):
            os.close(fd)
            raise OutputError(f"cannot write into {self.path}: it is not a folder")
        self._fd = fd
        if self.lock:
            try:
                self._lock = RunLock(self.path)
                self._lock._lock()
            except BaseException:
                self._lock = None
                self.close()
                if self.created:        # a folder made just now holds nothing but the lock
                    try:
                        os.unlink(self.path / LOCK_NAME)
                        self.path.rmdir()
                    except OSError:
                        pass
                raise
        return self

    @staticmethod
    def _open_error(exc: OSError, path) -> OutputError:
        if exc.errno in (errno.ELOOP, errno.ENOTDIR):
            return OutputError(f"cannot write into {path}: it is a symbolic link or not a "
                               f"folder (cosim never writes through a link); remove it")
        return output_error(exc, path, "cannot open the folder")

    def close(self) -> None:
        """Let the lock go and close the folder (no-op when not open)."""
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "OutputFolder":
        return self if self._fd is not None else self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def fd(self) -> int:
        if self._fd is None:
            raise RuntimeError(f"{self.path} is not open: use `with OutputFolder(...)`")
        return self._fd

    # ------------------------------------------------------------- names
    def path_of(self, name: str) -> Path:
        """The path of the checked name ``name`` in the folder (to read it,
        or to name it in a message)."""
        return self.path / check_name(name, self.path)

    def exists(self, name: str) -> bool:
        """Whether an entry (a link included) has the name ``name``."""
        try:
            os.stat(check_name(name, self.path), dir_fd=self.fd, follow_symlinks=False)
        except FileNotFoundError:
            return False
        return True

    def remove(self, name: str) -> None:
        """Remove the file ``name`` (a link itself, never its target; no-op
        when missing)."""
        try:
            os.unlink(check_name(name, self.path), dir_fd=self.fd)
        except FileNotFoundError:
            pass
        except OSError as exc:
            raise output_error(exc, self.path / name, "cannot remove") from None

    def read(self, name: str, max_bytes: int) -> bytes | None:
        """The bytes of the plain file ``name`` (``None`` when there is none),
        opened without following a link and read only up to ``max_bytes``:
        for the small files cosim reads back from a folder it writes (a
        cache entry, a point's record).

        Raises
        ------
        OutputError
            If ``name`` is a link, not a plain file, larger than
            ``max_bytes``, or cannot be read; the message says which.
        """
        flags = os.O_RDONLY | _NOFOLLOW | getattr(os, "O_NONBLOCK", 0)
        path = self.path_of(name)
        try:
            fd = os.open(name, flags, dir_fd=self.fd)
        except FileNotFoundError:
            return None
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise OutputError(f"{path} is a symbolic link") from None
            raise output_error(exc, path, "cannot read") from None
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise OutputError(f"{path} is not a plain file")
            chunks, size = [], 0
            while size <= max_bytes:
                chunk = os.read(fd, max_bytes + 1 - size)
                if not chunk:
                    break
                chunks.append(chunk)
                size += len(chunk)
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            raise output_error(exc, path, "cannot read") from None
        finally:
            os.close(fd)
        if size > max_bytes:
            raise OutputError(f"{path} holds more than {max_bytes} bytes")
        return b"".join(chunks)

    # ----------------------------------------------------------- writing
    def _temp_name(self, name: str) -> str:
        # os.urandom is what secrets.token_hex reads; the secrets module would
        # import hmac and hashlib (OpenSSL) into every run for these 6 bytes
        return f".{name}.{os.urandom(6).hex()}.tmp"

    def write(self, name: str, writer, mode: str = "wb") -> Path:
        """Write the file ``name`` whole: ``writer(fh)`` fills a new
        temporary file in the folder (created exclusively, never through a
        link), which is flushed to disk and renamed over ``name``.

        ``name`` keeps its old content, or none, when ``writer`` fails or
        the process is stopped; no temporary file is left.

        Raises
        ------
        OutputError
            An :class:`OSError` (a full disk, a read-only folder, a folder
            at ``name``) naming the file and the reason.
        """
        check_name(name, self.path)
        tmp = self._temp_name(name)
        created = False
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o666,
                         dir_fd=self.fd)
            created = True
            with os.fdopen(fd, mode) as fh:
                writer(fh)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, name, src_dir_fd=self.fd, dst_dir_fd=self.fd)
            created = False
        except BaseException as exc:
            if created:
                try:
                    os.unlink(tmp, dir_fd=self.fd)
                except OSError:
                    pass
            if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                raise output_error(exc, self.path / name) from exc
            raise
        return self.path / name

    def write_by_path(self, name: str, writer) -> Path:
        """Write the file ``name`` whole with a ``writer(path)`` that can only
        write to a path (an animation encoder, meshio): it writes into a new
        private temporary folder inside this one, whose file is then renamed
        over ``name``; the same guarantees as :meth:`write`."""
        check_name(name, self.path)
        tmpdir = self._temp_name(name)
        try:
            os.mkdir(tmpdir, 0o700, dir_fd=self.fd)
        except OSError as exc:
            raise output_error(exc, self.path / name) from exc
        try:
            writer(self.path / tmpdir / name)
            inner = os.open(tmpdir, _DIR_FLAGS, dir_fd=self.fd)
            try:
                st = os.stat(name, dir_fd=inner, follow_symlinks=False)
                if not stat.S_ISREG(st.st_mode):
                    raise OutputError(f"cannot write {self.path / name}: its writer made no "
                                      f"plain file")
                os.replace(name, name, src_dir_fd=inner, dst_dir_fd=self.fd)
            finally:
                os.close(inner)
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            raise output_error(exc, self.path / name) from exc
        finally:
            _remove_tree(self.fd, tmpdir)
        return self.path / name

    def create(self, name: str):
        """A new file ``name`` opened for reading and writing in binary (a
        spool): whatever had the name (a link, a stale file) is removed
        first, never followed, and the file is created exclusively."""
        check_name(name, self.path)
        self.remove(name)
        try:
            fd = os.open(name, os.O_RDWR | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o600,
                         dir_fd=self.fd)
        except OSError as exc:
            raise output_error(exc, self.path / name, "cannot create") from None
        return os.fdopen(fd, "w+b")

    def folder(self, name: str, *, lock: bool = False) -> "OutputFolder":
        """The subfolder ``name``, made when missing and opened without
        following a link (a link or a file at its place is refused); open,
        holding its own lock when ``lock``.  Close it (or use it as a
        context manager) when done."""
        check_name(name, self.path)
        sub = OutputFolder(self.path / name, lock=lock)
        try:
            os.mkdir(name, 0o777, dir_fd=self.fd)
            sub.created = True
        except FileExistsError:
            pass
        except OSError as exc:
            raise output_error(exc, sub.path, "cannot make the folder") from None
        try:
            fd = os.open(name, _DIR_FLAGS, dir_fd=self.fd)
        except OSError as exc:
            raise self._open_error(exc, sub.path) from None
        return sub._adopt(fd)


def atomic_write(path, writer, mode: str) -> Path:
    """Write the file ``path`` whole through :meth:`OutputFolder.write` on its
    folder (opened without following a link, not locked: for a caller that
    holds the folder's lock already, or writes where no run does)."""
    path = Path(path)
    with OutputFolder(path.parent, lock=False) as folder:
        return folder.write(path.name, writer, mode)


def run_folder_name(scene: str, variant: str | None = None, scheme: str | None = None) -> str:
    """The default name of a run's folder, ``SCENE[-VARIANT][-SCHEME]``:
    what tells the run apart.  ``variant`` is the variant run (None: the
    scene has none), ``scheme`` the scheme when it is not the scene's own
    (None otherwise), so that the runs of one scene under two schemes, or
    two variants, never meet in one folder."""
    return "-".join(part for part in (scene, variant, scheme) if part)
