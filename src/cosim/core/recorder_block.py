"""Recording many samples at once: :func:`record_block`, the array twin of
:meth:`cosim.core.recorder.Recorder.record`, behind
:meth:`Recorder.record_block <cosim.core.recorder.Recorder.record_block>`
(imported where a run first takes it: a run that never does loads nothing
of it).

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

from couplers.law_base import ContactLaw
from cosim.core.guard_block import flagged
from cosim.core.guard_error import GuardError
from cosim.core.hermite import hermite_cubic_max
from cosim.core.progress import Progress

try:                              # the crossings' bisection compiled (see _crossings)
    from cosim.core.kernel_import import import_kernel
    _compiled = import_kernel("cosim.core.schemes._driver_block")
except ImportError:               # not built: the same bisection on arrays
    _compiled = None

__all__ = ["record_block"]


def record_block(rec, t, d, dd, f, impulse, dissipated, internal, work, x, energy=None,
                 peaks=None, edges=None) -> None:
    """Add ``m`` samples at once: what ``m`` calls of
    :meth:`~cosim.core.recorder.Recorder.record` would
    keep, with the statistics, the guard's verdict and the stored series
    the same, found with array operations over the block.

    Parameters
    ----------
    rec : cosim.core.recorder.Recorder
        The recorder; its state is read and kept as ``record`` keeps it.
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
    edges : dict, optional
        Row -> the switches ``(contact, time, on)`` a side located in the
        step that ended at that row's sample, reported (:meth:`Recorder.edge
        <cosim.core.recorder.Recorder.edge>`) before the row is, as a caller
        of ``record`` reports them before its call; or a function that
        reports them.

    Raises
    ------
    GuardError
        As :meth:`record` would at the first sample the guard refuses, or
        at an edge that makes a contact chatter; the samples before it
        are kept, as they would be one by one.

    Notes
    -----
    No array handed in is kept: what the recorder keeps it copies (a
    caller may write its next samples into the same arrays).  The
    subsystems' own states are not read: a scheme that integrated
    past the block (it returns at ``t_end``, a full buffer or a switch)
    hands the states at each sample in ``x``.  Connection modes must not
    change inside the block: switches logged since the last sample
    belong to its first sample, as :meth:`record` would take them.  The
    progress callback is told at the block's end, throttled as
    :meth:`record` throttles it; with ``progress_interval`` 0 (a caller that
    asks for every sample) it is told of each sample, the contacts begun
    counted as before the block for all but its last (a block ends at a
    switch).
    """
    t = np.asarray(t, float)
    m = t.shape[0]
    if m == 0:
        return
    rec._begun_before_block = (sum(map(len, rec.intervals))
                               + sum(o is not None for o in rec._open))
    sysm = rec.system
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
    if rec.e0 is None:             # the first sample sets the start: one by one
        rec._record(t[0], d[0], dd[0], f[0], impulse[0], dissipated[0], internal[0],
                     None if work is None else work[0], float(energy[0]), x[0].copy(), peaks[0])
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
    diss_total = dissipated.sum(axis=1) + internal[:, 0]
    drift = energy + diss_total - internal[:, 1] - rec.e0
    active = f[:, :nc] > 0
    switched, released = [], set()
    if cs is not None:
        active |= sysm.in_touch(np.zeros(nc))[None, :]       # grasped
        switched = cs.log[rec._n_log:]
        rec._n_log = len(cs.log)
        released = {sysm.contact_names.index(e["contact"]) for e in switched
                    if e["to"] == "released"}
    tp, dp, ddp, ap = rec._prev
    t_prev = np.concatenate([[tp], t[:-1]])
    d_prev = np.concatenate([dp[None, :], d[:-1]])
    dd_prev = np.concatenate([ddp[None, :], dd[:-1]])
    a_prev = np.concatenate([np.asarray(ap, bool)[None, :], active[:-1]])
    h = t - t_prev
    # each sample's share of the peaks: what record() folds into `since`
    contrib = np.maximum(np.where(active, d[:, :nc], 0.0), peaks)
    rise = ((h > 0)[:, None] & (a_prev | active) & (dd_prev[:, :nc] > 0)
            & (dd[:, :nc] <= 0) & ~rec._located[None, :])
    for i, c in zip(*np.nonzero(rise)):
        contrib[i, c] = max(contrib[i, c], hermite_cubic_max(
            d_prev[i, c], dd_prev[i, c], d[i, c], dd[i, c], h[i])[0])
    peak_before = None              # what the guard is told of the peaks, when it looks
    flip = (a_prev != active) & rec.auto_edges[None, :]
    if released:
        flip[0, sorted(released)] = False
    edges = {j - i0: e for j, e in (edges or {}).items() if i0 <= j < m + i0}
    fr, fc = np.nonzero(flip)
    flips = {}                      # row -> its flipped contacts, each with its new state
    for j, c, on in zip(fr.tolist(), fc.tolist(), active[fr, fc].tolist()):
        flips.setdefault(j, []).append((c, on))
    edge_rows = sorted(flips.keys() | ({0} if switched else set())
                       | {j - 1 for j in edges if j > 0})
    at = _crossings(rec, flip, t_prev, d_prev, dd_prev, t, d, dd, a_prev)
    # the guard looks only at the stretches between edges that hold a sample
    # its fast test flags (the others pass it unchanged)
    flags = None if rec.guard is None else flagged(rec.guard, d, dd, f, drift, internal[:, 1])
    pos = 0
    if 0 in edges:
        _located(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
                 internal, active, contrib, edges[0], 0)
    for je in edge_rows + [m]:
        hi = min(je + 1, m)
        if rec.guard is not None and hi > pos and (flags is None or flags[pos:hi].any()):
            if peak_before is None:
                peak_before = np.maximum(rec.peak[None, :], np.vstack(
                    [np.full((1, nc), -np.inf), np.maximum.accumulate(contrib, axis=0)[:-1]]))
            try:
                rec.guard.check_block(
                    t[pos:hi], d[pos:hi], dd[pos:hi], f[pos:hi], drift[pos:hi],
                    internal[pos:hi, 1], dissipated[pos:hi],
                    None if work is None else work[pos:hi], peak_before[pos:hi])
            except GuardError as exc:
                _commit(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total,
                        drift, internal, active, contrib, pos + exc.sample)
                raise
        if je == m:
            break
        try:
            for c, on in flips.get(je, ()):
                tc = at.get((je, c))
                if tc is None:
                    tc = rec._crossing(c, t_prev[je], d_prev[je, c], dd_prev[je, c], t[je],
                                       d[je, c], dd[je, c], a_prev[je, c])
                rec.edge(c, tc, on)
            if je == 0:
                for e in switched:  # a grasp holds from its switch; a release frees
                    c = sysm.contact_names.index(e["contact"])
                    rec.edge(c, e["time"], e["to"] == "grasped" or e["closed"])
        except GuardError:
            _commit(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total,
                    drift, internal, active, contrib, je)
            raise
        if je + 1 in edges:
            _located(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
                     internal, active, contrib, edges[je + 1], je + 1)
        pos = hi
    _commit(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
            internal, active, contrib, m)


#: fewest crossings in a block located on arrays (each array bisection costs
#: about as much as eight located one by one; the compiled one, less than one)
ARRAY_CROSSINGS = 8 if _compiled is None else 1


def _crossings(rec, flip, t_prev, d_prev, dd_prev, t, d, dd, a_prev) -> dict:
    """(row, contact) -> the time :meth:`Recorder._crossing
    <cosim.core.recorder.Recorder._crossing>` locates, for the flips of
    contacts whose law switches on the penetration itself (the base
    ``switch``): its bisection on the cubic Hermite, with its formulas in its
    order, on all of them at once where they are :data:`ARRAY_CROSSINGS` or
    more (else none: the recorder locates them)."""
    rows, cs = np.nonzero(flip)
    keep = [i for i, c in enumerate(cs) if type(rec._laws[c]).switch is ContactLaw.switch]
    if len(keep) < ARRAY_CROSSINGS:     # a few: one by one costs less
        return {}
    rows, cs = rows[keep], cs[keep]
    t0, t1 = t_prev[rows], t[rows]
    d0, v0, d1, v1 = d_prev[rows, cs], dd_prev[rows, cs], d[rows, cs], dd[rows, cs]
    was = a_prev[rows, cs]
    if _compiled is not None:     # the same bisection in C, its operations in this order
        times = np.empty(len(rows))
        _compiled.crossings(t0, t1, d0, v0, d1, v1, was.view(np.uint8), times)
        return dict(zip(zip(rows.tolist(), cs.tolist()), times.tolist()))
    h = t1 - t0
    dx = d1 - d0
    c1, c2, c3 = h * v0, 3 * dx - h * (2 * v0 + v1), -2 * dx + h * (v0 + v1)
    lo, hi = np.zeros(len(rows)), np.ones(len(rows))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        up = (d0 + mid * (c1 + mid * (c2 + mid * c3)) > 0) == was
        lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
    times = t0 + 0.5 * (lo + hi) * h
    return {(int(j), int(c)): float(x) for j, c, x in zip(rows, cs, times)}


def _located(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
             internal, active, contrib, located, j) -> None:
    """Report the located switches before row ``j``; an edge that makes a
    contact chatter keeps the rows before ``j``."""
    try:
        if callable(located):       # the caller reports them
            located()
            return
        for c, ts, on in located:
            rec.edge(int(c), ts, bool(on))
    except GuardError:
        _commit(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
                internal, active, contrib, j)
        raise


def _commit(rec, t, d, dd, f, impulse, dissipated, work, x, energy, diss_total, drift,
            internal, active, contrib, k) -> None:
    """Keep the first ``k`` samples of a block (:meth:`record_block`)."""
    if k <= 0:
        return
    np.maximum(rec.peak, contrib[:k].max(axis=0), out=rec.peak)
    rec.supplied = internal[k - 1, 1]
    rec.max_drift = max(rec.max_drift, float(np.abs(drift[:k]).max()))
    top = float(drift[:k].max())
    if top > rec.max_created:
        rec.max_created = top
    rec._prev = (t[k - 1], d[k - 1].copy(), dd[k - 1].copy(), active[k - 1].copy())
    rec.last = (t[k - 1], impulse[k - 1].copy(), dissipated[k - 1].copy(),
                 float(energy[k - 1]), float(diss_total[k - 1]),
                 None if work is None else work[k - 1].copy(), d[k - 1].copy())
    rec._x_prev = x[k - 1].copy()
    # the stored samples, and the largest penetration since the one before each
    carry, start = rec._since, 0
    if rec.every == 1:              # every sample kept: slices, each its own peaks
        kept = slice(0, k)
        rows = contrib[:k].copy()
        last = k - 1
    else:
        kept = np.flatnonzero((rec._count + np.arange(k)) % rec.every == 0)
        # each kept sample's peaks: the largest over the samples since the
        # one kept before it (the first group with what was carried over)
        rows = np.maximum.reduceat(contrib[:kept[-1] + 1], np.r_[0, kept[:-1] + 1],
                                   axis=0) if kept.size else None
        last = kept[-1] if kept.size else None
    if last is not None:
        rows[0] = np.maximum(rows[0], carry)
        carry, start = np.zeros_like(carry), last + 1
        try:
            _store_rows(rec, t[kept], x[kept], d[kept], f[kept], energy[kept],
                        diss_total[kept], rows)
        except Exception:
            # a spool that cannot be written: the run reached the sample whose
            # store failed, as one by one (record keeps it, then stores it)
            i = int(np.searchsorted(t[:k], rec._last_t))
            rec._prev = (t[i], d[i].copy(), dd[i].copy(), active[i].copy())
            raise
    rec._since = np.maximum(carry, contrib[start:k].max(axis=0)) if start < k else carry
    rec._count += k
    if rec._progress is not None:
        now = time.monotonic()
        if now >= rec._next_progress:
            rec._next_progress = now + rec._progress_interval
            begun = sum(map(len, rec.intervals)) + sum(o is not None for o in rec._open)
            if rec._progress_interval <= 0:               # every sample was asked for
                for j in range(k - 1):
                    rec._progress(Progress(float(t[j]), float(rec.t_end),
                                           int(rec._begun_before_block), now - rec._wall0))
            rec._progress(Progress(float(t[k - 1]), float(rec.t_end), int(begun),
                                    now - rec._wall0))


def _store_rows(rec, t, x, d, f, energy, diss_total, pk) -> None:
    """:meth:`_store` of many rows (``pk``: each row's ``peak`` columns)."""
    sysm = rec.system
    L = rec._slices
    n, i = len(t), 0
    while i < n:
        if rec._n_buf == len(rec._buf):     # full: a stop came between its last row and its flush
            rec._flush()
        room = len(rec._buf) - rec._n_buf
        j = min(n, i + room)
        rows = rec._buf[rec._n_buf:rec._n_buf + j - i]
        rows[:, 0] = t[i:j]
        rows[:, L["x"]] = x[i:j]
        rows[:, L["d"]] = d[i:j]
        rows[:, L["f"]] = f[i:j]
        rows[:, L["e"]] = energy[i:j]
        rows[:, L["diss"]] = diss_total[i:j]
        if sysm.connections is not None:
            rows[:, L["mode"]] = sysm.connections.mode
        rows[:, L["pk"]] = pk[i:j]
        rec._n_buf += j - i
        rec._last_t = t[j - 1]
        i = j
        if rec._n_buf == len(rec._buf):
            rec._flush()
