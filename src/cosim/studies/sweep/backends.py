"""Parameter studies: one scene run over a grid of variants and overrides.

:func:`sweep` runs every combination of a scene's variants and of values of
``--set`` keys, on this process, a local process pool, or a Dask distributed
cluster, and returns one record per point in grid order.  Each point gets a
run directory named from its parameters alone (``summary.json``,
``series.npz``, ``scene.toml`` and ``point.json``), so a sweep that is run
again skips the points already done; the records go to one CSV table.

The points are loaded and validated here, and written here: a worker (a
process of the pool, or a Dask worker on another machine) receives the
validated :class:`~cosim.scene.load.Scene` and sends back its
:class:`~cosim.core.result.SimulationResult`, so workers need cosim but neither the
scene file nor the output directory.

Studies (:func:`load_study`) are TOML files that fix a scene, its points, the
axis of the plot and a title: ``studies/fig8_stiffness.toml`` and
``studies/fig11_chain_mass.toml`` are the paper's figures 8 and 11.

Neither Dask nor matplotlib is imported unless a sweep asks for a scheduler
or a plot.
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import logging
import math
import os
import re
import signal
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim.errors import UnsafeStepError
from cosim.core.result import _atomic_write, resolved_scene_text, write_outputs
from cosim.io.rundir import inside
from cosim.scene.load import SceneError, load_scene, parse_override, read_toml_file
from cosim.io.tomlread import TomlLimitError, read_bytes

__all__ = ["Point", "SweepEvent", "Study", "SweepError", "SweepInterrupted", "sweep", "grid_points", "split_values",
           "parse_grid_option", "impact_regime", "flatten", "write_table", "read_table",
           "plot_sweep", "load_study", "run_study", "TIMING_COLUMNS", "TABLE", "PLOT"]

log = logging.getLogger(__name__)

#: the table and the plot in a sweep's output directory
TABLE, PLOT = "sweep.csv", "sweep.png"

#: columns that measure the machine, not the model: they differ between two
#: runs of the same point
TIMING_COLUMNS = ("cpu_time_s",)

#: a point whose run ended in one of these is done: a sweep run again skips it
DONE = ("finished", "failed", "refused")

#: the columns every row starts with, after the grid's keys
_LEAD = ("variant", "point", "status", "message")

_SAFE = re.compile(r"[^A-Za-z0-9._=+-]")
_NAME_MAX = 120


# ------------------------------------------------------------------ the grid
def split_values(text: str) -> list[str]:
    """Split ``v1,v2,...`` at the commas that lie outside brackets, braces and
    quotes, so that TOML arrays and strings pass whole: ``[1, 2],[3, 4]``
    gives ``["[1, 2]", "[3, 4]"]``.

    Raises
    ------
    ValueError
        If a bracket or a quote is left open, or a value is empty.
    """
    out, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            cur.append(ch)
            if ch == quote:
                quote = None
            continue
        if ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise ValueError(f"`{text}` closes a bracket it never opened")
        elif ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    if quote or depth:
        raise ValueError(f"`{text}` leaves a {'quote' if quote else 'bracket'} open")
    out.append("".join(cur).strip())
    if not all(out):
        raise ValueError(f"`{text}` has an empty value")
    return out


def parse_grid_option(text: str) -> tuple[str, list]:
    """Parse one ``--set key.path=v1,v2,...`` of a sweep into the key and its
    values, each read as a TOML value (else kept as a string), as ``cosim run
    --set`` reads one value.

    Raises
    ------
    SceneError
        If the text is not ``key.path=values``.
    ValueError
        If the values do not split (see :func:`split_values`).
    """
    if "=" not in text:
        raise SceneError("--set", "", f"sweep value {text!r} must read key.path=v1,v2,...")
    key, values = text.split("=", 1)
    parsed = [parse_override(f"{key}={v}")[1] for v in split_values(values)]
    return ".".join(parse_override(f"{key}=0")[0]), parsed


def _text(value) -> str:
    """A grid value as it appears in a point's name: strings bare, numbers as
    Python writes them (round trip), anything else as compact JSON."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value
    if isinstance(value, (int, float)):
        return repr(value)
    return json.dumps(value, separators=(",", ":"), sort_keys=True)


