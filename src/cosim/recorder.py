"""Recording a run: time series, contact statistics and the energy ledger.

Contact statistics are kept online at every sample, so the series may be
decimated without losing them.  Between two samples the penetration is the
cubic Hermite interpolant of its values and rates; contact onset and release
(where the law's switch function changes sign) and the peak penetration are
located on it.
"""
from __future__ import annotations

import math
import time
from typing import Callable, NamedTuple

import numpy as np

from .result import SimulationResult

__all__ = ["Recorder", "Progress", "hermite_cubic_max"]


class Progress(NamedTuple):
    """How far a run is, as handed to a progress callback.

    Attributes
    ----------
    t : float
        Simulated time reached [s].
    t_end : float
        Simulated time the run ends at [s].
    contacts : int
        Contact intervals begun so far, all contacts together.
    elapsed_s : float
        Wall-clock time since recording began [s].
    """

    t: float
    t_end: float
    contacts: int
    elapsed_s: float


def _hcubic(d0, v0, d1, v1, h, th):
    t2, t3 = th * th, th * th * th
    p = (2 * t3 - 3 * t2 + 1) * d0 + (t3 - 2 * t2 + th) * h * v0 + (-2 * t3 + 3 * t2) * d1 \
        + (t3 - t2) * h * v1
    dp = ((6 * t2 - 6 * th) * d0 + (3 * t2 - 4 * th + 1) * h * v0 + (-6 * t2 + 6 * th) * d1
          + (3 * t2 - 2 * th) * h * v1) / h
    return p, dp


