"""The outcome of a run, and writing it to disk atomically."""
from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.errors import OutputExistsError
from cosim.io.rundir import inside
from cosim.core.series import atomic_write, write_npz

__all__ = ["SimulationResult", "intervals_until", "write_outputs", "check_output_dir", "resolved_scene_text",
           "written_by_a_run"]


# eq=False: a result holds arrays, so the generated == could only raise (its truth value
# is ambiguous); two results are equal when they are one, and hash by identity
@dataclass(frozen=True, eq=False)
class SimulationResult:
    """What :func:`cosim.simulate` returns.

    Attributes
    ----------
    t : (n,) array
        Sample times [s].
    series : mapping of str to array
        Time series named as in ``series.npz`` (``gap/C``, ``force/C``,
        ``q/SUB/JOINT``, ``dq/SUB/JOINT``, ``energy/total``, ...): a dict,
        or, for a run streamed to disk (``simulate(..., out=DIR)``), a
        :class:`~cosim.core.series.SeriesFile` that reads each array from
        ``DIR/series.npz`` when asked for.
    summary : dict
        The ``summary.json`` contract.
    contact_events : tuple of dict
        Contact intervals in time order: ``contact``, ``t_on``, ``t_off``.
    n_windows, n_iterations, n_rejected : int
        Macro steps, coupling iterations, rejected macro steps.
    status : {"finished", "failed", "interrupted", "error"}
        ``failed``: the run could not go on (a :class:`SimulationError`);
        ``interrupted``: stopped by Ctrl-C; ``error``: stopped by an
        unexpected exception.  The series and summary then end at the last
        sample.
    message : str
    success : bool
    """

    t: np.ndarray
    series: dict
    summary: dict
    contact_events: tuple
    n_windows: int
    n_iterations: int
    n_rejected: int
    status: str
    message: str
    success: bool

    def to_csv(self, path) -> None:
        """Write the series as CSV, ``time`` first."""
        names = [k for k in self.series if k != "t"]
        data = np.column_stack([self.t] + [self.series[k] for k in names])
        _atomic_write(Path(path), lambda fh: np.savetxt(
            fh, data, delimiter=",", header=",".join(["time"] + names), comments=""), "w")


def _atomic_write(path: Path, writer, mode: str) -> None:
    atomic_write(path, writer, mode)


#: files whose presence makes a directory hold a run
RUN_FILES = ("summary.json", "series.npz")
#: how every ``scene.toml`` a run writes begins
SCENE_HEADER = "# The scene as run: "


