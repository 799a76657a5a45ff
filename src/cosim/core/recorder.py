"""Recording a run: time series, contact statistics and the energy ledger.

Contact statistics are kept online at every sample, so the series may be
decimated without losing them.  Between two samples the penetration is the
cubic Hermite interpolant of its values and rates; the onset and release of
a contact the scheme exchanges (where the law's switch function changes
sign) and its peak penetration are located on it.  A contact evaluated
inside a subsystem's integrator has its switches and its peaks located
there (:meth:`cosim.core.system.CoupledSystem.take_peaks`); the series
``peak/CONTACT`` holds each contact's largest penetration since the
previous stored sample.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Callable

import numpy as np

from cosim.core.hermite import hermite_cubic_max
from cosim.core.progress import Progress
from cosim.core.result import SimulationResult, intervals_until
from cosim.core.series import SeriesFile, SeriesStore, chunk_rows, stop_signals_held

__all__ = ["Recorder", "Progress", "hermite_cubic_max", "intervals_until"]


class Recorder:
    """Collects samples of a run and builds its result.

    Parameters
    ----------
    system : CoupledSystem
    scene, scheme : str
        Names for the summary.
    t_end : float
    every : int
        Keep every ``every``-th sample in the series (statistics use all).
    auto_edges : bool or (n_contacts,) array of bool
        Locate contact onset/release between samples, for all contacts or
        those marked; a scheme (or an integrator) that locates them itself
        reports them with :meth:`edge`.
    progress : callable, optional
        Called with a :class:`Progress` from :meth:`record`, at most once per
        ``progress_interval`` of wall-clock time (and at the first sample).
        It must not raise; the library itself never prints.
    progress_interval : float
        Least wall-clock time between two progress calls [s].
    series_path : path-like, optional
        Stream the series to disk and write them there (``series.npz``) when
        the run finishes; the result then reads them from that file.  Without
        it, the series stay in memory.
    guard : cosim.core.guard.Guard, optional
        Checks every sample before it is kept and stops the run (raises)
        on non-finite values or energy growth beyond its bound.

    Notes
    -----
    With ``progress`` unset, recording pays nothing for it; set, one clock
    read per sample.

    Samples fill a preallocated chunk of rows (about 1 MB); a full chunk is
    turned into the series' columns and handed to a
    :class:`~cosim.core.series.SeriesStore`, which keeps it in memory or appends
    it to a spool file beside ``series_path``.  With a ``series_path``, the
    memory a run needs therefore does not grow with its length (contact
    intervals and impacts aside).
    """

    #: whether this recorder reads the system's live state when it takes a
    #: sample or an edge (a subclass's hook): the compiled loop then hands it
    #: each step as it is taken, not in blocks (:mod:`cosim.core.schemes.driven_block`)
    reads_live_system = False

    def __init__(self, system, scene: str, scheme: str, t_end: float, every: int = 1,
                 auto_edges: bool = True, *, progress: Callable[[Progress], None] | None = None,
                 progress_interval: float = 0.2, series_path=None, guard=None):
        self.system, self.scene, self.scheme, self.t_end = system, scene, scheme, t_end
        self.guard = guard           # a cosim.core.guard.Guard, checking every sample
        nc = system.n_contacts
        self.every = max(1, int(every))
        self.auto_edges = np.broadcast_to(np.asarray(auto_edges, dtype=bool), (nc,))
        self._laws = [ln.contact.law for ln in system.links]
        self._series_path = None if series_path is None else Path(series_path)
        self._store_ = None          # SeriesStore, made at the first sample
        self._buf = None             # (rows, width) chunk being filled
        self._n_buf = 0
        self._last_t = None          # time of the last stored sample
        self._x_prev = None          # subsystem states at the last sample
        self._count = 0
        self._prev = None            # (t, d, dd, active)
        self.peak = np.zeros(nc)
        #: per contact, the largest penetration since the last stored sample
        #: (the series ``peak/CONTACT``: a contact shorter than the sampling
        #: interval still shows there)
        self._since = np.zeros(nc)
        #: contacts whose peaks between samples their host's integrator (or
        #: the monolithic solver's peak events) locates: a cubic through the
        #: samples would only guess at them, and may overshoot
        self._located = np.array([c in system.embedded for c in range(nc)], dtype=bool)
        self.intervals = [[] for _ in range(nc)]
        self._open = [None] * nc
        self.e0 = None
        #: rigid impacts, in time order (dicts, see MultibodySubsystem.rigid_impact)
        self.impacts: list[dict] = []
        self.supplied = 0.0
        self.max_drift = 0.0
        self.max_created = 0.0        # [J] the largest energy created at any sample
        self.last = None
        self._d0 = None
        self._stored0 = None         # contacts' stored energy at the start, in their modes then
        self._n_log = 0              # switches of connections already turned into edges
        self._progress = progress
        self._progress_interval = float(progress_interval)
        self._wall0 = time.monotonic()
        self._next_progress = -math.inf

    @property
    def reached(self) -> float:
        """Simulated time of the last sample recorded [s] (0 before the first)."""
        return self._prev[0] if self._prev is not None else 0.0

    @property
    def n_offered(self) -> int:
        """Samples offered so far (recorded or not: every ``every``-th is
        stored)."""
        return self._count

    def edge(self, c: int, t: float, on: bool) -> None:
        """Report an exactly located contact onset (``on``) or release.

        Raises
        ------
        GuardError
            From the guard, when the contact chatters."""
        if on and self._open[c] is None:
            self._open[c] = t
        elif not on and self._open[c] is not None:
            self.intervals[c].append([self._open[c], t])
            self._open[c] = None
        else:
            return
        if self.guard is not None:
            self.guard.switched(c, t)

    def record(self, t: float, d: np.ndarray, dd: np.ndarray, f: np.ndarray,
               impulse: np.ndarray, dissipated: np.ndarray, internal=(0.0, 0.0),
               work: np.ndarray | None = None) -> None:
        """Add a sample; subsystem states are read from the system.

        ``dissipated`` is per contact; ``internal`` is the energy dissipated
        inside the subsystems and supplied to them by drives, in total;
        ``work`` is per contact, the work its forces did on the subsystems so
        far (as the scheme applied them)."""
        self._record(t, d, dd, f, impulse, dissipated, internal, work,
                     self.system.energy(d), None, None)

    def _record(self, t, d, dd, f, impulse, dissipated, internal, work, energy, x, taken):
        """:meth:`record` given the energy [J], the stacked states ``x`` and the
        embedded peaks ``taken`` (None: the system's own, and its ``take_peaks``)."""
        cs = self.system.connections
        if cs is not None:           # energy set free by connection switches
            dissipated = dissipated + cs.lost
        diss_total = float(np.sum(dissipated)) + internal[0]
        if self.e0 is None:
            self.e0 = energy
        drift = energy + diss_total - internal[1] - self.e0
        if self.guard is not None:   # raises before the sample is kept
            self.guard.check(t, d, dd, f, drift, internal[1], dissipated, work, self.peak)
        active = self.system.in_touch(f)
        nc = self.system.n_contacts
        switched, released = [], set()
        if cs is not None:
            switched = cs.log[self._n_log:]
            self._n_log = len(cs.log)
            released = {self.system.contact_names.index(e["contact"]) for e in switched
                        if e["to"] == "released"}
        prev = self._prev
        since = self._since.copy()   # kept only with the sample (an edge may raise)
        if prev is not None:
            tp, dp, ddp, ap = prev
            h = t - tp
            for c in range(nc):
                if h > 0 and (ap[c] or active[c]) and ddp[c] > 0 >= dd[c] \
                        and not self._located[c]:
                    since[c] = max(since[c], hermite_cubic_max(dp[c], ddp[c], d[c], dd[c],
                                                               h)[0])
                if self.auto_edges[c] and ap[c] != active[c] and c not in released:
                    self.edge(c, self._crossing(c, tp, dp[c], ddp[c], t, d[c], dd[c], ap[c]),
                              bool(active[c]))
        for e in switched:           # a grasp holds from its switch; a release frees
            c = self.system.contact_names.index(e["contact"])
            self.edge(c, e["time"], e["to"] == "grasped" or e["closed"])
        if nc:
            np.maximum(since, np.where(active, d[:nc], 0.0), out=since)
            # embedded contacts: the peaks their hosts' integrators located
            # inside the steps since the last sample
            np.maximum(since, self.system.take_peaks() if taken is None else taken, out=since)
            np.maximum(self.peak, since, out=self.peak)
        self._since = since
        # the ledger's extremes count kept samples only (an edge above may
        # still stop the run, and this sample is then not kept)
        self.supplied = internal[1]
        self.max_drift = max(self.max_drift, abs(drift))
        if drift > self.max_created:
            self.max_created = drift
        if prev is None:
            for c in np.flatnonzero(active):
                self.edge(int(c), t, True)
        self._prev = (t, d.copy(), dd.copy(), active)
        self.last = (t, impulse.copy(), np.array(dissipated, float), energy, diss_total,
                     None if work is None else np.array(work, float), d.copy())
        if self._d0 is None:
            self._d0 = d.copy()
            # evaluated now: a connection's potential depends on its mode, and
            # the mode at the end (grasped, released) need not be the start's
            self._stored0 = self.system.contact_potentials(d)
        self._x_prev = np.concatenate([s.x for s in self.system.subsystems]) if x is None else x
        if self._count % self.every == 0:
            self._store(t, self._x_prev, d, f, energy, diss_total)
        self._count += 1
        if self._progress is not None:
            now = time.monotonic()
            if now >= self._next_progress:
                self._next_progress = now + self._progress_interval
                begun = sum(map(len, self.intervals)) + sum(o is not None for o in self._open)
                self._progress(Progress(float(t), float(self.t_end), int(begun),
                                        now - self._wall0))

    def record_block(self, t, d, dd, f, impulse, dissipated, internal, work=None, *, x,
                     energy=None, peaks=None, edges=None) -> None:
        """Add samples as arrays (:func:`cosim.core.recorder_block.record_block`)."""
        from cosim.core.recorder_block import record_block     # where a side samples
        record_block(self, t, d, dd, f, impulse, dissipated, internal, work, x, energy, peaks,
                     edges)

    def _store(self, t, x, d, f, energy, diss_total):
        sysm = self.system
        if self._buf is None:
            self._layout(len(x), len(d))
        if self._n_buf == len(self._buf):   # full: a stop came between its last row and its flush
            self._flush()
        row = self._buf[self._n_buf]
        row[0] = t
        L = self._slices
        row[L["x"]] = x
        row[L["d"]] = d
        row[L["f"]] = f
        row[L["e"]] = energy
        row[L["diss"]] = diss_total
        if sysm.connections is not None:
            row[L["mode"]] = sysm.connections.mode
        row[L["pk"]] = self._since
        self._since[:] = 0.0
        self._last_t = t
        self._n_buf += 1            # the row counts only once it is whole
        if self._n_buf == len(self._buf):
            self._flush()

    def prepare(self) -> None:
        """Lay out the rows and open the spool, as the first sample would:
        set-up that a run calls before its solve's clock starts
        (:func:`cosim.scene.run.simulate`), so that its ``cpu_time_s`` counts
        no file created."""
        if self._buf is None:
            sysm = self.system
            self._layout(sum(len(sub.x) for sub in sysm.subsystems),
                         getattr(sysm, "n_rows", sysm.n_contacts))

    def _layout(self, nx: int, nd: int) -> None:
        """Row layout of the chunk buffer and the series' names, fixed at the
        first sample."""
        sysm = self.system
        nm = len(sysm.connections.mode) if sysm.connections is not None else 0
        edges = np.cumsum([1, nx, nd, nd, 1, 1, nm, sysm.n_contacts])
        self._slices = {"x": slice(edges[0], edges[1]), "d": slice(edges[1], edges[2]),
                        "f": slice(edges[2], edges[3]), "e": edges[3], "diss": edges[4],
                        "mode": slice(edges[5], edges[6]), "pk": slice(edges[6], edges[7])}
        width = int(edges[7])
        names, dtypes = ["t"], [np.float64]
        for name in sysm.contact_names:
            names += [f"gap/{name}", f"force/{name}"]
        for r in range(sysm.n_contacts, getattr(sysm, "n_rows", sysm.n_contacts)):
            names += [f"gap/{sysm.row_names[r]}", f"force/{sysm.row_names[r]}"]
        dtypes += [np.float64] * (len(names) - 1)
        if sysm.connections is not None:
            for c in sysm.connections.index:
                if sysm.links[c].connection.grasp is not None:
                    names.append(f"mode/{sysm.contact_names[c]}")
                    dtypes.append(np.int64)
        for sub in sysm.subsystems:
            if "modes" in sub.capabilities:
                dof_names = sub.named_values(sub.x)[0]
            else:
                dof_names = list(sub.coordinates())
            for dn in dof_names:
                names += [f"q/{sub.name}/{dn}", f"dq/{sub.name}/{dn}"]
                dtypes += [np.float64, np.float64]
        names += ["energy/total", "energy/dissipated"]
        dtypes += [np.float64, np.float64]
        names += [f"peak/{name}" for name in sysm.contact_names]
        dtypes += [np.float64] * sysm.n_contacts
        spool = None
        if self._series_path is not None:
            spool = self._series_path.with_name(f".{self._series_path.name}.spool")
        self._store_ = SeriesStore(names, dtypes, spool)
        self._buf = np.empty((chunk_rows(width), width))

    def _columns(self, B: np.ndarray) -> np.ndarray:
        """The series' columns (in the order of their names) of rows ``B``."""
        sysm = self.system
        L = self._slices
        X, D, F = B[:, L["x"]], B[:, L["d"]], B[:, L["f"]]
        cols = [B[:, 0]]
        for c in range(sysm.n_contacts):
            cols += [-D[:, c], F[:, c]]
        for r in range(sysm.n_contacts, getattr(sysm, "n_rows", sysm.n_contacts)):
            # tangential rows: coordinate of a - b along t from the grasp anchor, force on a
            cols += [D[:, r], F[:, r]]
        if sysm.connections is not None:
            modes = B[:, L["mode"]]
            for c in sysm.connections.index:
                if sysm.links[c].connection.grasp is not None:
                    cols.append(modes[:, c])
        offsets = sysm.stacked()
        for s, sub in enumerate(sysm.subsystems):
            if "modes" in sub.capabilities:      # a structure: physical DOFs of its modes
                _, U, V = sub.named_values(X[:, offsets[s]:offsets[s + 1]])
                for i in range(U.shape[1]):
                    cols += [U[:, i], V[:, i]]
                continue
            for iq, idq in sub.coordinates().values():
                cols += [X[:, offsets[s] + iq], X[:, offsets[s] + idq]]
        cols += [B[:, L["e"]], B[:, L["diss"]]]
        P = B[:, L["pk"]]
        cols += [P[:, c] for c in range(sysm.n_contacts)]
        return np.array(cols).reshape(len(cols), len(B))

    def _flush(self) -> None:
        if self._n_buf:
            block = self._columns(self._buf[:self._n_buf])
            with stop_signals_held():    # a Ctrl-C between the two would store the rows twice
                self._store_.append(block)
                self._n_buf = 0

    def _crossing(self, c, t0, d0, v0, t1, d1, v1, was_active):
        # Python floats: the same IEEE arithmetic as numpy's scalars, faster
        t0, d0, v0, t1, d1, v1 = map(float, (t0, d0, v0, t1, d1, v1))
        switch, h = self._laws[c].switch, t1 - t0
        # cosim.core.hermite.hermite_point's formulas, its coefficients formed once
        dx = d1 - d0
        c1, c2, c3 = h * v0, 3 * dx - h * (2 * v0 + v1), -2 * dx + h * (v0 + v1)
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            p = d0 + mid * (c1 + mid * (c2 + mid * c3))
            dp = (c1 + mid * (2 * c2 + 3 * mid * c3)) / h
            if (float(switch(p, dp)) > 0) == was_active:
                lo = mid
            else:
                hi = mid
        return t0 + 0.5 * (lo + hi) * h

    def discard(self) -> None:
        """Close and delete the spool of a run whose series will not be
        written (a full disk, a refused run); the recorder keeps no file open."""
        if self._store_ is not None:
            self._store_.close()

    # ----------------------------------------------------------------- result
    def finish(self, status: str, message: str, cpu_time: float, counters: dict) -> SimulationResult:
        """The run's result, its series completed up to the last sample.

        With a ``series_path``, ``series.npz`` is written there (atomically)
        and the spool deleted; the result's ``series`` then read that file.
        ``status`` other than ``"finished"`` takes the final state from the
        last sample (a run stopped mid-step leaves its subsystems part-way).
        """
        sysm = self.system
        try:
            if self._count and self._last_t != self._prev[0]:
                tp, dp, _, _ = self._prev   # always keep the final sample
                self._store(tp, self._x_prev, dp, self.system.forces(dp, self._prev[2]),
                            self.last[3], self.last[4])
            if self._store_ is None:        # stopped before the first sample
                self._layout(sum(len(sub.x) for sub in sysm.subsystems),
                             getattr(sysm, "n_rows", sysm.n_contacts))
            self._flush()
        except BaseException:               # a full disk: the spool goes with the run
            self.discard()
            raise
        t_last = self._prev[0] if self._prev else 0.0
        intervals = [intervals_until(iv, self._open[c], t_last)
                     for c, iv in enumerate(self.intervals)]
        impacts = [i for i in self.impacts if i["time"] <= t_last]
        store = self._store_
        if self._series_path is not None:
            try:
                store.write(self._series_path)
            finally:
                store.close()
            series = SeriesFile(self._series_path)
        else:
            series = store.arrays()
        t = series["t"]
        x_end = (np.concatenate([sub.x for sub in sysm.subsystems])
                 if status == "finished" or self._x_prev is None else self._x_prev)
        offsets = sysm.stacked()
        final_state = {}
        for s, sub in enumerate(sysm.subsystems):
            xs = x_end[offsets[s]:offsets[s + 1]]
            if "modes" in sub.capabilities:      # a structure: physical DOFs of its modes
                names, uf, vf = sub.named_values(xs)
                final_state[sub.name] = {name: {"q": float(uf[i]), "dq": float(vf[i])}
                                         for i, name in enumerate(names)}
                continue
            coords = sub.coordinates()
            if not coords:
                continue
            final_state[sub.name] = {name: {"q": float(xs[iq]), "dq": float(xs[idq])}
                                     for name, (iq, idq) in coords.items()}
        impulse = self.last[1] if self.last else np.zeros(sysm.n_contacts)
        dissipated = self.last[2] if self.last else np.zeros(sysm.n_contacts)
        contacts = {}
        events = []
        work = self.last[5] if self.last else None
        # a following contact's stiffness changed by a plane body's static
        # correction: the energy that changed in its spring with no work
        reduction = getattr(sysm, "reduction_work", lambda: None)()
        for c, name in enumerate(sysm.contact_names):
            iv = intervals[c]
            ledger = {}
            if work is not None:
                stored = float(sysm.contact_potentials(self.last[6])[c])
                stored0 = float(self._stored0[c])
                ledger = {"work": float(work[c]), "stored": stored,
                          "coupling_error": float(work[c] + stored - stored0 + dissipated[c])}
                if reduction is not None and reduction[c] != 0.0:
                    ledger["reduction"] = float(reduction[c])
                    ledger["coupling_error"] -= float(reduction[c])
            contacts[name] = {
                "peak_penetration": float(self.peak[c]),
                "intervals": [[float(a), float(b)] for a, b in iv],
                "count": len(iv),
                "in_touch_time": float(sum(b - a for a, b in iv)),
                "impulse": float(impulse[c]),
                "dissipated": float(dissipated[c]),
                "placement": sysm.links[c].placement,
                **ledger,
            }
            events += [{"contact": name, "t_on": float(a), "t_off": float(b)} for a, b in iv]
        events.sort(key=lambda e: e["t_on"])
        e_final = self.last[3] if self.last else 0.0
        # what the contact laws say of themselves (a restitution they cannot
        # reach), then what the guard says of the run
        warnings = [{"kind": w["kind"], "contact": ln.contact.name,
                     **{k: v for k, v in w.items() if k != "kind"},
                     "message": f"contact `{ln.contact.name}`: {w['message']}"}
                    for ln in sysm.links for w in ln.contact.law.calibration_warnings()]
        if self.guard is not None and self.last:
            warnings += self.guard.warnings(
                self.max_created, self.supplied,
                {n: c["coupling_error"] for n, c in contacts.items() if "coupling_error" in c},
                self.last[6], self.peak)
        summary = {
            "scene": self.scene,
            "scheme": self.scheme,
            "t_end": float(t_last),
            "cpu_time_s": float(cpu_time),
            "macro_steps": int(counters.get("n_windows", 0)),
            "iterations": int(counters.get("n_iterations", 0)),
            "rejected_steps": int(counters.get("n_rejected", 0)),
            "status": status,
            "message": message,
            "energy": {
                "initial": float(self.e0 if self.e0 is not None else 0.0),
                "final": float(e_final),
                "max_abs_drift": float(self.max_drift),
                "dissipated": float(self.last[4]) if self.last else 0.0,
                "supplied": float(self.supplied),
            },
            "warnings": warnings,
            "contacts": contacts,
            "impacts": sorted(impacts, key=lambda i: i["time"]),
            "switches": [{k: e[k] for k in ("time", "contact", "from", "to")}
                         for e in (sysm.connections.log if sysm.connections else [])],
            "final_state": final_state,
        }
        return SimulationResult(
            t=t, series=series, summary=summary, contact_events=tuple(events),
            n_windows=int(counters.get("n_windows", 0)),
            n_iterations=int(counters.get("n_iterations", 0)),
            n_rejected=int(counters.get("n_rejected", 0)),
            status=status, message=message, success=status == "finished")
