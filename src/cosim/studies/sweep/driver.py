"""The sweep itself: the points are made from the grid, loaded, validated
and checked against their folders on this process one at a time, as the
backend (:mod:`cosim.studies.sweep.backends`) has a worker free for them, and
each result is written to the point's run directory, through the checked
writer of the sweep's folder, and made a record of the table.
"""
from __future__ import annotations

import contextlib
import itertools
import logging
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

from cosim.core.result import resolved_scene_text
from cosim.core.series import npz_writer
from cosim.errors import shown
from cosim.io.rundir import OutputFolder
from cosim.io.strict_json import json_writer
from cosim.scene.load import SceneError, load_scene, read_toml_file
from cosim.studies.strike import find_strike
from cosim.studies.sweep.backends import _Runner
from cosim.studies.sweep.grid import LARGE_GRID, Point, grid_points
from cosim.scene.inputs import FileDigests, input_files
from cosim.studies.sweep.resume import (PointFolderError, _load_done,
                                        open_point, point_key)
from cosim.studies.sweep.table import TABLE, _record, table_writer

__all__ = ["SweepEvent", "SweepInterrupted", "sweep", "sweep_folder", "strike_names",
           "MAX_TIMEOUT_S"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SweepEvent:
    """What :func:`sweep` hands its ``progress`` callback after each point.

    Attributes
    ----------
    point : Point
    status : str
        ``finished``, ``failed`` (the run stopped; ``message`` says why),
        ``refused`` (the scene or its step was refused before the run),
        ``error`` (the worker raised, or its process died while running this
        point) or ``timeout`` (the point ran past the sweep's time limit).
    message : str
    skipped : bool
        The point was done before (resume) and was not run again.
    done, total : int
        Points accounted for so far, and in all.
    note : str
        Why a point that was done before ran again (``run again: ...``: its
        inputs or cosim changed, or its folder was damaged); empty otherwise.
    """

    point: Point
    status: str
    message: str
    skipped: bool
    done: int
    total: int
    note: str = ""


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (or by SIGTERM/SIGHUP, which ``cosim sweep``
    turns into this).  ``rows`` holds every point's record in grid order: the
    points that ended before the stop with their status, the others with
    status ``interrupted`` (in a grid of more than
    :data:`~cosim.studies.sweep.grid.LARGE_GRID` points, only those begun:
    the points never started are left out); the table was written."""

    def __init__(self, rows: list, signal_name: str = "SIGINT"):
        super().__init__(signal_name)
        self.rows, self.signal_name = rows, signal_name


def sweep(scene, *, variants=None, grid=None, scheme: str | None = None, workers: int = 1,
          scheduler=None, out=None, retry_failed: bool = False,
          contact: str | None = None, joint: str | None = None, progress=None, timeout: float | None = None,
          accuracy: float | None = None) -> list[dict]:
    """Run a scene over a grid of variants and overrides; one record per point.

    Parameters
    ----------
    scene : path-like
        The scene file, or the name of a shipped scene (``"three_mass"``:
        :func:`cosim.scene.shipped.find_scene`; a file of that name wins).
    variants : sequence of str, optional
        Variants to run (default: the scene's default variant alone).
    grid : mapping of str to sequence, optional
        ``key.path`` -> values, applied after the variant like ``--set``.
        Every combination of a variant and one value per key is a point.
    scheme : str, optional
        Another coupling scheme for every point.
    workers : int
        Processes of the local pool; 1 runs the points here, one after the
        other.  With ``scheduler = "local"``, the workers of a Dask
        ``LocalCluster`` started (and stopped) for this sweep.
    scheduler : str or dask.distributed.Client, optional
        Run on a Dask distributed cluster: its scheduler's address
        (``tcp://host:8786``), ``"local"``, or a ``Client``.  Its workers need
        cosim installed, not the scene file nor ``out``.
    out : path-like or OutputFolder, optional
        The sweep's directory: one run directory per point (named by
        :func:`point_name`) and the table ``sweep.csv``, all written through
        the checked writer (:class:`cosim.io.rundir.OutputFolder`).  The
        sweep holds the folder's lock while it runs (an ``OutputFolder``
        given is held by its caller).  A point whose directory holds a
        complete run of the same inputs (:mod:`~cosim.studies.sweep.resume`:
        the scene file and the files it names by content, cosim's version,
        variant, overrides and scheme) that ended ``finished``, ``failed`` or
        ``refused`` is not run again; one whose inputs changed or whose
        directory is damaged runs again (its event's ``note`` says why), and
        one whose directory is a link is recorded ``error`` and not run.
        Without ``out`` nothing is written and nothing is skipped.
    retry_failed : bool
        Run the points that failed or were refused before again.
    contact, joint : str, optional
        The contact and the striker's ``SUBSYSTEM/JOINT`` whose impact regime
        (:func:`cosim.studies.metrics.impact_regime`) is added as ``impact.*``
        columns.  Left out, each variant's scene chooses them
        (:func:`cosim.studies.strike.find_strike`: its only contact, else its
        only contact of a multibody on a structure, struck by the joint of the
        body that carries the contact's point); a scene that leaves no single
        choice gets no ``impact.*`` columns.
    progress : callable, optional
        Called with a :class:`SweepEvent` after each point.
    timeout : float, optional
        Most wall-clock seconds a point may run [s]; a point past it is
        recorded with status ``timeout`` and its process stopped (on Dask its
        task is cancelled and the worker running it restarted).  With a
        timeout, even ``workers = 1`` runs the points in a child process.

    accuracy : float, optional
        A relative accuracy in (0, 1) asked of every point: each is loaded
        with the scheme and steps the a-priori model chooses for it
        (:func:`cosim.studies.accurate.plan`; ``scheme``, when given, the
        only candidate).  A sweep runs no companion, so the choice is not
        checked nor refined, as `cosim run --accuracy` does.

    Returns
    -------
    list of dict
        One record per point, in grid order: the grid's values under
        ``set.KEY`` (``set.t_end``: ``t_end`` is the time the run reached),
        ``variant``,
        ``point`` (its directory's name), ``status``, ``message``, the
        flattened ``summary.json`` (``contacts.C.count``,
        ``energy.max_abs_drift``, ...) and ``impact.regime``,
        ``impact.rate_at_touch``, ``impact.rate_at_release``,
        ``impact.exit_velocity``.  A point that failed is a record with its
        status and message; the others run on.

    Raises
    ------
    SceneError
        If the scene file cannot be read, or ``contact`` or ``joint`` is given
        and a variant's scene has no such contact or joint (nothing written).
    ValueError
        If the grid is malformed (a repeated variant or value, more than
        :data:`~cosim.studies.sweep.grid.MAX_POINTS` points), ``workers`` is
        not a whole number >= 1, or ``timeout`` is not a number of seconds
        > 0 and at most :data:`MAX_TIMEOUT_S`.
    cosim.errors.OutputBusyError
        If another sweep or run holds ``out`` (nothing run).
    cosim.errors.OutputError
        If ``out`` is a link, a file or a filesystem root.
    SweepError
        If ``scheduler`` is malformed or cannot be reached (nothing written).
    SweepInterrupted
        On Ctrl-C (a ``KeyboardInterrupt``): the workers are ended, the table
        is written with the points not ended as ``interrupted``, and the
        exception carries the records.

    Notes
    -----
    The order of the records, and the table, is grid order, whatever order
    the points finish in, so the same sweep on one process, a pool and a
    cluster gives the same table (``cpu_time_s`` aside).  Points are loaded
    and validated on the calling process, one at a time as workers free up
    (the grid is never built whole); a point whose overrides do not make a
    valid scene is recorded ``refused`` without being sent anywhere.

    Examples
    --------
    >>> rows = sweep("three_mass", variants=["f1", "f100"],
    ...              grid={"t_end": [0.15]}, workers=2, out="runs/f")   # doctest: +SKIP
    >>> [(r["variant"], r["contacts.C.count"]) for r in rows]          # doctest: +SKIP
    [('f1', 1), ('f100', 9)]
    """
    from cosim.scene.shipped import find_scene
    _check_options(workers, timeout)
    scene_path = Path(find_scene(scene))
    if accuracy is not None:
        from cosim.scene.checks import parse_accuracy
        accuracy = parse_accuracy(accuracy, "accuracy")
    table = read_toml_file(scene_path)      # a regular file within the limits, or refused
    hashes = FileDigests()
    try:
        scene_hash = hashes(scene_path)
    except OSError as exc:
        raise SceneError(scene_path, "", f"cannot be read: {exc.strerror or exc}") from None
    if not variants:                    # name the default variant, so the point says it
        default = table.get("default_variant")
        variants = [default] if isinstance(default, str) else None
    points = grid_points(variants, grid)
    strikes = _strikes(scene_path, points.variants, contact, joint)
    with _held(out) as folder:
        return _sweep(points, folder, scene_path, scene_hash, hashes, strikes, scheme=scheme,
                      workers=workers, scheduler=scheduler, retry_failed=retry_failed,
                      progress=progress, timeout=timeout, accuracy=accuracy)


#: most wall-clock seconds a point may be given (a `poll` wait holds 24.8 days)
MAX_TIMEOUT_S = 1e6


def _check_options(workers, timeout, names=("workers", "timeout")) -> None:
    """Refuse a number of workers that is not a whole number >= 1, and a
    time limit that is not a number of seconds > 0 and at most
    :data:`MAX_TIMEOUT_S` (``names``: how the message calls them).

    Raises
    ------
    ValueError
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"`{names[0]}` must be a whole number >= 1, got {workers!r}")
    if timeout is None:
        return
    if (isinstance(timeout, bool) or not isinstance(timeout, (int, float))
            or not (timeout > 0 and math.isfinite(timeout))):
        raise ValueError(f"`{names[1]}` must be > 0 s, got {timeout!r}")
    if timeout > MAX_TIMEOUT_S:
        raise ValueError(f"`{names[1]}` must be at most {MAX_TIMEOUT_S:.0e} s "
                         f"({MAX_TIMEOUT_S / 86400:.1f} days), got {timeout!r}")


@contextlib.contextmanager
def sweep_folder(out):
    """Hold a sweep's folder ``out`` (an :class:`~cosim.io.rundir.OutputFolder`,
    made when missing and locked) while within; a folder made for it is
    removed again when nothing was written there (a sweep refused before it
    began).

    Raises
    ------
    cosim.errors.OutputBusyError
        If another sweep or run holds ``out``.
    cosim.errors.OutputError
        If ``out`` is a link, a file or a filesystem root.
    """
    folder = OutputFolder(out).open()
    try:
        yield folder
    finally:
        folder.close()
        if folder.created:
            try:
                os.rmdir(folder.path)           # only when nothing was written there
            except OSError:
                pass


@contextlib.contextmanager
def _held(out):
    """``out`` as a folder held for the sweep: None (nothing written), an
    :class:`~cosim.io.rundir.OutputFolder` its caller holds, or a path
    (held here, see :func:`sweep_folder`)."""
    if out is None or isinstance(out, OutputFolder):
        yield out
    else:
        with sweep_folder(out) as folder:
            yield folder


def _sweep(points, folder, scene_path, scene_hash, hashes, strikes, *, scheme, workers,
           scheduler, retry_failed, progress, timeout, accuracy=None) -> list[dict]:
    """:func:`sweep` once its grid is made and its folder held.  Each point
    is loaded, keyed and checked against its folder only when a worker is
    free for it, so a grid of any size starts at once."""
    total = len(points)
    # what a point's record keeps of how it was run (resume.point_key)
    chosen = scheme if accuracy is None else f"{scheme or 'chosen'} for accuracy {accuracy:g}"
    rows: dict[int, dict] = {}
    live: dict[int, tuple] = {}         # points loaded, not ended: scene, key, note
    seen_warnings: set[str] = set()
    stopped = None

    def report(point, status, message, skipped, note=""):
        if progress is not None:
            progress(SweepEvent(point, status, message, skipped, len(rows), total, note))

    def prepare(p):
        """The scene of point ``p`` to run, or None when it needs no run (it
        was done before, or it is refused or cannot be written)."""
        strike = strikes[p.variant]
        if folder is not None:
            try:
                fd = open_point(folder.fd, p.name)
            except PointFolderError as exc:
                message = f"its folder {shown(str(folder.path / p.name))}: {exc.strerror}"
                rows[p.index] = _record(p, {"variant": p.variant, "status": "error",
                                            "message": message}, None, None, *strike)
                report(p, "error", message, False)
                return None
            if fd is not None:
                os.close(fd)
        key = point_key(p, scene_path, chosen, scene_hash)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                if accuracy is None:
                    sc = load_scene(scene_path, p.variant, p.overrides, scheme)
                else:                       # the scheme and steps chosen for the accuracy
                    from cosim.studies.accurate import plan
                    sc = plan(scene_path, p.variant, p.overrides, accuracy, scheme)[0]
        except SceneError as exc:
            _finish(p, key, folder, None, None, "refused", str(exc), rows, *strike)
            report(p, "refused", str(exc), False)
            return None
        for w in caught:                # each warning once per sweep, not per point
            if str(w.message) not in seen_warnings:
                seen_warnings.add(str(w.message))
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        try:
            base = scene_path.resolve().parent
            inputs = [(f"{label} = {os.path.relpath(path, base)}", hashes(path))
                      for label, path in input_files(sc).items() if label != "scene"]
        except OSError as exc:
            message = f"{shown(str(exc.filename or 'an input file'))} cannot be read: " \
                      f"{exc.strerror or exc}"
            _finish(p, key, folder, None, sc, "refused", message, rows, *strike)
            report(p, "refused", message, False)
            return None
        key = point_key(p, scene_path, chosen, scene_hash, inputs)
        note = ""
        if folder is not None:
            wanted = (f"dq/{strike[1]}",) if strike[1] else ()
            done, why = _load_done(folder.fd, p.name, key, retry_failed, wanted)
            if done is not None:
                meta, summary, series = done
                try:
                    rows[p.index] = _record(p, meta, summary, series, *strike)
                except (TypeError, ValueError, KeyError, IndexError, AttributeError) as exc:
                    why = f"its run cannot be read back ({type(exc).__name__})"
                else:
                    report(p, meta["status"], meta.get("message") or "", True)
                    return None
            if why:
                note = f"run again: {why}"
                log.info("point %s: %s", p.name, note)
        live[p.index] = (sc, key, note)
        return sc

    def jobs():
        for p in points:
            sc = prepare(p)
            if sc is not None:
                yield p.index, sc

    with _Runner(workers, scheduler, timeout) as runner:
        try:
            feed = jobs()
            first = next(feed, None)        # a local cluster starts only for work to do
            if first is not None:
                for index, (kind, payload) in runner.run(itertools.chain([first], feed)):
                    p = points[index]
                    sc, key, note = live.pop(index)
                    res = payload if kind == "ran" else None
                    status, message = (res.status, res.message) if res else (kind, payload)
                    _finish(p, key, folder, res, sc, status, message, rows,
                            *strikes[p.variant])
                    report(p, status, message, False, note)
        except KeyboardInterrupt as exc:
            # the runner's exit ends the workers; the table keeps what ended
            stopped = exc
    if stopped is not None:
        name = getattr(stopped, "signal_name", None) or "SIGINT"
        # a large grid lists the points begun; a small one every point
        left = (live if total > LARGE_GRID
                else (i for i in range(total) if i not in rows))
        for i in list(left):
            p = points[i]
            rows[i] = _record(p, {"variant": p.variant, "status": "interrupted",
                                  "message": f"the sweep was stopped ({name}) before this "
                                             f"point ended"}, None, None, *strikes[p.variant])
    records = [rows[i] for i in sorted(rows)]
    if folder is not None:
        folder.write(TABLE, table_writer(records), "w")
    if stopped is not None:
        raise SweepInterrupted(records, name) from None
    return records


def _strikes(scene_path, variants, contact, joint) -> dict:
    """Variant -> (contact, joint) whose impact regime its records get, or
    (None, None): chosen by :func:`~cosim.studies.strike.find_strike` on the
    variant's scene.  A variant whose scene does not load gets (None, None):
    its points are refused when they load.  A name given that a scene lacks
    raises :class:`SceneError` before anything runs."""
    out = {}
    for variant in dict.fromkeys(variants):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")     # the points' own loads show them
                scene = load_scene(scene_path, variant)
        except SceneError:
            out[variant] = (None, None)
            continue
        out[variant] = find_strike(scene, contact, joint, required=False) or (None, None)
    return out


def strike_names(scene, variants=None, contact: str | None = None, joint: str | None = None
                 ) -> tuple:
    """The contact and the striker's joint that a sweep of ``variants`` reads
    (see ``contact`` and ``joint`` of :func:`sweep`): those of the first
    variant whose scene loads and leaves a choice, else ``contact`` and
    ``joint`` as given.  A caller that labels or draws the sweep uses them.

    Raises
    ------
    SceneError
        If ``contact`` or ``joint`` is given and a variant's scene has no such
        contact or joint.
    """
    for names in _strikes(Path(scene), list(variants or [None]), contact, joint).values():
        if names != (None, None):
            return names
    return contact, joint


def _finish(point, key, folder, res, scene, status, message, rows, contact, joint):
    """Write a point's run directory (when there is a sweep ``folder``) and
    its record.  ``point.json`` goes last, after it was removed first, so a
    folder whose ``point.json`` says done holds the whole run."""
    meta = {**key, "status": status, "message": message}
    summary = res.summary if res is not None else None
    series = res.series if res is not None else None
    if folder is not None:
        with folder.folder(point.name) as d:
            d.remove("point.json")
            for stale in ("summary.json", "series.npz"):
                d.remove(stale)
            if scene is not None:
                text = resolved_scene_text(scene)
                d.write("scene.toml", lambda fh: fh.write(text), "w")
            if res is not None:
                d.write("series.npz", npz_writer(series), "wb")
                d.write("summary.json", json_writer(summary, indent=2), "w")
            d.write("point.json", json_writer(meta, indent=2), "w")
    if status not in ("finished",):
        log.info("point %s: %s: %s", point.name, status, message)
    rows[point.index] = _record(point, meta, summary, series, contact, joint)
