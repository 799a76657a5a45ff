"""The names a run writes under: the rule a scene's names are held to
(:data:`NAME_RULE`, :func:`name_problem`), the check of a plain file name
(:func:`check_name`, :func:`inside`) and the error that names a path a write
failed on (:func:`output_error`).  Part of the run folder
(:mod:`cosim.io.rundir`, which holds these names too)."""
from __future__ import annotations

import os
import re
from pathlib import Path

from cosim.errors import OutputError

__all__ = ["NAME_RULE", "NAME_MAX", "name_problem", "inside", "check_name", "output_error"]

#: longest name a scene may give [characters]
NAME_MAX = 64
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*")
#: the rule, as messages state it
NAME_RULE = (f"a name is 1 to {NAME_MAX} of the characters A-Z a-z 0-9 _ . + -, does not "
             f"start with . + or -, and holds no `..`")
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
