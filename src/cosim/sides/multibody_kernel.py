"""The contact laws and joint effects of a multibody side as the compiled
kernel ``cosim.sides._multibody_step`` takes them: plain tuples of kinds and
parameters, built once when the kernel is built, or None where the kernel
does not know the law or effect (the numpy reference then steps); the
side's macro steps taken by the kernel across many output points
(:class:`SampledSteps`, for the macro loop's sampled path,
:mod:`cosim.core.schemes.sampled`); the tree's compiled model-exchange face
(:class:`TreeFaceMixin`); and its C face for a scheme that steps it from
compiled code (:class:`CompiledFace`).
:class:`cosim.sides.multibody.MultibodySubsystem` inherits all three."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cosim.core.links import kernel_law     # the numbering every kernel shares

from cosim.core.ode import RK4, ScipyStepper
from cosim.core.subsystem import MOMENT, QUADRATURES, Samples
from cosim.sides.kernel import compiled_module

if TYPE_CHECKING:
    from multibody import JointEffects

__all__ = ["kernel_law", "kernel_effects", "SampledSteps", "TreeFaceMixin", "CompiledFace"]


def kernel_effects(effects: JointEffects | None):
    """Joint effects as the compiled kernel takes them:
    ``(stiffness, rest, damping, drives)``, or None for no effects; raises
    ``TypeError`` for a drive or reference the kernel does not know."""
    if effects is None:
        return None
    # where a tree has effects, multibody.effects is loaded already (a scene built them)
    from multibody.effects import (ConstantTorque, MinimumJerk, PDTracking, Sinusoid, Table,
                                   TorqueTable)
    drives = []
    for d in effects.drives:
        ref_kind, ref_par, ts, vs = 0, (0.0,) * 4, (), ()
        if type(d) is ConstantTorque:
            kind, gains = 0, (d.torque, 0.0, 0.0)
        elif type(d) is TorqueTable:
            kind, gains, ts, vs = 1, (0.0,) * 3, d.torque.times, d.torque.values
        elif type(d) is PDTracking:
            kind, gains, r = 2, (d.kp, d.kd, d.max_torque), d.reference
            if type(r) is Table:
                ts, vs = r.times, r.values
            elif type(r) is MinimumJerk:
                ref_kind, ref_par = 1, (r.start, r.end, r.t_start, r.t_end)
            elif type(r) is Sinusoid:
                ref_kind, ref_par = 2, (r.amplitude, r.frequency, r.phase, r.offset)
            else:
                raise TypeError(f"reference {type(r).__name__}")
        else:
            raise TypeError(f"drive {type(d).__name__}")
        drives.append((d.joint, kind, gains, ref_kind, ref_par, ts, vs))
    return effects.stiffness, effects.rest, effects.damping, drives


#: switches the kernel keeps in its rows in one call of
#: :meth:`SampledSteps.sample_steps` before it hands them to the host one at
#: a time (each then ends the call after its step)
LOCATED = 256


def _located(ST, SJ, n, rows) -> list:
    """The kernel's kept switches ``(row, slot, time, on)`` of rows below ``rows``."""
    return [(int(r), int(j), float(ts), bool(on))
            for ts, (r, j, on) in zip(ST[:n].tolist(), SJ[:n].tolist()) if r < rows]


#: whether an adaptive pair (DOP853, RK45) over the compiled kernel runs in C
#: (``cosim.sides._embedded_rk``); False runs :mod:`cosim.core.embedded_rk`
#: over the kernel's right-hand side, the reference the tests hold it to
COMPILED_PAIRS = True


