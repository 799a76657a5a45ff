"""The run guard's check of many samples at once: :meth:`BlockCheck.check_block`,
with the verdict of :meth:`cosim.core.guard.Guard.check` made sample by
sample, which :class:`~cosim.core.guard.Guard` inherits."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["BlockCheck"]


class BlockCheck:
    """The block face of :class:`~cosim.core.guard.Guard` (a mixin: it calls
    the guard's own :meth:`check`)."""

    #: entries beyond this magnitude may overflow a row's sum: such rows are
    #: summed one by one, as :meth:`check` sums them
    _HUGE = 1e300

    def check_block(self, t, d, dd, f, created, supplied, dissipated, work=None,
                    peak=None) -> None:
        """:meth:`check` of ``m`` samples in order, with the same verdict.

        Parameters
        ----------
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
            As :meth:`check` would at the first sample it refuses; its
            ``sample`` is that sample's index in the block.

        Notes
        -----
        The fast test of :meth:`check` (a non-finite sum of the rows, or
        the created energy above the bound) is made on the whole block; the
        first sample it flags goes to the same slow path as one by one,
        which raises or raises the energy scale, and the test goes on after
        it with that scale.  A row's sum is non-finite exactly when an entry
        is, unless entries near the float64 limit overflow it: those rows
        are summed as :meth:`check` sums them.
        """
        t = np.asarray(t, float)
        m = t.shape[0]
        if m == 0:
            return
        d, dd, f = (np.asarray(a, float).reshape(m, -1) for a in (d, dd, f))
        created = np.asarray(created, float).reshape(m)
        supplied = np.asarray(supplied, float).reshape(m)
        i = 0
        if self.scale is None:          # the first sample starts the guard: as check does
            self._one(0, t, d, dd, f, created, supplied, dissipated, work, peak)
            i = 1
        rows = np.hstack([d, dd, f])
        odd = ~np.isfinite(rows).all(axis=1) | (np.abs(rows) > self._HUGE).any(axis=1)
        for j in np.flatnonzero(odd):
            s = d[j].sum() + dd[j].sum() + f[j].sum()
            odd[j] = s - s != 0
        while i < m:
            if self.growth == math.inf:
                bad = odd[i:]
            else:
                bound = np.maximum(self.growth * (self.scale + np.abs(supplied[i:])),
                                   self.options.energy_floor)
                bad = odd[i:] | ~(created[i:] <= bound)
            hit = np.flatnonzero(bad)
            if not hit.size:
                return
            i += int(hit[0])
            self._one(i, t, d, dd, f, created, supplied, dissipated, work, peak)
            i += 1

    def _one(self, j, t, d, dd, f, created, supplied, dissipated, work, peak):
        """:meth:`check` of sample ``j`` of a block, naming it if it raises."""
        from cosim.core.guard import GuardError       # the guard's module imports this one
        try:
            self.check(float(t[j]), d[j], dd[j], f[j], float(created[j]), float(supplied[j]),
                       np.asarray(dissipated)[j], None if work is None else np.asarray(work)[j],
                       None if peak is None else np.asarray(peak)[j])
        except GuardError as exc:
            exc.sample = j
            raise
