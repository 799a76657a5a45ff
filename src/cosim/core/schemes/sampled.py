"""The macro loop's sampled path: a side whose contacts all have rigid
partners integrates across the output points.

Where every contact is embedded in its moving side against a rigid partner
(no row is exchanged, no surface point follows, no connection switches
modes), the co-simulation adds no coupling error: the communication points
are only the output rate.  The loop of :meth:`CoSimulationScheme.run
<cosim.core.schemes.base.CoSimulationScheme.run>` would still return to
Python at each of them to restart the side's integrator and record one
sample.  Here the side takes many macro steps in one call (its
``sample_steps``: the compiled RK4 kernel restarted at each step exactly as
the loop restarts it, or an adaptive scipy method sampled from its dense
output) and the recorder takes the samples as arrays
(:meth:`~cosim.core.recorder.Recorder.record_block`).  The side returns to
Python at the end, at a full buffer of :data:`BLOCK` samples, or at a
non-finite state.  The switches it locates go with the samples: the RK4
kernel keeps a penalty law's touches and releases in rows (the step's row,
the contact, the time, on or off) and goes on integrating; it returns after
a step in which it told the side of a switch in Python (a rigid law's
impact, resolved there, or a switch past its rows), and an adaptive method
after each switch.  The recorder and the run guard see each step's switches
before its sample, contact by contact, as in the loop.

What the path gives, against the loop:

- RK4: the same steps from the same states (each macro step restarted at
  ``k H`` over ``min(H, t_end - k H)``, first moments from zero), so the same
  states; penetrations, forces and energies are then evaluated on arrays,
  which may differ from the loop's scalar evaluation by round-off.
- an adaptive method: it no longer restarts at each output point, so its
  steps differ, and so do its states, within the integrator's own error
  (its tolerances); the samples are its dense output (it restarts only at
  a switch and at each block of :data:`BLOCK` samples).  The first moments of
  the embedded contacts' forces then run from the block's start, not the
  macro step's: nothing reads them, for no contact is hosted against a
  moving partner.

A signal (Ctrl-C, SIGTERM, SIGHUP) stops the path as it stops the loop:
the compiled kernel looks at the signals within its steps (every 4096 RK4
steps), drops the step it was taking and raises the signal's
KeyboardInterrupt; the side emits the whole macro steps it took before, so
that the run keeps them (status ``interrupted``) within a fraction of a
second, however long the block.

:func:`refusal` says why a run does not take the path (logged at debug
level); :data:`ENABLED` False keeps every run in the loop.
"""
from __future__ import annotations

import logging
import math
import time

import numpy as np

from cosim.core.guard import GuardError, nonfinite_cause

__all__ = ["ENABLED", "BLOCK", "refusal", "run_sampled"]

log = logging.getLogger(__name__)

#: False keeps every run in the macro loop (the reference the path is tested against)
ENABLED = True
#: most samples a side returns at once [-]: its buffers' rows
BLOCK = 2048


def refusal(scheme, system) -> str | None:
    """Why ``scheme`` runs ``system`` in the macro loop and not on the
    sampled path, in words; None when it takes the path."""
    if not ENABLED:
        return "the sampled path is switched off (`cosim.core.schemes.sampled.ENABLED`)"
    if not scheme.explicit:
        return f"scheme `{scheme.name}` iterates its macro steps"
    from cosim.core.schemes.driver import advance_replaced
    if advance_replaced(scheme):
        return f"the `advance` of scheme `{scheme.name}` is replaced"
    if len(system.exchanged):
        names = sorted({system.row_names[r] for r in system.exchanged})
        return f"contacts {names} are exchanged between moving sides"
    if system.followers:
        return "a contact follows a structure's surface"
    if system.connections is not None:
        return "a connection's modes switch at communication points"
    loose = [system.contact_names[c] for c in range(system.n_contacts)
             if c not in system.embedded]
    if loose:
        return f"contacts {loose} are not embedded in a moving side"
    moving = [s for s, sub in enumerate(system.subsystems) if not sub.rigid]
    if len(moving) != 1:
        return f"{len(moving)} moving sides (the path takes one)"
    sub = system.subsystems[moving[0]]
    if (scheme.substeps or {}).get(sub.name, 1) != 1:
        return f"side `{sub.name}` takes sub-steps (multirate)"
    if "sampled_steps" not in sub.capabilities:
        return f"side `{sub.name}` cannot integrate across output points"
    return sub.sampling_refusal()


