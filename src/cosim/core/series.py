"""Time series of a run, kept in fixed-size chunks, and ``series.npz`` written
by streaming.

A run's series are columns of equal length (``t``, ``gap/C``, ...).  The
recorder hands them over a chunk at a time, as a block of columns.  A
:class:`SeriesStore` keeps the blocks in memory, or appends them to a spool
file on disk, so that a long run's memory stays that of one chunk.  The final
``series.npz`` is then assembled member by member: each ``.npy`` member gets
the header of its known final length, and its data is copied from the spool
chunk by chunk; nothing is concatenated in memory.

The archive's bytes depend on the data alone: members are stored (not
compressed), in a fixed order, with a fixed date and permissions, so two runs
that compute the same numbers write the same file.
"""
from __future__ import annotations

import contextlib

import os
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cosim.io.rundir import OutputFolder, atomic_write, output_error

__all__ = ["SeriesStore", "SeriesFile", "write_npz", "npz_writer", "atomic_write"]

#: date stamped on every member of ``series.npz`` (zip cannot go earlier)
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)
#: bytes of the chunk buffer the recorder fills before handing it over
CHUNK_BYTES = 1 << 20


def chunk_rows(width: int) -> int:
    """Rows of a chunk of ``width`` float64 columns (about :data:`CHUNK_BYTES`)."""
    return max(64, CHUNK_BYTES // (8 * max(1, width)))


def _member(name: str) -> zipfile.ZipInfo:
    parts = name.split("/")
    if not all(parts) or any(p in (".", "..") or "\\" in p for p in parts):
        raise ValueError(f"series name {name!r} must be words joined by `/` (no empty, "
                         f"`.` or `..` part): it is a path inside series.npz")
    info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_DATE)
    info.compress_type = zipfile.ZIP_STORED
    info.create_system = 3                 # the same on every platform
    info.external_attr = 0o644 << 16
    return info


def _header(dtype: np.dtype, n: int) -> dict:
    return {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
            "shape": (n,)}


def _open_member(zf: zipfile.ZipFile, name: str, nbytes: int):
    info = _member(name)
    info.file_size = nbytes + 128          # lets zipfile decide on zip64 up front
    return zf.open(info, "w")


def write_npz(path, arrays: Mapping) -> None:
    """Write ``arrays`` (name -> 1-D or n-D array) as an ``.npz`` whose bytes
    depend only on the names, order and values (see the module notes).

    The file is written next to ``path`` and moved into place, so a reader
    never sees half of it.
    """
    atomic_write(Path(path), npz_writer(arrays), "wb")


def npz_writer(arrays: Mapping):
    """The writer of :func:`write_npz`, for a caller that holds the folder
    (:meth:`cosim.io.rundir.OutputFolder.write`): ``writer(fh)`` writes
    ``arrays`` as that ``.npz`` into the binary file ``fh``."""
    def write(fh):
        with zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            for name, value in arrays.items():
                a = np.asanyarray(value)
                with _open_member(zf, name, a.nbytes) as out:
                    np.lib.format.write_array(out, a, version=(1, 0), allow_pickle=False)
    return write


def _open_spool(path: Path):
    """The spool, opened anew through the checked writer
    (:meth:`cosim.io.rundir.OutputFolder.create`): a stale spool (a run
    killed outright) or anything planted at its name is removed first, never
    followed, and the file is created exclusively."""
    with OutputFolder(path.parent, lock=False) as folder:
        return folder.create(path.name)


