"""Macro-step control of the co-simulation schemes: short steps while an
exchanged contact is closed or about to close, a rejected step retried to
end at the located or predicted onset, the interface error controller, and
the books a step closes when it is accepted.

:class:`StepController` proposes each step, judges it once taken (accept,
or roll back and retry shorter), and on acceptance moves the loop's state
on and books the step (impulse, dissipation and work ledgers, switch edges,
the recorder's sample).  All that the loop carries from one communication
point to the next is one small structure, :class:`StepState`, so that a
compiled driver can mirror it field for field.
"""
from __future__ import annotations

import numpy as np

from cosim.core.guard import GuardError, nonfinite_cause

__all__ = ["StepState", "StepController", "LAND_MARGIN", "ONSET_WINDOW", "onset_contacts",
           "watch_impacts"]

#: a contact step over which an exchanged contact closes is retried to end
#: this fraction of ``contact_step`` before the predicted onset
#: (``land_onsets``): the contact then closes at the next step's start, not at
#: a phase of the step that changes with the step
LAND_MARGIN = 1e-5

#: a coupler contact open at a step's start that its gap rate closes within
#: this fraction of ``contact_step`` is at its onset: the next step takes its
#: force from the law's value at touch-down (``land_onsets``)
ONSET_WINDOW = 1e-4


class StepState:
    """What the macro loop carries from one communication point to the next.

    Attributes
    ----------
    outs : list
        Every subsystem's port outputs at the current point.
    f : (n_rows,) array
        The row forces there [N].
    hist : list of (n_rows,) arrays
        The last (up to three) forces, oldest first, that the inputs of the
        next step are extrapolated from.
    outs_prev : list or None
        The outputs at the point before the current one.
    dd_prev : (n_rows,) array or None
        The penetration rates at the point before the current one [m/s].
    h_prev_step : float or None
        The length of the last accepted step [s].
    h_next : float or None
        The length a rejected step asks the next proposal to take [s].
    aimed : bool
        The current step ends at a predicted onset: accept it as it is.
    unconverged : bool
        The implicit scheme's last (long) step found no fixed point.
    h_adapt : float or None
        The step in contact under interface error control [s].
    f_scale : (n_rows,) array or None
        The largest force seen per row [N] (interface error control).
    """

    __slots__ = ("outs", "f", "hist", "outs_prev", "dd_prev", "h_prev_step", "h_next", "aimed",
                 "unconverged", "h_adapt", "f_scale")

    def __init__(self):
        self.outs = self.f = self.outs_prev = self.dd_prev = None
        self.h_prev_step = self.h_next = self.h_adapt = self.f_scale = None
        self.hist = []
        self.aimed = self.unconverged = False