@dataclass(frozen=True)
class Point:
    """One point of a sweep.

    Attributes
    ----------
    index : int
        Its place in grid order (variants outermost, then the grid's keys in
        the order given, the last fastest).
    variant : str or None
        The scene variant (None: the scene's default).
    params : tuple of (str, value)
        The grid's keys and this point's values, in the grid's key order.
    name : str
        Its run directory's name, made from ``variant`` and ``params`` only.
    """

    index: int
    variant: str | None
    params: tuple
    name: str

    @property
    def overrides(self) -> list:
        """The ``--set`` overrides of this point, as (path list, value)."""
        return [(k.split("."), v) for k, v in self.params]


def point_name(variant: str | None, params) -> str:
    """The run directory's name of a point: ``VARIANT,KEY=VALUE,...`` with the
    keys in grid order.  When a character outside ``[A-Za-z0-9._=+-]`` or a
    leading ``.`` had to be replaced (no point is ``..``, ``.`` or hidden), or
    the name is long, a hash of the exact parameters is
    appended, so that two points never share a name."""
    parts = ([variant] if variant is not None else []) + [f"{k}={_text(v)}" for k, v in params]
    clean = [_SAFE.sub("_", part) for part in parts]
    clean = ["_" + c[1:] if c.startswith(".") or not c else c for c in clean]
    safe = ",".join(clean) if parts else "default"
    if clean != parts or len(safe) > _NAME_MAX:
        blob = json.dumps([variant, [[k, v] for k, v in params]], sort_keys=True)
        digest = hashlib.sha256(blob.encode()).hexdigest()[:10]
        safe = f"{safe[:_NAME_MAX]}-{digest}"
    return safe


def grid_points(variants=None, grid=None) -> list[Point]:
    """Every combination of ``variants`` and the values of ``grid``, in grid
    order.

    Parameters
    ----------
    variants : sequence of str, optional
        Scene variants; none: the scene's default variant alone.
    grid : mapping of str to sequence, optional
        ``key.path`` -> values (TOML values: numbers, strings, arrays...).

    Raises
    ------
    ValueError
        If a variant repeats, a key has no values, or two points would be
        the same.
    """
    variants = list(variants) if variants else [None]
    if len(set(variants)) != len(variants):
        raise ValueError(f"`variants` repeats a name: {variants}")
    grid = dict(grid or {})
    for k, vals in grid.items():
        if isinstance(vals, (str, bytes)) or not len(vals):
            raise ValueError(f"grid key `{k}` needs a list of values, got {vals!r}")
    keys = list(grid)
    points = []
    for i, (variant, *values) in enumerate(itertools.product(variants, *grid.values())):
        params = tuple(zip(keys, values))
        points.append(Point(i, variant, params, point_name(variant, params)))
    names = [p.name for p in points]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ValueError(f"two points of the grid are the same: {dup}")
    return points


# -------------------------------------------------------------- the records
def flatten(tree: dict, prefix: str = "") -> dict:
    """Nested dicts to one level, keys joined with dots
    (``contacts.C.count``); lists stay values."""
    out = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def impact_regime(summary: dict, series, contact: str = "C", joint: str = "robot/arm") -> dict:
    """The impact regime of CASES.md section 5, read from a run.

    A striker (the side whose ``joint`` drives the contact point) comes down
    on a structure.  What it does by the end of its *first* contact decides
    the regime, because that is where the mass ratio shows: a heavy structure
    throws the striker back within one contact, a light one is pushed ahead
    of it.

    - ``backward``: one contact, and the striker's rate at the release has
      the opposite sign to its rate at the touch (it turned back);
    - ``backward+``: it turned back within the first contact, as above, but
      the contact closes again: the structure, moving faster, catches it;
    - ``forward``: it is still moving on (rate of the same sign) when the
      first contact releases, so it strikes again: a train of contacts
      before it turns back.

    Parameters
    ----------
    summary : dict
        The run's ``summary.json``: the contact's ``intervals`` and ``count``.
    series : mapping
        The run's series: ``t`` and ``dq/JOINT``.
    contact : str
    joint : str
        ``SUBSYSTEM/JOINT`` of the striker.

    Returns
    -------
    dict
        ``regime`` (one of the three, or ``none`` when the contact never
        closed, ``open-ended`` when its first contact lasts to the end of the
        run), ``rate_at_touch`` and ``rate_at_release`` (the joint's rate at
        the first contact's touch and release) and ``exit_velocity`` (its rate
        at the last release, NaN if that is the end of the run).
    """
    from cosim.studies.metrics import exit_velocity

    c = summary["contacts"][contact]
    iv = c["intervals"]
    out = {"regime": "none", "rate_at_touch": math.nan, "rate_at_release": math.nan,
           "exit_velocity": math.nan}
    if not iv:
        return out
    t, dq = np.asarray(series["t"]), np.asarray(series[f"dq/{joint}"])
    (t_on, t_off), t_last = iv[0], iv[-1][1]
    out["rate_at_touch"] = exit_velocity(t, dq, t_on)
    if t_off >= t[-1]:
        out["regime"] = "open-ended"
        return out
    out["rate_at_release"] = exit_velocity(t, dq, t_off)
    if t_last < t[-1]:
        out["exit_velocity"] = exit_velocity(t, dq, t_last)
    turned = out["rate_at_touch"] * out["rate_at_release"] < 0
    out["regime"] = ("forward" if not turned else "backward" if len(iv) == 1 else "backward+")
    return out


