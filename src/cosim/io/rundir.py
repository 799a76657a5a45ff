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
"""
from __future__ import annotations

import errno
import os
import re
import stat
from pathlib import Path

from cosim.errors import OutputBusyError, OutputError

__all__ = ["NAME_RULE", "NAME_MAX", "LOCK_NAME", "name_problem", "inside", "RunLock",
           "output_error", "check_name", "OutputFolder", "atomic_write", "run_folder_name",
           "fresh_folder", "MAX_RERUNS", "open_folder"]

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
    check_name(name, folder)
    path = folder / name
    if os.path.realpath(path.parent) != os.path.realpath(folder):
        raise OutputError(f"refusing to write {name!r}: a run writes only plain file names "
                          f"inside its folder {folder}")
    return path


def check_name(name, folder="its folder") -> str:
    """``name``, after checking it is one plain file name: not empty, not
    ``.`` or ``..``, no separator, no control character.

    Raises
    ------
    OutputError
        Naming ``name`` and ``folder``.
    """
    bad = (not isinstance(name, str) or not name or name in (".", "..") or "/" in name
           or "\0" in name or (os.altsep is not None and os.altsep in name) or os.sep in name
           or any(ord(ch) < 32 or ord(ch) == 127 for ch in name))
    if bad:
        from cosim.errors import shown
        raise OutputError(f"refusing to write {shown(repr(name))}: cosim writes only plain file "
                          f"names inside {folder}")
    return name


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


#: flags of every file descriptor the writer opens: never through a link, not inherited
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
#: opening a folder (``O_DIRECTORY`` where the system has it)
_DIR_FLAGS = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | _NOFOLLOW


def open_folder(path, make: bool = True, below: tuple = ()) -> tuple[int, bool]:
    """Open the folder ``path`` one name at a time from where it starts (the
    working folder, or ``/``), each name opened without following a link
    and made first when missing (``make``): a symbolic link anywhere in
    ``path`` as written -- at its place or above it -- is refused, never
    followed.  The one way cosim reaches a folder it writes into.
    ``below`` are names the caller will make inside it (said in messages).

    Returns
    -------
    fd : int
        The folder, open (``O_DIRECTORY``, not inherited); the caller closes it.
    made : bool
        Whether the folder itself was made here.

    Raises
    ------
    OutputError
        Naming the link and where it leads (the path to give instead), a
        file in the path, or the system's reason a name could not be made.
    """
    path = Path(path)
    parts = path.parts
    start = parts[0] if path.is_absolute() else "."
    if path.is_absolute():
        parts = parts[1:]
    try:
        fd = os.open(start, _DIR_FLAGS)
    except OSError as exc:
        raise output_error(exc, path, "cannot open the folder") from None
    here, made = Path(start), False
    try:
        for i, part in enumerate(parts):
            here = here / part
            made = False
            if make and part != "..":
                try:
                    os.mkdir(part, 0o777, dir_fd=fd)
                    made = True
                except FileExistsError:
                    pass
                except OSError as exc:
                    raise output_error(exc, path, "cannot make the output folder") from None
            try:
                sub = os.open(part, _DIR_FLAGS, dir_fd=fd)
            except OSError as exc:
                raise _component_error(exc, fd, part, here, path.joinpath(*below),
                                       parts[i + 1:] + tuple(below)) from None
            os.close(fd)
            fd = sub
    except BaseException:
        os.close(fd)
        raise
    return fd, made


def _component_error(exc: OSError, fd: int, part: str, here: Path, path: Path,
                     rest) -> OutputError:
    """Why the name ``part`` (at ``here``) of ``path`` could not be opened as
    a folder, in words; ``rest`` are the names after it."""
    try:
        st = os.stat(part, dir_fd=fd, follow_symlinks=False)
    except OSError:
        st = None
    if st is not None and stat.S_ISLNK(st.st_mode):
        real = Path(os.path.realpath(here))
        if not rest:
            return OutputError(f"cannot write into {path}: it is a symbolic link (cosim never "
                               f"writes through one); name the folder itself ({real})")
        return OutputError(f"cannot write into {path}: {here} is a symbolic link (cosim never "
                           f"writes through one); give the folder it leads to, "
                           f"{real.joinpath(*rest)}, or remove the link")
    if st is not None and not stat.S_ISDIR(st.st_mode) and not rest:
        return OutputError(f"cannot make the output folder {path}: it exists and is not a "
                           f"folder")
    return output_error(exc, path, "cannot make the output folder")


def _is_root(path: Path) -> bool:
    real = os.path.realpath(path)
    return os.path.dirname(real) == real


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


def _remove_tree(dir_fd: int, name: str) -> None:
    """Remove the folder ``name`` of the folder ``dir_fd`` and what it holds
    (files and folders only; links are removed, never followed)."""
    try:
        fd = os.open(name, _DIR_FLAGS, dir_fd=dir_fd)
    except FileNotFoundError:
        return
    except OSError:
        try:
            os.unlink(name, dir_fd=dir_fd)
        except OSError:
            pass
        return
    try:
        for entry in os.listdir(fd):
            st = os.stat(entry, dir_fd=fd, follow_symlinks=False)
            if stat.S_ISDIR(st.st_mode):
                _remove_tree(fd, entry)
            else:
                os.unlink(entry, dir_fd=fd)
    except OSError:
        pass
    finally:
        os.close(fd)
    try:
        os.rmdir(name, dir_fd=dir_fd)
    except OSError:
        pass


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


#: most folders :func:`fresh_folder` tries (``NAME``, ``NAME-2``, ...) before it gives up
MAX_RERUNS = 10000


def fresh_folder(parent, name: str) -> Path:
    """Make and return a new, empty folder ``parent/name``, or, when that
    exists, the first of ``name-2``, ``name-3``, ... that does not: a run
    asked again gets a folder of its own and never meets the one before.
    Each folder is made exclusively (``mkdir``), so two runs started at
    once get two folders.  ``parent`` is made when missing.

    Raises
    ------
    OutputError
        If ``parent`` cannot be made or written, or the first
        :data:`MAX_RERUNS` names are all taken.
    """
    parent = Path(parent)
    check_name(name, parent)
    fd, _ = open_folder(parent, below=(name,))  # never through a link
    try:
        for k in range(1, MAX_RERUNS + 1):
            here = name if k == 1 else f"{name}-{k}"
            try:
                os.mkdir(here, 0o777, dir_fd=fd)
            except FileExistsError:
                continue
            except OSError as exc:
                raise output_error(exc, parent / here, "cannot make the output folder") from None
            return parent / here
    finally:
        os.close(fd)
    raise OutputError(f"cannot make a new folder {parent / name}-N: the first {MAX_RERUNS} "
                      f"names are taken; give --out")


def _read_owner(fd: int) -> str:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return ""
    return text if text.isdigit() else ""
