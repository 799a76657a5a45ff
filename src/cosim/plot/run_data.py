"""Reading a run directory for drawing: :func:`load_run` gives a
:class:`RunData` from what ``cosim run`` wrote (``summary.json``,
``series.npz``, ``scene.toml``), finished or not, and says what is missing.
Needs no matplotlib.

A run folder may come from someone else, so everything here is read as
data, within stated limits, and checked before it is used:

- ``series.npz`` is a zip archive of ``.npy`` members.  Before any member is
  unpacked, the sizes its archive declares are held to
  :data:`MAX_SERIES_BYTES` and to :data:`MAX_EXPANSION` times the archive's
  own size (a few megabytes cannot claim gigabytes), and each member's
  ``.npy`` header to one dimension, a numeric type and a length that its
  declared size holds.  Nothing is ever unpickled.
- ``summary.json`` is at most :data:`MAX_SUMMARY_BYTES`, and each value the
  figures use is checked for its type.
- ``scene.toml`` is read within the limits of a scene file; the figures take
  its end time, its name and the types of its subsystems and joints, and
  pass over what does not fit.

Anything else is a :class:`PlotError` naming the file, what is wrong in it
and what was expected.
"""
from __future__ import annotations

import json
import math
import os
import stat
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["PlotError", "RunData", "load_run", "MAX_SERIES_BYTES", "MAX_EXPANSION",
           "MAX_SUMMARY_BYTES"]

#: most bytes the arrays of ``series.npz`` may take unpacked (4 GiB)
MAX_SERIES_BYTES = 4 * 2**30
#: most times its own size an archive may unpack to, plus :data:`_SLACK`
#: (``cosim run`` stores its members uncompressed: its archives unpack to
#: their own size)
MAX_EXPANSION = 16
_SLACK = 64 * 2**20
#: most bytes of ``summary.json`` (64 MiB)
MAX_SUMMARY_BYTES = 64 * 2**20
#: most bytes of an ``.npy`` member's header (numpy's own default limit)
_MAX_HEADER = 10_000
#: the kinds of numbers a series may hold: booleans, integers, floats
_NUMERIC = "biuf"


class PlotError(RuntimeError):
    """A run directory that cannot be drawn (what is missing is named)."""


@dataclass(frozen=True)
class RunData:
    """What a run directory holds.

    Attributes
    ----------
    path : Path
    summary : dict or None
        The values of ``summary.json`` the figures use, checked (``scene``,
        ``scheme``, ``status``, ``message``, ``contacts`` with their
        ``intervals``, ``peak_penetration``, ``impulse`` and
        ``coupling_error``, ``energy`` with ``max_abs_drift`` and
        ``supplied``); None if the run never wrote it.
    series : dict[str, ndarray]
        ``series.npz``, every array one-dimensional, numeric and cut to the
        shortest length; values that are not finite are NaN (left out of
        the lines drawn).
    scene : dict or None
        ``scene.toml`` (the scene as run), None for runs written before it
        or when it cannot be read.
    t_end : float or None
        The scene's end time [s] (None when unknown).
    incomplete : str
        Why the run is incomplete, empty if it is not.
    not_finite : tuple of str
        The series that held values that are not finite (NaN or infinite).
    """

    path: Path
    summary: dict | None
    series: dict
    scene: dict | None
    t_end: float | None
    incomplete: str
    not_finite: tuple = ()

    @property
    def t(self) -> np.ndarray:
        return self.series["t"]

    def title(self) -> str:
        from cosim.errors import shown

        s = self.summary or {}
        name = s.get("scene") or _scene_name(self.scene) or self.path.name
        head = shown(name, 80)
        if s.get("scheme"):
            head += f", scheme {shown(s['scheme'], 40)}"
        return head + (f"\nINCOMPLETE run: {self.incomplete}" if self.incomplete else "")


def _scene_name(scene) -> str | None:
    name = (scene or {}).get("name")
    return name if isinstance(name, str) else None


