"""The compiled macro loop's samples taken in blocks.

The compiled loop (:mod:`cosim.core.schemes._driver`) used to return to
Python after every accepted step, for the recorder and the run guard
(:meth:`StepBooks.book_driven
<cosim.core.schemes.step_control.StepBooks.book_driven>`).  Here
:func:`cosim.core.schemes._driver_block.fill` keeps taking steps and writes
each step's sample into preallocated rows; the recorder takes them as arrays
(:meth:`~cosim.core.recorder.Recorder.record_block`), and the guard judges
them there (:meth:`~cosim.core.guard.Guard.check_block`) with the verdict
of sample by sample: the first sample it refuses, with the same message
and time, and the samples before it kept.

The switches the sides locate in a step are reported before that step's
sample, as step by step.  A block ends when its :data:`BLOCK` rows are
full, at the run's end, at the first step whose rows are not finite
(stopped as step by step: the samples before are kept), or when a step
raised: a signal's KeyboardInterrupt keeps the whole samples before it and
is raised again.  The progress callback is told at the end of each block,
so within :data:`BLOCK` macro steps of its interval.

A recorder that reads the system's live state at each sample or edge (a
subclass's hook: ``reads_live_system``, as ``cosim info``'s probe of the
first touch does) is handed each step as it is taken.

A guard that stops the run inside a block leaves the sides past the sample
it refused (the loop took the block's later steps): the recorder keeps the
states of the samples, which is what a stopped run reports.

:data:`ENABLED` False books every step as it comes (the reference the
blocks are tested against).
"""
from __future__ import annotations

import time

import numpy as np

from cosim.core.guard_error import GuardError

__all__ = ["ENABLED", "BLOCK", "takes", "run_blocks"]

#: False: the compiled loop returns to Python after every step
ENABLED = True
#: most samples the compiled loop writes before it returns [-]
BLOCK = 256


def takes(recorder) -> bool:
    """Whether the compiled loop hands ``recorder`` its samples in blocks:
    unless :data:`ENABLED` is False or the recorder reads the system's live
    state at each sample (``reads_live_system``)."""
    return ENABLED and not getattr(recorder, "reads_live_system", False)


class _Rows:
    """The preallocated rows of one run's blocks."""

    def __init__(self, system, m):
        nr, nc = system.n_rows, system.n_contacts
        self.off = system.stacked().tolist()        # each side's columns of x
        nx = self.off[-1]
        self.t = np.zeros(m)
        self.d, self.dd, self.f = np.zeros((m, nr)), np.zeros((m, nr)), np.zeros((m, nr))
        self.imp, self.diss, self.work = np.zeros((m, nc)), np.zeros((m, nc)), np.zeros((m, nc))
        self.internal = np.zeros((m, 2))
        self.x = np.zeros((m, nx))
        self.energy = np.zeros(m)
        self.peaks = np.zeros((m, nc))
        self.rej = np.zeros(m, dtype=np.int_)

    def args(self):
        return (self.t, self.d, self.dd, self.f, self.imp, self.diss, self.internal, self.work,
                self.x, self.peaks, self.rej)

    def energies(self, system, b) -> None:
        """The system's energy at rows ``0 .. b - 1``: each side's
        (:meth:`~cosim.core.subsystem.Subsystem.energies`) and the contacts'
        stored energy, summed in the order of
        :meth:`~cosim.core.system.CoupledSystem.energy`."""
        if b <= 0:                  # a block that ends at its first step
            return
        off = self.off
        e = 0
        for s, sub in enumerate(system.subsystems):
            e = e + sub.energies(self.x[:b, off[s]:off[s + 1]])
        if system.connections is None and not system.circles:
            pot = 0
            for c, ln in enumerate(system.links):
                pot = pot + ln.contact.law.potential(self.d[:b, c])
        else:
            pot = np.array([system.contact_potential(self.d[i]) for i in range(b)])
        self.energy[:b] = e + pot

    def record(self, rec, b, edges) -> None:
        """Record rows ``0 .. b - 1``, with the switches ``edges`` (row,
        contact, time, on) located in their steps."""
        if b <= 0:
            return
        at = {}
        for j, c, ts, on in edges:
            if j < b:
                at.setdefault(j, []).append((c, ts, on))
        # views of the rows, which the next block overwrites: the recorder copies
        # what it keeps (record_block keeps no array it is handed)
        rec.record_block(self.t[:b], self.d[:b], self.dd[:b], self.f[:b], self.imp[:b],
                         self.diss[:b], self.internal[:b], self.work[:b], x=self.x[:b],
                         energy=self.energy[:b], peaks=self.peaks[:b], edges=at)


def run_blocks(scheme, system, recorder, drv, t, t_end, k, n, H, sliver, controlled):
    """Run the compiled loop ``drv`` from time ``t`` and step count ``k`` to
    ``t_end`` in blocks (``n`` steps of ``H`` when not ``controlled``).

    Returns ``(k, n_rejected, compiled_cpu)``: the steps taken, the tries
    rejected and the process CPU [s] inside the compiled loop's calls.
    Raises as step by step would (:class:`GuardError`, a signal's
    KeyboardInterrupt), with ``scheme.n_windows`` and ``n_rejected`` those
    of the step that stopped it.
    """
    from cosim.core.schemes import _driver_block
    subs = system.subsystems
    emb = sorted(system.embedded.items())
    e_c = np.array([c for c, _ in emb], dtype=np.int_)
    e_host = np.array([hs[0] for _, hs in emb], dtype=np.int_)
    e_slot = np.array([hs[1] for _, hs in emb], dtype=np.int_)
    rows = _Rows(system, BLOCK)
    compiled_cpu = 0.0
    drv.fresh = False               # the rows are copied into the blocks
    while True:
        c0 = time.process_time()
        edges = []
        try:
            m, t, k1, why, error = _driver_block.fill(
                drv, subs, edges, e_c, e_host, e_slot, t, t_end, k, n, H, sliver, controlled,
                *rows.args())
        finally:
            drv.sync()              # the sides' time, steps and switches, kept in C
        compiled_cpu += time.process_time() - c0
        rows.energies(system, m - 1 if why == "nonfinite" else m)
        kept0 = recorder.n_offered
        try:
            rows.record(recorder, m - 1 if why == "nonfinite" else m, edges)
            if why == "nonfinite":
                for j, c, ts, on in edges:      # the step's switches, then its verdict
                    if j == m - 1:
                        recorder.edge(int(c), ts, bool(on))
        except GuardError:
            # the step of the refused sample counts, as step by step
            j = recorder.n_offered - kept0
            scheme.n_windows = k + j + 1
            scheme.n_rejected = int(rows.rej[j])
            raise
        k = k1
        scheme.n_windows = k
        if m:
            scheme.n_rejected = int(rows.rej[m - 1])
        if why == "nonfinite":
            from cosim.core.schemes.step_control import nonfinite_cause
            cause = nonfinite_cause(system, drv.d, drv.dd, drv.f)
            raise GuardError(cause[0] if cause else "non-finite state", float(rows.t[m - 1]),
                             cause[1] if cause else None, "non-finite")
        if why == "raised":         # the step that raised is not counted
            raise error
        if why == "end":
            return k, drv.n_rejected, compiled_cpu
