"""`cosim run --accuracy X`: the run's side of :mod:`cosim.studies.accurate`.

:meth:`Request.make` chooses the scheme and steps before the run (the
scene that runs), after refusing what cannot go with a request (a step it
chooses set by ``--set``, the estimate turned off); :meth:`Request.check`,
once the run's error is estimated, refines once where the estimate lies above
``CHECK_MARGIN`` times the accuracy, and adds ``accuracy.request`` to the summary.

The refined run goes into a folder of its own inside the run's
(:data:`REFINING`), the first run's files untouched: only when it finished
with a lower estimate are its files renamed over the first's (each rename
atomic, the set of them with the stop signals held back), and the folder
removed.  Stopped meanwhile (Ctrl-C, SIGTERM, SIGHUP) or failed, the first
run is kept, its summary says so, and the refined folder is removed.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

__all__ = ["Request", "REFINING", "estimate_and_check", "exit_status", "skipped"]

#: the folder, inside the run's, that a refined run is written to before it
#: replaces the first
REFINING = "refining.tmp"


@dataclass
class Request:
    """An accuracy asked of one `cosim run`.

    Attributes
    ----------
    args
        The command's arguments (scene, variant, ``--set``, ``--yes``).
    accuracy : float
    source : str
        ``--accuracy`` or ``scheme.accuracy``.
    scene
        The scene with the chosen scheme and steps.
    choice : cosim.studies.choose.Choice
    run : callable
        ``run(scene, out)``: runs a scene into the folder ``out`` (set by
        the command).
    stopped : BaseException or None
        The signal (a KeyboardInterrupt) that stopped the refinement, if one
        did: the first run was kept.
    """

    args: object
    accuracy: float
    source: str
    scene: object
    choice: object
    run: object = field(default=None, repr=False)
    stopped: object = field(default=None, repr=False)

    @classmethod
    def make(cls, args, scene) -> "Request":
        """The request of ``args`` (``--accuracy``, else the scene's
        ``scheme.accuracy``), its scheme and steps chosen.

        Raises
        ------
        SceneError
            If the model covers no contact of the scene, or no scheme meets
            the accuracy (one below what the scene can reach included), or
            the accuracy goes with what it cannot: ``--no-estimate`` or
            ``output.estimate = false`` (nothing would check it), or a
            ``--set`` of a step it chooses.
        """
        from cosim.scene.checks import SceneError
        from cosim.studies.accurate import asked, conflicts, plan

        accuracy, source = asked(scene, args.accuracy)
        off = ("--no-estimate" if args.no_estimate else
               None if scene.estimate else "`output.estimate = false`")
        why = conflicts(args.set or (), source, off)
        if why is not None:
            raise SceneError(scene.path, "", why)
        scheme = args.scheme if args.scheme else None
        chosen, choice = plan(args.scene, args.variant, args.set or (), accuracy, scheme,
                              first=scene, source=source)
        return cls(args, accuracy, source, chosen, choice)

    @property
    def contact(self) -> str:
        """The contact the accuracy is asked of (the exit rates are read at
        its last release)."""
        return self.choice.knob.contact

    def check(self, res, folder):
        """The run ``res`` (its summary's ``accuracy`` estimated, its files
        in ``folder``, an open :class:`~cosim.io.rundir.OutputFolder`)
        checked, and refined once when the estimate lies above
        :data:`~cosim.studies.accurate.CHECK_MARGIN` times the accuracy asked
        (met stays: the estimate at most that accuracy): the run kept, its
        summary with ``accuracy.request``."""
        from cosim.studies.accurate import (CHECK_MARGIN, limiting_order, refined,
                                            request_record)

        estimated, why = self._verdict(res)
        record = (lambda choice, e, w, first=None, note="":
                  request_record(self.accuracy, self.source, choice, e, w, first, self.scene,
                                 note))
        if estimated is None or estimated <= CHECK_MARGIN * self.accuracy:
            res.summary["accuracy"]["request"] = record(self.choice, estimated, why)
            return res
        args = self.args
        factor = res.summary["accuracy"].get("factor") or 4.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene, choice, refused = refined(
                args.scene, args.variant, args.set or (), self.choice, self.scene, estimated,
                factor, limiting_order(res.summary["accuracy"], self.choice, self.scene))
        if scene is not None:
            work, first = scene.work().steps, self.scene.work().steps
            if work > _limit() * first and not getattr(args, "yes", False):
                scene, refused = None, (f"its steps would take {work:.3g} integrator steps, "
                                        f"{work / first:.3g} times the first run's, more "
                                        f"than {_limit():g} times: pass --yes to run it")
        if scene is None:
            res.summary["accuracy"]["request"] = record(self.choice, estimated, "",
                                                        note=f"not refined: {refused}")
            return res
        # the first run is whole on disk, its estimate with it, before the refined one starts
        res.summary["accuracy"]["request"] = record(
            self.choice, estimated, "", note="refining: this run is kept until a refined run "
                                             "finishes with a lower estimate")
        _write_summary(folder, res.summary)
        again, acc2, note = self._refine(scene, folder)
        if acc2 is None:
            res.summary["accuracy"]["request"] = record(self.choice, estimated, "", note=note)
            return res
        again.summary["accuracy"] = acc2
        self_choice, self_scene = self.choice, self.scene
        self.scene, self.choice = scene, choice
        try:
            estimated2, why2 = self._verdict(again)
        except KeyboardInterrupt as exc:
            self.scene, self.choice = self_scene, self_choice
            _discard(folder)
            res.summary["accuracy"]["request"] = record(self.choice, estimated, "",
                                                        note=self._stop(exc))
            return res
        if estimated2 is None or estimated2 >= estimated:
            self.scene, self.choice = self_scene, self_choice
            _discard(folder)
            shown = (f"not estimated ({why2})" if estimated2 is None else
                     f"estimated at {100 * estimated2:.2g} %, no lower: the steps refined are "
                     f"not what limits its estimate")
            res.summary["accuracy"]["request"] = record(
                self.choice, estimated, "",
                note=f"the refined run, at {choice.step:.3g} s in contact, was {shown}; this "
                     f"run is kept")
            return res
        again.summary["accuracy"]["request"] = record(choice, estimated2, why2,
                                                      (self_choice, estimated))
        stopped = _swap(folder, again.summary)
        if stopped is not None:
            self.stopped = stopped
        from cosim.core.series import SeriesFile
        if isinstance(again.series, SeriesFile):       # read where its file is now
            again.series.path = folder.path / "series.npz"
        return again

    def _refine(self, scene, folder):
        """Run ``scene`` into :data:`REFINING` and estimate it: ``(result,
        accuracy, "")``, or ``(None, None, why the first run is kept)``
        with the refined folder removed."""
        from cosim.api import estimated

        _discard(folder)                     # a refinement killed outright before
        try:
            sub = folder.folder(REFINING)
            sub.close()
            again = self.run(scene, folder.path / REFINING)
            if not again.success:
                _discard(folder)
                return None, None, (f"the refined run did not finish ({again.status}: "
                                    f"{again.message}): this run is kept")
            acc = estimated(scene, again, contact=self.contact)
        except KeyboardInterrupt as exc:
            _discard(folder)
            return None, None, self._stop(exc)
        except Exception as exc:         # noqa: BLE001 - the first run is kept, and says why
            _discard(folder)
            return None, None, (f"the refined run stopped on {type(exc).__name__}: {exc}; "
                                f"this run is kept")
        return again, acc, ""

    def _stop(self, exc) -> str:
        """Note the signal ``exc`` (a KeyboardInterrupt, or the
        :class:`~cosim.scene.run.RunInterrupted` it caused) as what stopped
        the refinement; the note that says so."""
        from cosim.scene.run import RunInterrupted
        self.stopped = exc.__cause__ if isinstance(exc, RunInterrupted) and \
            exc.__cause__ is not None else exc
        name = getattr(self.stopped, "signal_name", None) or "Ctrl-C"
        return f"the refinement was stopped ({name}): this run is kept"

    def _verdict(self, res):
        """:func:`cosim.studies.accurate.verdict` of ``res``; where the
        companion at 4x the step closed a contact another number of times,
        or did not finish (a step that long is unstable), a second one at 2x
        the step (half the run's cost, paid only then) gives the estimate,
        which replaces the summary's ``accuracy``."""
        from cosim.api import estimated as estimate
        from cosim.studies.accurate import verdict

        acc = res.summary["accuracy"]
        estimated, why = verdict(acc, self.choice, self.scene)
        counts = [(c.get("count") or {}).get("robust", True)
                  for c in acc.get("contacts", {}).values()]
        failed = (acc.get("companion") or {}).get("status") not in ("finished", "not run")
        if estimated is None and not self.choice.knob.grasp and (failed or not all(counts)):
            closer = estimate(self.scene, res, factor=2, contact=self.contact)
            estimated, why2 = verdict(closer, self.choice, self.scene)
            if estimated is not None:
                res.summary["accuracy"] = closer
                return estimated, why2
            why = f"{why}; at 2x the step too: {why2}"
        return estimated, why


def estimate_and_check(scene, res, out, request=None):
    """Add the run's error estimate (summary key ``accuracy``) to its
    summary and rewrite ``summary.json`` through the checked writer; a run
    asked for an accuracy (``request``: :class:`cosim.cli.accuracy.Request`)
    is checked and refined once (:mod:`cosim.studies.accurate`) first.  The
    folder is held (locked) from the estimate to the summary.

    Raises
    ------
    OutputError
        If the folder cannot be held or the summary not written (a full
        disk): the message says that the run is kept as it finished, with
        the summary it wrote, without the estimate.
    RunInterrupted
        When Ctrl-C, SIGTERM or SIGHUP stopped a companion run (or the
        check before a refinement): the run is kept as it finished, its
        summary's ``accuracy`` says the estimate was skipped and why
        (:func:`skipped`; a request is ``unchecked``), and the exception's
        ``result`` is the run, its cause the signal.
    """
    from cosim.io.strict_json import json_writer

    from cosim.errors import OutputError
    from cosim.io.rundir import OutputFolder
    from cosim.api import estimated
    from cosim.scene.run import RunInterrupted, _lost

    stop = None
    try:
        with OutputFolder(out) as folder:
            try:
                res.summary["accuracy"] = estimated(scene, res,
                                                    contact=request and request.contact)
                if request is not None:
                    res = request.check(res, folder)
            except KeyboardInterrupt as exc:
                stop = _signal(exc)
                res.summary["accuracy"] = skipped(stop)
                if request is not None:
                    from cosim.studies.accurate import request_record
                    res.summary["accuracy"]["request"] = request_record(
                        request.accuracy, request.source, request.choice, None,
                        res.summary["accuracy"]["skipped"], scene=request.scene)
            folder.write("summary.json", json_writer(res.summary, indent=2),
                         "w")
    except OutputError as exc:
        raise _lost(exc, "the run finished and is kept, with the summary.json it wrote "
                         "without its estimate (`accuracy`)", out) from None
    if stop is not None:
        raise RunInterrupted(res) from stop
    return res


def _signal(exc: BaseException) -> BaseException:
    """The signal's KeyboardInterrupt behind ``exc`` (a run's
    :class:`~cosim.scene.run.RunInterrupted` is caused by it)."""
    from cosim.scene.run import RunInterrupted
    if isinstance(exc, RunInterrupted) and exc.__cause__ is not None:
        return exc.__cause__
    return exc


def skipped(stop: BaseException) -> dict:
    """The summary's ``accuracy`` of a finished run whose estimate the signal
    ``stop`` (a KeyboardInterrupt) cut short: ``skipped`` says so, no
    quantity has an estimate, ``companion.status`` is ``interrupted``."""
    name = getattr(stop, "signal_name", None) or "Ctrl-C"
    why = (f"the estimate was skipped: {name} stopped its companion run; the run finished "
           f"and is kept, without an error estimate")
    return {"reliable": False, "skipped": why, "companions": [], "contacts": {}, "exit": {},
            "companion": {"status": "interrupted", "message": why}, "why": [why]}


def exit_status(summary: dict) -> int:
    """The exit status of a finished run: 3 when the accuracy asked of it
    was not met; 0 else, with a warning when it could not be checked."""
    import sys

    from cosim.studies.accurate import EXIT_NOT_MET, percent
    req = summary.get("accuracy", {}).get("request")
    if req is None:
        return 0
    if req["outcome"] == "not met":
        print(f"error: the accuracy asked ({100 * req['accuracy']:.3g} %, {req['from']}) was "
              f"not met: the run's error is estimated at "
              f"{percent(req['estimated_error'], req['accuracy'])}", file=sys.stderr)
        return EXIT_NOT_MET
    if req["outcome"] == "unchecked":
        print(f"warning: the accuracy asked ({100 * req['accuracy']:.3g} %, {req['from']}) "
              f"was not checked: {req['unchecked']}", file=sys.stderr)
    return 0


def _limit() -> float:
    from cosim.studies.accurate import REFINE_WORK_LIMIT
    return REFINE_WORK_LIMIT


def _write_summary(folder, summary: dict) -> None:
    from cosim.io.strict_json import json_writer
    folder.write("summary.json", json_writer(summary, indent=2), "w")


def _discard(folder) -> None:
    """Remove the refined run's folder and what it holds."""
    from cosim.io.rundir import _remove_tree
    _remove_tree(folder.fd, REFINING)


def _swap(folder, summary: dict):
    """The refined run's files renamed over the first's, its summary first
    written whole in its folder; the stop signals are held back meanwhile,
    so that the folder holds one run or the other.  Returns the signal's
    KeyboardInterrupt when one came meanwhile (it is taken after the swap),
    else None."""
    import os
    import signal
    import stat

    from cosim.io.rundir import LOCK_NAME, output_error

    sub = folder.folder(REFINING)
    try:
        _write_summary(sub, summary)
        held = {signal.SIGINT} | {getattr(signal, n) for n in ("SIGTERM", "SIGHUP")
                                  if hasattr(signal, n)}
        old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
        try:
            # summary.json last: a folder with the refined summary holds the refined run
            for name in sorted(os.listdir(sub.fd), key=lambda n: n == "summary.json"):
                if name == LOCK_NAME or name.startswith("."):
                    continue
                st = os.stat(name, dir_fd=sub.fd, follow_symlinks=False)
                if stat.S_ISREG(st.st_mode):
                    try:
                        os.replace(name, name, src_dir_fd=sub.fd, dst_dir_fd=folder.fd)
                    except OSError as exc:
                        raise output_error(exc, folder.path / name) from None
        finally:
            stopped = None
            try:
                signal.pthread_sigmask(signal.SIG_SETMASK, old)
                stopped = None          # a signal held back is taken here, after the swap
            except KeyboardInterrupt as exc:
                stopped = exc
    finally:
        sub.close()
        _discard(folder)
    return stopped
