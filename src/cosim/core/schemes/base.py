"""Base classes of coupling schemes: :class:`CouplingScheme` (options,
counters) and :class:`CoSimulationScheme`, the macro-step loop the
co-simulation schemes share.  Its macro-step control and the books of a step
are in :mod:`cosim.core.schemes.step_control`, the extrapolation of the inputs over
a step in :mod:`cosim.core.schemes.extrapolation`."""
from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from typing import Any, Callable, ClassVar, NamedTuple

import numpy as np

from cosim.core import preflight
from cosim.errors import CouplingError, UnsafeStepError
from cosim.core.preflight import stiffest_normal
from cosim.core.schemes import driven_block, driver
from cosim.core.schemes.extrapolation import InputExtrapolation, extrapolation_coeffs
from cosim.core.schemes.step_control import (StepBooks, StepController, StepState,
                                              watch_impacts)
from cosim.core.subsystem import reparametrised

__all__ = ["Option", "CouplingScheme", "CoSimulationScheme", "UnsafeStepError", "CouplingError",
           "extrapolation_coeffs"]


class Option(NamedTuple):
    """A scheme option: its type, default, check and the rule it states."""

    kind: type
    default: Any
    check: Callable[[Any], bool]
    rule: str


def _pos(v):
    return v > 0 and math.isfinite(v)


#: the smallest relative tolerance a scheme accepts: float64's machine
#: epsilon, the finest relative difference it resolves; a tolerance below it
#: could never be met, and an iteration held to it only runs out its count
MIN_RELATIVE_TOLERANCE = float(np.finfo(float).eps)


def _relative(v):
    return math.isfinite(v) and v >= MIN_RELATIVE_TOLERANCE


#: the rule of a relative tolerance, as an error states it
RELATIVE_RULE = (f">= {MIN_RELATIVE_TOLERANCE:.3g} (relative; float64 resolves no finer, "
                 f"`cosim.core.schemes.base.MIN_RELATIVE_TOLERANCE`)")

#: the smallest ``rtol`` scipy's ``solve_ivp`` honours: it raises a smaller
#: one to ``100 eps`` (with a warning) and runs at that, so a scene asking
#: less would be run at another tolerance than it says (the rule holds for
#: every method, cosim's own pairs included, so a tolerance means the same
#: whichever solver runs it)
MIN_SOLVER_RTOL = 100 * MIN_RELATIVE_TOLERANCE


def _solver_rtol(v):
    return math.isfinite(v) and v >= MIN_SOLVER_RTOL


#: the rule of a solver's ``rtol``, as an error states it
SOLVER_RTOL_RULE = (f">= {MIN_SOLVER_RTOL:.3g} (100 machine epsilons: scipy's solvers raise a "
                    f"smaller rtol to it)")


#: j + 1 for the rows j of force polynomials: int s^j ds over [0, 1] is 1 / (j + 1)
_POWERS_PLUS_ONE = np.arange(1.0, 9.0)[:, None]


def _substeps_ok(v) -> bool:
    return isinstance(v, dict) and all(
        isinstance(k, str) and isinstance(n, int) and not isinstance(n, bool) and n >= 1
        for k, n in v.items())


class _Topology(NamedTuple):
    """The layout of a coupled system as the macro loop reads it."""

    system: Any
    #: indices of the subsystems that move (not rigid)
    moving: list
    #: per subsystem, the coupler rows with it on a side
    rows: tuple