def _record(point: Point, spec: dict, summary: dict | None, series, contact, joint) -> dict:
    """One row: the grid's values (``set.KEY``, apart from the summary's own
    keys such as ``t_end``, the time a run reached), variant, point, status, message, then the
    flattened summary and the impact regime (when the scene has ``contact``
    and the series ``dq/joint``)."""
    row = {f"set.{k}": v for k, v in point.params}
    row.update(variant=spec["variant"], point=point.name, status=spec["status"],
               message=spec["message"])
    if summary is None:
        return row
    summary = json.loads(json.dumps(summary))       # the same values read back from disk
    flat = flatten(summary)
    flat.pop("status", None)
    flat.pop("message", None)
    row.update(flat)
    if (contact in summary.get("contacts", {}) and series is not None
            and f"dq/{joint}" in series and "t" in series):
        row.update({f"impact.{k}": v
                    for k, v in impact_regime(summary, series, contact, joint).items()})
    return row


# ---------------------------------------------------------------- the table
def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple, dict)):
        return json.dumps(v, separators=(",", ":"))
    return str(v)


def columns(rows: list[dict]) -> list[str]:
    """The table's columns: the grid's keys (``set.KEY``), ``variant``, ``point``,
    ``status``, ``message``, then every other key in order of first
    appearance (rows in grid order), so the same rows give the same columns
    whatever order they were computed in."""
    grid = _grid_keys(rows)
    cols = grid + list(_LEAD)
    for r in rows:
        cols.extend(k for k in r if k not in cols)
    return cols


def _grid_keys(rows: list[dict]) -> list[str]:
    """The grid's keys: what every record holds before ``variant``."""
    if not rows:
        return []
    first = list(rows[0])
    return first[:first.index("variant")]


def write_table(rows: list[dict], path) -> Path:
    """Write the records as CSV, one row per point in grid order.  Floats are
    written to round trip, lists as JSON, missing values empty."""
    cols = columns(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in cols])
    path = Path(path)
    _atomic_write(path, lambda fh: fh.write(buf.getvalue()), "w")
    return path


def read_table(path) -> list[dict]:
    """Read a sweep's CSV back: numbers as numbers, JSON lists as lists, empty
    cells (a missing value, or an empty message) as None, everything else as
    text."""
    def value(s: str):
        if s == "":
            return None
        if s[0] in "[{":
            try:
                return json.loads(s)
            except ValueError:
                return s
        for kind in (int, float):
            try:
                return kind(s)
            except ValueError:
                pass
        return {"true": True, "false": False}.get(s, s)

    with open(path, newline="") as fh:
        return [{k: value(v) for k, v in r.items()} for r in csv.DictReader(fh)]


# ---------------------------------------------------------------- the runs
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


def _file_hash(path: Path) -> str:
    return hashlib.sha256(read_bytes(path)).hexdigest()


def _spec(point: Point, scene_path: Path, scheme, scene_hash: str) -> dict:
    return {"scene": scene_path.name, "scene_sha256": scene_hash, "variant": point.variant,
            "set": [[k, v] for k, v in point.params], "scheme": scheme}