class SampledSteps:
    """The sampled face of :class:`~cosim.sides.multibody.MultibodySubsystem`
    (a mixin: it reads the side's kernel, state and logs)."""

    #: (kernel, its compiled pairs) of :meth:`_tree_rk`
    _rk = (None, None)

    def _with_pairs(self, kernel):
        """``kernel``, with its compiled pairs (:meth:`_tree_rk`) loaded where it
        steps this side: when the kernel is built, not inside the first solve."""
        if self._kernel_steps:
            self._tree_rk(kernel)
        return kernel

    def _tree_rk(self, kernel):
        """The compiled pairs over ``kernel`` (``cosim.sides._embedded_rk.TreeRK``)
        where the integrator is DOP853 or RK45 and the module is built, else
        None (the numpy pairs over the kernel's right-hand side)."""
        if not COMPILED_PAIRS or not isinstance(self.integrator, ScipyStepper) or \
                self.integrator.method not in ("RK45", "DOP853"):
            return None         # a plug-in integrator is called as the protocol says
        if self._rk[0] is not kernel:
            module = compiled_module("_embedded_rk")
            self._rk = (kernel, None if module is None else module.TreeRK(kernel))
        return self._rk[1]

    def sampling_refusal(self) -> str | None:
        """Why :meth:`sample_steps` cannot take this side's macro steps, or
        None when it can: the compiled kernel steps it, with RK4 or an
        adaptive scipy method."""
        if self._compiled() is None or not self._kernel_steps:
            return (f"side `{self.name}` is stepped by the numpy reference (`COSIM_KERNEL`, or "
                    f"a law, drive, connection or integrator the kernel does not take)")
        if type(self.integrator) is not RK4 and not isinstance(self.integrator, ScipyStepper):
            return f"side `{self.name}`'s integrator is neither RK4 nor an adaptive scipy method"
        return None

    def sample_steps(self, k0: int, k1: int, H: float, t_end: float, sliver: float, emit):
        """Take macro steps ``k0 .. k1 - 1`` (from ``k H`` over
        ``min(H, t_end - k H)``) without a return to Python at each, with
        no input force (every partner of this side is rigid).

        RK4 takes each step as :meth:`step` does, restarted at its start,
        in one call of the kernel; an adaptive method integrates across the
        steps' ends and samples them from its dense output
        (:meth:`cosim.core.ode.ScipyStepper.sample`).  ``emit(samples,
        switch_row, located)`` receives the steps' ends in order as
        :class:`~cosim.core.subsystem.Samples`; ``switch_row`` (or None) is
        the sample before which :attr:`switch_log` and :attr:`impact_log`
        hold switches to report; ``located`` lists the switches the kernel
        kept in its rows without a return to Python (RK4: a penalty law's
        touches and releases), each ``(row, slot, time, on)`` in the order
        located, to report before sample ``row``.  Every sample before a step that raises
        is emitted before the exception goes on, and so is every sample
        before a step that a signal stopped (the kernel looks at the
        signals within its steps: Ctrl-C raises there).

        Returns
        -------
        k : int
            The macro steps taken so far (``k0`` plus those taken).
        why : str
            ``"steps"`` (all taken), ``"end"`` (the next would be a sliver
            of round-off: the run is over), ``"switch"``, ``"nonfinite"``.
        """
        kernel = self._compiled()
        integ = self.integrator
        self.switch_log, self.impact_log = [], []
        self._last_switch = (None, None, None, None)
        if type(integ) is RK4:
            m = k1 - k0
            T = np.empty(m)
            Y = np.empty((m, self.x.size + self.aux.size))
            PK = np.empty((m, len(self._embedded)))
            self.port_moments = np.zeros((3, self.n_ports), complex)
            ST = np.empty(LOCATED)
            SJ = np.empty((LOCATED, 3), dtype=np.int_)
            try:
                rows, why, n_loc = kernel.sample_steps(
                    self.x, self.aux, self._embedded, k0, k1, H, t_end, sliver,
                    integ.max_step, integ.free_step or 0.0, self._on_switch, self.peak, T, Y,
                    PK, self.port_moments, ST, SJ)
            except BaseException as exc:
                # a step that raised (or that Ctrl-C or SIGTERM stopped: the kernel
                # looks at the signals within its steps) is dropped; the whole
                # steps before it are the side's, and emitted
                if isinstance(exc, Exception):
                    self.status = "failed"
                done = kernel.n_sampled
                if done:
                    self._sampled_clock(T, done)
                    emit(self._samples(T[:done], Y[:done], PK[:done]), None,
                         _located(ST, SJ, kernel.n_located, done))
                raise
            if rows:
                self._sampled_clock(T, rows)
                located = _located(ST, SJ, n_loc, rows)
                last = None
                if why in ("switch", "nonfinite"):
                    # the last step (it told the host, or it is the last the
                    # recorder sees): its switches kept in the rows join the
                    # host's log, in the order located
                    last = rows - 1
                    mine = [(ts, j, on) for r, j, ts, on in located if r == last]
                    located = [e for e in located if e[0] != last]
                    self.switch_log = sorted(mine + self.switch_log, key=lambda e: e[0])
                emit(self._samples(T[:rows], Y[:rows], PK[:rows]), last, located)
            return k0 + rows, why
        # the steps' ends k H + min(H, t_end - k H), on arrays (the same
        # roundings as one step at a time), up to a sliver of round-off
        t = np.arange(k0, k1) * H
        h = np.minimum(H, t_end - t)
        short = np.flatnonzero(h <= sliver)
        why = "steps" if not short.size else "end"
        T = t[:short[0] if short.size else None] + h[:short[0] if short.size else None]
        if not T.size:
            return k0, why
        na, nx = self.aux.size, self.x.size
        t0 = k0 * H
        kernel.set_step(t0, T[-1] - t0, None, self._embedded)
        self.aux[MOMENT:-2:len(QUADRATURES)] = 0.0
        y0 = np.concatenate([self.x, self.aux, np.zeros(6 * self.n_ports)])

        refused = []            # the recorder's exceptions: the side itself did not fail

        def out(i0, i1, Yb, Pb):
            # the side stands at the sample whose switches are reported (the
            # loop reports them at the end of their step), else at the last
            row = 0 if self.switch_log else i1 - i0 - 1
            self.x[:] = Yb[row, :nx]
            self.aux[:] = Yb[row, nx:nx + na]
            self._sampled_clock(T[i0:i0 + row + 1], row + 1)
            self.n_steps += i1 - i0 - row - 1
            try:
                emit(self._samples(T[i0:i1], np.ascontiguousarray(Yb), Pb, nx + na),
                     0 if self.switch_log else None, ())
            except BaseException:
                refused.append(True)
                raise

        try:
            y1 = integ.sample(kernel.rhs, t0, y0, T, kernel.switch if self._embedded else None,
                              self._on_switch, self._probe if self._embedded else None,
                              len(self._embedded), out, probe_rows=kernel.sample_penetrations,
                              tree=self._tree_rk(kernel))
        except Exception:
            if not refused:
                self.status = "failed"
            raise
        self.x[:] = y1[:nx]
        self.aux[:] = y1[nx:nx + na]
        self.t = float(T[-1])
        self.port_moments = y1[nx + na:].view(complex).reshape(3, self.n_ports)
        return k0 + len(T), why

    def _sampled_clock(self, T, rows):
        """The clock after ``rows`` more macro steps, ending at ``T[:rows]``."""
        self.t = float(T[rows - 1])
        self.n_steps += rows

    def _samples(self, T, Y, PK, width=None) -> Samples:
        """What a recorder needs at states ``Y`` (rows ``[x, aux]``, or the
        first ``width`` columns of longer rows: read in place, not copied)
        at times ``T``."""
        m, n2, npt = len(T), 2 * self.n_dof, self.n_ports
        P = np.empty((m, 2 * npt, 2))
        E = np.empty(m)
        self._compiled().sample_outputs(Y, P, E)      # reads each row's [q, dq] only
        if width is not None:
            Y = Y[:, :width]
        if self.effects is not None:
            E += np.array([self.effects.potential(Y[j, :self.n_dof]) for j in range(m)])
        ne = len(self._embedded)
        return Samples(T, Y[:, :n2], Y[:, n2:n2 + len(QUADRATURES) * ne].reshape(
            m, ne, len(QUADRATURES)), Y[:, -2:], PK, E, P[:, :npt], P[:, npt:])