def _size_text(nbytes: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if nbytes < 1024 or unit == "TiB":
            return f"{nbytes:.3g} {unit}" if unit != "bytes" else f"{int(nbytes)} bytes"
        nbytes /= 1024


# ------------------------------------------------------------ series.npz
def _open_regular(file: Path) -> int:
    """A read-only descriptor of the regular file ``file`` (opened without
    blocking, so that a named pipe cannot hang the reader)."""
    try:
        fd = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
                     | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise PlotError(f"{file}: cannot be opened: {exc.strerror or exc}") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise PlotError(f"{file}: must be a regular file, got a folder or a special file")
    return fd


def _read_series(file: Path) -> dict:
    """The arrays of ``series.npz``, checked before they are unpacked."""
    fd = _open_regular(file)
    with os.fdopen(fd, "rb") as fh:
        size = os.fstat(fd).st_size
        if size > MAX_SERIES_BYTES:
            raise PlotError(f"{file}: holds {_size_text(size)}, more than the "
                            f"{_size_text(MAX_SERIES_BYTES)} a plot reads "
                            f"(`cosim.plot.run_data.MAX_SERIES_BYTES`)")
        try:
            zf = zipfile.ZipFile(fh)
        except (zipfile.BadZipFile, EOFError, ValueError, OSError) as exc:
            raise PlotError(f"{file}: is not a zip archive ({exc}); a run's series.npz is "
                            f"one, of .npy arrays") from None
        with zf:
            infos = zf.infolist()
            budget = min(MAX_SERIES_BYTES, MAX_EXPANSION * size + _SLACK)
            total = sum(info.file_size for info in infos)
            if total > budget:
                raise PlotError(
                    f"{file}: its members declare {_size_text(total)} unpacked, more than "
                    f"the {_size_text(budget)} a plot unpacks from an archive of "
                    f"{_size_text(size)} (at most {MAX_EXPANSION} times its size plus "
                    f"{_size_text(_SLACK)}, and {_size_text(MAX_SERIES_BYTES)} in all)")
            series = {}
            for info in infos:
                key = _member_key(info, file)
                if key in series:
                    raise PlotError(f"{file}: holds the array `{_shown(key)}` twice")
                series[key] = _read_member(zf, info, key, file)
    return series


def _shown(text) -> str:
    from cosim.errors import shown
    return shown(text, 80)


def _member_key(info: zipfile.ZipInfo, file: Path) -> str:
    name = info.filename
    if info.is_dir() or not name.endswith(".npy") or len(name) == 4:
        raise PlotError(f"{file}: member `{_shown(name)}` is not an .npy array; a run's "
                        f"series.npz holds .npy arrays only")
    return name[:-4]


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, key: str, file: Path):
    """One ``.npy`` member: its header checked, then exactly the bytes it
    declares read (never more than the member's declared size)."""
    where = f"{file}: array `{_shown(key)}`"
    fmt = np.lib.format
    try:
        with zf.open(info) as fh:
            try:
                version = fmt.read_magic(fh)
                if version == (1, 0):
                    shape, _, dtype = fmt.read_array_header_1_0(fh, max_header_size=_MAX_HEADER)
                elif version == (2, 0):
                    shape, _, dtype = fmt.read_array_header_2_0(fh, max_header_size=_MAX_HEADER)
                else:
                    raise ValueError(f".npy format version {version[0]}.{version[1]}, "
                                     f"where 1.0 or 2.0 was expected")
            except (ValueError, TypeError, SyntaxError, OverflowError) as exc:
                raise PlotError(f"{where} has no readable .npy header: "
                                f"{_shown(str(exc))}") from None
            if dtype.hasobject or dtype.kind not in _NUMERIC or dtype.fields or dtype.subdtype:
                raise PlotError(f"{where} holds values of type {_shown(str(dtype))}; a series "
                                f"holds numbers (booleans, integers or floats)")
            if len(shape) != 1:
                raise PlotError(f"{where} must be a one-dimensional array (one value per "
                                f"sample), got shape {shape}")
            n = shape[0]
            nbytes = n * dtype.itemsize
            held = info.file_size - fh.tell()
            if n < 0 or nbytes != held:
                raise PlotError(f"{where} declares {n} values ({_size_text(max(nbytes, 0))}), "
                                f"but its member holds {_size_text(max(held, 0))} of data")
            data = fh.read(nbytes)
    except PlotError:
        raise
    except (zlib.error, zipfile.BadZipFile, EOFError, OSError, NotImplementedError,
            RuntimeError, ValueError) as exc:
        raise PlotError(f"{where} is damaged and cannot be unpacked: "
                        f"{_shown(str(exc) or type(exc).__name__)}") from None
    if len(data) != nbytes:
        raise PlotError(f"{where} is cut short: {len(data)} of {nbytes} bytes")
    return np.frombuffer(data, dtype).astype(dtype.newbyteorder("="))


def _check_series(series: dict, file: Path) -> tuple[dict, tuple]:
    """Cut every array to the shortest; refuse a time that is not finite
    numbers; NaN for the other series' values that are not finite."""
    t = series.get("t")
    if t is None:
        raise PlotError(f"{file}: has no time array `t`")
    if t.dtype.kind not in "iuf":
        raise PlotError(f"{file}: array `t` must hold numbers [s], got values of type {t.dtype}")
    n = min(len(v) for v in series.values())
    series = {k: v[:n] for k, v in series.items()}
    t = series["t"] = series["t"].astype(float)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise PlotError(f"{file}: array `t` must hold finite times [s], got "
                        f"{float(t[bad[0]])!r} at sample {bad[0]} ({bad.size} such sample(s))")
    not_finite = []
    for k, v in series.items():
        if v.dtype.kind == "f" and not np.all(np.isfinite(v)):
            series[k] = np.where(np.isfinite(v), v, np.nan)
            not_finite.append(k)
    return series, tuple(not_finite)