def _load_done(run_dir: Path, spec: dict, retry_failed: bool):
    """The record of a point done before, or None when it must run: its
    ``point.json`` names the same scene file (by content), variant, overrides
    and scheme, ended in a status of :data:`DONE`, and, if it ran, its
    ``summary.json`` is complete with the same status."""
    try:
        done = json.loads((run_dir / "point.json").read_text())
    except (OSError, ValueError):
        return None
    if any(done.get(k) != v for k, v in spec.items()):
        return None
    status = done.get("status")
    if status not in DONE or (retry_failed and status != "finished"):
        return None
    if status == "refused":
        return done, None, None
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        with np.load(run_dir / "series.npz") as z:
            series = {k: z[k] for k in z.files}
    except (OSError, ValueError):
        return None
    if summary.get("status") != status:
        return None
    return done, summary, series


class SweepError(ValueError):
    """A sweep that cannot start: a scheduler address that is malformed or
    cannot be reached.  Nothing has run, nothing is written."""


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (or by SIGTERM/SIGHUP, which ``cosim sweep``
    turns into this).  ``rows`` holds every point's record in grid order: the
    points that ended before the stop with their status, the others with
    status ``interrupted``; the table was written."""

    def __init__(self, rows: list, signal_name: str = "SIGINT"):
        super().__init__(signal_name)
        self.rows, self.signal_name = rows, signal_name


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
        import time
        from collections import deque
        from multiprocessing.connection import wait

        todo = deque(jobs.items())
        while todo or any(w.key is not None for w in self.workers):
            idle = sum(w.key is None for w in self.workers)
            while todo and len(self.workers) < self.n and idle < len(todo):
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

    def close(self, wait: float = 5.0) -> None:
        workers, self.workers = self.workers, []
        for w in workers:
            w.stop(wait if w.key is None else 0.0)


#: seconds ``--scheduler ADDRESS`` waits for the scheduler to answer
CONNECT_TIMEOUT_S = 10.0


def _private_cluster(n_workers: int):
    """A Dask ``LocalCluster`` that other users of this machine cannot use:
    TLS with a certificate made for this cluster alone (mutual: a client or
    a worker must present it), listening on 127.0.0.1; without the
    ``cryptography`` package, the workers are threads of this process
    reached by the in-process transport (no socket at all)."""
    from distributed import LocalCluster
    try:
        from distributed.security import Security
        security = Security.temporary()
    except ImportError:
        log.warning("no `cryptography` package: the local Dask cluster runs its workers "
                    "as threads of this process (no network listener)")
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=False,
                            protocol="inproc://", dashboard_address=None)
    return LocalCluster(n_workers=n_workers, threads_per_worker=1, host="127.0.0.1",
                        protocol="tls://", security=security, dashboard_address=None)


class _Runner:
    """Where the points run: this process, a process pool, or Dask.

    A Dask scheduler given by address is reached when the runner is entered
    (a :class:`SweepError` if it cannot be); a ``local`` cluster is started
    only when there are points to run."""

    def __init__(self, workers: int, scheduler, timeout: float | None = None):
        self.workers, self.scheduler, self.timeout = workers, scheduler, timeout
        self._pool = self._client = self._cluster = None

    def __enter__(self):
        if self.scheduler is not None:
            try:
                from distributed import Client
            except ImportError as exc:
                raise ImportError('a Dask scheduler needs dask.distributed: '
                                  'pip install "cosim[dask]"') from exc
            if self.scheduler == "local":
                pass                                    # started by run()
            elif isinstance(self.scheduler, str):
                try:
                    self._client = Client(self.scheduler, timeout=CONNECT_TIMEOUT_S)
                except (ValueError, TypeError) as exc:
                    raise SweepError(f"`--scheduler` must be `local` or a Dask scheduler's "
                                     f"address (tcp://HOST:PORT or tls://HOST:PORT), got "
                                     f"{self.scheduler!r}: {exc}") from None
                except OSError as exc:
                    raise SweepError(f"`--scheduler` {self.scheduler!r} cannot be reached: "
                                     f"{exc}") from None
            else:                                       # a Client or a cluster object
                self._client = (self.scheduler if hasattr(self.scheduler, "submit")
                                else Client(self.scheduler))
        elif self.workers > 1 or self.timeout is not None:
            self._pool = _ProcessPool(self.workers, self.timeout)
        return self

    def __exit__(self, *exc):
        if self._pool is not None:
            self._pool.close(wait=0.0 if exc[0] is not None else 5.0)
        if self._client is not None and self._client is not self.scheduler:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()

    def run(self, jobs):
        """Run ``{key: scene}``; yield ``(key, outcome)`` as each completes."""
        if self.scheduler == "local" and self._client is None:
            from distributed import Client
            self._cluster = _private_cluster(max(self.workers, 1))
            self._client = Client(self._cluster)
        if self._client is not None:
            yield from self._run_dask(jobs)
        elif self._pool is not None:
            yield from self._pool.run(jobs)
        else:
            for key, scene in jobs.items():
                yield key, _simulate(scene)

    def _run_dask(self, jobs):
        """On Dask: as many points in flight as the cluster has threads, so
        a point's time limit runs from its submission.  A worker that dies is
        Dask's to handle: it runs the points that worker held elsewhere, and
        a point that kills workers again and again ends in ``KilledWorker``
        for that point alone."""
        import time
        from collections import deque

        from distributed import wait

        client = self._client
        try:
            slots = max(sum(client.nthreads().values()), 1)
        except Exception:                          # noqa: BLE001 - not told: one by one
            slots = 1
        todo = deque(jobs.items())
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


def sweep(scene, *, variants=None, grid=None, scheme: str | None = None, workers: int = 1,
          scheduler=None, out=None, retry_failed: bool = False, contact: str = "C",
          joint: str = "robot/arm", progress=None, timeout: float | None = None
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
    contact, joint : str
        The contact and the striker's ``SUBSYSTEM/JOINT`` whose impact regime
        (:func:`impact_regime`) is added as ``impact.*`` columns, where the
        scene has them.
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
        If the scene file cannot be read.
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
                        rows[p.index] = _record(p, meta, summary, series, contact, joint)
                        report(p, meta["status"], meta["message"], True)
                        continue
                try:
                    with warnings.catch_warnings(record=True) as caught:
                        warnings.simplefilter("always")
                        sc = load_scene(scene_path, p.variant, p.overrides, scheme)
                except SceneError as exc:
                    _finish(p, spec, out, None, None, "refused", str(exc), rows, contact, joint)
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
                                rows, contact, joint)
                        report(p, res.status, res.message, False)
                    else:
                        _finish(p, spec, out, None, scenes[index], kind, payload, rows,
                                contact, joint)
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
                                        None, None, contact, joint)
    records = [rows[p.index] for p in points]
    if out is not None:
        write_table(records, out / TABLE)
    if stopped is not None:
        raise SweepInterrupted(records, name) from None
    return records


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


# ----------------------------------------------------------------- the plot
_NUMBER = re.compile(r"^(?P<prefix>.*?)(?P<value>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)$")


def _axis(rows: list[dict], x=None):
    """The plot's abscissa: a grid key's numbers (``x`` names the key), else the
    number that ends each variant's name under a shared prefix (``ms0.05`` ->
    0.05), else the points' places in grid order, labelled by name.  Returns
    the values, the axis label, the tick labels (None: a numeric axis) and
    the record key the abscissa comes from (None: the points' places)."""
    keys = _grid_keys(rows)
    if x is None:
        varying = [k for k in keys if len({_text(r[k]) for r in rows}) > 1]
        x = varying[0] if len(varying) == 1 else None
    elif not x.startswith("set."):
        x = f"set.{x}"
    if x is not None and all(isinstance(r.get(x), (int, float)) for r in rows):
        return [float(r[x]) for r in rows], x, None, x
    names = [r["variant"] or "" for r in rows]
    m = [_NUMBER.match(n) for n in names]
    if all(m) and len({g["prefix"] for g in m}) == 1 and len({r["variant"] for r in rows}) > 1:
        return [float(g["value"]) for g in m], f"variant {m[0]['prefix']}…", None, "variant"
    return list(range(len(rows))), "point", [r["point"] for r in rows], None


#: marker and colour of each regime in the plot
_REGIME_STYLE = {"backward": ("o", "tab:blue"), "backward+": ("s", "tab:green"),
                 "forward": ("^", "tab:red"), "none": ("x", "0.5"),
                 "open-ended": ("x", "0.5")}


def plot_sweep(rows: list[dict], path, *, contact: str = "C", x: str | None = None,
               x_scale: float = 1.0, x_label: str | None = None, title: str | None = None
               ) -> Path:
    """Draw a sweep: the contact's count, and its time in touch and span (first
    touch to last release), against the swept parameter; each point marked by
    its impact regime when the table has one.  Needs matplotlib.

    Parameters
    ----------
    rows : list of dict
        Records of :func:`sweep` (or :func:`read_table`).
    path : path-like
        The image to write (its suffix picks the format).
    contact : str
    x : str, optional
        The grid key on the abscissa; by default the only grid key that
        varies, else the number ending the variants' names.
    x_scale : float
        Multiplies the abscissa (a stiffness over c_ref gives f).
    x_label, title : str, optional
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs, label, ticks, x_key = _axis(rows, x)
    xs = [v * x_scale for v in xs] if ticks is None else xs
    if not any(f"contacts.{contact}.count" in r for r in rows):     # another scene's contact
        named = [k.split(".")[1] for r in rows for k in r
                 if k.startswith("contacts.") and k.endswith(".count")]
        contact = named[0] if named else contact
    ok = [i for i, r in enumerate(rows) if r.get(f"contacts.{contact}.count") is not None]
    ratio = [(rows[i].get("impact.rate_at_release"), rows[i].get("impact.rate_at_touch"))
             for i in ok]
    ratio = [a / b if isinstance(a, float) and isinstance(b, float) and b and a == a
             else None for a, b in ratio]
    has_ratio = any(v is not None for v in ratio)
    fig, axes = plt.subplots(3 if has_ratio else 2, 1, sharex=True,
                             figsize=(6.4, 7.6 if has_ratio else 5.6),
                             constrained_layout=True)
    ax1, ax2 = axes[0], axes[1]
    count = [rows[i][f"contacts.{contact}.count"] for i in ok]
    touch = [1e3 * rows[i][f"contacts.{contact}.in_touch_time"] for i in ok]
    span = []
    for i in ok:
        iv = rows[i][f"contacts.{contact}.intervals"]
        span.append(1e3 * (iv[-1][1] - iv[0][0]) if iv else 0.0)
    xo = [xs[i] for i in ok]
    # one line through the points that differ in the abscissa alone
    others = [k for k in ["variant", *_grid_keys(rows)] if k != x_key]
    lines: dict = {}
    for j, i in enumerate(ok):
        lines.setdefault(tuple(_text(rows[i].get(k)) for k in others) if x_key
                         else (), []).append(j)
    for n, js in enumerate(lines.values()):
        def pick(v):
            return [v[j] for j in js]
        ax1.plot(pick(xo), pick(count), color="0.6", lw=1, zorder=1)
        ax2.plot(pick(xo), pick(span), color="0.6", lw=1, ls="--",
                 label="first touch to last release" if n == 0 else None)
        ax2.plot(pick(xo), pick(touch), color="0.3", lw=1,
                 label="in touch (sum of intervals)" if n == 0 else None)
    regimes = [rows[i].get("impact.regime") for i in ok]
    seen = set()
    for xi, ci, ti, reg in zip(xo, count, touch, regimes):
        marker, colour = _REGIME_STYLE.get(reg, ("o", "k"))
        lab = reg if reg and reg not in seen else None
        seen.add(reg)
        ax1.scatter([xi], [ci], marker=marker, color=colour, s=45, zorder=2, label=lab)
        ax2.scatter([xi], [ti], marker=marker, color=colour, s=30, zorder=2)
    if has_ratio:
        ax3 = axes[2]
        for js in lines.values():
            js = [j for j in js if ratio[j] is not None]
            ax3.plot([xo[j] for j in js], [ratio[j] for j in js], color="0.6", lw=1, zorder=1)
        for xi, v, reg in zip(xo, ratio, regimes):
            if v is None:
                continue
            marker, colour = _REGIME_STYLE.get(reg, ("o", "k"))
            ax3.scatter([xi], [v], marker=marker, color=colour, s=30, zorder=2)
        ax3.axhline(0.0, color="k", lw=0.8)
        ax3.set_ylabel("striker's rate at 1st release\n/ its rate at touch", fontsize=8)
        ax3.text(0.99, 0.04, "< 0: turned back within the first contact",
                 transform=ax3.transAxes, ha="right", fontsize=7)
        ax3.grid(alpha=0.3)
    bottom = axes[-1]
    failed = [i for i, r in enumerate(rows) if r.get("status") != "finished"]
    for i in failed:
        ax1.axvline(xs[i], color="tab:red", lw=0.8, ls=":")
    if failed:
        ax1.text(0.01, 0.97, f"{len(failed)} point(s) did not finish (dotted)",
                 transform=ax1.transAxes, va="top", fontsize=8, color="tab:red")
    ax1.set_ylabel(f"contacts of {contact}")
    ax2.set_ylabel(f"time of {contact} [ms]")
    bottom.set_xlabel(x_label or label)
    if any(r is not None for r in regimes):
        ax1.legend(title="impact regime", fontsize=8, title_fontsize=8)
    ax2.legend(fontsize=8)
    if ticks is not None:
        bottom.set_xticks(xs, ticks, rotation=30, ha="right", fontsize=7)
    elif min(xs) > 0 and max(xs) / min(xs) >= 20:
        bottom.set_xscale("log")
    ax1.grid(alpha=0.3)
    ax2.grid(alpha=0.3)
    if title:
        ax1.set_title(title, fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# ---------------------------------------------------------------- studies
@dataclass(frozen=True)
class Study:
    """A ready parameter study: a scene, its points, and how to draw them.

    Read from a TOML file by :func:`load_study`::

        title = "..."
        scene = "../cases/three_mass.toml"     # relative to the study file
        variants = ["ms6.4", "ms3.2"]
        contact = "C"                          # optional, default C
        joint = "robot/arm"                    # optional, default robot/arm
        [set]                                  # optional grid: key -> values
        "contacts.C.law.contact_stiffness" = [1.6e5, 3.2e5]
        [x]                                    # optional plot axis
        key = "contacts.C.law.contact_stiffness"
        scale = 6.25e-6
        label = "f"

    and optionally ``timeout``, the most wall-clock seconds a point may run
    (see :func:`sweep`).
    """

    name: str
    title: str
    scene: Path
    variants: tuple = ()
    grid: dict = field(default_factory=dict)
    contact: str = "C"
    joint: str = "robot/arm"
    x: str | None = None
    x_scale: float = 1.0
    x_label: str | None = None
    timeout: float | None = None


def load_study(path) -> Study:
    """Read a study file (see :class:`Study`).

    Raises
    ------
    SceneError
        Naming the file and the key, if a value is missing or of the wrong
        kind.
    """
    from cosim.scene.load import _Table

    path = Path(path)
    top = _Table(read_toml_file(path), (), path)
    title = top.string("title", path.stem)
    scene = top.string("scene")
    variants = top.raw("variants", [])
    if not isinstance(variants, list) or not all(isinstance(v, str) for v in variants):
        top.error("variants", f"must be a list of names, got {variants!r}")
    grid = top.raw("set", {})
    if not isinstance(grid, dict) or not all(isinstance(v, list) and v for v in grid.values()):
        top.error("set", f"must be a table of key = [values], got {grid!r}")
    contact = top.string("contact", "C")
    joint = top.string("joint", "robot/arm")
    timeout = top.number("timeout", None, rule=">0", unit="s")
    x = top.table("x", {})
    key = x.string("key", None)
    scale = x.number("scale", 1.0)
    label = x.string("label", None)
    x.finish()
    top.finish()
    return Study(name=path.stem, title=title, scene=path.parent / scene,
                 variants=tuple(variants), grid=dict(grid), contact=contact, joint=joint,
                 x=key, x_scale=scale, x_label=label, timeout=timeout)


def run_study(study: Study, *, out, workers: int = 1, scheduler=None, scheme=None,
              retry_failed: bool = False, progress=None, plot: bool = True):
    """Run a study with :func:`sweep` into ``out`` and draw it there.

    Returns
    -------
    rows : list of dict
    plot : Path or None
        ``out/sweep.png``; None when ``plot`` is false.
    """
    rows = sweep(study.scene, variants=study.variants or None, grid=study.grid,
                 scheme=scheme, workers=workers, scheduler=scheduler, out=out,
                 retry_failed=retry_failed, contact=study.contact, joint=study.joint,
                 progress=progress, timeout=study.timeout)
    png = None
    if plot:
        png = plot_sweep(rows, Path(out) / PLOT, contact=study.contact, x=study.x,
                         x_scale=study.x_scale, x_label=study.x_label, title=study.title)
    return rows, png


def default_workers() -> int:
    """The CPUs this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                      # not on Linux
        return os.cpu_count() or 1