class CouplingScheme(ABC):
    """A way of advancing a :class:`~cosim.core.system.CoupledSystem` in time.

    Subclasses declare ``name`` and the option names they accept in
    ``options``; :meth:`run` fills a :class:`~cosim.core.recorder.Recorder` and
    returns the counters ``n_windows``, ``n_iterations``, ``n_rejected``.
    """

    name: ClassVar[str] = ""
    #: option name -> Option; the scene loader validates them.
    options: ClassVar[dict] = {}
    explicit: ClassVar[bool] = False
    #: whether the compiled macro loop (:mod:`cosim.core.schemes.driver`) knows
    #: this class's algorithm; read from the class itself, never inherited (a
    #: subclass may change the algorithm): Jacobi and Gauss-Seidel declare it
    compiled_loop: ClassVar[bool] = False
    #: counters so far, kept as a run goes (a run that stops early reports them)
    n_windows: int = 0
    n_iterations: int = 0
    n_rejected: int = 0

    def counters(self) -> dict:
        """The counters so far: ``n_windows``, ``n_iterations``, ``n_rejected``."""
        return {"n_windows": self.n_windows, "n_iterations": self.n_iterations,
                "n_rejected": self.n_rejected}

    def __init__(self, **opts):
        unknown = set(opts) - set(self.options)
        if unknown:
            raise TypeError(f"scheme `{self.name}` takes no options {sorted(unknown)}; "
                            f"valid options are {sorted(self.options)}")
        for key, opt in self.options.items():
            value = opts.get(key, opt.default)
            if value is not None and not opt.check(value):
                raise ValueError(f"`{key}` of scheme `{self.name}` must be {opt.rule}, "
                                 f"got {value!r}")
            setattr(self, key, value)

    def preflight(self, system, t_end: float = math.inf) -> None:
        """Refuse, before anything is written, a scheme setting that cannot
        work on ``system`` over a run to ``t_end`` [s]
        (:class:`~cosim.errors.UnsafeStepError`).  Nothing to refuse here; the
        co-simulation schemes check their steps against the contacts."""

    def prepare(self, system, t_end: float, recorder) -> None:
        """Do before the solve's clock starts what a :meth:`run` of ``system``
        to ``t_end`` [s] into ``recorder`` would do at its start, once: build
        the sides' compiled kernels, load the modules its loop takes
        (:func:`cosim.scene.run.simulate` calls it; a ``run`` without it does
        the same itself, inside its solve).  Nothing here."""

    @abstractmethod
    def run(self, system, t_end: float, recorder) -> dict:
        """Advance the system to ``t_end``, recording as it goes."""


