"""Where a sweep's points run: this process, a local pool of worker processes
(one point per process at a time, so a point that kills its process or runs
past the time limit is recorded alone), or a Dask cluster (an address, a
``Client``, or a private ``LocalCluster``).  A worker receives a validated
:class:`~cosim.scene.load.Scene` and sends back its
:class:`~cosim.core.result.SimulationResult`, so it needs cosim but neither
the scene file nor the output directory.  Dask is imported only when a
scheduler is asked for; an address is first checked to be a Dask scheduler
with bounded reads of its own (:mod:`cosim.studies.sweep.scheduler`).
"""
from __future__ import annotations

import logging
import os
import signal
import time
import warnings

from cosim.errors import UnsafeStepError
from cosim.scene.load import SceneError
from cosim.sides.fmu_unpack import remove_stale_unpacked
from cosim.studies.sweep.scheduler import (CONNECT_TIMEOUT_S, SweepError, _connect_client,
                                          _probe_scheduler)

__all__ = ["SweepError", "CONNECT_TIMEOUT_S", "default_workers"]

log = logging.getLogger(__name__)


def _simulate(scene):
    """The task a worker runs: one validated scene.  Returns the result, or
    the reason it was refused or raised (never raises, so one point cannot
    stop the others)."""
    from cosim.scene.run import simulate

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")     # the client showed them when it loaded
            return "ran", simulate(scene)
    except (UnsafeStepError, SceneError) as exc:
        return "refused", str(exc)
    except Exception as exc:                     # noqa: BLE001 - recorded, the sweep goes on
        return "error", f"{type(exc).__name__}: {exc}"