def run_sampled(scheme, system, t_end: float, recorder) -> dict | None:
    """Run ``system`` to ``t_end`` on the sampled path and return the
    counters :meth:`CoSimulationScheme.run
    <cosim.core.schemes.base.CoSimulationScheme.run>` returns, or None
    (having done nothing) where :func:`refusal` gives a reason."""
    why = refusal(scheme, system)
    if why is not None:
        log.debug("macro loop, not the sampled path: %s", why)
        return None
    H = scheme.macro_step
    cpu0 = time.process_time()
    # what the loop does before its first step
    scheme.preflight(system, t_end)
    scheme._system = system
    scheme._watch_impacts(system, recorder)
    scheme.n_iterations = scheme.n_windows = scheme.n_rejected = 0
    nc = system.n_contacts
    d, dd = system.penetrations(system.outputs())
    f = system.forces(d, dd)
    zero = np.zeros(nc)
    recorder.record(0.0, d, dd, f, zero, zero.copy(), scheme._internal(system), zero.copy())
    n = max(1, math.ceil(t_end / H - 1e-9))
    sliver = 1e-12 * min(H, t_end)
    s = next(i for i, sub in enumerate(system.subsystems) if not sub.rigid)
    emit = _Emitter(system, s, recorder)
    sub = system.subsystems[s]
    k, inside = 0, 0.0
    try:
        while k < n:
            c0 = time.process_time()
            k, why = sub.sample_steps(k, min(n, k + BLOCK), H, t_end, sliver, emit)
            inside += time.process_time() - c0
            scheme.n_windows = k
            if why == "end":
                break
    except BaseException:
        # a signal too (the kernel looks at them within its steps);
        # the loop's count: the steps whose samples were kept, and the step
        # whose sample (or report) was refused; a step that raised is not counted
        scheme.n_windows = recorder.n_offered - (0 if emit.refused else 1)
        raise
    # the side's compiled steps: its calls less the recorder's blocks they called back
    scheme.loop_stats = {"loop": "sampled", "refusal": None, "macro_steps": k,
                         "compiled_cpu_s": inside - emit.cpu,
                         "run_cpu_s": time.process_time() - cpu0}
    return {"n_windows": k, "n_iterations": scheme.n_iterations, "n_rejected": 0}


