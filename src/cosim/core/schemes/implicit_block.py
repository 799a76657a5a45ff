"""The implicit scheme's macro loop in compiled code, its samples in blocks.

Where the implicit scheme's iterations are compiled
(:meth:`Implicit._compiled_iterations
<cosim.core.schemes.implicit.Implicit._compiled_iterations>`) and the macro
step is not controlled, :class:`cosim.core.schemes._implicit_block.ImplicitBlocks`
takes the macro steps too: the extrapolated forces, the compiled
iterations, the rows, forces and ledgers of each step, its sample written
into preallocated rows that the recorder takes as arrays
(:meth:`~cosim.core.recorder.Recorder.record_block`) and the run guard
judges there, with the verdict of sample by sample (the first sample it
refuses, its message and time).

A connection's switch stays Python's: a block ends at a step after which
one may come (a grasp that closes on touch whose law gives a force, a
``time`` or ``after`` trigger due), the rows before it are recorded in the
modes they were taken in, :meth:`CoupledSystem.switch_modes
<cosim.core.system.CoupledSystem.switch_modes>` decides, and the step is
booked at the next block's head.  A block also ends at the run's end, at the
first step whose rows are not finite (stopped as step by step), or when a
step raised: a signal's KeyboardInterrupt keeps the whole samples before
it and is raised again.  The progress callback is told at each block's end.

:data:`ENABLED` False (or ``COSIM_DRIVER=python``) runs the Python loop of
:meth:`cosim.core.schemes.base.CoSimulationScheme.run`, the reference the
blocks are tested against; so does a recorder that reads the system's live
state at each sample (``reads_live_system``).
"""
from __future__ import annotations

import math
import time

import numpy as np

from cosim.core.guard_error import GuardError

__all__ = ["ENABLED", "BLOCK", "refusal", "run_blocks"]

#: False: the implicit scheme's macro loop stays in Python
ENABLED = True
#: most samples the compiled loop writes before it returns [-]
BLOCK = 256


def refusal(scheme, system, recorder, controlled) -> str | None:
    """Why this implicit run's macro loop stays in Python, or None."""
    from cosim.core.schemes import driver
    if not ENABLED:
        return "the compiled implicit loop is switched off (`implicit_block.ENABLED`)"
    if driver.driver_choice() == "python":
        return f"the Python loop was asked for (`{driver.DRIVER_ENV}=python`)"
    if scheme._kernel is None:
        return "the implicit iterations are not compiled for this system"
    if controlled:
        return "the macro step is controlled (`contact_step`)"
    if getattr(recorder, "reads_live_system", False):
        return "the recorder reads the system at each sample"
    try:
        from cosim.core.schemes import _implicit_block
    except ImportError:
        return "the compiled implicit loop is not built"
    if _replaced(scheme, "advance") or _replaced(scheme, "_advance_compiled"):
        return f"the `advance` of scheme `{scheme.name}` is replaced"
    if system.circles or system.embedded or len(system.coupler) != system.n_contacts:
        return "a contact is not exchanged as a force"
    for ln in system.links:
        if ln.contact.law.name not in _implicit_block.LAW_KINDS:
            return f"contact `{ln.contact.name}` has a law the compiled loop does not evaluate"
    return None


def prepare(scheme, system, recorder):
    """Before the solve's clock: build ``scheme``'s compiled iterations over
    ``system`` (None where the Python reference iterates) and load the
    modules its compiled macro loop takes where :func:`refusal` lets it.
    Returns the iterations' kernel, for the run."""
    import importlib
    if not scheme.compiled_iterations:
        return None
    kernel = scheme._compiled_iterations(system)
    built = scheme.__dict__.get("_kernel", None)
    scheme._kernel = kernel
    try:
        controlled = scheme.contact_step is not None and len(system.exchanged) > 0
        if kernel is not None and refusal(scheme, system, recorder, controlled) is None:
            importlib.import_module("cosim.core.guard_block")
            importlib.import_module("cosim.core.recorder_block")
    finally:
        scheme._kernel = built
    return kernel


def _replaced(scheme, name) -> bool:
    """Whether method ``name`` of ``scheme``'s class is not the implicit
    scheme's own (a test or a user wrapped it): the Python loop calls it."""
    fn = getattr(type(scheme), name)
    return (getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)) != (
        "cosim.core.schemes.implicit", f"Implicit.{name}")


def _contacts(system):
    """:class:`ImplicitBlocks`'s contacts (every one exchanged)."""
    row_a, row_b = system.contact_rows
    cs, out = system.connections, []
    for c, ln in enumerate(system.links):
        law, conn = ln.contact.law, ln.connection
        g = None if conn is None else conn.grasp
        touch = g is not None and conn.close.kind == "touch"
        out.append((int(row_a[c]), int(row_b[c]), system.contact_normals[c],
                    system.contact_offsets[c], _kind(law), law.contact_stiffness,
                    getattr(law, "contact_damping", 0.0), int(system.tangent_row[c]),
                    None if g is None else (g.stiffness, g.damping, g.tangential_stiffness,
                                            g.tangential_damping), touch and cs is not None))
    return out


def _kind(law) -> int:
    from cosim.core.schemes._implicit_block import LAW_KINDS
    return LAW_KINDS[law.name]