class CoSimulationScheme(InputExtrapolation, CouplingScheme):
    """Macro-step loop shared by the co-simulation schemes.

    Contacts placed ``coupler`` are exchanged as forces: at each
    communication point the scheme computes them from the subsystems'
    outputs and hands each side a force polynomial for the next step;
    :meth:`advance` decides which.
    """

    options: ClassVar[dict] = {
        "macro_step": Option(float, None, _pos, "> 0 s"),
        "extrapolation_order": Option(int, 0, lambda v: v in (0, 1, 2), "0, 1 or 2"),
        "max_energy_gain": Option(float, 0.01, lambda v: v >= 0 and math.isfinite(v), ">= 0"),
        "accept_unsafe_step": Option(bool, False, lambda v: True, "true or false"),
        "contact_step": Option(float, None, _pos, "> 0 s"),
        "approach_horizon": Option(float, None, _pos, "> 0 s"),
        "interface_tolerance": Option(float, None, _relative, RELATIVE_RULE),
        "land_onsets": Option(bool, True, lambda v: True, "true or false"),
        "substeps": Option(dict, None, _substeps_ok,
                           "a table of subsystem name = number of sub-steps (>= 1)"),
    }

    def prepare(self, system, t_end: float, recorder) -> None:
        # the sides' kernels, the compiled loop's or the sampled path's modules
        driver.prepare(self, system, recorder)

    @property
    def horizon(self) -> float:
        """How far ahead [s] a contact predicted to close shortens the step to
        ``contact_step``: ``approach_horizon``, else ``macro_step``."""
        return self.approach_horizon or self.macro_step

    def preflight(self, system, t_end: float = math.inf) -> None:
        """Refuse a macro step that is too large for a contact's stiffness.

        A step longer than the run (``t_end`` [s]) is judged as the one step
        to ``t_end`` that it is."""
        if not self.explicit or self.accept_unsafe_step:
            return
        given = self.contact_step or self.macro_step     # the step used while in contact
        H = min(given, t_end)
        which = "contact_step" if self.contact_step else "macro_step"
        step = (f"macro step {H:.3g} s" if H == given else
                f"macro step {H:.3g} s (the whole run: `scheme.{which}` = {given:.3g} s is "
                f"longer)")
        checked, refused = [], None        # every contact the step is judged on; the first refused
        for c in system.coupler:
            ln = system.links[c]
            mob = system.contact_mobility(c)
            if mob <= 0:
                continue
            m, (k, cd) = 1.0 / mob, stiffest_normal(ln)     # the law's, or a grasp's
            if not (math.isfinite(k) and math.isfinite(cd)):
                raise UnsafeStepError(
                    f"contact `{ln.contact.name}`: law `{ln.contact.law.name}` has no "
                    f"linearised stiffness, so the pre-flight check cannot judge {step} of "
                    f"scheme `{self.name}`; give the law a "
                    f"`reference_penetration`, use the `implicit` scheme, or set "
                    f"`scheme.accept_unsafe_step = true`")
            problem = (m, k, cd, self.extrapolation_order, self.max_energy_gain,
                       self._partner_first(system, c))
            checked.append(problem)
            if refused is None and not preflight.is_safe(m, k, cd, H, *problem[3:]):
                refused = (ln, problem)
        if refused is None:
            return
        ln, (m, k, cd, order, allowed, partner_first) = refused
        hmax = preflight.largest_safe_step(m, k, cd, H, order, allowed, partner_first)
        gain = preflight.contact_energy_gain(m, k, cd, H, order, partner_first)
        # the advice holds for every contact the check judges, not the first alone
        advised = preflight.advised_step(checked, H)
        fix = ("Use the `implicit` scheme, " if advised <= 0 else
               f"Set `scheme.{which}` to {advised:.2g} s or less"
               + ("" if which == "contact_step" else
                  " (or `scheme.contact_step` to it, which keeps the longer steps away "
                  "from contact)")
               + ", use the `implicit` scheme, ")
        raise UnsafeStepError(
            f"contact `{ln.contact.name}`: {step} is too large for scheme "
            f"`{self.name}` (extrapolation order {order}; the step is `scheme.{which}`): contact "
            f"frequency omega = {math.sqrt(k / m):.4g} rad/s with reduced mass {m:.4g} kg; "
            f"one contact would change the energy by a factor {gain:.4g} "
            f"(allowed 1 + {allowed:g}). The largest safe macro step is "
            f"{hmax:.3g} s. {fix}or set `scheme.accept_unsafe_step = true` to run anyway.")

    def _partner_first(self, system, c) -> bool:
        return False

    def partner_first(self, system, c) -> bool:
        """Whether contact ``c``'s partner side takes its step first under this
        scheme (:func:`cosim.core.preflight.partner_first`): what the
        pre-flight check passes on as ``partner_first``."""
        return self._partner_first(system, c)

    @abstractmethod
    def advance(self, system, t: float, h: float, ratio: float) -> np.ndarray:
        """Step every subsystem over [t, t + h]; return the impulse [N s] the
        coupler forces gave each contact's side ``a`` (n_contacts,), for the
        impulse ledger."""

    def run(self, system, t_end, recorder):
        H = self.macro_step
        if H is None:
            raise ValueError(f"scheme `{self.name}` needs `macro_step` [s]")
        if not len(system.exchanged):       # all partners rigid: perhaps no loop at all
            from cosim.core.schemes.sampled import run_sampled
            done = run_sampled(self, system, t_end, recorder)
            if done is not None:
                return done
        self.preflight(system, t_end)
        cpu0 = time.process_time()
        self._system = system
        self._watch_impacts(system, recorder)
        self.n_iterations = self.n_windows = self.n_rejected = 0
        st = self._state = StepState()
        ctl = StepController(self, system, st)
        outs = system.outputs()
        d, dd = system.penetrations(outs)
        f = system.forces(d, dd)
        st.outs, st.f = outs, f
        # a step longer than the run is one step to t_end, as the history and sliver see it
        st.hist = self._starting_history(system, d, dd, f, min(H, t_end))
        books = StepBooks(self, system, recorder, f, d, dd)
        books.start(d, dd, f)
        controlled = self.contact_step is not None and len(system.exchanged) > 0
        n = max(1, math.ceil(t_end / H - 1e-9))
        # what is left of the run below this is round-off, not a step: relative to the shorter
        # of the step and the run (to a step longer than t_end alone, the run would be a sliver)
        sliver = 1e-12 * min(H, t_end)
        h_prev = min(H, t_end)
        k, t, n_rejected = 0, 0.0, 0
        drv = self._compiled_loop(system, st, d, dd, controlled, h_prev)
        compiled_cpu = 0.0                      # the compiled loop, its samples in blocks:
        if done := drv is None and self._macro_blocks(system, recorder, books, t_end, n, H,
                                                      sliver, controlled, h_prev):
            k, n_rejected, compiled_cpu = done          # the implicit scheme's, in blocks
        if blocks := drv is not None and driven_block.takes(recorder):
            k, n_rejected, compiled_cpu = driven_block.run_blocks(
                self, system, recorder, drv, t, t_end, k, n, H, sliver, controlled)
        while drv is not None and not blocks:   # the compiled loop, one step per call
            if controlled:
                if t_end - t <= sliver:
                    break
                c0 = time.process_time()
                h = drv.step(t, t_end - t)
            else:
                if k >= n:
                    break
                t = k * H
                h = min(H, t_end - t)
                if h <= sliver:
                    break
                c0 = time.process_time()
                drv.step(t, h, h)
            compiled_cpu += time.process_time() - c0
            n_rejected = self.n_rejected = drv.n_rejected
            k += 1
            self.n_windows = k
            books.book_driven(t + h, drv)
            if controlled:
                t = t + h
        while drv is None and not done:
            if controlled:
                if t_end - t <= sliver:
                    break
                h = ctl.propose(d, dd, f, t_end - t)
                saved = system.get_state()
            else:
                if k >= n:
                    break
                t = k * H
                h = min(H, t_end - t)
                if h <= sliver:
                    break
            if system.followers:
                system.update_followers(st.outs)
            predicted = self._predicted_end_forces(system, h / h_prev) if self.interface_tolerance \
                and controlled else None
            st.unconverged = False
            stepped = self.advance(system, t, h, h / h_prev)
            outs = system.outputs()
            d1, dd1 = system.penetrations(outs)
            f = system.forces(d1, dd1)
            if controlled:
                retry = ctl.judge(d, dd, d1, dd1, f, stepped, predicted, outs, t, h)
                if retry is not None:           # an onset inside, or too large an error
                    ctl.retry(saved, *retry)
                    n_rejected += 1
                    self.n_rejected = n_rejected
                    continue
            if system.connections is not None and system.switch_modes(t + h, d1, dd1):
                d1, dd1 = system.penetrations(outs)     # a grasp moves the tangential anchor
                f = system.forces(d1, dd1)
            f_was, was_aimed = st.f, st.aimed
            ctl.accept(dd, h, outs, f)
            d, dd = d1, dd1
            h_prev = h
            if controlled and ctl.land:
                onsets = ctl.at_onset(d, dd, f, f_was, was_aimed)
                if len(onsets):             # the history starts again at the onset
                    h_prev = self.contact_step
                    st.hist = self.onset_history(system, d, dd, f, onsets, h_prev)
            k += 1
            self.n_windows = k          # kept as they go: a run that fails reports them
            books.book(t + h, h, d, dd, f, stepped)
            if controlled:
                t = t + h
        self.loop_stats = {"loop": "python" if drv is None and not done else "compiled",
                           "refusal": self.loop_refusal, "macro_steps": k, "compiled_cpu_s":
                           compiled_cpu, "run_cpu_s": time.process_time() - cpu0,
                           **({} if drv is None else drv.side_counts())}
        return {"n_windows": k, "n_iterations": self.n_iterations, "n_rejected": n_rejected}

    #: the macro loop's state (set by :meth:`run`)
    _state = None
    #: why the last run took the Python loop (None: it took the compiled one)
    loop_refusal: str | None = None
    #: the last finished run's loop: ``loop`` (``"compiled"`` or ``"python"``), ``refusal``
    #: (:attr:`loop_refusal`), ``macro_steps``, ``compiled_cpu_s`` (process CPU inside the
    #: compiled loop's calls [s]) and ``run_cpu_s`` (the whole of :meth:`run` [s]), for benchmarks
    #: (and the compiled loop's ``face_steps``, ``python_side_steps``: ``Driver.side_counts``)
    loop_stats: dict | None = None

    def _macro_blocks(self, *run):
        """Run a compiled macro loop of the scheme's own: ``(k, n_rejected, cpu)``; None if not."""

    def _compiled_loop(self, system, state, d, dd, controlled, h_prev):
        """The compiled macro loop for this run (:mod:`cosim.core.schemes.driver`),
        or None where the Python loop runs it (:attr:`loop_refusal` says why)."""
        self.loop_refusal = why = driver.refusal(self, system)
        if why is not None:
            return None
        module = driver.compiled_driver()
        if module is None:
            self.loop_refusal = "the compiled loop is not built"
            return None
        order = self._order(system) if hasattr(self, "_order") else self._moving(system)
        drv = module.Driver(self, system, order, state, d, dd, controlled)
        drv.start(h_prev)
        return drv

    # the implicit scheme reads the loop's state by these names
    @property
    def _f(self):
        """The forces the next step starts from: the last of the history
        (the forces at the point, or a contact's at its onset)."""
        return self._state.hist[-1]

    @property
    def _outs(self):
        return self._state.outs

    @property
    def _unconverged(self):
        return self._state.unconverged

    @_unconverged.setter
    def _unconverged(self, value):
        self._state.unconverged = value

    def _predicted_end_forces(self, system, ratio):
        """Force each coupler contact is predicted to carry at the step's
        end: the extrapolated force at ``s = 1``.  (A hosted contact's
        prediction is the force its host saw at the step's end, against the
        partner's extrapolated motion; it is read after the step.)"""
        return np.sum(self._extrapolated(ratio), axis=0)

    @staticmethod
    def _internal(system):
        led = [s.ledger() for s in system.subsystems]
        return sum(a for a, _ in led), sum(b for _, b in led)

    @staticmethod
    def _hosted_impulses(system) -> dict:
        """Impulse so far of each hosted contact, before a step."""
        return {c: system.subsystems[host].embedded_quadratures()[slot, 0]
                for c, (host, slot, _, _, _) in system.hosted.items()}

    def rows_of(self, system, s: int) -> list:
        """The coupler rows (normal, then tangential) with subsystem ``s`` on a side."""
        return self._topology(system).rows[s]

    def _step_side(self, system, s: int, t: float, h: float, coeffs: np.ndarray,
                   after: dict) -> np.ndarray:
        """Step subsystem ``s`` over ``[t, t + h]`` under the force polynomials
        ``coeffs`` (order + 1, n_contacts).  With ``substeps`` m > 1 for it
        (multirate), it takes m steps of ``h / m``, and at each its coupler
        contacts' forces are evaluated anew from its own outputs and its
        partners' predicted ones (:meth:`_predicted_outputs`): held at
        order 0, linear towards its own motion extrapolated over the
        sub-step otherwise.  Returns the impulse [N s] each row gave it."""
        sub = system.subsystems[s]
        m = (self.substeps or {}).get(system.names[s], 1)
        if m == 1:
            sub.step(t, h, system.step_input(s, t, h, coeffs))
            system.collect_work(s)
            return h * (coeffs / _POWERS_PLUS_ONE[:coeffs.shape[0]]).sum(axis=0)
        hk = h / m
        mine = self.rows_of(system, s)
        width = max(2, coeffs.shape[0])
        impulse = np.zeros(system.n_rows)
        j = np.arange(width)[:, None]
        for k in range(m):
            tk = t + k * hk
            cf = np.zeros((width, system.n_rows))
            cf[:coeffs.shape[0]] = reparametrised(coeffs, k / m, 1.0 / m)
            if mine:
                d0, dd0 = system.penetrations(self._predicted_outputs(system, s, tk, t, h, after))
                f0 = system.forces(d0, dd0, mine)
                f1 = f0
                if self.extrapolation_order > 0:
                    d1, dd1 = system.penetrations(self._predicted_outputs(
                        system, s, tk + hk, t, h, after, own_ahead=hk))
                    f1 = system.forces(d1, dd1, mine)
                cf[:, mine] = 0.0
                cf[0, mine], cf[1, mine] = f0, f1 - f0
            sub.step(tk, hk, system.step_input(s, tk, hk, cf))
            system.collect_work(s)
            impulse += hk * np.sum(cf / (j + 1), axis=0)
        return impulse

    _watch_impacts = staticmethod(watch_impacts)

    def _moving(self, system):
        return self._topology(system).moving

    def _topology(self, system) -> "_Topology":
        """What the macro loop reads of the system's layout at every step,
        worked out once per system."""
        topo = self.__dict__.get("_topo")
        if topo is None or topo.system is not system:
            links, rc = system.links, system.row_contact
            rows = tuple([r for r in system.coupler_rows
                          if s in (links[rc[r]].sub_a, links[rc[r]].sub_b)]
                         for s in range(len(system.subsystems)))
            topo = _Topology(system, [s for s, sub in enumerate(system.subsystems)
                                      if not sub.rigid], rows)
            self._topo = topo
        return topo
