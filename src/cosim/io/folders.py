"""Reaching a folder cosim writes into: one name at a time, never through a
symbolic link (:func:`open_folder`), making a fresh folder for a run asked
again (:func:`fresh_folder`) and removing a folder's tree without following
a link.  Part of the run folder (:mod:`cosim.io.rundir`, which holds these
names too)."""
from __future__ import annotations

import os
import stat
from pathlib import Path

from cosim.errors import OutputError
from cosim.io.names import check_name, output_error

__all__ = ["open_folder", "fresh_folder", "MAX_RERUNS"]

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