def next_trigger(system) -> float:
    """A time below the earliest at which a ``time`` or ``after`` trigger
    known now may be due (:meth:`Trigger.due <couplers.connection.Trigger.due>`
    within its tolerance), inf if none."""
    from couplers.connection import GRASPED, OPEN
    cs, best = system.connections, math.inf
    if cs is None:
        return best
    for c in cs.index:
        conn = cs.connections[c]
        if conn.grasp is None:
            continue
        trig = (conn.close if cs.mode[c] == OPEN else
                conn.release if cs.mode[c] == GRASPED else None)
        at = None if trig is None else trig.at(cs.events)
        if at is not None:
            best = min(best, at - 4e-12 * abs(at) - 4e-15)
    return best


class _Rows:
    """The preallocated rows of one run's blocks."""

    def __init__(self, system, m):
        nr, nc = system.n_rows, system.n_contacts
        self.t = np.zeros(m)
        self.d, self.dd, self.f = np.zeros((m, nr)), np.zeros((m, nr)), np.zeros((m, nr))
        self.imp, self.diss, self.work = np.zeros((m, nc)), np.zeros((m, nc)), np.zeros((m, nc))
        self.internal = np.zeros((m, 2))
        self.x = np.zeros((m, int(system.stacked()[-1])))
        self.pot = np.zeros(m)
        self.its = np.zeros(m, dtype=np.int_)       # iterations so far

    def args(self):
        return (self.t, self.d, self.dd, self.f, self.imp, self.diss, self.internal, self.work,
                self.x, self.pot, self.its)

    def record(self, system, rec, b) -> None:
        """Record rows ``0 .. b - 1``, their energy each side's
        (:meth:`~cosim.core.subsystem.Subsystem.energies`) plus the
        contacts' stored energy, summed as :meth:`CoupledSystem.energy
        <cosim.core.system.CoupledSystem.energy>` sums them."""
        if b <= 0:
            return
        off, e = system.stacked(), 0
        for s, sub in enumerate(system.subsystems):
            e = e + sub.energies(self.x[:b, off[s]:off[s + 1]])
        s = slice(0, b)
        # copies: the recorder keeps some of what it is given, and the rows are reused
        rec.record_block(self.t[s].copy(), self.d[s].copy(), self.dd[s].copy(),
                         self.f[s].copy(), self.imp[s].copy(), self.diss[s].copy(),
                         self.internal[s].copy(), self.work[s].copy(), x=self.x[s].copy(),
                         energy=e + self.pot[s])


def run_blocks(scheme, system, recorder, books, state, t_end, n, H, sliver, h_prev):
    """Run the implicit scheme's macro loop from the start to ``t_end`` in
    blocks (``n`` steps of ``H``).  ``books`` are the run's
    :class:`~cosim.core.schemes.step_control.StepBooks` (the first sample
    recorded), ``state`` its :class:`~cosim.core.schemes.step_control.StepState`.

    Returns ``(k, n_rejected, compiled_cpu)``: the steps taken, 0, and the
    process CPU [s] inside the compiled loop's calls.  Raises as step by
    step would (:class:`GuardError`, :class:`CouplingError`, a side's error,
    a signal's KeyboardInterrupt), with ``scheme.n_windows`` and
    ``n_iterations`` those of the step that stopped it.
    """
    from cosim.core.schemes._implicit_block import ImplicitBlocks
    moving = scheme._kernel_sides
    first = np.cumsum([0] + [sub.n_ports for sub in system.subsystems])
    maps = system.exchange_maps
    sides = [(system.subsystems[s], system.subsystems[s].compiled_side(), maps[s],
              int(first[s])) for s in moving]
    outs = system.outputs()
    p_prev = np.zeros(system.n_contacts)
    p_prev[system.coupler] = books.p_prev       # every contact is exchanged
    loop = ImplicitBlocks(scheme, system, sides, np.concatenate([o[0] for o in outs]),
                          np.concatenate([o[1] for o in outs]), _contacts(system), state.hist,
                          p_prev, h_prev)
    rows = _Rows(system, BLOCK)
    n_it0 = scheme.n_iterations
    k, compiled_cpu = 0, 0.0
    try:
        while True:
            loop.next_trigger = next_trigger(system)
            k0, pending = k, loop.pending_step
            c0 = time.process_time()
            m, k, why, error, t1 = loop.fill(t_end, k, n, H, sliver, *rows.args())
            compiled_cpu += time.process_time() - c0
            scheme.n_iterations = n_it0 + loop.n_iterations
            kept0 = recorder.n_offered
            try:
                rows.record(system, recorder, m)
            except GuardError:
                # the step of the refused sample counts, as step by step
                j = recorder.n_offered - kept0
                scheme.n_windows = k0 - pending + j + 1
                scheme.n_iterations = n_it0 + int(rows.its[j])
                raise
            scheme.n_windows = k
            if why == "switch":
                d, dd, _ = loop.rows
                loop.resume(system.switch_modes(t1, d, dd))
            elif why == "nonfinite":
                from cosim.core.schemes.step_control import nonfinite_cause
                d, dd, f = loop.rows
                cause = nonfinite_cause(system, d, dd, f)
                raise GuardError(cause[0] if cause else "non-finite state", t1,
                                 cause[1] if cause else None, "non-finite")
            elif why == "raised":       # the step that raised is not counted
                raise error
            elif why == "end":
                return k, 0, compiled_cpu
    finally:
        state.hist = loop.history()
        state.f = loop.rows[2]
        state.outs = system.outputs()
