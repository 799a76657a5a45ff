"""Accuracy on request: which scheme and steps meet a relative accuracy at
the least CPU, chosen before the run.

The model is a-priori.  An impact's errors (the peak penetration of the
contact a study reads and the striker's exit velocity at its last release,
relative to a fine monolithic reference) follow the dimensionless step in
contact ``omega h``: ``e = max(a (omega h) ** p, floor)``, where ``omega`` is the
contact's frequency at its first touch (``cosim info``) and ``h`` the step
that integrates it.  Which step that is depends on where the contact is
evaluated (:func:`knob`):

- ``exchanged``: the two sides exchange it each macro step (a coupler
  contact, or one embedded in a side against a moving partner, whose motion
  is extrapolated over the step): the scheme's ``contact_step`` when the
  scene sets one, else its ``macro_step``; ``a`` and ``p`` depend on the
  scheme;
- ``host_rk4``: a multibody side's RK4 integrates it against a rigid
  partner: that side's ``integrator.max_step``, whatever the scheme (the
  macro step, and with it the series' sampling, grows with it: the exit
  velocity's error there is mostly that sampling's).

``a``, ``p`` and ``floor`` (:data:`MODEL`) were measured on the shipped
scenes by ``benchmarks/accuracy_model.py``, which prints them again; ``a``
is the largest a scene needed (the fit bounds every measured point from
above), so the prediction is conservative where the scenes scatter, and a
scheme whose ``floor`` lies above the accuracy is refused.  The step chosen
meets :data:`SAFETY` times the requested accuracy by the model, and is no
longer than a step whose error the run's estimate can check
(:data:`CHECKABLE`).  The CPU
time is ``c0 + c1 * steps`` (:data:`COST`, measured per scheme), the steps
counted before the run (:meth:`cosim.Scene.work`): it ranks the schemes of
a scene rather than timing them.  The monolithic scheme is a candidate at
the ``rtol`` its own fit asks (:data:`MONOLITHIC_MODEL`).  Only a step that
the scheme's pre-flight check (and the scene's build) accepts is chosen:
the candidates are counted unbuilt, then built and checked cheapest first
until one passes (a costlier one is left unbuilt, ``unchecked``).

A scene's contact the model does not cover (one a structure steps against
a rigid partner, a law without a linearisation) is refused with a
:class:`~cosim.scene.checks.SceneError`; a grasp is chosen for with a
caveat (:attr:`Choice.caveat`).  Building the scene and finding where its
contact first closes runs it briefly (as ``cosim info`` does), an FMU's
code included; that run is of the system :func:`knob` built, whose
initial-pose frequencies are read before it.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from cosim.errors import UnsafeStepError
from cosim.scene.checks import parse_accuracy
from cosim.studies.companion import ASYMPTOTIC_OMEGA_H, MIN_FACTOR, OMEGA_H_MAX
from cosim.studies.error_model import (COST, MODEL, MONOLITHIC_COST_EXPONENT, MONOLITHIC_MODEL,
                                       QUANTITIES, SAFETY, _bound, _floor2, _largest_x,
                                       _params, predicted_error, step_for)
from cosim.studies.reach import (DOUBLE_PRECISION_FLOOR, MIN_RTOL, check_omega, reachable,
                                 refusal)

__all__ = ["Choice", "Knob", "MODEL", "MONOLITHIC_MODEL", "COST", "SAFETY",
           "DOUBLE_PRECISION_FLOOR", "MIN_RTOL", "parse_accuracy", "knob", "predicted_error",
           "step_for", "reachable", "choose"]


@dataclass(frozen=True)
class Knob:
    """The step that integrates a contact, and the contact's frequency.

    Attributes
    ----------
    contact : str
    regime : str
        ``exchanged`` or ``host_rk4`` (see the module).
    key : str
        The scene key of that step.
    value : float
        Its value in the scene [s].
    omega : float
        The contact's angular frequency at its first touch [rad/s].
    macro_step : float
        The scheme's ``macro_step`` [s].
    grasp : bool
        Whether the contact is a grasp.
    check_omega : float
        The frequency [rad/s] at which the run's error estimate judges the
        step (:func:`cosim.studies.companion.contact_omega` at the initial
        pose, the largest over the contacts that limit the companion's
        factor, see :func:`knob`): the step chosen is capped with it, so
        that a step chosen checkable is the one the companion checks.
    """

    contact: str
    regime: str
    key: str
    value: float
    omega: float
    macro_step: float
    grasp: bool = False
    check_omega: float = math.nan

    def overrides(self, h: float) -> list[str]:
        """The ``--set`` strings that make the step ``h`` [s]: the macro
        step grows with it where it would be shorter."""
        out = [f"{self.key}={h!r}"]
        if self.key != "scheme.macro_step" and self.macro_step < h:
            out.append(f"scheme.macro_step={h!r}")
        return out


def knob(scene, contact: str | None = None) -> Knob:
    """The step that integrates ``contact`` (the scene's strike by default,
    :func:`cosim.studies.strike.find_strike`; else its contact of the
    highest frequency) and its frequency at its first touch.

    Two frequencies, one definition: a contact's frequency is ``sqrt(k m)``,
    ``k`` its linearised normal stiffness and ``m`` the two sides' mobility
    along its normal (:func:`cosim.studies.companion.contact_omega`).  The
    model (:attr:`Knob.omega`) reads it at the contact's first touch, the
    pose it was fitted at; the error estimate's companion reads it with that
    same function at the initial pose, and :attr:`Knob.check_omega` is
    what it reads there (the largest over the contacts whose steps set the
    companion's factor: every contact the sides exchange, or every contact
    the host side steps).  The cap on a checkable step (:data:`CHECKABLE`)
    takes the higher of the two, so that the companion checks the step
    chosen whichever pose is the stiffer.

    Raises
    ------
    SceneError
        If no contact of the scene has a penalty law with a frequency.
    """
    return _knob(scene, contact)[0]


def _knob(scene, contact: str | None = None):
    """:func:`knob` and the system it built (run to the first touch: its
    structure alone is to be read)."""
    from cosim.core.preflight import stiffest_normal
    from cosim.scene.checks import SceneError
    from cosim.scene.info import first_touch
    from cosim.studies.companion import contact_omega
    from cosim.studies.strike import find_strike

    built = scene.build()
    system = built[0]
    if contact is None:
        strike = find_strike(scene, required=False)
        contact = strike[0] if strike else None
    # what is read at the initial pose, read before the system runs to the first touch
    soft = [c for c, ln in enumerate(system.links) if not ln.contact.law.rigid]
    start_mob = {c: system.contact_mobility(c) for c in soft}
    start_omega = {c: contact_omega(system, c) for c in soft}
    # the run to the first touch of the contact asked (of every one, to find the
    # stiffest, when none is): on brachiation gripper 1 is closed at the start,
    # gripper 2 closes after 0.84 s.  It runs the system built here, whose
    # structure is all the rest of this function reads
    touches, _ = first_touch(scene, contacts=None if contact is None else {contact},
                             built=built)
    omegas = {}
    for c in soft:
        k, _ = stiffest_normal(system.links[c])
        mob = touches[c][1] if c in touches else start_mob[c]   # at the start
        if math.isfinite(k) and math.isfinite(mob) and mob > 0:
            omegas[c] = math.sqrt(k * mob)
    if not omegas:
        raise SceneError(scene.path, "contacts", "holds no contact whose penalty law has a "
                         "known frequency: the accuracy model needs one")
    if contact is None:
        c = max(omegas, key=omegas.get)
    elif contact not in system.contact_names:
        raise SceneError(scene.path, "contacts", f"has no contact {contact!r}; its contacts "
                         f"are {', '.join(system.contact_names)}")
    else:
        c = system.contact_names.index(contact)
        if c not in omegas:
            raise SceneError(scene.path, f"contacts.{contact}", "has a law without a known "
                             "frequency: the accuracy model needs a linearisable penalty law")
    ln = system.links[c]
    opts = scene.scheme_options
    check = check_omega(system, c, start_omega)
    H = opts.get("macro_step") or math.nan
    rigid = [system.subsystems[s].rigid for s in (ln.sub_a, ln.sub_b)]
    grasp = ln.connection is not None and ln.connection.grasp is not None
    if ln.placement == "embedded" and any(rigid):
        host = system.subsystems[system.embedded[c][0]]
        spec = next(s for s in scene.subsystems if s.name == host.name)
        if spec.type != "multibody" or spec.integrator != "rk4":
            raise SceneError(scene.path, f"contacts.{ln.contact.name}",
                             f"is stepped by `{host.name}`'s `{spec.integrator}` integrator "
                             f"against a rigid partner: the accuracy model has no step for it "
                             f"(it was measured where the sides exchange a contact and where "
                             f"a multibody's rk4 hosts one)")
        return Knob(ln.contact.name, "host_rk4", f"{spec.key}.integrator.max_step",
                    spec.max_step, omegas[c], H, grasp, check), system
    key = "scheme.contact_step" if opts.get("contact_step") else "scheme.macro_step"
    return Knob(ln.contact.name, "exchanged", key, opts.get(key.split(".")[1]), omegas[c], H,
                grasp, check), system


@dataclass(frozen=True)
class Choice:
    """What :func:`choose` chose.

    Attributes
    ----------
    scheme : str
    overrides : tuple of str
        ``--set`` strings (``key.path=value``) for
        :func:`cosim.scene.load.load_scene`.
    accuracy : float
        The relative accuracy asked.
    predicted_error : dict
        ``peak`` and ``exit_velocity``: relative errors the model predicts.
    work_steps : float
        The counted work of the run [integrator steps].
    predicted_cpu_s : float
        [s]
    step : float
        The step in contact chosen [s] (the monolithic scheme: its rtol).
    knob : Knob
    why : str
        One sentence.
    candidates : list of dict
        Every scheme considered: its step, predicted errors and CPU, or why
        it was left out (``refused``), or that it was not built
        (``unchecked``: costlier than the one chosen).
    scene : Scene or None
        The scene loaded with the chosen scheme and overrides, whose build
        the pre-flight check passed (what :func:`cosim.studies.accurate.plan`
        runs); None where it is not kept (a refinement's choice).
    """

    scheme: str
    overrides: tuple
    accuracy: float
    predicted_error: dict
    work_steps: float
    predicted_cpu_s: float
    step: float
    knob: Knob
    why: str
    candidates: list = field(default_factory=list)
    scene: object = field(default=None, repr=False, compare=False)

    @property
    def caveat(self) -> str | None:
        """What the model does not cover here, or None."""
        if self.knob.grasp:
            return (f"`{self.knob.contact}` is a grasp: the model was fitted on impacts, and "
                    f"the one grasp measured (brachiation) kept a 2 % exit-velocity error "
                    f"whatever the step; check the run against a finer one")
        return None

    def as_dict(self) -> dict:
        return {"accuracy": self.accuracy, "caveat": self.caveat, "scheme": self.scheme,
                "overrides": list(self.overrides), "step": self.step,
                "contact": self.knob.contact, "regime": self.knob.regime,
                "omega_rad_s": self.knob.omega, "predicted_error": dict(self.predicted_error),
                "work_steps": self.work_steps, "predicted_cpu_s": self.predicted_cpu_s,
                "why": self.why, "candidates": self.candidates}


def _load(scene, overrides, scheme):
    """``scene`` with ``overrides`` and ``scheme`` applied to its merged
    table (which holds the variant and overrides it was loaded with)."""
    import copy
    from cosim.scene.load import _validate
    from cosim.scene.read import apply_override, parse_override
    data = copy.deepcopy(scene.data)
    for ov in overrides:
        apply_override(data, *parse_override(ov, scene.path), scene.path)
    data.setdefault("scheme", {})["name"] = scheme
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _validate(data, Path(scene.path), scene.variant, scheme != scene.scheme)


def _candidate(scene, k: Knob, scheme: str, accuracy: float, checkable: bool = True,
               at_most: float = math.inf, system=None) -> dict:
    """One scheme at the step the model asks: its overrides, errors, work
    and CPU, or ``refused`` with the reason; not built (:func:`_checked`
    builds it).  ``system``: the scene built (:func:`knob`'s), whose
    structures' stiffest mode counts the monolithic scheme's work."""
    from cosim.scene.checks import SceneError
    out = {"scheme": scheme}
    if scheme == "monolithic":
        rtol = _rtol_for(accuracy)
        if rtol is None:
            return {**out, "refused": "no monolithic model"}
        ov = [f"scheme.monolithic.rtol={rtol!r}", f"scheme.monolithic.atol={rtol * 1e-3:.3g}"]
        s = _load(scene, ov, "monolithic")
        steps = s.work(system=system).steps
        c0, c1 = COST["monolithic"]
        cpu = (c0 + c1 * steps) * (rtol / 1e-6) ** -MONOLITHIC_COST_EXPONENT
        err = {q: _bound(v, rtol) for q, v in MONOLITHIC_MODEL.items()}
        return {**out, "step": rtol, "overrides": ov, "predicted_error": err,
                "work_steps": steps, "predicted_cpu_s": cpu, "scene": s}
    h = step_for(k.regime, scheme, k.omega, accuracy)
    if h is None:
        why = ("not measured in this regime" if _params(k.regime, scheme) is None else
               "its error floor lies above the accuracy asked")
        return {**out, "refused": why}
    # within the range at the frequency the companion reads (so that it checks the step)
    # and at the model's (the range it was measured in): the higher of the two
    w = max(k.omega, k.check_omega) if math.isfinite(k.check_omega) else k.omega
    cap = _floor2(CHECKABLE[k.regime] / w) if checkable else math.inf
    if h > at_most:                  # a refinement: shorter than the model says
        out["model_step"], out["capped"], h = h, "refined", _floor2(at_most)
    elif h > cap:                    # the model allows a longer step than can be checked
        out["model_step"], out["capped"], h = h, "checkable", cap
    if scheme not in COST:
        return {**out, "refused": "its cost was not measured"}
    ov = k.overrides(h)
    try:
        s = _load(scene, ov, scheme)
    except SceneError as exc:
        return {**out, "step": h, "refused": _refused(h, exc)}
    steps = s.work().steps
    return {**out, "step": h, "overrides": ov,
            "predicted_error": predicted_error(k.regime, scheme, k.omega * h),
            "work_steps": steps, "predicted_cpu_s": COST[scheme][0] + COST[scheme][1] * steps,
            "scene": s}


def _refused(h: float, exc) -> str:
    return f"the pre-flight check refuses the step it needs, {h:.3g} s: {exc}"


def _checked(cand: dict) -> dict:
    """``cand`` built and its step judged by the scheme's pre-flight check
    (the scene's build included): as it was, or ``refused`` with why."""
    from cosim.scene.checks import SceneError
    try:
        system, sch = cand["scene"].build()
        sch.preflight(system)
    except (UnsafeStepError, SceneError) as exc:
        return {k: v for k, v in cand.items() if k not in ("overrides", "predicted_error",
                                                           "work_steps", "predicted_cpu_s",
                                                           "scene")
                } | {"refused": _refused(cand["step"], exc)}
    return cand


#: regime -> the largest omega h chosen, so that the run's error estimate can
#: check it (:mod:`cosim.studies.estimate`): an exchanged contact's companion
#: at :data:`~cosim.studies.companion.MIN_FACTOR` times the step stays within
#: :data:`~cosim.studies.companion.ASYMPTOTIC_OMEGA_H`; a host's RK4 step at
#: 4 times stays within :data:`~cosim.studies.companion.OMEGA_H_MAX`, so that
#: the companion coarsens it.  A longer step the model allows would meet the
#: accuracy unchecked (three_mass f100 at 1 %: omega h 0.59, where the
#: errors of neighbouring steps scatter by 3x).
CHECKABLE = {"exchanged": ASYMPTOTIC_OMEGA_H / MIN_FACTOR, "host_rk4": OMEGA_H_MAX / 4.0}


def _rtol_for(accuracy: float) -> float | None:
    """The monolithic scheme's rtol for ``accuracy`` (at most 1e-3); None
    where it would lie below :data:`MIN_RTOL`."""
    r = _largest_x(MONOLITHIC_MODEL, SAFETY * accuracy)
    return None if r is None or r < MIN_RTOL else _floor2(min(r, 1e-3))


def choose(scene, accuracy: float, contact: str | None = None,
           schemes=None, checkable: bool = True, at_most: float = math.inf,
           source: str = "accuracy") -> Choice:
    """The scheme and steps that meet ``accuracy`` at the least predicted CPU.

    Parameters
    ----------
    scene : Scene
        The loaded scene (variant and overrides applied).
    accuracy : float
        Relative accuracy of the contact's peak penetration and the
        striker's exit velocity, in (0, 1).
    contact : str, optional
        The contact the accuracy is asked of (see :func:`knob`).
    schemes : sequence of str, optional
        The candidates (default: every scheme with a model, and the
        monolithic scheme).
    checkable : bool
        Choose a step whose error the run's estimate can check
        (:data:`CHECKABLE`), and the monolithic scheme (which gets no
        estimate) only where no other scheme meets the accuracy; False: the
        model's choice alone, at the least predicted CPU.
    at_most : float
        The longest step [s] (a refinement's, from the run's estimate).
    source : str
        Where the accuracy was asked (``--accuracy``, ``scheme.accuracy``,
        ``accuracy``): what a refusal names.

    Returns
    -------
    Choice

    Raises
    ------
    ValueError
        If ``accuracy`` is not in (0, 1).
    SceneError
        If ``accuracy`` lies below what the scene can reach
        (:func:`reachable`), if no candidate meets it (every one refused),
        or if the scene has no contact the model knows.
    """
    accuracy = parse_accuracy(accuracy, source)
    k, system = _knob(scene, contact)
    if schemes is None:         # host_rk4: the scheme does not matter, the scene's runs
        schemes = ([] if k.regime == "host_rk4" else
                   sorted({s for (r, s) in MODEL if r == k.regime} - {scene.scheme}))
        schemes = [scene.scheme] + schemes + (["monolithic"] if scene.scheme != "monolithic"
                                              else [])
    low = reachable(k, schemes)
    if accuracy < low:
        raise refusal(scene, source, f"{accuracy:.3g} lies below {low:.2g}, the smallest "
                      f"relative accuracy this scene can be asked of `{k.contact}` (with "
                      f"{', '.join(schemes)}: the schemes' error floors and the precision of "
                      f"doubles, see `cosim.studies.choose.reachable`); ask {low:.2g} or more")
    cands = [_candidate(scene, k, s, accuracy, checkable, at_most, system)
             for s in schemes]
    # built and checked cheapest first, until one passes: a costlier one is not
    # chosen whatever its check says, and is left unbuilt
    order = sorted((c for c in cands if "refused" not in c),
                   key=lambda c: (checkable and c["scheme"] == "monolithic",
                                  c["predicted_cpu_s"], c["scheme"] != scene.scheme))
    best = None
    for c in order:
        if best is None:
            cands[cands.index(c)] = c = _checked(c)
            best = None if "refused" in c else c
        else:
            del c["scene"]
            c["unchecked"] = "costlier by the model than the one chosen: not built"
    ok = [c for c in cands if "refused" not in c]
    if best is None:
        raise refusal(scene, source, f"{accuracy:.3g}: no scheme meets it by the model: "
                      + "; ".join(f"{c['scheme']}: {c['refused']}" for c in cands))
    chosen = best.pop("scene")
    return Choice(best["scheme"], tuple(best["overrides"]), accuracy,
                  best["predicted_error"], best["work_steps"], best["predicted_cpu_s"],
                  best["step"], k, _why(best, ok, k), cands, chosen)


def _at(c: dict, k: Knob) -> str:
    if c["scheme"] == "monolithic":
        return f"rtol {c['step']:.2g}"
    if k.regime == "host_rk4":
        return f"`{k.key}` = {c['step'] * 1e6:.3g} us"
    return f"{c['step'] * 1e6:.3g} us in contact"


def _why(best: dict, ok: list, k: Knob) -> str:
    err = best["predicted_error"]
    text = (f"{best['scheme']} at {_at(best, k)}: predicted {err['peak'] * 100:.2g} % peak and "
            f"{err['exit_velocity'] * 100:.2g} % exit-velocity error on `{k.contact}` "
            f"(omega h = {k.omega * best['step']:.2g})" if best["scheme"] != "monolithic" else
            f"monolithic at {_at(best, k)}: predicted {max(err.values()) * 100:.2g} % error")
    if "model_step" in best:
        text += (", capped so that the run's error can be estimated" if best["capped"] ==
                 "checkable" else ", shorter than the first run's step as its estimate asks")
        text += f" (the model allows omega h = {k.omega * best['model_step']:.2g})"
    others = sorted((c for c in ok if c is not best), key=lambda c: c["predicted_cpu_s"])
    if others:
        o = others[0]
        ratio = o["predicted_cpu_s"] / best["predicted_cpu_s"]
        text += (f"; {o['scheme']} would meet it at {_at(o, k)} but costs {ratio:.2g}x"
                 if ratio >= 1 else
                 f"; {o['scheme']} would meet it at {_at(o, k)} for {ratio:.2g}x the CPU, "
                 f"but gets no error estimate")
    return text
