"""The run guard's check of many samples at once: :func:`check_block`, with
the verdict of :meth:`cosim.core.guard.Guard.check` made sample by sample,
behind :meth:`Guard.check_block <cosim.core.guard.Guard.check_block>`
(imported where a run first takes it)."""
from __future__ import annotations

import math

import numpy as np

from cosim.core.guard_error import GuardError

__all__ = ["check_block", "flagged", "HUGE"]

#: entries beyond this magnitude may overflow a row's sum: such rows are
#: summed one by one, as :meth:`~cosim.core.guard.Guard.check` sums them
HUGE = 1e300


def check_block(guard, t, d, dd, f, created, supplied, dissipated, work=None,
                peak=None) -> None:
    """:meth:`Guard.check <cosim.core.guard.Guard.check>` of ``m`` samples
    in order, with the same verdict.

    Parameters
    ----------
    guard : cosim.core.guard.Guard
    t : (m,) array
    d, dd, f : (m, n_rows) arrays
    created, supplied : (m,) arrays
    dissipated : (m, n_contacts) array
    work : (m, n_contacts) array, optional
    peak : (m, n_contacts) array, optional
        Each contact's largest penetration before each sample.

    Raises
    ------
    GuardError
        As ``check`` would at the first sample it refuses; its ``sample`` is
        that sample's index in the block.

    Notes
    -----
    The fast test of ``check`` (a non-finite sum of the rows, or the
    created energy above the bound) is made on the whole block; the
    first sample it flags goes to the same slow path as one by one,
    which raises or raises the energy scale, and the test goes on after
    it with that scale.  A row's sum is non-finite exactly when an entry
    is, unless entries near the float64 limit overflow it: those rows
    are summed as ``check`` sums them.
    """
    t = np.asarray(t, float)
    m = t.shape[0]
    if m == 0:
        return
    d, dd, f = (np.asarray(a, float).reshape(m, -1) for a in (d, dd, f))
    created = np.asarray(created, float).reshape(m)
    supplied = np.asarray(supplied, float).reshape(m)
    i = 0
    if guard.scale is None:          # the first sample starts the guard: as check does
        _one(guard, 0, t, d, dd, f, created, supplied, dissipated, work, peak)
        i = 1
    odd = _odd(d, dd, f)
    while i < m:
        hit = np.flatnonzero(_bad(guard, odd[i:], created[i:], supplied[i:]))
        if not hit.size:
            return
        i += int(hit[0])
        _one(guard, i, t, d, dd, f, created, supplied, dissipated, work, peak)
        i += 1


def flagged(guard, d, dd, f, created, supplied):
    """The samples (``(m,)`` bool) that ``check`` would judge on its slow
    path under the guard's present scale, or None before its first sample.
    Samples none of which is flagged pass :func:`check_block` without a
    change to the guard: a scale the slow path raised flags fewer."""
    if guard.scale is None:
        return None
    d, dd, f = (np.asarray(a, float).reshape(len(created), -1) for a in (d, dd, f))
    return _bad(guard, _odd(d, dd, f), np.asarray(created, float), np.asarray(supplied, float))


def _odd(d, dd, f):
    """Rows whose sum (``check``'s) is not finite."""
    rows = np.hstack([d, dd, f])
    odd = ~np.isfinite(rows).all(axis=1) | (np.abs(rows) > HUGE).any(axis=1)
    for j in np.flatnonzero(odd):
        s = d[j].sum() + dd[j].sum() + f[j].sum()
        odd[j] = s - s != 0
    return odd


def _bad(guard, odd, created, supplied):
    """The fast test of ``check`` on rows, under the guard's present scale."""
    if guard.growth == math.inf:    # the energy bound off: a ledger not finite still stops
        return odd | ~np.isfinite(created)
    bound = np.maximum(guard.growth * (guard.scale + np.abs(supplied)),
                       guard.options.energy_floor)
    return odd | ~(created <= bound)


def _one(guard, j, t, d, dd, f, created, supplied, dissipated, work, peak):
    """``guard.check`` of sample ``j`` of a block, naming it if it raises."""
    try:
        guard.check(float(t[j]), d[j], dd[j], f[j], float(created[j]), float(supplied[j]),
                    np.asarray(dissipated)[j], None if work is None else np.asarray(work)[j],
                    None if peak is None else np.asarray(peak)[j])
    except GuardError as exc:
        exc.sample = j
        raise
