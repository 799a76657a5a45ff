"""The files a scene reads, and digests of their content.

A result computed from a scene depends on more than the scene's table: an
FMU side runs the binary in the ``.fmu`` file its ``path`` names, which can
be replaced while the scene file stays as it was.  Whatever keeps a result
for reuse (the bench's reference cache, :mod:`cosim.studies.bench`) keys it
on :func:`input_digests`: the SHA-256 of the scene file and of every file it
names, so that a changed byte in any of them is a new key.

The files a scene names are the ``path`` of its ``type = "fmu"``
subsystems; no other key of a scene names a file.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

from cosim.scene.checks import SceneError
from cosim.scene.specs import FMUSpec

__all__ = ["input_files", "input_digests", "file_digest"]

#: bytes read at a time while hashing
_CHUNK = 1 << 20


def input_files(scene) -> dict[str, Path]:
    """The files ``scene`` reads, by what names them: ``"scene"`` (the scene
    file itself) and ``"subsystems.NAME.path"`` for each FMU side."""
    files = {"scene": Path(scene.path)}
    for spec in scene.subsystems:
        if isinstance(spec, FMUSpec):
            files[f"subsystems.{spec.name}.path"] = Path(spec.path)
    return files


def file_digest(path) -> str:
    """The SHA-256 of a file's content, as hex digits (read in chunks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


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