class StepController:
    """The macro-step control of one run of a co-simulation scheme.

    Parameters
    ----------
    scheme : CoSimulationScheme
        Gives the options (``macro_step``, ``contact_step``,
        ``interface_tolerance``, ``extrapolation_order``).
    system : CoupledSystem
    state : StepState
        The loop's state, which this controller reads and moves on.
    """

    def __init__(self, scheme, system, state: StepState):
        self.scheme, self.system, self.state = scheme, system, state
        #: land each contact step on the onsets inside it (``land_onsets``)
        self.land = bool(getattr(scheme, "land_onsets", False))
        self.macro_step = scheme.macro_step
        self.contact_step = scheme.contact_step
        #: how far ahead [s] a contact predicted to close shortens the step
        self.horizon = scheme.horizon
        self.interface_tolerance = scheme.interface_tolerance
        self.extrapolation_order = scheme.extrapolation_order

    # ------------------------------------------------------------ propose
    def propose(self, d, dd, f, remaining):
        """The next macro step: the onset found by a rejected step, else
        ``contact_step`` while a coupler contact is closed or would close
        within ``approach_horizon`` (default: a long step; penetration
        predicted linearly), else
        ``macro_step``."""
        st = self.state
        if st.h_next is not None:
            h, st.h_next = st.h_next, None
            return min(h, remaining)
        system = self.system
        c = system.exchanged
        H = self.macro_step
        # short steps while a contact is closed, was closed a step ago (so the
        # extrapolation history is clear of force before the step grows), or
        # would close within a long step
        recent = len(st.hist) > 1 and np.any(st.hist[-2][c] != 0)
        normal = c[c < system.n_contacts]
        if np.any(system.in_touch(f)[system.row_contact[c]]) or recent \
                or np.any(d[normal] + self.horizon * dd[normal] > 0):
            h = self.contact_step
            if self.interface_tolerance and st.h_adapt is not None:
                h = st.h_adapt
            return min(h, remaining)
        st.h_adapt = None               # contacts open: start again from contact_step
        return min(H, remaining)

    # -------------------------------------------------------------- judge
    def judge(self, d, dd, d1, dd1, f1, stepped, predicted, outs, t, h):
        """Whether the step over ``[t, t + h]`` just taken must be retried:
        ``(h_retry, aimed)`` if so, else None.  ``d``, ``dd`` are the rows at
        its start, ``d1``, ``dd1``, ``f1`` at its end, ``stepped`` the impulse
        the coupler forces gave, ``predicted`` the forces predicted at its end
        (interface error control) or None, ``outs`` the outputs at its end."""
        st, system = self.state, self.system
        if predicted is not None and not st.aimed:
            for c, view in system.hosted_view_forces(outs).items():
                predicted[c] = view
            h_new = self.error_control(f1, predicted, h)
            if h_new is not None:           # the interface error is too large
                return h_new, None
        if h > self.contact_step:
            if st.unconverged:              # an implicit step found no fixed point
                return 0.5 * h, False
            if not st.aimed:
                onset = self.onset(d, dd, d1, dd1, t, h)
                if onset is None and self.touched(stepped):
                    onset = 0.5 * h, False
                return onset
            return self.overshot(d, d1, dd1, h)     # the predicted onset may come too late
        if self.land:
            if st.unconverged:              # a landing step found no fixed point
                return 0.5 * h, False
            if not st.aimed:
                return self.landing(d, dd, d1, dd1, t, h)
        return None

    def landing(self, d0, dd0, d1, dd1, t, h):
        """The step to retry a contact step with when an exchanged contact
        closed inside it (``land_onsets``): ending :data:`LAND_MARGIN` times
        ``contact_step`` after the onset its host located, or as long before
        the onset predicted for a coupler contact (:meth:`onset`), so that
        every onset falls at a step's end whatever the step; None where
        none closed, where an onset is not predicted, or where it lies within
        :data:`ONSET_WINDOW` of the start (the contact is at its onset
        there already)."""
        onset = self.onset(d0, dd0, d1, dd1, t, h)
        if onset is None or not onset[1]:
            return None
        # past a located onset (its host sees it inside the step, not at
        # the step's end give or take round-off), short of a predicted one
        tau = onset[0] + (LAND_MARGIN if self.hosted_closed() else -LAND_MARGIN) \
            * self.contact_step
        return (tau, True) if tau > ONSET_WINDOW * self.contact_step else None

    def hosted_closed(self) -> bool:
        """Whether a hosted contact closed in the step just taken (its host
        located the onset)."""
        system = self.system
        return any(on and j == slot for c, (host, slot, _, _, _) in system.hosted.items()
                   for _, j, on in system.subsystems[host].switch_log)

    def at_onset(self, d, dd, f, f_was, aimed) -> np.ndarray:
        """The coupler contacts that start the next step at their onset
        (``land_onsets``): open, and closed by their gap rate within
        :data:`ONSET_WINDOW` times ``contact_step``; after a step aimed at an
        onset, also those that closed in it."""
        return onset_contacts(self.system, self.contact_step, d, dd, f, f_was, aimed)


    def retry(self, saved, h_retry, aimed) -> None:
        """Roll the system back to ``saved`` and ask for a step of ``h_retry``
        (ending at a predicted onset when ``aimed``; None keeps the flag)."""
        system, st = self.system, self.state
        system.set_state(saved)
        system.discard_work()
        st.h_next = h_retry
        if aimed is not None:
            st.aimed = aimed
        st.outs = system.outputs()

    def accept(self, dd, h, outs, f) -> None:
        """Move the state on past an accepted step of length ``h``: ``dd`` the
        rates at its start, ``outs`` and ``f`` the outputs and forces at its
        end."""
        st = self.state
        st.aimed = False
        st.dd_prev, st.h_prev_step = dd.copy(), h
        st.outs_prev = st.outs
        st.outs, st.f = outs, f
        st.hist = (st.hist + [f])[-3:]

    # --------------------------------------------------- interface error
    def error_control(self, f, predicted, h):
        """Interface error estimate (predictor against corrector): the
        largest difference between the force each exchanged contact was
        predicted to carry at the step's end and the force it carries,
        relative to the largest force it has carried so far.  Returns a
        shorter step to retry with when it exceeds ``interface_tolerance``,
        else None, and sets the next contact step from it (Schierz, Arnold
        and Clauss 2012: elementary controller on the extrapolation error,
        whose order is ``extrapolation_order + 1``).  The step in contact
        stays between ``contact_step / 64`` and ``contact_step``."""
        st = self.state
        c = self.system.exchanged
        if st.f_scale is None:
            st.f_scale = np.zeros(self.system.n_rows)
        st.f_scale[c] = np.maximum(st.f_scale[c], np.abs(f[c]))
        scale = np.maximum(st.f_scale[c], 1e-300)
        err = float(np.max(np.abs(f[c] - predicted[c]) / scale)) if len(c) else 0.0
        if not np.any(st.f_scale[c] > 0):
            return None
        tol, p = self.interface_tolerance, self.extrapolation_order + 1
        fac = 2.0 if err == 0 else min(2.0, max(0.2, 0.9 * (tol / err) ** (1.0 / (p + 1))))
        floor = self.contact_step / 64.0
        if err > tol and h > floor * (1 + 1e-9):
            return max(fac * h, floor)
        # never above contact_step: an end-point estimate cannot see a
        # contact that opens and closes again inside a longer step
        st.h_adapt = min(max(fac * h, floor), self.contact_step)
        return None

    # ------------------------------------------------------------- onsets
    def onset(self, d0, dd0, d1, dd1, t, h):
        """Length of the step to retry after an exchanged contact closed
        inside a step of length ``h``, and whether it ends at the onset;
        None if no contact closed in the step.

        A hosted contact's onset was located by its host's integrator: the
        retried step ends there and is accepted.  For a coupler contact, the
        end state of the rejected step already holds the contact's response,
        so the onset is predicted from the free motion before it:
        ``d0 + dd0 tau + a tau^2 / 2 = 0``, the relative acceleration ``a``
        from the last two outputs (exact under a constant push).  When every
        closing contact has a root inside the step, the retried step ends
        at the earliest and is accepted as it is.  Otherwise (no history
        yet, or no root) it is half the step, or the earliest root if
        sooner, and it is checked again like any long step: a guess must
        not carry a contact through its onset with the force still at zero."""
        system, st = self.system, self.state
        hosted = [ts - t for c, (host, slot, _, _, _) in system.hosted.items()
                  for ts, j, on in system.subsystems[host].switch_log if j == slot and on]
        if hosted:
            return max(min(hosted), 1e-12 * h), True
        c = system.coupler
        closing = c[(d0[c] <= 0) & (d1[c] > 0)]
        if not len(closing):
            return None
        found, all_found = [], True
        for i in closing:
            a = 0.0
            if st.dd_prev is not None:
                a = (dd0[i] - st.dd_prev[i]) / st.h_prev_step
            roots = np.roots([0.5 * a, dd0[i], d0[i]]) if a else (
                [-d0[i] / dd0[i]] if dd0[i] > 0 else [])
            tau = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and
                   0 < r.real < h]
            found += tau
            all_found = all_found and bool(tau)
        if all_found:
            return max(min(found), 1e-12 * h), True
        return max(min([0.5 * h, *found]), 1e-12 * h), False

    def touched(self, stepped) -> bool:
        """Whether a long step gave a coupler contact open at its start a
        force: the contact touched inside the step, though it may be open
        again at the end (Gauss-Seidel's force interpolated towards a partner
        that has stepped, an implicit iterate), and the step must be
        shortened like one over an onset."""
        r = self.system.coupler_rows
        return bool(np.any((self.state.f[r] == 0.0) & (stepped[r] != 0.0)))

    def overshot(self, d0, d1, dd1, h):
        """Check a step aimed at a predicted coupler onset: the prediction
        (free motion with a constant relative acceleration) can fall late when
        a side vibrates, and the step then carries the contact closed with no
        force in it.  When a coupler contact closed more than ``contact_step``
        before the step's end (its penetration over its rate, the time since
        touch-down at that rate), returns half the step, to be checked again
        like any long step; else None."""
        c = self.system.coupler
        late = (d0[c] <= 0) & (d1[c] > np.maximum(dd1[c], 0.0) * self.contact_step)
        if np.any(late):
            return 0.5 * h, False
        return None