class SeriesStore:
    """Columns of equal length, received as blocks.

    Parameters
    ----------
    names : list of str
        Column names, in the order of the block rows.
    dtypes : list of numpy dtype, optional
        Type each column is written with (float64 by default; blocks always
        arrive as float64).
    spool : path-like, optional
        File to append the blocks to.  Without it, blocks stay in memory.
    """

    def __init__(self, names, dtypes=None, spool=None):
        self.names = list(names)
        self.dtypes = [np.dtype(d) for d in (dtypes or [np.float64] * len(self.names))]
        self.length = 0
        self._blocks: list[np.ndarray] = []
        self._chunks: list[tuple[int, int]] = []      # (offset, rows) in the spool
        self.spool = None if spool is None else Path(spool)
        self._fh = None
        if self.spool is not None:
            self._fh = _open_spool(self.spool)

    def append(self, block: np.ndarray) -> None:
        """Add ``block`` (n_columns, rows)."""
        block = np.ascontiguousarray(block, dtype="<f8")
        rows = block.shape[1]
        if rows == 0:
            return
        if self._fh is None:
            self._blocks.append(block)
        else:
            try:
                self._fh.seek(0, os.SEEK_END)
                offset = self._fh.tell()
                self._fh.write(block.tobytes())
            except OSError as exc:
                raise output_error(exc, self.spool) from exc
            self._chunks.append((offset, rows))
        self.length += rows

    def arrays(self) -> dict:
        """Every column as one array (in memory: for a run without a spool).

        The blocks are freed as they are copied, so the peak is about one copy
        of the series; the store is consumed."""
        if self._fh is not None:
            raise RuntimeError("a spooled store is read through write() and SeriesFile")
        columns = [np.empty(self.length, dtype=d) for d in self.dtypes]
        start = 0
        for k, block in enumerate(self._blocks):    # each block freed once copied
            rows = block.shape[1]
            for j, col in enumerate(columns):
                col[start:start + rows] = block[j]
            start += rows
            self._blocks[k] = None
        self._blocks = None                          # consumed: a second call fails
        return dict(zip(self.names, columns))

    def write(self, path) -> None:
        """Write ``series.npz`` at ``path``, column by column, copying the
        spool chunk by chunk (at most one chunk's column in memory)."""
        if self._fh is None:
            write_npz(path, self.arrays())
            return
        try:
            self._fh.flush()               # a full disk may show only here
        except OSError as exc:
            raise output_error(exc, self.spool) from exc
        n = self.length
        biggest = max((r for _, r in self._chunks), default=0)
        buf = np.empty(biggest, dtype="<f8")

        def write(fh):
            with zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
                for j, name in enumerate(self.names):
                    dtype = self.dtypes[j]
                    with _open_member(zf, name, n * dtype.itemsize) as out:
                        np.lib.format.write_array_header_1_0(out, _header(dtype, n))
                        for offset, rows in self._chunks:
                            part = buf[:rows]
                            self._fh.seek(offset + 8 * j * rows)
                            self._fh.readinto(memoryview(part).cast("B"))
                            out.write(part.astype(dtype, copy=False).tobytes())
        atomic_write(Path(path), write, "wb")

    def close(self) -> None:
        """Close and delete the spool file, whatever state it is in.

        On a full disk the spool's buffer cannot be flushed: closing it then
        raises, though the file is closed all the same.  Its content is
        discarded anyway (it is either copied into ``series.npz`` already or
        lost with the run), so that error is not raised again here; the spool
        is deleted in every case."""
        if self._fh is None:
            return
        fh, self._fh = self._fh, None
        try:
            fh.close()
        except OSError:
            pass                           # the buffer could not be written: dropped
        finally:
            if os.path.lexists(self.spool):
                os.unlink(self.spool)


class SeriesFile(Mapping):
    """The series of a run as written in ``series.npz``, read one array at a
    time when asked for (``series["gap/C"]``), so a long run's result does
    not hold them all in memory."""

    def __init__(self, path):
        self.path = Path(path)
        with zipfile.ZipFile(self.path) as zf:
            self._names = [n[:-4] for n in zf.namelist() if n.endswith(".npy")]

    def __getitem__(self, key):
        if key not in self._names:
            raise KeyError(key)
        with np.load(self.path) as npz:
            return npz[key]

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)

    def __repr__(self):
        return f"SeriesFile({str(self.path)!r}, {len(self)} arrays)"


@contextlib.contextmanager
def stop_signals_held():
    """Hold back the stop signals (SIGINT, SIGTERM, SIGHUP) of the calling
    thread for the block, so that a store and its count change together; a
    signal that came meanwhile is taken when the block ends."""
    import signal
    held = {signal.SIGINT} | {getattr(signal, n) for n in ("SIGTERM", "SIGHUP")
                              if hasattr(signal, n)}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