def hermite_cubic_max(d0, v0, d1, v1, h) -> tuple[float, float]:
    """Largest value of the cubic Hermite interpolant on [0, h] and where it is."""
    a = 6 * d0 + 3 * h * v0 - 6 * d1 + 3 * h * v1
    b = -6 * d0 - 4 * h * v0 + 6 * d1 - 2 * h * v1
    c = h * v0
    cands = [0.0, 1.0]
    if abs(a) > 1e-300:
        disc = b * b - 4 * a * c
        if disc >= 0:
            r = math.sqrt(disc)
            cands += [(-b + r) / (2 * a), (-b - r) / (2 * a)]
    elif abs(b) > 1e-300:
        cands.append(-c / b)
    best = (-math.inf, 0.0)
    for th in cands:
        if 0.0 <= th <= 1.0:
            p, _ = _hcubic(d0, v0, d1, v1, h, th)
            if p > best[0]:
                best = (p, th * h)
    return best


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
    guard : cosim.guard.Guard, optional
        Checks every sample before it is kept and stops the run (raises)
        on non-finite values or energy growth beyond its bound.

    Notes
    -----
    With ``progress`` unset, recording pays nothing for it; set, one clock
    read per sample.
    """

    def __init__(self, system, scene: str, scheme: str, t_end: float, every: int = 1,
                 auto_edges: bool = True, *, progress: Callable[[Progress], None] | None = None,
                 progress_interval: float = 0.2, guard=None):
        self.system, self.scene, self.scheme, self.t_end = system, scene, scheme, t_end
        self.guard = guard           # a cosim.guard.Guard, checking every sample
        nc = system.n_contacts
        self.every = max(1, int(every))
        self.auto_edges = np.broadcast_to(np.asarray(auto_edges, dtype=bool), (nc,))
        self._laws = [ln.contact.law for ln in system.links]
        self._t, self._x, self._d, self._f, self._e, self._diss = [], [], [], [], [], []
        self._count = 0
        self._prev = None            # (t, d, dd, active)
        self.peak = np.zeros(nc)
        self.intervals = [[] for _ in range(nc)]
        self._open = [None] * nc
        self.e0 = None
        #: rigid impacts, in time order (dicts, see MultibodySubsystem.rigid_impact)
        self.impacts: list[dict] = []
        self.supplied = 0.0
        self.max_drift = 0.0
        self.last = None
        self._d0 = None
        self._stored0 = None         # contacts' stored energy at the start, in their modes then
        self._n_log = 0              # switches of connections already turned into edges
        self._modes = []
        self._progress = progress
        self._progress_interval = float(progress_interval)
        self._wall0 = time.monotonic()
        self._next_progress = -math.inf

    def edge(self, c: int, t: float, on: bool) -> None:
        """Report an exactly located contact onset (``on``) or release."""
        if on and self._open[c] is None:
            self._open[c] = t
        elif not on and self._open[c] is not None:
            self.intervals[c].append([self._open[c], t])
            self._open[c] = None

    def record(self, t: float, d: np.ndarray, dd: np.ndarray, f: np.ndarray,
               impulse: np.ndarray, dissipated: np.ndarray, internal=(0.0, 0.0),
               work: np.ndarray | None = None) -> None:
        """Add a sample; subsystem states are read from the system.

        ``dissipated`` is per contact; ``internal`` is the energy dissipated
        inside the subsystems and supplied to them by drives, in total;
        ``work`` is per contact, the work its forces did on the subsystems so
        far (as the scheme applied them)."""
        energy = self.system.energy(d)
        cs = self.system.connections
        if cs is not None:           # energy set free by connection switches
            dissipated = dissipated + cs.lost
        diss_total = float(np.sum(dissipated)) + internal[0]
        if self.e0 is None:
            self.e0 = energy
        drift = energy + diss_total - internal[1] - self.e0
        if self.guard is not None:   # raises before the sample is kept
            self.guard.check(t, d, dd, f, drift, internal[1], dissipated, work, self.peak)
        self.supplied = internal[1]
        self.max_drift = max(self.max_drift, abs(drift))
        active = self.system.in_touch(f)
        nc = self.system.n_contacts
        switched, released = [], set()
        if cs is not None:
            switched = cs.log[self._n_log:]
            self._n_log = len(cs.log)
            released = {self.system.contact_names.index(e["contact"]) for e in switched
                        if e["to"] == "released"}
        prev = self._prev
        if prev is not None:
            tp, dp, ddp, ap = prev
            h = t - tp
            for c in range(nc):
                if h > 0 and (ap[c] or active[c]) and ddp[c] > 0 >= dd[c]:
                    self.peak[c] = max(self.peak[c], hermite_cubic_max(dp[c], ddp[c], d[c],
                                                                       dd[c], h)[0])
                if self.auto_edges[c] and ap[c] != active[c] and c not in released:
                    self.edge(c, self._crossing(c, tp, dp[c], ddp[c], t, d[c], dd[c], ap[c]),
                              bool(active[c]))
        for e in switched:           # a grasp holds from its switch; a release frees
            c = self.system.contact_names.index(e["contact"])
            self.edge(c, e["time"], e["to"] == "grasped" or e["closed"])
        if nc:
            self.peak = np.maximum(self.peak, np.where(active, d[:nc], 0.0))
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
        if self._count % self.every == 0:
            self._store(t, d, f, energy, diss_total)
        self._count += 1
        if self._progress is not None:
            now = time.monotonic()
            if now >= self._next_progress:
                self._next_progress = now + self._progress_interval
                begun = sum(map(len, self.intervals)) + sum(o is not None for o in self._open)
                self._progress(Progress(float(t), float(self.t_end), int(begun),
                                        now - self._wall0))

    def _store(self, t, d, f, energy, diss_total):
        self._t.append(t)
        self._x.append(np.concatenate([s.x for s in self.system.subsystems]))
        self._d.append(d.copy())
        self._f.append(f.copy())
        self._e.append(energy)
        self._diss.append(diss_total)
        if self.system.connections is not None:
            self._modes.append(self.system.connections.mode.copy())

    def _crossing(self, c, t0, d0, v0, t1, d1, v1, was_active):
        law, h = self._laws[c], t1 - t0
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            p, dp = _hcubic(d0, v0, d1, v1, h, mid)
            if (float(law.switch(p, dp)) > 0) == was_active:
                lo = mid
            else:
                hi = mid
        return t0 + 0.5 * (lo + hi) * h

    # ----------------------------------------------------------------- result
    def finish(self, status: str, message: str, cpu_time: float, counters: dict) -> SimulationResult:
        sysm = self.system
        if self._count and self._t[-1] != self._prev[0]:
            tp, dp, _, _ = self._prev   # always keep the final sample
            self._store(tp, dp, self.system.forces(dp, self._prev[2]), self.last[3],
                        self.last[4])
        t_last = self._prev[0] if self._prev else 0.0
        intervals = [list(iv) + ([[self._open[c], t_last]] if self._open[c] is not None else [])
                     for c, iv in enumerate(self.intervals)]
        t = np.array(self._t)
        X = np.array(self._x).reshape(len(t), -1)
        D = np.array(self._d).reshape(len(t), -1)
        Fc = np.array(self._f).reshape(len(t), -1)
        series = {"t": t}
        for c, name in enumerate(sysm.contact_names):
            series[f"gap/{name}"] = -D[:, c]
            series[f"force/{name}"] = Fc[:, c]
        for r in range(sysm.n_contacts, getattr(sysm, "n_rows", sysm.n_contacts)):
            # tangential rows: coordinate of a - b along t from the grasp anchor, force on a
            series[f"gap/{sysm.row_names[r]}"] = D[:, r]
            series[f"force/{sysm.row_names[r]}"] = Fc[:, r]
        if sysm.connections is not None:
            modes = np.array(self._modes).reshape(len(t), -1)
            for c in sysm.connections.index:
                if sysm.links[c].connection.grasp is not None:
                    series[f"mode/{sysm.contact_names[c]}"] = modes[:, c]
        offsets = sysm.stacked()
        final_state = {}
        for s, sub in enumerate(sysm.subsystems):
            if hasattr(sub, "named_values"):      # a structure: physical DOFs of its modes
                names, U, V = sub.named_values(X[:, offsets[s]:offsets[s + 1]])
                _, uf, vf = sub.named_values(sub.x)
                final_state[sub.name] = {}
                for i, name in enumerate(names):
                    series[f"q/{sub.name}/{name}"] = U[:, i]
                    series[f"dq/{sub.name}/{name}"] = V[:, i]
                    final_state[sub.name][name] = {"q": float(uf[i]), "dq": float(vf[i])}
                continue
            coords = sub.coordinates()
            if not coords:
                continue
            final_state[sub.name] = {}
            for name, (iq, idq) in coords.items():
                series[f"q/{sub.name}/{name}"] = X[:, offsets[s] + iq]
                series[f"dq/{sub.name}/{name}"] = X[:, offsets[s] + idq]
                final_state[sub.name][name] = {"q": float(sub.x[iq]), "dq": float(sub.x[idq])}
        series["energy/total"] = np.array(self._e)
        series["energy/dissipated"] = np.array(self._diss)
        impulse = self.last[1] if self.last else np.zeros(sysm.n_contacts)
        dissipated = self.last[2] if self.last else np.zeros(sysm.n_contacts)
        contacts = {}
        events = []
        work = self.last[5] if self.last else None
        for c, name in enumerate(sysm.contact_names):
            iv = intervals[c]
            ledger = {}
            if work is not None:
                stored = float(sysm.contact_potentials(self.last[6])[c])
                stored0 = float(self._stored0[c])
                ledger = {"work": float(work[c]), "stored": stored,
                          "coupling_error": float(work[c] + stored - stored0 + dissipated[c])}
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
            "contacts": contacts,
            "impacts": sorted(self.impacts, key=lambda i: i["time"]),
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