def written_by_a_run(path) -> bool:
    """Whether ``path`` is a ``scene.toml`` that a run wrote (it begins with
    :data:`SCENE_HEADER`), not a user's scene file."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(SCENE_HEADER)) == SCENE_HEADER.encode()
    except OSError:
        return False


#: what to do about an output folder that holds a run: from Python, and from the command line
_REMEDIES = ("choose another `out`, or pass overwrite=True to replace it",
             "choose another --out, or pass --overwrite to replace it")


def check_output_dir(out_dir, overwrite: bool = False, exports=()) -> Path:
    """Refuse an output directory where a run would replace what it must not.

    A run writes ``scene.toml``, ``summary.json``, ``series.npz`` and, for
    each structure in ``exports``, ``NAME.xdmf``.  Without ``overwrite``,
    none of them may exist, but for a ``scene.toml`` that a run wrote (the
    leftover of a run killed outright).  Even with ``overwrite``, a
    ``scene.toml`` that no run wrote (a user's scene, e.g. ``cosim run
    scene.toml --out .``) is never replaced.

    Parameters
    ----------
    out_dir : path-like
    overwrite : bool
        Allow replacing the run there (its files are replaced one by one,
        each atomically; other files are left alone).
    exports : sequence of str
        Structures whose fields the run exports.

    Raises
    ------
    OutputExistsError
        If ``out_dir`` holds ``summary.json`` or ``series.npz`` (or an export
        file) and ``overwrite`` is false, or a ``scene.toml`` that no run
        wrote.
    """
    out = Path(out_dir)
    found = [name for name in RUN_FILES if os.path.lexists(out / name)]
    if found and not overwrite:
        raise OutputExistsError(f"{out} already holds a run ({', '.join(found)})", *_REMEDIES)
    scene = out / "scene.toml"
    if os.path.lexists(scene) and not written_by_a_run(scene):
        raise OutputExistsError(
            f"{scene} was not written by a run (it may be your scene file), and a run "
            f"writes its scene.toml there: choose another --out (--overwrite does not "
            f"replace it)")
    other = [f"{name}.xdmf" for name in exports if os.path.lexists(out / f"{name}.xdmf")]
    if other and not overwrite:
        raise OutputExistsError(f"{out} already holds {', '.join(other)}, which this run "
                                f"would replace", *_REMEDIES)
    return out


def write_summary(summary: dict, path) -> None:
    """Write ``summary.json`` atomically (keys in their order, two-space
    indent), as strict JSON: a value that is not finite is written as null
    and noted under ``not_finite`` (:mod:`cosim.io.strict_json`)."""
    from cosim.io.strict_json import json_writer
    _atomic_write(Path(path), json_writer(summary, indent=2), "w")


def write_scene(scene, out_dir) -> Path:
    """Write ``scene.toml``, the scene as run, atomically."""
    path = inside(out_dir, "scene.toml")
    text = resolved_scene_text(scene)
    _atomic_write(path, lambda fh: fh.write(text), "w")
    return path


def write_outputs(result: SimulationResult, out_dir, scene=None, *,
                  overwrite: bool = False) -> tuple[Path, Path]:
    """Write ``summary.json`` and ``series.npz`` into ``out_dir`` atomically.

    Parameters
    ----------
    result : SimulationResult
    out_dir : path-like
    scene : Scene, optional
        The scene that ran; its merged table (variant, overrides and scheme
        applied) is written as ``scene.toml`` too, a scene file of its own
        that ``cosim plot --animate`` rebuilds the geometry from (and that
        ``cosim run`` runs again).
    overwrite : bool
        Replace a run that ``out_dir`` already holds.

    Returns
    -------
    summary, series : Path

    Raises
    ------
    OutputExistsError
        If ``out_dir`` holds a run and ``overwrite`` is false.

    Notes
    -----
    Each file goes to a temporary name beside it and is moved into place, so
    no reader ever sees half a file.  ``series.npz`` has deterministic bytes
    (see :mod:`cosim.core.series`).  A result whose series were streamed into
    ``out_dir`` by :func:`cosim.simulate` (``out=``) is not written twice.
    """
    out = Path(out_dir)
    summary = inside(out, "summary.json")
    series = inside(out, "series.npz")
    source = getattr(result.series, "path", None)
    same = source is not None and series.exists() and os.path.samefile(source, series)
    if not same:
        check_output_dir(out, overwrite)
    elif scene is not None:
        check_output_dir(out, True)         # never a user's scene.toml
    if scene is not None:
        write_scene(scene, out)
    if source is None:
        write_npz(series, result.series)
    elif not same:
        def copy(fh):
            with open(source, "rb") as src:
                shutil.copyfileobj(src, fh)
        _atomic_write(series, copy, "wb")
    write_summary(result.summary, summary)
    return summary, series


def resolved_scene_text(scene) -> str:
    """``scene.toml`` of a run: the scene's merged table as TOML, its origin in a comment."""
    from cosim.io.tomlwrite import dumps

    data = {"name": scene.name, **scene.data}
    origin = Path(scene.path).name.translate({c: "?" for c in (*range(32), 127)})
    head = (f"{SCENE_HEADER}{origin}"
            + (f", variant {scene.variant!r}" if scene.variant else "")
            + ", overrides and scheme applied (written by `cosim run`).\n")
    return head + dumps(data)


def intervals_until(intervals, opened: float | None, t_stop: float) -> list:
    """One contact's intervals as a summary gives them, for a run whose last
    kept sample is at ``t_stop`` [s].

    ``intervals`` are the closed ones ``[t_on, t_off]`` in time order and
    ``opened`` the onset of one still open (or None).  A scheme reports a
    step's switches before the sample at its end, and that sample may never
    be kept (the guard refuses it, or Ctrl-C comes first): what began after
    ``t_stop`` is dropped, and an interval that runs past it, or is still
    open, ends at ``t_stop``.  Every interval returned therefore has
    ``t_on <= t_off <= t_stop``.

    Examples
    --------
    >>> intervals_until([[0.0, 0.2]], 0.35, 0.3)
    [[0.0, 0.2]]
    >>> intervals_until([[0.0, 0.2], [0.25, 0.32]], None, 0.3)
    [[0.0, 0.2], [0.25, 0.3]]
    >>> intervals_until([], 0.1, 0.3)
    [[0.1, 0.3]]
    """
    out = [[a, min(b, t_stop)] for a, b in intervals if a <= t_stop]
    if opened is not None and opened <= t_stop:
        out.append([opened, t_stop])
    return out
