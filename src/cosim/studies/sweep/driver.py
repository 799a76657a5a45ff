"""The sweep itself: the points are loaded and validated on this process,
handed to a backend (:mod:`cosim.studies.sweep.backends`), and each result is
written to the point's run directory and made a record of the table.
"""
from __future__ import annotations

import json
import logging
import warnings
from dataclasses import dataclass
from pathlib import Path

from cosim.core.result import _atomic_write, resolved_scene_text, write_outputs
from cosim.io.rundir import inside
from cosim.io.tomlread import TomlLimitError
from cosim.scene.load import SceneError, load_scene, read_toml_file
from cosim.studies.strike import find_strike
from cosim.studies.sweep.backends import _Runner
from cosim.studies.sweep.grid import Point, grid_points
from cosim.studies.sweep.resume import _file_hash, _load_done, _spec
from cosim.studies.sweep.table import TABLE, _record, write_table

__all__ = ["SweepEvent", "SweepInterrupted", "sweep", "strike_names"]

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
    """

    point: Point
    status: str
    message: str
    skipped: bool
    done: int
    total: int


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (or by SIGTERM/SIGHUP, which ``cosim sweep``
    turns into this).  ``rows`` holds every point's record in grid order: the
    points that ended before the stop with their status, the others with
    status ``interrupted``; the table was written."""

    def __init__(self, rows: list, signal_name: str = "SIGINT"):
        super().__init__(signal_name)
        self.rows, self.signal_name = rows, signal_name


def sweep(scene, *, variants=None, grid=None, scheme: str | None = None, workers: int = 1,
          scheduler=None, out=None, retry_failed: bool = False,
          contact: str | None = None, joint: str | None = None, progress=None, timeout: float | None = None
          ) -> list[dict]:
    """Run a scene over a grid of variants and overrides; one record per point.

    Parameters
    ----------
    scene : path-like
        The scene file.
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
    out : path-like, optional
        The sweep's directory: one run directory per point (named by
        :func:`point_name`) and the table ``sweep.csv``.  A point whose
        directory holds a complete run of the same scene file, variant,
        overrides and scheme that ended ``finished``, ``failed`` or
        ``refused`` is not run again.  Without ``out`` nothing is written and
        nothing is skipped.
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
        If the grid is malformed.
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
    and validated on the calling process; a point whose overrides do not make
    a valid scene is recorded ``refused`` without being sent anywhere.

    Examples
    --------
    >>> rows = sweep("cases/three_mass.toml", variants=["f1", "f100"],
    ...              grid={"t_end": [0.15]}, workers=2, out="runs/f")   # doctest: +SKIP
    >>> [(r["variant"], r["contacts.C.count"]) for r in rows]          # doctest: +SKIP
    [('f1', 1), ('f100', 9)]
    """
    scene_path = Path(scene)
    table = read_toml_file(scene_path)      # a regular file within the limits, or refused
    try:
        scene_hash = _file_hash(scene_path)
    except (OSError, TomlLimitError) as exc:
        raise SceneError(scene_path, "", f"cannot be read: {getattr(exc, 'strerror', None) or exc}"
                         ) from None
    if not variants:                    # name the default variant, so the point says it
        default = table.get("default_variant")
        variants = [default] if isinstance(default, str) else None
    points = grid_points(variants, grid)
    strikes = _strikes(scene_path, [p.variant for p in points], contact, joint)
    out = Path(out) if out is not None else None
    total = len(points)
    rows: dict[int, dict] = {}
    scenes, specs = {}, {}
    seen_warnings: set[str] = set()
    stopped = None

    def report(point, status, message, skipped):
        if progress is not None:
            progress(SweepEvent(point, status, message, skipped, len(rows), total))

    with _Runner(workers, scheduler, timeout) as runner:
        try:
            for p in points:
                spec = _spec(p, scene_path, scheme, scene_hash)
                specs[p.index] = spec
                if out is not None:
                    done = _load_done(out / p.name, spec, retry_failed)
                    if done is not None:
                        meta, summary, series = done
                        rows[p.index] = _record(p, meta, summary, series, *strikes[p.variant])
                        report(p, meta["status"], meta["message"], True)
                        continue
                try:
                    with warnings.catch_warnings(record=True) as caught:
                        warnings.simplefilter("always")
                        sc = load_scene(scene_path, p.variant, p.overrides, scheme)
                except SceneError as exc:
                    _finish(p, spec, out, None, None, "refused", str(exc), rows,
                            *strikes[p.variant])
                    report(p, "refused", str(exc), False)
                    continue
                for w in caught:                # each warning once per sweep, not per point
                    if str(w.message) not in seen_warnings:
                        seen_warnings.add(str(w.message))
                        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
                scenes[p.index] = sc

            if scenes:
                for index, (kind, payload) in runner.run(scenes):
                    p, spec = points[index], specs[index]
                    if kind == "ran":
                        res = payload
                        _finish(p, spec, out, res, scenes[index], res.status, res.message,
                                rows, *strikes[p.variant])
                        report(p, res.status, res.message, False)
                    else:
                        _finish(p, spec, out, None, scenes[index], kind, payload, rows,
                                *strikes[p.variant])
                        report(p, kind, payload, False)
        except KeyboardInterrupt as exc:
            # the runner's exit ends the workers; the table keeps what ended
            stopped = exc
    if stopped is not None:
        name = getattr(stopped, "signal_name", None) or "SIGINT"
        for p in points:
            if p.index not in rows:
                rows[p.index] = _record(p, {**specs.get(p.index, {}), "variant": p.variant,
                                            "status": "interrupted",
                                            "message": f"the sweep was stopped ({name}) "
                                                       f"before this point ended"},
                                        None, None, *strikes[p.variant])
    records = [rows[p.index] for p in points]
    if out is not None:
        write_table(records, out / TABLE)
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


def _finish(point, spec, out, res, scene, status, message, rows, contact, joint):
    """Write a point's run directory (when there is ``out``) and its record."""
    meta = {**spec, "status": status, "message": message}
    summary = res.summary if res is not None else None
    series = res.series if res is not None else None
    if out is not None:
        d = inside(out, point.name)
        if res is not None:
            # the sweep itself chose to (re)run this point: a stale or failed
            # run of it is what gets replaced
            write_outputs(res, d, scene, overwrite=True)
        else:
            for stale in ("summary.json", "series.npz"):
                (d / stale).unlink(missing_ok=True)
            if scene is not None:
                text = resolved_scene_text(scene)
                _atomic_write(d / "scene.toml", lambda fh: fh.write(text), "w")
        _atomic_write(d / "point.json", lambda fh: json.dump(meta, fh, indent=2), "w")
    if status not in ("finished",):
        log.info("point %s: %s: %s", point.name, status, message)
    rows[point.index] = _record(point, meta, summary, series, contact, joint)
