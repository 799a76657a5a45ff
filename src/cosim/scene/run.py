"""Running a scene."""
from __future__ import annotations

import contextlib
import gc
import logging
import sys
import time
from pathlib import Path

from cosim.core.guard import Guard, GuardError
from cosim.core.recorder import Recorder
from cosim.scene.load import Scene, load_scene
from cosim.errors import FMUError, OutputError, PluginError, SimulationError, UnsafeStepError

__all__ = ["simulate", "run_scene", "RunInterrupted", "stop_message"]

log = logging.getLogger(__name__)


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a run; its outputs up to then are in :attr:`result`.

    A :class:`KeyboardInterrupt`, so a loop over runs still stops.
    """

    def __init__(self, result):
        super().__init__(result.message)
        self.result = result


def simulate(scene: Scene, *, scheme: str | None = None, progress=None,
             progress_interval: float = 0.2, out=None, overwrite: bool = False):
    """Run a validated scene and return its :class:`~cosim.core.result.SimulationResult`.

    Parameters
    ----------
    scene : Scene
    scheme : str, optional
        Another coupling scheme than the scene's.
    progress : callable, optional
        Called with a :class:`~cosim.core.recorder.Progress` (simulated time,
        end time, contact intervals begun, wall time) as the run goes, at most
        once per ``progress_interval`` seconds of wall-clock time.
    progress_interval : float
        [s]
    out : path-like, optional
        Run directory.  ``scene.toml`` is written there before the run, the
        series are streamed to disk as the run goes (memory does not grow
        with its length), and ``series.npz`` and ``summary.json`` are written
        when it ends, however it ends.  The result's ``series`` then read
        ``out/series.npz``; the structures the scene lists in
        ``output.export`` are written there as ``NAME.xdmf`` too.  The run
        holds a lock on ``out`` meanwhile.  Without ``out`` nothing is
        written and the series stay in memory (:func:`cosim.write_outputs`
        writes them).
    overwrite : bool
        Allow ``out`` to hold a previous run, which is replaced.

    Returns
    -------
    SimulationResult
        ``status`` is ``finished``, or ``failed`` when the run could not go
        on (:class:`SimulationError`: the series end where it stopped and
        ``message`` says why; for an FMU's failure, :class:`~cosim.FMUError`, the
        summary's ``fmu_failure`` names the subsystem, the FMU, the FMI
        function, how it failed and the time).  ``cpu_time_s`` counts the
        CPU time of the FMUs' host processes too.

    Raises
    ------
    ValueError
        If ``COSIM_KERNEL`` or ``COSIM_DRIVER`` holds a value they do not
        take; nothing has run or been written then.
    UnsafeStepError
        If an explicit scheme's macro step is too large for a contact (the
        pre-flight check); nothing has run then.
    OutputExistsError
        If ``out`` holds a run and ``overwrite`` is false, or a
        ``scene.toml`` that no run wrote (see
        :func:`~cosim.core.result.check_output_dir`); checked first.
    OutputBusyError
        If another run is writing into ``out`` (it holds the folder's lock,
        see :class:`~cosim.io.rundir.RunLock`); nothing is touched then.
    OutputError
        If ``out`` cannot be made or written (a read-only place, a file in
        the path, a full disk); the message names the path and what the run
        could not keep.  No file is left half-written.
    RunInterrupted
        On Ctrl-C (a :class:`KeyboardInterrupt`; also SIGTERM and SIGHUP
        under ``cosim run``, whose handlers raise one), after the result up
        to that point, ``status`` ``interrupted``, is complete (and written
        to ``out``); it is the exception's ``result``.
    Exception
        Any other exception during the run is re-raised after the result up
        to that point, ``status`` ``error``, is complete (and written to
        ``out``); it is the exception's ``partial_result``.
    """
    from cosim.io.rundir import OutputFolder

    folder = None
    if out is not None:
        out = Path(out)
        # refuses a link, a root, or a folder another run is writing
        folder = OutputFolder(out).open()
    try:
        return _simulate(scene, scheme, progress, progress_interval, out, overwrite)
    finally:
        if folder is not None:
            folder.close()
            if folder.created and out.is_dir() and not any(out.iterdir()):
                out.rmdir()                # a refused run leaves no folder it made


def _simulate(scene, scheme, progress, progress_interval, out, overwrite):
    from cosim.core.result import check_output_dir, write_scene, write_summary
    from cosim.io.rundir import inside
    from cosim.scene.plausible import gap_warnings, scene_size, structure_warnings
    from cosim.scene.work import warn_work

    from cosim.core.schemes.driver import driver_choice
    from cosim.sides.kernel import kernel_choice
    kernel_choice()                     # a bad COSIM_KERNEL or COSIM_DRIVER: refused
    driver_choice()                     # here, before anything is written or runs
    if out is not None:
        check_output_dir(out, overwrite, scene.export)
    system, sch = scene.build(scheme)
    warn_work(scene.path, scene.work(scheme, system))      # a long run says so first
    # what looks like a unit slip (cosim.scene.plausible): judged on the system as built,
    # said in the summary's warnings, never a refusal
    plausible = structure_warnings(scene, system)
    size = scene_size(system)
    if out is not None:
        sch.preflight(system, scene.t_end)     # a refusal writes nothing
    if _is_monolithic(sch):
        auto = False                       # it locates every switch itself
    else:                                  # embedded contacts: their integrator does
        auto = [c not in system.embedded for c in range(system.n_contacts)]
    rec = Recorder(system, scene.name, sch.name, scene.t_end, every=scene.output_every,
                   auto_edges=auto, progress=progress, progress_interval=progress_interval,
                   series_path=None if out is None else inside(out, "series.npz"),
                   guard=Guard(system, scene.guard))
    # what the run does once at its start (kernels built, its loop's modules
    # loaded, the recorder's rows and spool), before the clock: a process's
    # first run counts none of it; a kernel built wrong writes nothing
    sch.prepare(system, scene.t_end, rec)
    if out is not None:
        write_scene(scene, out)
    rec.prepare()                          # its rows laid out, its spool opened
    cpu0 = time.process_time() - _host_cpu(system)
    status, message = "finished", ""
    counters = {}
    stop = failure = None
    try:
        with _setup_out_of_collection():
            counters = sch.run(system, scene.t_end, rec)
    except UnsafeStepError:                # refused before the first step
        _discard(rec, out)
        raise
    except OutputError as exc:             # the spool: a full disk during the run
        _discard(rec, None)
        raise _lost(exc, f"the run stopped at t = {_reached(rec):.6g} s and wrote no "
                         f"series or summary", out) from None
    except SimulationError as exc:
        status, message = "failed", stop_message(exc, _reached(rec))
        failure = exc.details() if isinstance(exc, FMUError) else None
    except KeyboardInterrupt as exc:
        stop = exc
        cause = getattr(exc, "signal_name", None) or "Ctrl-C"
        status, message = "interrupted", f"interrupted ({cause}) at t = {_reached(rec):.6g} s"
    except (Exception, SystemExit) as exc:   # a bug or a model's error: keep what was done
        from cosim.core.plugin_guard import blame
        stop = blame(exc)          # an installed plug-in's, sys.exit() too: it failed, not cosim
        if stop is None and isinstance(exc, SystemExit):
            raise
        if stop is not None:
            status, message = "failed", f"run stopped at t = {_reached(rec):.6g} s: {stop}"
        else:
            stop = exc
            status = "error"
            message = (f"stopped by {type(exc).__name__} at t = {_reached(rec):.6g} s: {exc}")
    if status == "finished" and not _reached(rec) >= scene.t_end * (1.0 - 1e-9):
        # a scheme that returns short of t_end has not finished, whatever it says
        status = "error"
        message = (f"scheme `{sch.name}` returned at t = {_reached(rec):.6g} s, short of "
                   f"t_end = {scene.t_end:.6g} s: a bug of cosim, not of the scene")
        from cosim.core.plugin_guard import origin_of
        if origin_of(sch) is not None:
            stop = PluginError(f"the plug-in {origin_of(sch)}: its run() returned at t = "
                               f"{_reached(rec):.6g} s, short of t_end = {scene.t_end:.6g} s")
            status, message = "failed", f"run stopped at t = {_reached(rec):.6g} s: {stop}"
        else:
            log.error("%s", message)
    if status != "finished":            # the counters up to where the run stopped
        counters = sch.counters()
    if status != "finished":             # the result says it; a caller decides to show it
        log.info("%s", message)
    ended = f"the run ended ({status} at t = {_reached(rec):.6g} s)"
    try:
        res = rec.finish(status, message, time.process_time() + _host_cpu(system) - cpu0,
                         counters)
    except OutputError as exc:
        raise _lost(exc, f"{ended} but wrote no series or summary", out) from None
    if failure is not None:
        res.summary["fmu_failure"] = failure     # which FMU call failed, and when
    if status == "finished":
        plausible += gap_warnings(res.summary, res.series, size)
    res.summary["warnings"] = plausible + res.summary.get("warnings", [])
    if out is not None:
        try:
            write_summary(res.summary, inside(out, "summary.json"))
        except OutputError as exc:
            inside(out, "series.npz").unlink(missing_ok=True)   # never one without the other
            raise _lost(exc, f"{ended} but wrote no summary, so its series.npz is removed "
                             f"too", out) from None
        if scene.export:
            from cosim.io.export import export_structures
            try:
                export_structures(scene, res, out, system)
            except OutputError as exc:
                raise _lost(exc, f"{ended}; its series and summary are written, not all of "
                                 f"its exports", out) from None
    if isinstance(stop, KeyboardInterrupt):
        raise RunInterrupted(res) from stop
    if stop is not None:
        stop.partial_result = res
        raise stop
    return res


def stop_message(exc: SimulationError, t_stop: float) -> str:
    """The message of a run that ``exc`` stopped, its last kept sample at
    ``t_stop`` [s].

    It opens with ``run stopped at t = T s``, ``T`` being ``t_stop``: the
    summary's ``t_end`` and the series' last time, so the three agree.  A
    guard trips on a sample it then refuses (or at a switch inside the step
    before it), after ``t_stop``: the message says that time too.  Another
    error's own text follows (it names the time of its cause).
    """
    head = f"run stopped at t = {t_stop:.6g} s"
    if isinstance(exc, GuardError):
        if f"{exc.t:.6g}" != f"{t_stop:.6g}":
            head += f" (the last sample kept; the guard tripped at t = {exc.t:.6g} s)"
        return f"{head}: {exc.reason}"
    return f"{head}: {exc}"


def _is_monolithic(sch) -> bool:
    """``isinstance(sch, Monolithic)`` without importing the monolithic scheme
    for a run that does not use it (an instance means its module is loaded)."""
    module = sys.modules.get("cosim.core.schemes.monolithic")
    return module is not None and isinstance(sch, module.Monolithic)


def _lost(exc: OutputError, what: str, out) -> OutputError:
    """``exc`` with what the run could not keep."""
    err = OutputError(f"{exc}; {what}" + (f" (in {out})" if out is not None else ""))
    err.errno, err.path = exc.errno, getattr(exc, "path", None)
    return err


def _discard(rec: Recorder, out) -> None:
    """Remove what a refused run wrote: the spool and ``scene.toml`` (the
    folder, if the run made it, goes with the lock in :func:`simulate`)."""
    rec.discard()
    if out is None:
        return
    (out / "scene.toml").unlink(missing_ok=True)


@contextlib.contextmanager
def _setup_out_of_collection():
    """The objects that exist when the solve starts (the scene, the system
    built, the kernels, every module: all of the run's set-up) kept out of
    the cyclic garbage collector's passes during it (:func:`gc.freeze`), and
    handed back to its oldest generation after (:func:`gc.unfreeze`).

    Set-up leaves tens of thousands of objects in the collector's young
    generations; a collection of them that falls inside the solve costs
    about a millisecond, several tenths of a short run's solve, and would
    only promote them to the oldest generation, where :func:`gc.unfreeze`
    puts them anyway.  Objects the solve makes are collected as ever.  A
    process that froze objects itself (or turned the collector off) is
    left as it is: nothing is frozen, so nothing of its own is unfrozen.
    """
    if gc.get_freeze_count() or not gc.isenabled():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _host_cpu(system) -> float:
    """CPU time [s] that the subsystems' own processes (an FMU's host) have spent."""
    return sum(sub.host_cpu_time for sub in system.subsystems)


def _reached(rec: Recorder) -> float:
    """Simulated time of the last sample."""
    return rec.reached


def run_scene(path, *, variant=None, scheme=None, overrides=(), out=None,
              overwrite: bool = False):
    """Load and run a scene file in one call (see :func:`simulate`); ``path``
    may name a shipped scene (``"spring_drop"``: a file of that name wins)."""
    from cosim.scene.shipped import find_scene
    return simulate(load_scene(find_scene(path), variant, overrides, scheme), out=out,
                    overwrite=overwrite)