def onset_contacts(system, contact_step, d, dd, f, f_was, aimed) -> np.ndarray:
    """:meth:`StepController.at_onset` (the compiled loop calls it too)."""
    c = np.asarray(system.coupler)
    c = c[c < system.n_contacts]
    w = ONSET_WINDOW * contact_step
    hit = (d[c] <= 0) & (d[c] + w * dd[c] > 0)
    if aimed:
        hit |= (f[c] != 0) & (f_was[c] == 0)
    return c[hit]


class StepBooks:
    """The ledgers of a run, booked at each accepted step, and its samples.

    Parameters
    ----------
    scheme : CoSimulationScheme
    system : CoupledSystem
    recorder : Recorder
    f, d, dd : (n_rows,) arrays
        Forces and rows at the start.
    """

    def __init__(self, scheme, system, recorder, f, d, dd):
        nc = system.n_contacts
        self.scheme, self.system, self.recorder = scheme, system, recorder
        self.impulse, self.diss, self.work = np.zeros(nc), np.zeros(nc), np.zeros(nc)
        self.p_prev = system.dissipation_rates(f, d, dd)[system.coupler]

    def start(self, d, dd, f) -> None:
        """Record the initial sample."""
        self.recorder.record(0.0, d, dd, f, self.impulse, self.diss,
                             self.scheme._internal(self.system), self.work)

    def book(self, t1, h, d, dd, f, stepped) -> None:
        """Book the accepted step of length ``h`` ending at ``t1`` with rows
        ``d``, ``dd`` and forces ``f`` there; ``stepped`` the impulse the
        coupler forces gave each contact's side ``a`` over it.  Raises
        :class:`~cosim.core.guard.GuardError` on a non-finite state."""
        system, recorder = self.system, self.recorder
        coupler = system.coupler
        impulse, diss = self.impulse, self.diss
        self.work += system.exchange_work()
        if len(coupler):
            impulse[coupler] += stepped[coupler]
            p_now = system.dissipation_rates(f, d, dd)[coupler]
            diss[coupler] += 0.5 * h * (self.p_prev + p_now)
            self.p_prev = p_now
        emb = system.embedded_quadratures()
        for c, (s, slot) in system.embedded.items():
            impulse[c], diss[c] = emb[c]
            sub = system.subsystems[s]
            rigid = system.links[c].contact.law.rigid
            for ts, j, on in sub.switch_log:
                if j == slot and not rigid:
                    recorder.edge(c, ts, on)
                elif j == slot and on:            # an impact is an instant
                    recorder.edge(c, ts, True)
                    recorder.edge(c, ts, False)
        for s in self.scheme._moving(system):
            sub = system.subsystems[s]
            if "rigid_impacts" in sub.capabilities:
                recorder.impacts += sub.impact_log
        if not (np.isfinite(d).all() and np.isfinite(dd).all()):
            cause = nonfinite_cause(system, d, dd, f)
            raise GuardError(cause[0] if cause else "non-finite state", t1,
                             cause[1] if cause else None, "non-finite")
        recorder.record(t1, d, dd, f, impulse, diss, self.scheme._internal(system),
                        self.work + system.embedded_work())

    def book_driven(self, t1, drv) -> None:
        """:meth:`book` for a step the compiled loop took (``drv``, a
        ``cosim.core.schemes._driver.Driver``), which kept the ledgers: the
        switches its sides located become edges, and the sample is recorded."""
        system, recorder = self.system, self.recorder
        for c, (s, slot) in system.embedded.items():
            for ts, j, on in system.subsystems[s].switch_log:
                if j == slot:           # the compiled loop takes no rigid contact
                    recorder.edge(c, ts, on)
        d, dd, f = drv.d, drv.dd, drv.f
        if not drv.finite:
            cause = nonfinite_cause(system, d, dd, f)
            raise GuardError(cause[0] if cause else "non-finite state", t1,
                             cause[1] if cause else None, "non-finite")
        recorder.record(t1, d, dd, f, drv.impulse, drv.diss,
                        (drv.internal_dissipated, drv.internal_supplied), drv.work_rec)


def watch_impacts(system, recorder) -> None:
    """Let the run guard see each rigid impact as a side's integrator
    resolves it: the switches of the step so far after those it noted
    (:meth:`~cosim.core.guard.Guard.switches_ahead`; an impact is a touch
    and a release at one instant).  A train of impacts that accumulates
    at a finite time would otherwise never end its step."""
    guard = getattr(recorder, "guard", None)
    rigid = {}                       # subsystem -> {embedded slot: contact}
    for c, (s, slot) in system.embedded.items():
        if system.links[c].contact.law.rigid:
            rigid.setdefault(s, {})[slot] = c
    for s, slots in rigid.items():
        sub = system.subsystems[s]
        if "impact_watch" not in sub.capabilities:
            continue
        sub.impact_watch = None
        if guard is None:
            continue
        keep = guard.options.chatter_switches // 2 + 1    # impacts that can trip it

        def watch(t, sub=sub, slots=slots):
            for slot, c in slots.items():
                times = [ts for ts, j, on in sub.switch_log if j == slot and on][-keep:]
                if times and times[-1] == t:
                    guard.switches_ahead(c, [x for ts in times for x in (ts, ts)])
        sub.impact_watch = watch
