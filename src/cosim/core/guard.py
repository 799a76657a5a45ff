"""The run guard: stop a run that turns non-finite or creates energy.

At every accepted step the recorder hands the guard the rows'
penetrations, rates and forces and the energy the run has *created* so far,

    created(t) = E(t) + D(t) - S(t) - E(0),

with ``E`` the energy of the subsystems and the contacts' springs, ``D``
what contacts and subsystems dissipated and ``S`` what drives supplied.  An
exact run keeps ``created`` at zero; a coupling that lags (a force held or
extrapolated over a step too long for a stiff contact) makes it grow with
every impact.  The guard stops the run with a :class:`GuardError`, naming the
time and the contact responsible, when

- a penetration, rate, force or the energy is not finite, or
- ``created`` exceeds ``energy_growth`` times the energy scale plus the
  energy supplied so far, and exceeds ``energy_floor`` (1 mJ by default: a
  scene that starts at rest has almost no energy scale at its first step).
  The energy scale is the sum of the magnitudes of each subsystem's energy
  and each contact's stored energy at the start.
  Before it stops a run the guard looks again: the scale becomes the largest
  of that sum, the energy the contacts stored at their peak penetrations so
  far, and the energy they store now plus what they dissipated so far, and
  the run is stopped only if the growth still exceeds the bound.
  (A subsystem's energy may be small while much is in play: a body pushed
  from rest by a constant drive has kinetic energy and an equal and opposite
  potential of the drive; the contact it strikes stores that kinetic
  energy.)  The scale found is kept for the following steps.  The energy now
  is not part of the scale: it holds the energy created.

The contact responsible is the one whose own ledger (the work its forces did
on the subsystems, as the scheme applied them, plus the change of its stored
energy plus what it dissipated: the summary's ``coupling_error``) holds the
largest share of the created energy; when no contact holds half of it, the
message says the rest came from inside the subsystems' integrators.

The guard also stops a run whose contact **chatters**: one contact that
switches (touches or releases) ``chatter_switches`` times while the
simulated time advances by no more than ``chatter_window``.  A solver whose
tolerances are too loose to settle a contact's switch may restart at the
switch again and again without advancing (three_mass f100 under the
monolithic scheme at rtol 0.5 recorded thousands of empty contact intervals
at one instant and never ended); the message names the contact and the
time.  The defaults, 100 switches within 1 us, ask for a contact frequency
above 50 MHz before a physical train of rebounds trips them.


A rigid contact's impacts reach the guard as its side's integrator finds
them (:meth:`Guard.switches_ahead`), not only when the step ends: the
rebounds of a body coming to rest on a rigid contact with restitution
``e < 1`` shorten geometrically and accumulate at a finite time, so the step
that holds that time would never end.  The rule stops such a Zeno train just
before its accumulation time, within ``chatter_window`` of it.

The check costs three sums and two comparisons per step, and one comparison
per contact switch, and nothing else unless it trips.

Below the stop lies a warning level: a run that finishes having created more
than ``energy_warning`` times its energy scale (1 % by default; the largest
created energy over the samples, against the scale the stop would use at the
end), or with a contact whose ``coupling_error`` exceeds ``coupling_warning``
times that scale in magnitude (1 % too), carries ``warnings`` in its summary
(:meth:`Guard.warnings`), each naming the contact and the energy, and the
command line prints them.  Both levels respect ``energy_floor``.  They cost
one comparison per sample (the recorder keeps the largest created energy).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from cosim.core.guard_error import GuardError

__all__ = ["GuardOptions", "Guard", "GuardError", "nonfinite_cause", "energy_scale",
           "peak_stored_energy", "DEFAULT_ENERGY_GROWTH", "DEFAULT_ENERGY_FLOOR",
           "DEFAULT_ENERGY_WARNING", "DEFAULT_COUPLING_WARNING", "DEFAULT_CHATTER_SWITCHES",
           "DEFAULT_CHATTER_WINDOW"]

#: default bound on the created energy, relative to the energy scale
DEFAULT_ENERGY_GROWTH = 0.1
#: [J] default least bound (a scene that starts with next to no energy)
DEFAULT_ENERGY_FLOOR = 1e-3
#: default warning level of the created energy, relative to the energy scale
DEFAULT_ENERGY_WARNING = 0.01
#: default warning level of a contact's |coupling_error|, relative to the energy scale
DEFAULT_COUPLING_WARNING = 0.01
#: default number of switches of one contact that, within the chatter window, stop a run
DEFAULT_CHATTER_SWITCHES = 100
#: [s] default chatter window
DEFAULT_CHATTER_WINDOW = 1e-6


@dataclass(frozen=True)
class GuardOptions:
    """Settings of the run guard (the scene's ``[guard]`` table).

    Parameters
    ----------
    energy_growth : float
        Largest energy a run may create, relative to its energy scale
        (see the module notes), > 0.
    energy_check : bool
        False turns the energy bound off; non-finite values stop a run
        whatever this says.
    energy_floor : float
        Created energy below this never stops a run, nor warns [J], >= 0.
    energy_warning : float
        Created energy that makes a finished run warn, relative to its energy
        scale, > 0 (``inf``: never).
    coupling_warning : float
        A contact's ``|coupling_error|`` that makes a run warn, relative to
        the energy scale, > 0 (``inf``: never).
    chatter_switches : int
        A contact that switches this many times (>= 2) within
        ``chatter_window`` of simulated time chatters, and stops the run.
    chatter_window : float
        [s], >= 0.
    """

    energy_growth: float = DEFAULT_ENERGY_GROWTH
    energy_check: bool = True
    energy_floor: float = DEFAULT_ENERGY_FLOOR
    energy_warning: float = DEFAULT_ENERGY_WARNING
    coupling_warning: float = DEFAULT_COUPLING_WARNING
    chatter_switches: int = DEFAULT_CHATTER_SWITCHES
    chatter_window: float = DEFAULT_CHATTER_WINDOW

    def __post_init__(self):
        g = self.energy_growth
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not (
                math.isfinite(g) and g > 0):
            raise ValueError(f"`energy_growth` must be a finite number > 0, got {g!r}")
        for key in ("energy_warning", "coupling_warning"):
            w = getattr(self, key)
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not w > 0:
                raise ValueError(f"`{key}` must be a number > 0 (inf: never), got {w!r}")
        e = self.energy_floor
        if isinstance(e, bool) or not isinstance(e, (int, float)) or not (
                math.isfinite(e) and e >= 0):
            raise ValueError(f"`energy_floor` must be a finite number >= 0 J, got {e!r}")
        if not isinstance(self.energy_check, bool):
            raise TypeError(f"`energy_check` must be true or false, got {self.energy_check!r}")
        n = self.chatter_switches
        if isinstance(n, bool) or not isinstance(n, int) or n < 2:
            raise ValueError(f"`chatter_switches` must be an integer >= 2, got {n!r}")
        w = self.chatter_window
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not (
                math.isfinite(w) and w >= 0):
            raise ValueError(f"`chatter_window` must be a finite number >= 0 s, got {w!r}")


def energy_scale(system, d) -> float:
    """Sum of the magnitudes of each subsystem's energy and each contact's
    stored energy [J]."""
    return float(sum(abs(s.energy()) for s in system.subsystems)
                 + np.sum(np.abs(system.contact_potentials(d))))


def peak_stored_energy(system, d, peak) -> float:
    """Energy the contacts store at the penetrations ``peak`` (n_contacts,)
    [J], all together; the rows ``d`` give the tangential rows."""
    at_peak = np.array(d, float)
    at_peak[:system.n_contacts] = peak
    return float(np.sum(np.abs(system.contact_potentials(at_peak))))


def nonfinite_cause(system, d, dd, f) -> tuple[str, str | None] | None:
    """What is not finite, in words, and the contact to blame.

    Looks at the rows' penetrations, rates and forces first, then at each
    subsystem's state; returns None when all are finite.  A subsystem whose
    state is not finite is blamed on the contact acting on it that carried
    the largest finite force."""
    for what, arr in (("penetration", d), ("penetration rate", dd), ("force", f)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            r = int(bad[0])
            name = system.row_names[r]
            return (f"the {what} of contact `{name}` is {float(arr[r])!r}",
                    system.contact_names[system.row_contact[r]])
    for s, sub in enumerate(system.subsystems):
        if np.all(np.isfinite(sub.x)):
            continue
        on = [c for c, ln in enumerate(system.links) if s in (ln.sub_a, ln.sub_b)]
        blame = max(on, key=lambda c: abs(float(f[c])) if math.isfinite(f[c]) else -1.0,
                    default=None)
        names = ", ".join(f"`{system.contact_names[c]}`" for c in on) or "none"
        text = f"the state of subsystem `{sub.name}` is not finite (contacts on it: {names}"
        if blame is not None:
            text += (f"; `{system.contact_names[blame]}` carried the largest force, "
                     f"{float(f[blame]):.4g} N")
            return text + ")", system.contact_names[blame]
        return text + ")", None
    return None


class Guard:
    """Stops a run on non-finite values or on energy growth beyond a bound.

    Parameters
    ----------
    system : CoupledSystem
    options : GuardOptions

    Notes
    -----
    :meth:`check` must see the run's first sample first: the energy scale
    and each contact's stored energy are taken then.
    """

    def __init__(self, system, options: GuardOptions = GuardOptions()):
        self.system, self.options = system, options
        self.growth = options.energy_growth if options.energy_check else math.inf
        #: [J] energy scale at the start (None before the first sample)
        self.scale: float | None = None
        self._stored0 = None
        #: per contact, the times of its last ``chatter_switches`` switches
        self._switches = [deque(maxlen=options.chatter_switches)
                          for _ in range(system.n_contacts)]

    def switched(self, c: int, t: float) -> None:
        """Note that contact ``c`` touched or released at ``t`` [s].

        Raises
        ------
        GuardError
            When it has switched ``chatter_switches`` times within
            ``chatter_window`` (it chatters: the run makes no progress).
        """
        ring = self._switches[c]
        ring.append(t)
        self._chatter(c, ring, t)

    def switches_ahead(self, c: int, times) -> None:
        """Raise as :meth:`switched` would if contact ``c`` switched at each
        of ``times`` (ascending, after those noted), without noting them.

        A side's integrator asks this of the switches it has located within
        a step not yet accepted: a train of rigid impacts that accumulates
        at a finite time (a Zeno train) never ends its step, so the guard
        must see it as it happens.

        Raises
        ------
        GuardError
            When contact ``c`` would chatter.
        """
        ring = self._switches[c].copy()
        for t in times:
            ring.append(t)
            self._chatter(c, ring, t)

    def _chatter(self, c, ring, t):
        if len(ring) == ring.maxlen and t - ring[0] <= self.options.chatter_window:
            o = self.options
            name = self.system.contact_names[c]
            raise GuardError(
                f"contact `{name}` chatters: it switched "
                f"{len(ring)} times within {t - ring[0]:.3g} s of simulated time (since "
                f"t = {ring[0]:.6g} s; `guard.chatter_switches` = {o.chatter_switches} within "
                f"`guard.chatter_window` = {o.chatter_window:g} s), so the run would not "
                f"advance. " + (self._RIGID_ADVICE if self.system.links[c].contact.law.rigid
                                else self._ADVICE), t, name, "chatter")

    _ADVICE = ("Tighten the solver's tolerances (`scheme.monolithic.rtol`, `atol`) or reduce "
               "the step; if the switching is physical, raise `guard.chatter_switches` or lower "
               "`guard.chatter_window`.")
    _RIGID_ADVICE = ("Its impacts accumulate, as the rebounds of a body coming to rest on a "
                     "rigid contact with restitution below 1 do (a Zeno train, whose "
                     "accumulation time no threshold passes): a rigid contact cannot hold a "
                     "body at rest; model a lasting contact with a penalty law.")

    def check(self, t: float, d: np.ndarray, dd: np.ndarray, f: np.ndarray, created: float,
              supplied: float, dissipated: np.ndarray, work: np.ndarray | None = None,
              peak: np.ndarray | None = None) -> None:
        """Check one accepted sample.

        Parameters
        ----------
        t : float
            [s]
        d, dd, f : (n_rows,) ndarray
            Penetrations [m], their rates [m/s] and the row forces [N].
        created : float
            Energy created since the start [J] (see the module notes).
        supplied : float
            Energy supplied by drives so far [J].
        dissipated : (n_contacts,) ndarray
            Energy each contact dissipated so far [J].
        work : (n_contacts,) ndarray, optional
            Work each contact's forces did on the subsystems so far [J].
        peak : (n_contacts,) ndarray, optional
            Each contact's largest penetration so far [m].

        Raises
        ------
        GuardError
            When a value is not finite or the created energy exceeds the bound.
        """
        if self.scale is None:
            self._start(t, d, dd, f)
        s = d.sum() + dd.sum() + f.sum()
        # created - created is 0 only for a finite ledger: an infinite one is
        # judged (and stopped) even when the energy bound is off (infinite)
        if s - s != 0 or created - created != 0 or not created <= self._bound(self.scale,
                                                                             supplied):
            self._judge(t, d, dd, f, created, supplied, dissipated, work, peak)

    def check_block(self, t, d, dd, f, created, supplied, dissipated, work=None,
                    peak=None) -> None:
        """:meth:`check` of many samples in order, with the same verdict
        (:func:`cosim.core.guard_block.check_block`)."""
        from cosim.core.guard_block import check_block        # where a side samples
        check_block(self, t, d, dd, f, created, supplied, dissipated, work, peak)

    def warnings(self, created: float, supplied: float, coupling_errors: dict, d,
                 peak=None) -> list[dict]:
        """What a run that did not stop should still say about its accuracy.

        Parameters
        ----------
        created : float
            The largest energy created at any sample [J].
        supplied : float
            Energy supplied by drives by the end [J].
        coupling_errors : dict
            Contact name -> its ledger's ``coupling_error`` at the end [J].
        d : (n_rows,) ndarray
            The last sample's penetrations [m] (the tangential rows' stored
            energy is part of the scale).
        peak : (n_contacts,) ndarray, optional
            Each contact's largest penetration [m].

        Returns
        -------
        list of dict
            One per warning: ``kind`` (``"energy"`` or ``"coupling_error"``),
            ``contact`` (its name, or None), ``energy`` [J], ``level`` [J] and
            ``message``.  The scale is the one the stop uses: the start's,
            raised to the energy the contacts stored at their peaks.
        """
        if self.scale is None:
            return []
        opts, system = self.options, self.system
        scale = self.scale
        if peak is not None and system.n_contacts:
            scale = max(scale, peak_stored_energy(system, d, peak))
        scale += abs(supplied)
        out = []
        level = max(opts.energy_warning * scale, opts.energy_floor)
        if created > level:
            worst = max(coupling_errors, key=coupling_errors.get, default=None)
            contact = worst if worst is not None and coupling_errors[worst] > 0 else None
            text = (f"the run created up to {created:.4g} J ({created / scale:.2%} of the "
                    f"energy scale {scale:.4g} J; warning level `guard.energy_warning` = "
                    f"{opts.energy_warning:g})")
            text += (f"; contact `{contact}` has the largest coupling error at the end, "
                     f"{coupling_errors[contact]:.4g} J" if contact is not None else
                     "; no contact's coupling error is positive at the end")
            out.append({"kind": "energy", "contact": contact, "energy": float(created),
                        "level": float(level), "message": text})
        level = max(opts.coupling_warning * scale, opts.energy_floor)
        for name, err in coupling_errors.items():
            if abs(err) > level:
                out.append({"kind": "coupling_error", "contact": name, "energy": float(err),
                            "level": float(level),
                            "message": f"contact `{name}`'s coupling error is {err:.4g} J "
                                       f"({'created' if err > 0 else 'removed'} by the "
                                       f"coupling; warning level `guard.coupling_warning` = "
                                       f"{opts.coupling_warning:g} of {scale:.4g} J)"})
        return out

    def _bound(self, scale: float, supplied: float) -> float:
        if self.growth == math.inf:
            return math.inf
        return max(self.growth * (scale + abs(supplied)), self.options.energy_floor)

    def _start(self, t, d, dd, f):
        cause = nonfinite_cause(self.system, d, dd, f)
        if cause is not None:
            raise GuardError(f"{cause[0]} at the start",
                             t, cause[1], "non-finite")
        self.scale = energy_scale(self.system, d)
        self._stored0 = self.system.contact_potentials(d)

    def _judge(self, t, d, dd, f, created, supplied, dissipated, work, peak):
        """The slow path: find what tripped the check, and raise (or not)."""
        system = self.system
        cause = nonfinite_cause(system, d, dd, f)
        if cause is not None:
            raise GuardError(cause[0], t, cause[1],
                             "non-finite")
        if not math.isfinite(created):
            raise GuardError(f"the energy ledger is not finite "
                             f"({created!r} J created)", t, None, "non-finite")
        scale = self.scale
        if system.n_contacts:
            scale = max(scale, float(np.sum(np.abs(system.contact_potentials(d)))
                                     + np.sum(np.abs(dissipated))))
            if peak is not None:
                scale = max(scale, peak_stored_energy(system, d, peak))
        self.scale = scale
        bound = self._bound(scale, supplied)
        if created <= bound:
            return                      # more energy is in play than at the start
        text = (f"the energy grew by {created:.4g} J over the "
                f"initial energy plus the energy supplied (bound {bound:.4g} J: "
                f"`guard.energy_growth` = {self.growth:g} of the energy scale "
                f"{scale + abs(supplied):.4g} J)")
        blame = None
        if work is not None and system.n_contacts:
            ledger = (np.asarray(work, float) + system.contact_potentials(d) - self._stored0
                      + np.asarray(dissipated, float))
            c = int(np.argmax(ledger))
            share = float(ledger[c])
            if share >= 0.5 * created:
                blame = system.contact_names[c]
                text += (f"; contact `{blame}` created {share:.4g} J of it (the work of its "
                         f"forces plus its change of stored energy plus what it dissipated)")
            else:
                text += (f"; no contact accounts for it (the largest share, contact "
                         f"`{system.contact_names[c]}`: {share:.4g} J): the rest was created "
                         f"inside the subsystems' own integrators")
        else:
            text += "; the scheme gave no per-contact ledger to attribute it"
        text += (". Reduce the step (`scheme.contact_step` in contact, `scheme.macro_step`), "
                 "use the `implicit` scheme, or, if the growth is physical, raise "
                 "`guard.energy_growth`.")
        raise GuardError(text, t, blame, "energy growth")