class _Emitter:
    """Turns a side's :class:`~cosim.core.subsystem.Samples` into the
    recorder's block: the contacts' penetrations, forces, quadratures and
    peaks, the system's energy, and the switches the loop reports before a
    step's sample."""

    def __init__(self, system, s, recorder):
        self.system, self.s, self.recorder = system, s, recorder
        self.sub = system.subsystems[s]
        subs = system.subsystems
        first = np.cumsum([0] + [sub.n_ports for sub in subs])
        self.ports = slice(first[s], first[s + 1])
        # every other side is rigid: its ports stand still
        self.pos = np.concatenate([sub.outputs(sub.t, sub.x)[0] for sub in subs]).reshape(-1, 2)
        self.vel = np.concatenate([sub.outputs(sub.t, sub.x)[1] for sub in subs]).reshape(-1, 2)
        self.off = system.stacked()
        # the other sides' states (a rigid side's may have none)
        self.x_rest = [(self.off[i], self.off[i + 1], sub.x.copy())
                       for i, sub in enumerate(subs) if i != s and self.off[i + 1] > self.off[i]]
        self.slots = np.array([system.embedded[c][1] for c in range(system.n_contacts)],
                              dtype=int)
        self.laws = [ln.contact.law for ln in system.links]
        self.rigid = np.array([law.rigid for law in self.laws], dtype=bool)
        self.order = [(c, slot) for c, (_, slot) in system.embedded.items()]
        # each contact's port on this side and its rigid partner's, which stands still
        row_a, row_b = system.contact_rows
        a_in = (row_a >= first[s]) & (row_a < first[s + 1])
        b_in = (row_b >= first[s]) & (row_b < first[s + 1])
        self.split = bool(np.all(a_in != b_in))
        if self.split:
            mine = np.where(a_in, row_a, row_b) - first[s]
            fixed = np.where(a_in, row_b, row_a)
            run = len(mine) and np.array_equal(mine, np.arange(mine[0], mine[0] + len(mine)))
            self.mine = slice(int(mine[0]), int(mine[0]) + len(mine)) if run else mine
            self.sign = np.where(a_in, 1.0, -1.0)[:, None]      # (a - b): +-(mine - fixed)
            self.fixed_pos, self.fixed_vel = self.pos[fixed], self.vel[fixed]

    #: whether the recorder (or the guard) refused a sample
    refused = False
    #: process CPU spent here, called back from the side's steps [s]
    cpu = 0.0

    def __call__(self, smp, switch_row, located=()) -> None:
        c0 = time.process_time()
        try:
            self._emit(smp, switch_row, located)
        except Exception:
            self.refused = True
            raise
        finally:
            self.cpu += time.process_time() - c0

    def _emit(self, smp, switch_row, located) -> None:
        sysm, nc = self.system, self.system.n_contacts
        m = len(smp.t)
        # CoupledSystem.penetrations, on every sample at once
        normals = sysm.contact_normals
        if self.split:          # side a's port less side b's, one of them still
            dx = (smp.position[:, self.mine] - self.fixed_pos) * self.sign
            dv = (smp.velocity[:, self.mine] - self.fixed_vel) * self.sign
        else:
            pos = np.broadcast_to(self.pos, (m,) + self.pos.shape).copy()
            vel = np.broadcast_to(self.vel, (m,) + self.vel.shape).copy()
            pos[:, self.ports], vel[:, self.ports] = smp.position, smp.velocity
            row_a, row_b = sysm.contact_rows
            dx = pos[:, row_a] - pos[:, row_b]
            dv = vel[:, row_a] - vel[:, row_b]
        d = sysm.contact_offsets - (dx[..., 0] * normals[:, 0] + dx[..., 1] * normals[:, 1])
        dd = -(dv[..., 0] * normals[:, 0] + dv[..., 1] * normals[:, 1])
        f = np.empty((m, nc))
        energy = smp.energy.copy()          # the other sides are rigid: no energy
        for c, law in enumerate(self.laws):
            f[:, c] = law.force(d[:, c], dd[:, c])
        pot = 0
        for c, law in enumerate(self.laws):
            pot = pot + law.potential(d[:, c])
        energy = energy + pot
        quad = smp.quadratures[:, self.slots]
        peaks = np.where(self.rigid[None, :], 0.0, smp.peak[:, self.slots])
        if self.x_rest:
            x = np.empty((m, self.off[-1]))
            x[:, self.off[self.s]:self.off[self.s + 1]] = smp.x
            for a, b, xr in self.x_rest:
                x[:, a:b] = xr
        else:                   # the side's states are the system's: read in place
            x = smp.x
        block = (smp.t, d, dd, f, quad[:, :, 0], quad[:, :, 1], smp.ledger, quad[:, :, 3], x,
                 energy, peaks)
        self._push(block, 0, m, switch_row, located)

    def _edges(self, located) -> dict:
        """Row -> the switches ``(contact, time, on)`` the side kept in its
        rows, in the order :meth:`_report` reports a step's: contact by
        contact, each contact's in the order located (a rigid law's touch
        as its impact, an instant; its release is not an edge)."""
        at = {}
        for row, slot, ts, on in located:
            at.setdefault(row, []).append((slot, ts, on))
        out = {}
        for row, got in at.items():
            edges = []
            for c, slot in self.order:
                for j, ts, on in got:
                    if j != slot:
                        continue
                    if not self.rigid[c]:
                        edges.append((c, ts, on))
                    elif on:
                        edges += [(c, ts, True), (c, ts, False)]
            if edges:
                out[row] = edges
        return out

    def _push(self, block, a, b, switch_row=None, located=()) -> None:
        """Record rows ``a .. b - 1``, the switches the side kept in its rows
        (``located``) and those of the step of row ``switch_row`` reported
        before them (:meth:`_report`, in the recorder's block); stop at a
        non-finite row as the loop does."""
        if b <= a:
            return
        edges = self._edges(located)
        if switch_row is not None:
            edges[switch_row] = self._report
        t, d, dd, f, impulse, diss, ledger, work, x, energy, peaks = block
        ok = np.isfinite(d[a:b]).all(axis=1) & np.isfinite(dd[a:b]).all(axis=1)
        bad = np.flatnonzero(~ok)
        stop = b if not bad.size else a + int(bad[0])
        if stop > a:
            self.recorder.record_block(t[a:stop], d[a:stop], dd[a:stop], f[a:stop],
                                       impulse[a:stop], diss[a:stop], ledger[a:stop],
                                       work[a:stop], x=x[a:stop], energy=energy[a:stop],
                                       peaks=peaks[a:stop],
                                       edges={r - a: e for r, e in edges.items()} or None)
        if stop in edges:               # the loop reports them before it looks at the rows
            if callable(edges[stop]):
                edges[stop]()
            else:
                for c, ts, on in edges[stop]:
                    self.recorder.edge(c, ts, on)
        if stop < b:
            cause = nonfinite_cause(self.system, d[stop], dd[stop], f[stop])
            raise GuardError(cause[0] if cause else "non-finite state", float(t[stop]),
                             cause[1] if cause else None, "non-finite")

    def _report(self) -> None:
        """The switches and impacts of the side's last step, as the loop
        reports them before the step's sample."""
        sysm, sub, rec = self.system, self.sub, self.recorder
        for c, (_, slot) in sysm.embedded.items():
            rigid = sysm.links[c].contact.law.rigid
            for ts, j, on in sub.switch_log:
                if j == slot and not rigid:
                    rec.edge(c, ts, on)
                elif j == slot and on:            # an impact is an instant
                    rec.edge(c, ts, True)
                    rec.edge(c, ts, False)
        if "rigid_impacts" in sub.capabilities:
            rec.impacts += sub.impact_log
            sub.impact_log = []
        sub.switch_log = []