# ----------------------------------------------------------- summary.json
def _read_summary(file: Path) -> dict | None:
    """The checked values of ``summary.json``, None when there is none."""
    from cosim.io.tomlread import TomlLimitError, read_bytes

    if not os.path.lexists(file):
        return None
    try:
        data = read_bytes(file, MAX_SUMMARY_BYTES)
    except TomlLimitError as exc:
        raise PlotError(f"{file}: {exc}") from None
    except OSError as exc:
        raise PlotError(f"{file}: cannot be read: {exc.strerror or exc}") from None
    try:
        raw = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise PlotError(f"{file}: is not UTF-8 text (JSON is): byte {exc.start}") from None
    except RecursionError:
        raise PlotError(f"{file}: is nested too deep to be a run's summary") from None
    except ValueError as exc:
        raise PlotError(f"{file}: is not JSON: {_shown(str(exc))}") from None
    return _check_summary(raw, file)


def _kind(v) -> str:
    return {dict: "an object", list: "an array", str: "a string", bool: "a boolean",
            type(None): "null"}.get(type(v), "a number")


def _check_summary(raw, file: Path) -> dict:
    """The values of a summary the figures use, each of its type."""

    def bad(key, want, v):
        raise PlotError(f"{file}: `{key}` must be {want}, got {_kind(v)} {_shown(repr(v))}")

    def obj(key, v):
        if not isinstance(v, dict):
            bad(key or "the top level", "an object", v)
        return v

    def number(key, v):
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            bad(key, "a number or null", v)
        return float(v)

    def text(key, v):
        if v is not None and not isinstance(v, str):
            bad(key, "a string or null", v)
        return v

    raw = obj("", raw)
    out = {k: text(k, raw.get(k)) for k in ("scene", "scheme", "status", "message")}
    contacts = {}
    for name, c in obj("contacts", raw.get("contacts", {})).items():
        key = f"contacts.{name}"
        c = obj(key, c)
        rec = {k: number(f"{key}.{k}", c.get(k))
               for k in ("peak_penetration", "impulse", "coupling_error")}
        intervals = c.get("intervals", [])
        if not isinstance(intervals, list):
            bad(f"{key}.intervals", "an array of [start, end] times", intervals)
        rec["intervals"] = []
        for iv in intervals:
            if (not isinstance(iv, list) or len(iv) != 2
                    or any(isinstance(x, bool) or not isinstance(x, (int, float))
                           or not math.isfinite(x) for x in iv)):
                bad(f"{key}.intervals", "an array of [start, end] finite times [s]", iv)
            rec["intervals"].append([float(iv[0]), float(iv[1])])
        contacts[name] = rec
    out["contacts"] = contacts
    energy = obj("energy", raw.get("energy", {}))
    out["energy"] = {k: number(f"energy.{k}", energy.get(k))
                     for k in ("max_abs_drift", "supplied")}
    return out


# ------------------------------------------------------------ scene.toml
def _read_scene(file: Path) -> dict | None:
    """``scene.toml`` read as data within the limits of a scene file, or
    None (a run written before it, or a file that is not a scene)."""
    from cosim.io.tomlread import read_toml

    if not file.is_file():
        return None
    try:
        return read_toml(file)
    except (OSError, ValueError):           # TOMLDecodeError, TomlLimitError
        return None


def load_run(run_dir) -> RunData:
    """Read a run directory, finished or not.

    Raises
    ------
    PlotError
        If there is no readable ``series.npz``, or it or ``summary.json``
        is damaged, too large or not of the form ``cosim run`` writes (the
        message names the file and what is wrong).
    """
    from cosim.errors import shown

    path = Path(run_dir)
    fseries = path / "series.npz"
    if not os.path.lexists(fseries):
        raise PlotError(f"{fseries}: no such file; `cosim plot` needs a run directory "
                        f"written by `cosim run`")
    series, not_finite = _check_series(_read_series(fseries), fseries)
    summary = _read_summary(path / "summary.json")
    scene = _read_scene(path / "scene.toml")
    t_end = scene.get("t_end") if scene is not None else None
    if isinstance(t_end, bool) or not isinstance(t_end, (int, float)) or not (
            math.isfinite(t_end) and t_end > 0):
        t_end = None
    else:
        t_end = float(t_end)
    why = []
    if summary is None:
        why.append("no readable summary.json")
    elif summary.get("status") != "finished":
        why.append(f"status {shown(repr(summary.get('status')), 60)}"
                   + (f" ({shown(summary['message'], 200)})" if summary.get("message") else ""))
    t = series["t"]
    t_last = float(t[-1]) if len(t) else 0.0
    if t_end is not None and t_last < t_end * (1 - 1e-9):
        why.append(f"series reach t = {t_last:.6g} s of {t_end:.6g} s")
    return RunData(path, summary, series, scene, t_end, "; ".join(why), not_finite)