def _signal_text(code) -> str:
    """How a process ended, from its exit code."""
    if code is None:
        return "it stopped answering"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def _worker_main(conn) -> None:
    """A pool process: run the scenes it is sent, one at a time, until it is
    sent None or its parent is gone.  Ctrl-C is the parent's to handle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from cosim.scene import run  # noqa: F401 - import the models before the clock of a point starts
    try:
        conn.send("ready")
    except OSError:
        return
    while True:
        try:
            scene = conn.recv()
        except (EOFError, OSError):
            return
        if scene is None:
            return
        try:
            conn.send(_simulate(scene))
        except (BrokenPipeError, OSError):
            return


class _Feed:
    """The points still to run, drawn from their source only as they are
    needed: ``{key: scene}`` or an iterator of ``(key, scene)`` pairs, which
    a sweep makes one point at a time (a grid of a million points is never
    loaded whole).  Offers what a queue of points needs: truth (any left?),
    :meth:`more_than`, :meth:`popleft`, :meth:`appendleft`."""

    def __init__(self, jobs):
        from collections import deque
        self._source = iter(jobs.items() if hasattr(jobs, "items") else jobs)
        self._ahead = deque()

    def _fill(self, n: int) -> int:
        while len(self._ahead) < n:
            try:
                self._ahead.append(next(self._source))
            except StopIteration:
                break
        return len(self._ahead)

    def __bool__(self) -> bool:
        return self._fill(1) > 0

    def more_than(self, n: int) -> bool:
        """Whether more than ``n`` points are left."""
        return self._fill(n + 1) > n

    def popleft(self):
        self._fill(1)
        return self._ahead.popleft()

    def appendleft(self, item) -> None:
        self._ahead.appendleft(item)

    def __iter__(self):
        while self:
            yield self.popleft()


class _Worker:
    """One process of :class:`_ProcessPool` and the point it holds."""

    def __init__(self, ctx):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child,), daemon=True)
        self.proc.start()
        child.close()
        self.key = self.deadline = None
        self.ready = False

    def stop(self, wait: float = 0.0) -> None:
        """End the process: politely when idle (``wait`` > 0), else killed."""
        if self.proc.is_alive() and wait > 0 and self.key is None:
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.proc.join(wait)
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join()
        self.conn.close()


class _ProcessPool:
    """Local worker processes, each holding one point at a time, so that the
    sweep knows which point a process held when it died or ran past the time
    limit: that point alone is recorded (``error`` with how the process
    ended, or ``timeout``), the process is replaced, and the other points run
    on.  Processes are started with ``spawn`` (no state of this process is
    inherited) and ignore Ctrl-C; :meth:`close` kills any still running."""

    def __init__(self, n: int, timeout: float | None):
        import multiprocessing
        self.ctx = multiprocessing.get_context("spawn")
        self.n, self.timeout = max(n, 1), timeout
        self.workers: list[_Worker] = []
        self.failed_starts = 0

    def run(self, jobs: dict):
        from multiprocessing.connection import wait

        todo = _Feed(jobs)
        while todo or any(w.key is not None for w in self.workers):
            idle = sum(w.key is None for w in self.workers)
            while len(self.workers) < self.n and todo.more_than(idle):
                self.workers.append(_Worker(self.ctx))      # started only for work left
                idle += 1
            for w in self.workers:
                if w.ready and w.key is None and todo:
                    key, scene = todo.popleft()
                    try:
                        w.conn.send(scene)
                    except OSError:             # died idle: the point goes to a new one
                        todo.appendleft((key, scene))
                        self._replace(w)
                        continue
                    w.key = key
                    w.deadline = (time.monotonic() + self.timeout
                                  if self.timeout is not None else None)
            starting = [w for w in self.workers if not w.ready]
            busy = [w for w in self.workers if w.key is not None]
            deadlines = [w.deadline for w in busy if w.deadline is not None]
            left = max(min(deadlines) - time.monotonic(), 0.0) if deadlines else None
            ready = wait([w.conn for w in busy + starting]
                         + [w.proc.sentinel for w in busy + starting], left)
            now = time.monotonic()
            for w in starting:
                if w.conn in ready:
                    try:
                        w.ready = w.conn.recv() == "ready"
                    except (EOFError, OSError):
                        ready.append(w.proc.sentinel)
                if w.proc.sentinel in ready and not w.ready:
                    w.proc.join()
                    self.failed_starts += 1
                    if self.failed_starts > 3:
                        raise RuntimeError(f"sweep worker processes die before they can "
                                           f"start ({_signal_text(w.proc.exitcode)})")
                    self._replace(w)
            for w in busy:
                key = w.key
                if w.conn in ready:
                    try:
                        outcome = w.conn.recv()
                    except (EOFError, OSError):
                        # the pipe closed with no result: the process died (a
                        # killed worker's pipe and its sentinel become ready
                        # together, in either order)
                        w.proc.join(1.0)
                        outcome = ("error", f"its worker process died while running it "
                                            f"({_signal_text(w.proc.exitcode)}); the other "
                                            f"points ran on")
                        self._replace(w)
                    else:
                        w.key = w.deadline = None
                    yield key, outcome
                elif w.proc.sentinel in ready:
                    w.proc.join()
                    yield key, ("error", f"its worker process died while running it "
                                         f"({_signal_text(w.proc.exitcode)}); the other "
                                         f"points ran on")
                    self._replace(w)
                elif w.deadline is not None and now >= w.deadline:
                    yield key, ("timeout", f"ran past the time limit of {self.timeout:g} s "
                                           f"(wall clock); its process was stopped")
                    self._replace(w)

    def _replace(self, w: _Worker) -> None:
        """End ``w``; :meth:`run` starts another if points are left."""
        w.key = None
        w.stop()
        self.workers.remove(w)
        remove_stale_unpacked()         # the FMU folders a killed worker could not remove

    def close(self, wait: float = 5.0) -> None:
        workers, self.workers = self.workers, []
        for w in workers:
            w.stop(wait if w.key is None else 0.0)


def _local_security():
    """The TLS set-up of a private local cluster (a certificate made for it
    alone), or ``None`` without the ``cryptography`` package."""
    try:
        from distributed.security import Security
        return Security.temporary()
    except ImportError:
        return None


def _private_cluster(n_workers: int, *, local_directory=None, security=False):
    """A Dask ``LocalCluster`` that other users of this machine cannot use:
    TLS with a certificate made for this cluster alone (mutual: a client or
    a worker must present it), listening on 127.0.0.1; without the
    ``cryptography`` package, the workers are threads of this process
    reached by the in-process transport (no socket at all).

    Parameters
    ----------
    n_workers : int
        Worker processes (threads without ``cryptography``), one thread each.
    local_directory : str or os.PathLike, optional
        Where the scheduler and the workers keep their scratch space (Dask's
        default is ``dask-scratch-space`` in the system's temporary folder,
        which it leaves behind).
    security : distributed.security.Security or None, optional
        From :func:`_local_security`; made here when not given.
    """
    from distributed import LocalCluster

    if security is False:
        security = _local_security()
    where = {} if local_directory is None else {
        "local_directory": str(local_directory),
        "scheduler_kwargs": {"local_directory": str(local_directory)}}
    if security is None:
        log.warning("no `cryptography` package: the local Dask cluster runs its workers "
                    "as threads of this process (no network listener)")
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=False,
                            protocol="inproc://", dashboard_address=None, **where)
    return LocalCluster(n_workers=n_workers, threads_per_worker=1, host="127.0.0.1",
                        protocol="tls://", security=security, dashboard_address=None, **where)


class _Runner:
    """Where the points run: this process, a process pool, or Dask.

    A Dask scheduler given by address is reached when the runner is entered
    (a :class:`SweepError` if it cannot be, or is not a Dask scheduler); a
    ``local`` cluster is started only when there are points to run, with
    its scratch space in a temporary folder that :meth:`__exit__` removes."""

    def __init__(self, workers: int, scheduler, timeout: float | None = None):
        self.workers, self.scheduler, self.timeout = workers, scheduler, timeout
        self._pool = self._client = self._cluster = self._scratch = None
        self._security = False

    def __enter__(self):
        if self.scheduler is not None:
            try:
                from distributed import Client
            except ImportError as exc:
                raise ImportError('a Dask scheduler needs dask.distributed: '
                                  'pip install "cosim[dask]"') from exc
            if self.scheduler == "local":
                self._security = _local_security()          # the cluster: run()
                if self._security is None and self.timeout is not None:
                    raise SweepError(
                        "`--timeout` with `--scheduler local` needs the local cluster's "
                        "workers to be processes, which needs the `cryptography` package "
                        "(pip install \"cosim[dask]\"); without it they are threads, and "
                        "a thread past the time limit cannot be stopped")
            elif isinstance(self.scheduler, str):
                start = time.monotonic()
                _probe_scheduler(self.scheduler, CONNECT_TIMEOUT_S)
                self._client = _connect_client(
                    self.scheduler, max(CONNECT_TIMEOUT_S - (time.monotonic() - start), 0.1))
            else:                                       # a Client or a cluster object
                self._client = (self.scheduler if hasattr(self.scheduler, "submit")
                                else Client(self.scheduler))
        elif self.workers > 1 or self.timeout is not None:
            self._pool = _ProcessPool(self.workers, self.timeout)
        return self

    def __exit__(self, *exc):
        try:
            if self._pool is not None:
                self._pool.close(wait=0.0 if exc[0] is not None else 5.0)
            if self._client is not None and self._client is not self.scheduler:
                self._client.close()
            if self._cluster is not None:
                self._cluster.close()
        finally:
            if self._scratch is not None:
                import shutil
                shutil.rmtree(self._scratch, ignore_errors=True)

    def run(self, jobs):
        """Run ``{key: scene}``, or the ``(key, scene)`` pairs of an iterator
        (drawn only as workers free up); yield ``(key, outcome)`` as each
        completes."""
        if self.scheduler == "local" and self._client is None:
            import tempfile

            from distributed import Client
            self._scratch = tempfile.mkdtemp(prefix="cosim-dask-")
            self._cluster = _private_cluster(max(self.workers, 1), security=self._security,
                                             local_directory=self._scratch)
            self._client = Client(self._cluster)
        if self._client is not None:
            yield from self._run_dask(jobs)
        elif self._pool is not None:
            yield from self._pool.run(jobs)
        else:
            for key, scene in _Feed(jobs):
                yield key, _simulate(scene)

    def _run_dask(self, jobs):
        """On Dask: as many points in flight as the cluster has threads, so
        a point's time limit runs from its submission.  A worker that dies is
        Dask's to handle: it runs the points that worker held elsewhere, and
        a point that kills workers again and again ends in ``KilledWorker``
        for that point alone."""
        from distributed import wait

        client = self._client
        try:
            slots = max(sum(client.nthreads().values()), 1)
        except Exception:                          # noqa: BLE001 - not told: one by one
            slots = 1
        todo = _Feed(jobs)
        live: dict = {}

        def submit():
            while todo and len(live) < slots:
                key, scene = todo.popleft()
                fut = client.submit(_simulate, scene, pure=False)
                live[fut] = (key, None if self.timeout is None
                             else time.monotonic() + self.timeout)

        try:
            submit()
            while live:
                deadlines = [d for _, d in live.values() if d is not None]
                left = max(min(deadlines) - time.monotonic(), 0.0) if deadlines else None
                try:
                    finished, _ = wait(list(live), timeout=left, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    finished = ()
                for fut in finished:
                    key, _ = live.pop(fut)
                    try:
                        outcome = fut.result()
                    except Exception as exc:   # noqa: BLE001 - a lost worker
                        outcome = ("error", f"{type(exc).__name__}: {exc}")
                    yield key, outcome
                now = time.monotonic()
                for fut, (key, deadline) in list(live.items()):
                    if deadline is not None and now >= deadline:
                        del live[fut]
                        restarted = _stop_dask_task(client, fut)
                        yield key, ("timeout", f"ran past the time limit of "
                                               f"{self.timeout:g} s (wall clock); its task "
                                               f"was cancelled"
                                               + (" and its worker restarted" if restarted
                                                  else ""))
                submit()
        finally:
            client.cancel(list(live))


def _stop_dask_task(client, fut) -> bool:
    """Cancel a task past its time limit and restart the worker running it
    (Dask cannot stop a running task; a worker under a nanny restarts).
    Returns whether a worker was restarted."""
    try:
        holders = [w for w, keys in client.processing().items() if fut.key in keys]
    except Exception:                              # noqa: BLE001 - best effort
        holders = []
    client.cancel([fut], force=True)
    if not holders:
        return False
    try:
        client.restart_workers(holders, timeout=30)
    except Exception as exc:                       # noqa: BLE001 - say it, go on
        log.warning("could not restart the Dask worker(s) %s running a point past its "
                    "time limit: %s", holders, exc)
        return False
    return True


def default_workers() -> int:
    """The CPUs this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                      # not on Linux
        return os.cpu_count() or 1
