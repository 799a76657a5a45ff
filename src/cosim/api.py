"""``cosim.simulate`` and ``cosim.run_scene``: a run as ``cosim run`` makes it.

The scene layer runs a scene (:func:`cosim.scene.run.simulate`); its error
estimate lives a layer above (:mod:`cosim.studies.estimate`), so the public
functions are here: they run the scene and, as ``cosim run`` does, estimate
the finished run's error into ``result.summary["accuracy"]`` (and
``summary.json``) unless the scene's ``output.estimate`` is false.  The
library's own runs (a companion, a bench point, a sweep point, a check of
``cosim verify``) call the scene layer and pay for no estimate.
"""
from __future__ import annotations

__all__ = ["simulate", "run_scene", "estimated"]


def estimated(scene, res, **options) -> dict:
    """:func:`cosim.studies.estimate.estimate_errors` of ``res``, a finished
    run of ``scene`` (``options`` passed on)."""
    from cosim.studies.estimate import estimate_errors
    return estimate_errors(scene, res, **options)


def simulate(scene, *, scheme: str | None = None, progress=None,
             progress_interval: float = 0.2, out=None, overwrite: bool = False,
             estimate: bool | None = None):
    from cosim.scene import run

    res = run.simulate(scene, scheme=scheme, progress=progress,
                       progress_interval=progress_interval, out=out, overwrite=overwrite)
    if (scene.estimate if estimate is None else estimate) and res.status == "finished":
        if scheme not in (None, scene.scheme):       # the companion runs that scheme too
            from cosim.studies.choose import _load
            scene = _load(scene, [], scheme)
        _add_estimate(scene, res, out)
    return res


def _add_estimate(scene, res, out) -> None:
    """``res.summary["accuracy"]``, and ``summary.json`` in ``out`` written
    again with it (the folder held meanwhile).  Stopped meanwhile (Ctrl-C),
    :class:`~cosim.scene.run.RunInterrupted` with ``res`` as it finished."""
    from cosim.io.strict_json import json_writer

    from cosim.errors import OutputError
    from cosim.io.rundir import OutputFolder
    from cosim.scene.run import RunInterrupted, _lost

    try:
        acc = estimated(scene, res)
    except KeyboardInterrupt as exc:
        raise RunInterrupted(res) from exc
    res.summary["accuracy"] = acc
    if out is None:
        return
    try:
        with OutputFolder(out) as folder:
            folder.write("summary.json", json_writer(res.summary, indent=2), "w")
    except OutputError as exc:
        raise _lost(exc, "the run finished and is kept, with the summary.json it wrote "
                         "without its estimate (`accuracy`)", out) from None


def run_scene(path, *, variant=None, scheme=None, overrides=(), out=None,
              overwrite: bool = False, estimate: bool | None = None):
    """Load and run a scene file in one call (see :func:`simulate`, whose
    ``estimate`` defaults to the scene's ``output.estimate``, as for ``cosim
    run``); ``path`` may name a shipped scene (``"spring_drop"``: a file of
    that name wins)."""
    from cosim.scene.load import load_scene
    from cosim.scene.shipped import find_scene
    return simulate(load_scene(find_scene(path), variant, overrides, scheme), out=out,
                    overwrite=overwrite, estimate=estimate)


def _simulate_doc() -> str:
    """The scene layer's docstring, with ``estimate``."""
    from cosim.scene import run
    doc = run.simulate.__doc__
    head, sep, tail = doc.partition("\n    Returns\n")
    return (head.rstrip() + """
    estimate : bool, optional
        Estimate the finished run's error with a companion run
        (:func:`cosim.studies.estimate.estimate_errors`, about a quarter of
        the run's cost) into ``result.summary["accuracy"]`` (and
        ``summary.json``), as ``cosim run`` does.  Default: the scene's
        ``output.estimate`` (true unless the scene turns it off), as for
        ``cosim run``.  A run that does not finish gets none; stopped by
        Ctrl-C during the estimate, :class:`~cosim.scene.run.RunInterrupted`
        holds the finished run without it.  A scene's ``scheme.accuracy`` is
        acted on by ``cosim run`` only.
""" + sep + tail)


simulate.__doc__ = _simulate_doc()
