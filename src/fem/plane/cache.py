"""A plane body's modal basis cached on disk, keyed on what it depends on.

The key is the SHA-256 of the mesh file's bytes (of the points, cells and
groups for a mesh built in code), the model's material, thickness, element,
scale and supports, the modes asked for (count and cutoff), the layout of
an entry and scikit-fem's version.  An entry is one ``.npz`` file of the
key (as JSON), the basis and a SHA-256 checksum over both; it is used only
when its key is this one, its arrays have their shapes and are finite, and
its checksum matches.  Any other entry (damaged, edited, another key's) is
recomputed with a warning and written again.

The caller gives the folder: an object with the ``read(name, max_bytes)``
and ``write(name, writer, mode)`` of cosim's checked writer
(:class:`cosim.io.rundir.OutputFolder`), which writes an entry whole or not
at all and never through a link.
"""
from __future__ import annotations

import hashlib
import io
import json
import warnings
import zipfile

import numpy as np

from ..modal import ModalBasis, modes

__all__ = ["CACHE_FORMAT", "cache_key", "entry_name", "cached_modes"]

#: the layout of an entry (part of its key)
CACHE_FORMAT = 1


def _mesh_digest(mesh) -> str:
    if mesh.digest:
        return mesh.digest
    h = hashlib.sha256()
    for a in (mesh.points, mesh.cells):
        h.update(np.ascontiguousarray(a).tobytes())
    for name in sorted(mesh.groups):
        h.update(name.encode())
        h.update(np.ascontiguousarray(mesh.groups[name]).tobytes())
    return h.hexdigest()


def cache_key(structure, n_modes=None, cutoff_hz=None) -> dict:
    """What the modal basis of ``structure`` (a :class:`PlaneStructure`) for
    ``n_modes`` / ``cutoff_hz`` depends on (see the module's notes)."""
    import skfem

    return {"format": CACHE_FORMAT, "mesh_sha256": _mesh_digest(structure.mesh),
            "model": structure.plane.describe(), "n_modes": n_modes,
            "cutoff_hz": cutoff_hz, "scikit-fem": skfem.__version__,
            "n_dof": structure.n_dof}


def entry_name(key: dict) -> str:
    """The file name of the entry of ``key``."""
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()
    return f"plane-modes-{digest[:24]}.npz"


def _checksum(key_json: str, omega: np.ndarray, shapes: np.ndarray, meta: np.ndarray) -> str:
    h = hashlib.sha256(key_json.encode())
    for a in (omega, shapes, meta):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _pack(key: dict, basis: ModalBasis) -> bytes:
    key_json = json.dumps(key, sort_keys=True)
    meta = np.array([basis.kept, basis.dropped, basis.n_rigid], dtype=np.int64)
    omega = np.ascontiguousarray(basis.omega, dtype=float)
    shapes = np.ascontiguousarray(basis.shapes, dtype=float)
    buf = io.BytesIO()
    np.savez(buf, key=np.array(key_json), omega=omega, shapes=shapes, meta=meta,
             checksum=np.array(_checksum(key_json, omega, shapes, meta)))
    return buf.getvalue()


def _unpack(data: bytes, key: dict, n_dof: int):
    """The basis in ``data``, or the text of why it cannot be used."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            if set(z.files) != {"key", "omega", "shapes", "meta", "checksum"}:
                return "does not hold a modal basis"
            key_json, omega, shapes = str(z["key"]), z["omega"], z["shapes"]
            meta, checksum = z["meta"], str(z["checksum"])
    except (ValueError, OSError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        return f"cannot be read ({type(exc).__name__}: {exc})"
    if key_json != json.dumps(key, sort_keys=True):
        return "was written for other inputs"
    if (omega.dtype != float or shapes.dtype != float or meta.dtype != np.int64
            or omega.ndim != 1 or shapes.shape != (n_dof, omega.size) or meta.shape != (3,)
            or not (np.all(np.isfinite(omega)) and np.all(np.isfinite(shapes)))):
        return "holds arrays of the wrong shape or not finite"
    if checksum != _checksum(key_json, omega, shapes, meta):
        return "does not match its checksum (damaged, or edited)"
    kept, dropped, n_rigid = (int(v) for v in meta)
    if kept != omega.size or kept + dropped != n_dof or not 0 <= n_rigid <= kept:
        return "holds counts that do not fit its arrays"
    for a in (omega, shapes):
        a.setflags(write=False)
    return ModalBasis(omega=omega, shapes=shapes, kept=kept, dropped=dropped,
                      cutoff_hz=key["cutoff_hz"], n_rigid=n_rigid)


def cached_modes(structure, folder, n_modes=None, cutoff_hz=None):
    """The modes of ``structure`` (:func:`fem.modes`), from ``folder``'s
    entry when it holds a fit one, else computed and written there.

    Parameters
    ----------
    structure : PlaneStructure
        The assembled body.
    folder : OutputFolder-like or None
        Where entries live (``None``: no cache).
    n_modes, cutoff_hz
        As :func:`fem.modes`.

    Returns
    -------
    basis : ModalBasis
    hit : bool
        Whether the basis was read from the cache.
    """
    if folder is None:
        return modes(structure, n_modes=n_modes, cutoff_hz=cutoff_hz), False
    key = cache_key(structure, n_modes, cutoff_hz)
    name = entry_name(key)
    n = structure.n_dof
    width = n if n_modes is None else min(n, n_modes)
    data = folder.read(name, 8 * n * width + 8 * width + (1 << 16))
    if data is not None:
        got = _unpack(data, key, n)
        if isinstance(got, ModalBasis):
            return got, True
        warnings.warn(f"the modal cache entry {folder.path_of(name)} {got}: computed again",
                      stacklevel=2)
    basis = modes(structure, n_modes=n_modes, cutoff_hz=cutoff_hz)
    blob = _pack(key, basis)
    folder.write(name, lambda fh: fh.write(blob), "wb")
    return basis, False
