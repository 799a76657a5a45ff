"""The files a scene reads, and digests of their content.

A result computed from a scene depends on more than the scene's table: an
FMU side runs the binary in the ``.fmu`` file its ``path`` names, which can
be replaced while the scene file stays as it was.  Whatever keeps a result
for reuse (the bench's reference cache, a sweep's points) keys it
on :func:`input_digests`: the SHA-256 of the scene file and of every file it
names, so that a changed byte in any of them is a new key.

The files a scene names are the ``path`` of its ``type = "fmu"``
subsystems and the ``mesh`` of its ``type = "plane"`` ones; no other key of
a scene names a file.
"""
from __future__ import annotations

import errno
import hashlib
import os
import stat
from pathlib import Path

from cosim.scene.checks import SceneError
from cosim.scene.specs import FMUSpec

__all__ = ["input_files", "input_digests", "file_digest", "FileDigests"]

#: bytes read at a time while hashing
_CHUNK = 1 << 20


def input_files(scene) -> dict[str, Path]:
    """The files ``scene`` reads, by what names them: ``"scene"`` (the scene
    file itself), ``"subsystems.NAME.path"`` for each FMU side and
    ``"subsystems.NAME.mesh"`` for each plane body."""
    files = {"scene": Path(scene.path)}
    for spec in scene.subsystems:
        if isinstance(spec, FMUSpec):
            files[f"subsystems.{spec.name}.path"] = Path(spec.path)
        elif getattr(spec, "type", None) == "plane":
            files[f"subsystems.{spec.name}.mesh"] = Path(spec.model.mesh)
    return files


class FileDigests:
    """The SHA-256 of files' content, as hex digits: each file read once
    while its device, inode, size and modification time stay the same (a
    sweep hashes the FMU of each of its points once).  A FIFO or device is
    refused, never read."""

    def __init__(self):
        self._known: dict = {}

    def __call__(self, path) -> str:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
                     | getattr(os, "O_CLOEXEC", 0))
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise OSError(errno.EINVAL, "not a regular file", str(path))
            ident = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
            if ident not in self._known:
                h = hashlib.sha256()
                while chunk := os.read(fd, _CHUNK):
                    h.update(chunk)
                self._known[ident] = h.hexdigest()
            return self._known[ident]
        finally:
            os.close(fd)


def file_digest(path) -> str:
    """The SHA-256 of a file's content, as hex digits (read in chunks)."""
    return FileDigests()(path)


def input_digests(scene) -> dict[str, str]:
    """:func:`input_files` -> the SHA-256 of each file's content.

    Raises
    ------
    SceneError
        If a file cannot be read any more (removed since the scene loaded),
        naming the file and the key that names it.
    """
    out = {}
    for key, path in input_files(scene).items():
        try:
            out[key] = file_digest(path)
        except OSError as exc:
            raise SceneError(scene.path, "" if key == "scene" else key,
                             f"cannot be read to key a result on its content: {path}: "
                             f"{exc.strerror or exc}") from None
    return out
