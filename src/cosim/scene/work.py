"""The work a run will do, counted before it starts.

A run's work is counted in integrator steps, summed over its sides: a
co-simulation takes ``t_end / macro_step`` macro steps (``t_end /
contact_step`` while a contact is closed, when the scheme has one), repeats
each up to ``max_iterations`` times (the implicit scheme), and in each a
side takes its ``substeps`` (multirate), each of them split into steps of
its integrator's ``max_step`` (a multibody side's ``rk4``) or, while a
contact it hosts is closed, of its ``contact_step`` (a structure).  Which
of the free and the closed phases a run spends its time in is not known
before it runs, so the count is the larger of the two, an upper bound (step
rejections aside).  The monolithic scheme's solver chooses its steps: the
count is a lower bound, from its ``max_step``, its ``output_interval`` and,
for an explicit method, the stability of the scene's stiffest mode
(:data:`cosim.core.preflight.EXPLICIT_STABILITY`).

A run whose count passes the scene's ``guard.max_steps`` (by default
:data:`~cosim.scene.checks.MAX_STEPS`) is refused before anything is built
or written, naming the key that makes most of it; one above
:data:`WARN_STEPS` says so in a warning.  Raising ``guard.max_steps`` is the
one way to run more.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

from cosim.scene.checks import SceneError

__all__ = ["WorkEstimate", "estimate_work", "check_work", "warn_work", "WARN_STEPS"]

#: a run counted above this many steps says so before it starts (a tenth of
#: the default limit: minutes to hours of CPU time at a few microseconds a step)
WARN_STEPS = 10 ** 8


@dataclass(frozen=True)
class WorkEstimate:
    """What a run will do, counted before it starts.

    Attributes
    ----------
    steps : float
        Integrator steps summed over the sides (for the monolithic scheme,
        its solver's steps and samples).
    bound : str
        ``"at most"`` (a co-simulation: an upper bound) or ``"at least"``
        (the monolithic scheme: a lower bound).
    how : str
        How it was counted, for a message.
    key : str
        The key of the scene that makes most of it.
    value : object
        That key's value.
    """

    steps: float
    bound: str
    how: str
    key: str
    value: object

    def text(self) -> str:
        """``at most 1.2e+03 integrator steps (how)``."""
        return f"{self.bound} {self.steps:.3g} integrator steps ({self.how})"

    def as_dict(self) -> dict:
        return {"steps": self.steps, "bound": self.bound, "how": self.how, "key": self.key}




def _count(x: float) -> float:
    """``ceil(x)`` that does not make a step of round-off (``1 + 1e-16`` is 1);
    a count past the doubles (a step of 5e-324 s) is ``inf``."""
    if not math.isfinite(x):
        return math.inf
    return float(max(1, math.ceil(x * (1.0 - 1e-12))))


def _side_steps(side, h: float, substeps: int, closed: bool, hosts: bool,
                default_step: float) -> tuple[float, str, object]:
    """Steps side ``side`` takes over a macro step ``h`` [s] split into
    ``substeps``; ``closed``: with the contacts it hosts (``hosts``) closed.
    Returns (steps, key of its step, its value)."""
    kind = side.type
    if kind == "rigid":
        return 0.0, "", None
    hk = h / substeps
    if kind == "multibody":
        step = side.max_step or (default_step if side.integrator == "rk4" else None)
        key = f"{side.key}.integrator.max_step"
        if step is None:                 # an adaptive method without a bound: one at least
            return float(substeps), key, None
        free = side.integrator_options.get("free_step")    # rk4's step in free flight
        if free is not None and free < step:
            step, key = free, f"{side.key}.integrator.free_step"
        return substeps * _count(hk / step), key, step
    if kind != "fmu" and closed and hosts:          # a structure, built-in or a plug-in
        return (substeps * _count(hk / side.contact_step), f"{side.key}.integrator.contact_step",
                side.contact_step)
    return float(substeps), "", None       # a structure's exact step, an FMU's doStep


def _closed_form(side, contacts) -> bool:
    """Whether structure ``side`` steps its closed contacts in closed form
    (:class:`cosim.sides.fem_closed_form.ClosedFormContacts`: stepped
    exactly, undamped, every embedded contact on it a linear spring), so
    that its ``contact_step`` is never used: one step per sub-step."""
    if side.type in ("multibody", "rigid", "fmu") or side.integrator != "exact":
        return False
    if any(getattr(side.model, "rayleigh", None) or ()):
        return False
    from couplers import LinearLaw
    mine = [c for c in contacts if c.placement == "embedded" and side.name in (c.a[0], c.b[0])]
    return bool(mine) and all(type(c.law) is LinearLaw for c in mine)


def estimate_work(spec, t_end: float, subsystems=(), contacts=(), system=None
                  ) -> WorkEstimate:
    """Count the work of a run of scheme ``spec`` (a
    :class:`~cosim.scene.specs.SchemeSpec`) to ``t_end`` [s].

    Parameters
    ----------
    spec : SchemeSpec
    t_end : float
        [s]
    subsystems, contacts : sequence of specs
        The scene's; without them a co-simulation counts one step per side
        and sub-step.
    system : CoupledSystem, optional
        The built system: the monolithic scheme's count then takes its
        stiffest mode into account.

    Returns
    -------
    WorkEstimate
    """
    from cosim.core.schemes import get_scheme
    if spec.name == "monolithic" or "macro_step" not in get_scheme(spec.name).options:
        return _monolithic(spec, t_end, system)      # (a plug-in that subclasses it)

    opts = spec.options
    H = opts["macro_step"]
    taken = get_scheme(spec.name).options.get("max_iterations")    # the implicit scheme
    iterations = int(opts.get("max_iterations", taken.default)) if taken is not None else 1
    substeps = dict(opts.get("substeps") or {})
    hosted = {side for c in contacts if c.placement == "embedded" for side in (c.a[0], c.b[0])}
    hosted -= {side.name for side in subsystems if _closed_form(side, contacts)}
    sides = list(subsystems)
    phases = [("macro_step", H, False)]
    hc = opts.get("contact_step")
    phases.append(("contact_step", hc, True) if hc is not None else ("macro_step", H, True))
    best = None
    for key, h, closed in phases:
        h = min(h, t_end)
        n = _count(t_end / h)
        parts = []
        if sides:
            for side in sides:
                m = substeps.get(side.name, 1)
                k, skey, sval = _side_steps(side, h, m, closed, side.name in hosted,
                                            spec.default_step)
                if k:
                    parts.append((k, side.name, m, skey, sval))
        else:                             # the scheme alone: one step per side and sub-step
            parts = [(float(m), name, m, "", None) for name, m in substeps.items()] or [
                (1.0, "", 1, "", None)]
        per = sum(p[0] for p in parts) or 1.0
        steps = n * iterations * per
        if best is not None and steps <= best[0]:
            continue
        best = (steps, key, h, n, parts, per)
    steps, key, h, n, parts, per = best
    how = f"{n:.4g} macro steps of {h:.3g} s (`scheme.{key}`, t_end {t_end:.4g} s)"
    if iterations > 1:
        how += f" x at most {iterations} iterations (`scheme.max_iterations`)"
    if parts and parts[0][1]:
        how += " x (" + " + ".join(
            f"{name} {k:.3g}" + (f" in {m:.3g} sub-steps" if m > 1 else "")
            for k, name, m, _, _ in parts) + ") steps each"
    # the key that makes most of it: the largest of the factors
    factors = [(n, f"scheme.{key}", opts[key]), (iterations, "scheme.max_iterations",
                                                 iterations)]
    if parts:
        k, name, m, skey, sval = max(parts, key=lambda p: p[0])
        if m > 1 and m >= k / m:
            factors.append((k, "scheme.substeps", substeps))
        elif skey:
            factors.append((k, skey, sval))
    _, bkey, bval = max(factors, key=lambda f: f[0])
    return WorkEstimate(steps, "at most", how, bkey, bval)


def _monolithic(spec, t_end: float, system) -> WorkEstimate:
    from cosim.core.preflight import EXPLICIT_STABILITY, stiffest_mode

    opts = spec.options
    method = opts.get("method", "DOP853")
    counts = []
    max_step = opts.get("max_step", math.inf)
    if math.isfinite(max_step):
        counts.append((t_end / max_step, f"`max_step` {max_step:.3g} s", "scheme.max_step",
                       max_step))
    interval = opts.get("output_interval")
    if interval is not None:
        counts.append((t_end / interval, f"a sample every `output_interval` {interval:.3g} s",
                       "scheme.output_interval", interval))
    reach = EXPLICIT_STABILITY.get(method)
    if system is not None and reach is not None:
        omega, what = stiffest_mode(system)
        if omega > 0:
            counts.append((t_end * omega / reach,
                           f"{method} is explicit: its steps stay below {reach:g} / omega = "
                           f"{reach / omega:.3g} s for {what}", "t_end", t_end))
    if not counts:
        return WorkEstimate(1.0, "at least", f"{method} chooses its steps", "t_end", t_end)
    steps, how, key, value = max(counts, key=lambda c: c[0])
    return WorkEstimate(max(1.0, steps), "at least",
                        f"t_end {t_end:.4g} s; {how}", key, value)


def check_work(file, est: WorkEstimate, limit: float) -> None:
    """Refuse a run whose count ``est`` passes ``limit`` (``guard.max_steps``).

    Raises
    ------
    SceneError
        At the key that makes most of the count, with the count and how it
        was made.
    """
    if not est.steps > limit:
        return
    value = "" if est.value is None else f"is {_value(est.value)}: "
    raise SceneError(file, est.key,
                     f"{value}the run would take {est.text()}, more than the {limit:.3g} a run "
                     f"may take (`guard.max_steps`); change `{est.key}`, or raise "
                     f"`guard.max_steps` to run it anyway")


def warn_work(file, est: WorkEstimate, stacklevel: int = 2) -> None:
    """Say before a run starts that its count ``est`` is large (above
    :data:`WARN_STEPS`)."""
    if est.steps > WARN_STEPS:
        warnings.warn(f"{file}: a long run ahead: {est.text()}", stacklevel=stacklevel + 1)


def _value(v) -> str:
    if isinstance(v, float):            # the steps and times counted here are in s
        return f"{v:.4g} s"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {n}" for k, n in list(v.items())[:8]) + (
            ", ..." if len(v) > 8 else "") + "}"
    return str(v)
