"""Recording many samples at once: :meth:`BlockRecording.record_block`, the
array twin of :meth:`cosim.core.recorder.Recorder.record`, which
:class:`~cosim.core.recorder.Recorder` inherits.

A scheme whose side integrates across the output points (the macro loop's
sampled path, :mod:`cosim.core.schemes.sampled`) hands them over as arrays:
the statistics, the run guard's verdict (:meth:`cosim.core.guard.Guard.check_block`)
and the stored series are those of one call of ``record`` per sample, found
with array operations; the edges and the guard's slow path are taken one at a
time where they fall.
"""
from __future__ import annotations

import time

import numpy as np

from cosim.core.guard import GuardError
from cosim.core.hermite import hermite_cubic_max

__all__ = ["BlockRecording"]


class BlockRecording:
    """The block face of :class:`~cosim.core.recorder.Recorder` (a mixin: it
    reads and keeps the recorder's state)."""

    def record_block(self, t, d, dd, f, impulse, dissipated, internal, work=None, *, x,
                     energy=None, peaks=None) -> None:
        """Add ``m`` samples at once: what ``m`` calls of :meth:`record` would
        keep, with the statistics, the guard's verdict and the stored series
        the same, found with array operations over the block.

        Parameters
        ----------
        t : (m,) array
            Sample times [s], increasing, after the last sample recorded.
        d, dd, f : (m, n_rows) arrays
            Penetrations [m], their rates [m/s] and the row forces [N].
        impulse, dissipated : (m, n_contacts) arrays
            Each contact's impulse [N s] and dissipated energy [J] so far.
        internal : (m, 2) array
            Energy dissipated inside the subsystems and supplied by drives so
            far [J] (:meth:`record`'s ``internal`` at each sample).
        work : (m, n_contacts) array, optional
            Work each contact's forces did on the subsystems so far [J].
        x : (m, n_states) array
            The subsystems' states at each sample, stacked as
            :meth:`~cosim.core.system.CoupledSystem.stacked` orders them.
        energy : (m,) array, optional
            The system's energy at each sample [J]
            (:meth:`~cosim.core.system.CoupledSystem.energy`); computed from
            ``x`` and ``d`` by the same sum when not given.
        peaks : (m, n_contacts) array, optional
            Per sample, the largest penetration of each contact since the
            sample before, as its host's integrator located it: what
            :meth:`~cosim.core.system.CoupledSystem.take_peaks` would have
            given there (0 for rigid laws and for contacts not embedded).
            None: zeros.

        Raises
        ------
        GuardError
            As :meth:`record` would at the first sample the guard refuses, or
            at an edge that makes a contact chatter; the samples before it
            are kept, as they would be one by one.

        Notes
        -----
        The subsystems' own states are not read: a scheme that integrated
        past the block (it returns at ``t_end``, a full buffer or a switch)
        hands the states at each sample in ``x``.  Connection modes must not
        change inside the block: switches logged since the last sample
        belong to its first sample, as :meth:`record` would take them.  The
        progress callback is told once, at the block's end.
        """
        t = np.asarray(t, float)
        m = t.shape[0]
        if m == 0:
            return
        sysm = self.system
        nc = sysm.n_contacts
        d, dd, f = (np.asarray(a, float).reshape(m, -1) for a in (d, dd, f))
        impulse = np.asarray(impulse, float).reshape(m, nc)
        dissipated = np.asarray(dissipated, float).reshape(m, nc)
        internal = np.asarray(internal, float).reshape(m, 2)
        work = None if work is None else np.asarray(work, float).reshape(m, nc)
        x = np.asarray(x, float).reshape(m, -1)
        peaks = np.zeros((m, nc)) if peaks is None else np.asarray(peaks, float).reshape(m, nc)
        if energy is None:
            off = sysm.stacked()
            energy = np.array([float(sum([sub.energy(x[i, off[s]:off[s + 1]])
                                          for s, sub in enumerate(sysm.subsystems)]))
                               + sysm.contact_potential(d[i]) for i in range(m)])
        energy = np.asarray(energy, float).reshape(m)
        i0 = 0
        if self.e0 is None:             # the first sample sets the start: one by one
            self._record(t[0], d[0], dd[0], f[0], impulse[0], dissipated[0], internal[0],
                         None if work is None else work[0], float(energy[0]), x[0], peaks[0])
            i0 = 1
            if m == 1:
                return
        t, d, dd, f, impulse, dissipated, internal, x, energy, peaks = (
            a[i0:] for a in (t, d, dd, f, impulse, dissipated, internal, x, energy, peaks))
        work = None if work is None else work[i0:]
        m -= i0
        cs = sysm.connections
        if cs is not None:           # energy set free by connection switches
            dissipated = dissipated + cs.lost
        diss_total = np.sum(dissipated, axis=1) + internal[:, 0]
        drift = energy + diss_total - internal[:, 1] - self.e0
        active = f[:, :nc] > 0
        switched, released = [], set()
        if cs is not None:
            active |= sysm.in_touch(np.zeros(nc))[None, :]       # grasped
            switched = cs.log[self._n_log:]
            self._n_log = len(cs.log)
            released = {sysm.contact_names.index(e["contact"]) for e in switched
                        if e["to"] == "released"}
        tp, dp, ddp, ap = self._prev
        t_prev = np.concatenate([[tp], t[:-1]])
        d_prev = np.concatenate([dp[None, :], d[:-1]])
        dd_prev = np.concatenate([ddp[None, :], dd[:-1]])
        a_prev = np.concatenate([np.asarray(ap, bool)[None, :], active[:-1]])
        h = t - t_prev
        # each sample's share of the peaks: what record() folds into `since`
        contrib = np.maximum(np.where(active, d[:, :nc], 0.0), peaks)
        rise = ((h > 0)[:, None] & (a_prev | active) & (dd_prev[:, :nc] > 0)
                & (dd[:, :nc] <= 0) & ~self._located[None, :])
        for i, c in zip(*np.nonzero(rise)):
            contrib[i, c] = max(contrib[i, c], hermite_cubic_max(
                d_prev[i, c], dd_prev[i, c], d[i, c], dd[i, c], h[i])[0])
        peak_before = np.maximum(self.peak[None, :], np.vstack(
            [np.full((1, nc), -np.inf), np.maximum.accumulate(contrib, axis=0)[:-1]]))
        flip = (a_prev != active) & self.auto_edges[None, :]
        if released:
            flip[0, sorted(released)] = False
        edge_rows = sorted(set(np.nonzero(flip)[0].tolist()) | ({0} if switched else set()))
        pos = 0
        for je in edge_rows + [m]:
            hi = min(je + 1, m)
            if self.guard is not None and hi > pos:
                try:
                    self.guard.check_block(
                        t[pos:hi], d[pos:hi], dd[pos:hi], f[pos:hi], drift[pos:hi],
                        internal[pos:hi, 1], dissipated[pos:hi],
                        None if work is None else work[pos:hi], peak_before[pos:hi])
                except GuardError as exc:
                    self._commit(t, d, dd, f, impulse, dissipated, work, x, energy, diss_total,
                                 drift, internal, active, contrib, pos + exc.sample)
                    raise
            if je == m:
                break
            try:
                for c in np.flatnonzero(flip[je]):
                    c = int(c)
                    self.edge(c, self._crossing(c, t_prev[je], d_prev[je, c], dd_prev[je, c],
                                                t[je], d[je, c], dd[je, c], a_prev[je, c]),
                              bool(active[je, c]))
                if je == 0:
                    for e in switched:  # a grasp holds from its switch; a release frees
                        c = sysm.contact_names.index(e["contact"])
                        self.edge(c, e["time"], e["to"] == "grasped" or e["closed"])
            except GuardError:
                self._commit(t, d, dd, f, impulse, dissipated, work, x, energy, diss_total,
                             drift, internal, active, contrib, je)
                raise
            pos = hi
        self._commit(t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
                     internal, active, contrib, m)

    def _commit(self, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
                internal, active, contrib, k) -> None:
        """Keep the first ``k`` samples of a block (:meth:`record_block`)."""
        if k <= 0:
            return
        np.maximum(self.peak, np.max(contrib[:k], axis=0), out=self.peak)
        self.supplied = internal[k - 1, 1]
        self.max_drift = max(self.max_drift, float(np.max(np.abs(drift[:k]))))
        top = float(np.max(drift[:k]))
        if top > self.max_created:
            self.max_created = top
        self._prev = (t[k - 1], d[k - 1].copy(), dd[k - 1].copy(), active[k - 1].copy())
        self.last = (t[k - 1], impulse[k - 1].copy(), dissipated[k - 1].copy(),
                     float(energy[k - 1]), float(diss_total[k - 1]),
                     None if work is None else work[k - 1].copy(), d[k - 1].copy())
        self._x_prev = x[k - 1].copy()
        # the stored samples, and the largest penetration since the one before each
        kept = np.flatnonzero((self._count + np.arange(k)) % self.every == 0)
        carry = self._since
        start = 0
        rows = []
        for i in kept:
            rows.append(np.maximum(carry, np.max(contrib[start:i + 1], axis=0)))
            carry, start = np.zeros_like(carry), i + 1
        self._since = (np.maximum(carry, np.max(contrib[start:k], axis=0)) if start < k
                       else carry)
        if kept.size:
            self._store_rows(t[kept], x[kept], d[kept], f[kept], energy[kept],
                             diss_total[kept], np.array(rows))
        self._count += k
        if self._progress is not None:
            now = time.monotonic()
            if now >= self._next_progress:
                self._next_progress = now + self._progress_interval
                begun = sum(map(len, self.intervals)) + sum(o is not None for o in self._open)
                from cosim.core.recorder import Progress      # the recorder imports this module
                self._progress(Progress(float(t[k - 1]), float(self.t_end), int(begun),
                                        now - self._wall0))

    def _store_rows(self, t, x, d, f, energy, diss_total, pk) -> None:
        """:meth:`_store` of many rows (``pk``: each row's ``peak`` columns)."""
        sysm = self.system
        L = self._slices
        n, i = len(t), 0
        while i < n:
            room = len(self._buf) - self._n_buf
            j = min(n, i + room)
            rows = self._buf[self._n_buf:self._n_buf + j - i]
            rows[:, 0] = t[i:j]
            rows[:, L["x"]] = x[i:j]
            rows[:, L["d"]] = d[i:j]
            rows[:, L["f"]] = f[i:j]
            rows[:, L["e"]] = energy[i:j]
            rows[:, L["diss"]] = diss_total[i:j]
            if sysm.connections is not None:
                rows[:, L["mode"]] = sysm.connections.mode
            rows[:, L["pk"]] = pk[i:j]
            self._n_buf += j - i
            i = j
            if self._n_buf == len(self._buf):
                self._flush()
        self._last_t = t[-1]