class TreeFaceMixin:
    """``compiled_face`` of a :class:`cosim.sides.multibody.MultibodySubsystem`
    (:meth:`cosim.core.subsystem.Subsystem.compiled_face`): the tree's kernel
    (``cosim.sides._tree_face.TreeFace``), or None where the kernel is
    not built or not chosen (``COSIM_KERNEL=numpy``) or does not step the
    side (a user's own drive or integrator: its joint effects are not
    loaded), or was built from older sources without a face; and
    ``energies`` of many states in one compiled call."""

    def compiled_face(self):
        kernel = self._compiled()
        if kernel is None or not self._kernel_steps or not hasattr(kernel, "face"):
            return None
        return kernel.face()

    def energies(self, X):
        """:meth:`energy` at each row of ``X``: the kernel's, row by row in
        one compiled call, where ``energy`` is the kernel's alone (no joint
        effects' potential)."""
        kernel = self._compiled()
        if kernel is None or self.effects is not None:
            return super().energies(X)
        return kernel.energies(X)
class CompiledFace:
    """:meth:`compiled_loop_refusal` and :meth:`compiled_side` of
    :class:`cosim.sides.multibody.MultibodySubsystem`."""

    def compiled_loop_refusal(self) -> str | None:
        """Why the compiled macro loop cannot take this side (words that
        follow its name), or None: its kernel must step it, with RK4, and
        no rigid contact may be embedded here."""
        if self.kernel != "compiled":
            return ("is not stepped by its compiled kernel (a user's law, drive or "
                    "integrator, or a grasp)")
        if type(self.integrator) is not RK4:
            return f"is integrated by {type(self.integrator).__name__}, not RK4"
        if any(e.law.rigid for e in self._embedded):
            return "has a rigid contact (its impacts are resolved in Python)"
        return None

    def compiled_side(self):
        """The compiled kernel, whose ``side_face()`` is its C face
        (:mod:`cosim.core._side_face`), for a scheme that steps this side from
        compiled code, or None where
        the kernel does not step it, where its integrator is not RK4, or where
        a contact is embedded here (its switches call back into Python).  The
        scheme records each such step with :meth:`took_compiled_step`."""
        kernel = self._compiled_step(None)
        integ = self.integrator
        if (kernel is None or self._embedded or type(integ) is not RK4
                or not hasattr(kernel, "configure_side")):     # built before the C face
            return None
        kernel.configure_side(integ.max_step, integ.free_step or 0.0)
        return kernel
