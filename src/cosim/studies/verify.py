"""The verification cases: each scene against its analytic or reference answer."""
from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

from cosim.studies import analytic
from cosim.errors import UnsafeStepError
from cosim.core.guard import energy_scale, peak_stored_energy
from cosim.scene.run import simulate
from cosim.scene.load import SceneError, load_scene

__all__ = ["Check", "run_checks", "folder_checks", "CHECKS", "HardCase", "hard_matrix", "run_hard_case",
           "hard_checks", "hard_line", "robustness", "HARD_COPIES"]


@dataclass(frozen=True)
class Check:
    """One verdict: ``passed`` and a one-line ``detail``; ``skipped`` for a
    check that could not be made here (it passes, and says why)."""
    name: str
    passed: bool
    detail: str
    skipped: bool = False


def _rel(a, b):
    return abs(a - b) / abs(b)


def _spring_drop(cases: Path, variant: str, scheme: str | None, tol_t: float,
                 tol_e: float) -> list[Check]:
    with warnings.catch_warnings():   # switching scheme drops options: expected here
        warnings.simplefilter("ignore")
        scene = load_scene(cases / "spring_drop.toml", variant, scheme=scheme)
    res = simulate(scene)
    label = f"spring_drop/{variant}/{res.summary['scheme']}"
    law = scene.contacts[0]["law"]
    m = scene.subsystems[0]["bodies"][0]["mass"]
    v0 = -scene.subsystems[0]["joints"][0]["dq0"]
    if law.damping > 0:
        t_ref, e_ref = analytic.kelvin_voigt_clipped(m, law.stiffness, law.damping)
    else:
        t_ref, e_ref = analytic.linear_contact(m, law.stiffness), 1.0
    c = res.summary["contacts"]["wall"]
    out = []
    ok = c["count"] == 1
    t_c = c["intervals"][0][1] - c["intervals"][0][0] if ok else math.nan
    out.append(Check(f"{label}: contact time", ok and _rel(t_c, t_ref) <= tol_t,
                     f"{t_c:.9g} s vs {t_ref:.9g} s (rel. tol. {tol_t:g}), count {c['count']}"))
    v_out = res.summary["final_state"]["body"]["x"]["dq"]
    out.append(Check(f"{label}: rebound velocity", _rel(v_out / v0, e_ref) <= tol_e,
                     f"{v_out:.9g} m/s vs {e_ref * v0:.9g} m/s (rel. tol. {tol_e:g})"))
    e = res.summary["energy"]
    bal = abs(e["initial"] - e["final"] - e["dissipated"]) / e["initial"]
    out.append(Check(f"{label}: energy ledger", bal <= tol_e,
                     f"|initial - final - dissipated| / initial = {bal:.3g} (tol. {tol_e:g})"))
    return out


#: name -> callable(cases_dir) -> list of Check
CHECKS = {
    "spring_drop undamped, monolithic":
        lambda p: _spring_drop(p, "undamped", "monolithic", 1e-6, 1e-6),
    "spring_drop kelvin_voigt, monolithic":
        lambda p: _spring_drop(p, "kelvin_voigt", "monolithic", 1e-6, 1e-6),
    "spring_drop undamped, default scheme":
        lambda p: _spring_drop(p, "undamped", None, 1e-5, 1e-5),
    "spring_drop kelvin_voigt, default scheme":
        lambda p: _spring_drop(p, "kelvin_voigt", None, 1e-5, 1e-5),
}


# ------------------------------------------------------------- hard cases
#: three_mass's hard variants (CASES.md section 5) and the matrix's axes
HARD_VARIANTS = ("f1000", "ms0.01")
HARD_SCHEMES = ("monolithic", "jacobi", "gauss_seidel", "implicit")
HARD_PLACEMENTS = ("embedded", "coupler")
#: macro steps in contact, as multiples of the reference step
HARD_FACTORS = (0.5, 1.0, 2.0, 5.0, 10.0)
_NUM = r"[-+0-9.e]+"


@dataclass(frozen=True)
class HardCase:
    """One point of the hard-case matrix.

    ``step`` is the step while C is in contact (``scheme.contact_step``;
    ``scheme.macro_step`` stays 1 ms in free flight), None for the
    monolithic reference; ``forced`` runs an explicit step the pre-flight
    check refuses with ``scheme.accept_unsafe_step = true``."""

    variant: str
    scheme: str
    placement: str
    step: float | None = None
    factor: float | None = None
    forced: bool = False

    @property
    def label(self) -> str:
        s = "-" if self.step is None else f"{self.step:.3g} s ({self.factor:g} x ref)"
        return (f"three_mass/{self.variant}/{self.scheme}/{self.placement}/{s}"
                + (" forced" if self.forced else ""))

    def overrides(self, t_end: float | None = None) -> list:
        ov = [f'contacts.C.placement="{self.placement}"']
        if t_end is not None:
            ov.append(f"t_end={t_end}")
        if self.step is not None:
            ov += [f"scheme.contact_step={self.step!r}",
                   f"scheme.macro_step={max(1e-3, self.step)!r}"]
        if self.forced:
            ov.append("scheme.accept_unsafe_step=true")
        return ov


def reference_step(cases: Path, variant: str, scheme: str, placement: str) -> float:
    """The matrix's reference step in contact [s]: for an explicit scheme with
    C exchanged (``coupler``), the pre-flight check's largest safe step;
    otherwise (C hosted by the chain, or the implicit scheme), which the
    check does not limit, a tenth of C's contact time ``pi / omega``."""
    from cosim.core import preflight
    from cosim.core.preflight import stiffest_normal

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(cases / "three_mass.toml", variant,
                           [f'contacts.C.placement="{placement}"'], scheme=scheme)
    system, sch = scene.build()
    c = system.contact_names.index("C")
    ln = system.links[c]
    m = 1.0 / system.contact_mobility(c)
    k, cd = stiffest_normal(ln)
    if placement == "coupler" and sch.explicit:
        return preflight.largest_safe_step(m, k, cd, 1e-3, sch.extrapolation_order,
                                           sch.max_energy_gain, sch.partner_first(system, c))
    return 0.1 * math.pi / math.sqrt(k / m)


def hard_matrix(cases="cases", factors=HARD_FACTORS, variants=HARD_VARIANTS,
                schemes=HARD_SCHEMES, placements=HARD_PLACEMENTS) -> list[HardCase]:
    """Every point of the matrix: each variant, scheme and placement of C, at
    each factor of the reference step (:func:`reference_step`); the
    monolithic reference once per variant and placement; an explicit
    coupler step the pre-flight check refuses is also run forced."""
    cases = Path(cases)
    out = []
    for v in variants:
        for s in schemes:
            for p in placements:
                if s == "monolithic":
                    out.append(HardCase(v, s, p))
                    continue
                ref = reference_step(cases, v, s, p)
                for fac in factors:
                    # three digits, rounded down: 1 x the limit stays within it
                    step = float(f"{ref * fac * (1 - 5e-3):.3g}")
                    out.append(HardCase(v, s, p, step, fac))
                    if p == "coupler" and s != "implicit" and fac > 1:
                        out.append(HardCase(v, s, p, step, fac, True))
    return out


#: round-off copies of each hard case whose verdicts must agree (the scene and
#: two copies moved by +1 and -1 ulp, :func:`cosim.studies.roundoff.spread`)
HARD_COPIES = 3


def _verdict(outcome: str, message: str) -> str:
    """The discrete verdict of one run: its outcome and, for a stopped run,
    the cause and the contact named (``stopped (energy growth, C)``)."""
    if outcome != "stopped":
        return outcome
    cause = ("chatter" if " chatters" in message else
             "energy growth" if "the energy grew" in message else
             "non-finite" if "not finite" in message or " is nan" in message
             or " is inf" in message else "failed")
    named = re.search(r"contact `([^`]+)`", message)
    return f"stopped ({cause}, {named.group(1) if named else 'no contact'})"


def _run_one(case: HardCase, scene) -> dict:
    """Run one scene of a hard case and judge its outcome (see
    :func:`run_hard_case`)."""
    try:
        res = simulate(scene)
    except (UnsafeStepError, SceneError) as exc:
        msg = str(exc)
        ok = "contact `C`" in msg and (case.step is None or f"{case.step:.3g} s" in msg)
        return {"outcome": "refused", "ok": ok, "detail": msg, "created": math.nan,
                "bound": math.nan, "cpu_s": 0.0, "verdict": "refused"}
    import numpy as np
    s = res.summary
    finite = all(np.all(np.isfinite(a)) for a in res.series.values())
    e = res.series["energy/total"] + res.series["energy/dissipated"] - s["energy"]["supplied"]
    created = float(np.max(e - s["energy"]["initial"])) if len(e) else 0.0
    system, _ = scene.build()
    d0, _ = system.penetrations(system.outputs())
    peaks = np.array([s["contacts"][n]["peak_penetration"] for n in system.contact_names])
    scale = max(energy_scale(system, d0), peak_stored_energy(system, d0, peaks))
    g = scene.guard
    bound = max(g.energy_growth * (scale + abs(s["energy"]["supplied"])), g.energy_floor)
    out = {"created": created, "bound": bound, "cpu_s": s["cpu_time_s"],
           "detail": s["message"] or f"created {created:.3g} J of {bound:.3g} J allowed"}
    if res.status == "finished":
        out.update(outcome="bounded", ok=finite and created <= bound)
    else:
        msg = s["message"]
        named = re.search(r"contact `[^`]+`", msg) is not None
        timed = re.search(rf"t = {_NUM} s", msg) is not None
        out.update(outcome="stopped", ok=finite and named and timed)
    out["verdict"] = _verdict(out["outcome"], s["message"])
    return out


def run_hard_case(case: HardCase, cases="cases", t_end: float | None = None,
                  copies: int = HARD_COPIES) -> dict:
    """Run one point, and its round-off copies, and judge their outcomes.

    A train of impacts amplifies round-off, so a point's verdict is computed
    for the scene and ``copies - 1`` copies whose initial state is moved by
    a few ulps (:func:`cosim.studies.roundoff.spread`); it is ``robust`` when
    all agree.

    Returns a dict with ``outcome`` (``"bounded"``, ``"refused"`` or
    ``"stopped"``), ``detail``, ``created`` (largest energy created over the
    kept samples [J]), ``bound`` [J] and ``cpu_s``, all of the unmoved
    scene; ``verdicts`` (one per copy, the scene's first: the outcome, and
    for a stopped run its cause and contact, ``"stopped (energy growth,
    C)"``), ``robust`` (they agree) and ``ok`` (every copy's outcome is one
    the matrix allows, with its evidence: never NaN, never silent growth).

    - bounded: finished, every series value finite, and the energy created
      (total + dissipated - supplied - initial) at every sample within
      ``guard.energy_growth`` times the energy scale (the guard's, taken
      anew from the scene and the contacts' peaks);
    - refused: :class:`UnsafeStepError` or :class:`SceneError` before the
      run, naming contact C and the step;
    - stopped: status failed, a message naming a contact and the time, and
      the series written up to there finite.
    """
    from cosim.studies.roundoff import spread

    cases = Path(cases)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(cases / "three_mass.toml", case.variant, case.overrides(t_end),
                           scheme=case.scheme)
        runs = [_run_one(case, s) for s in spread(scene, copies)]
    out = dict(runs[0])
    out["verdicts"] = [r["verdict"] for r in runs]
    out["robust"] = len(set(out["verdicts"])) == 1
    out["ok"] = all(r["ok"] for r in runs)
    if not out["ok"]:
        bad = next(r for r in runs if not r["ok"])
        out["detail"] = f"a copy: {bad['outcome']}: {bad['detail']}"
    return out


def robustness(r: dict) -> str:
    """``robust``, or ``not robust (verdicts: ...)``, of a
    :func:`run_hard_case` result."""
    return "robust" if r["robust"] else f"not robust (verdicts: {'; '.join(r['verdicts'])})"


def hard_checks(cases="cases", t_end: float | None = None, matrix=None,
                copies: int = HARD_COPIES):
    """Yield a :class:`Check` per point of the hard-case matrix; its detail,
    one line, is :func:`hard_line` of the point's :func:`run_hard_case`
    (``copies`` runs each)."""
    for case in (matrix if matrix is not None else hard_matrix(cases)):
        r = run_hard_case(case, cases, t_end, copies)
        yield Check(case.label, r["ok"], hard_line(r))


#: the guard's figures in its message (cosim.core.guard), and the pre-flight
#: check's largest safe step (cosim.core.schemes.base)
_GREW = re.compile(rf"the energy grew by ({_NUM}) J .*?\(bound ({_NUM}) J")
_TRIPPED = re.compile(rf"the guard tripped at t = ({_NUM}) s")
_STOPPED = re.compile(rf"^run stopped at t = ({_NUM}) s")
_SAFE = re.compile(rf"largest safe macro step is ({_NUM}) s")


def hard_line(r: dict) -> str:
    """One line for a :func:`run_hard_case` result: the outcome, the figures
    that judge it, and whether the copies agree.

    The energy figures are one quantity, the energy created (total +
    dissipated - supplied - initial) against its bound: for a bounded run
    its largest value over the samples kept; for a run the guard stopped, the
    guard's own figures at the sample it refused (the samples kept before it
    are within the bound by construction).  A point that fails shows its
    failing copy's message, flattened to one line."""
    tail = robustness(r)
    if not r["ok"]:
        return f"{r['outcome']}, {tail}: {' '.join(r['detail'].split())}"
    detail, verdict = r["detail"], r["verdicts"][0]
    if r["outcome"] == "bounded":
        return f"bounded: created {r['created']:.3g} J, bound {r['bound']:.3g} J; {tail}"
    if r["outcome"] == "refused":
        safe = _SAFE.search(detail)
        why = f" (largest safe step {safe.group(1)} s)" if safe else ""
        return f"refused by the pre-flight check{why}; {tail}"
    when = _TRIPPED.search(detail) or _STOPPED.search(detail)
    at = f" at t = {when.group(1)} s" if when else ""
    grew = _GREW.search(detail)
    figures = f": created {grew.group(1)} J, bound {grew.group(2)} J" if grew else ""
    return f"{verdict.replace('stopped', 'stopped by the guard' + at, 1)}{figures}; {tail}"


def folder_checks(cases_dir, hard: bool = False):
    """Yield the checks of a folder of scene files (``cosim verify --cases
    DIR``): spring_drop's analytic checks if ``spring_drop.toml`` is there,
    else one skipped line that says so (any scene is checked by ``cosim
    verify SCENE``, :mod:`cosim.studies.verify_scene`); with ``hard``, the
    hard-case matrix, which needs ``three_mass.toml``.  A folder that is
    not one, holds no scene file, or lacks the file ``hard`` runs is
    refused (:class:`~cosim.scene.load.SceneError`) before anything runs."""
    cases = Path(cases_dir)
    if not cases.is_dir():
        raise SceneError(cases, "", "is not a folder of scene files (`--cases DIR`)")
    if not any(cases.glob("*.toml")):
        raise SceneError(cases, "", "holds no scene file (*.toml) to verify")
    if hard and not (cases / "three_mass.toml").is_file():
        raise SceneError(cases / "three_mass.toml", "",
                         "not found: the hard-case matrix (`--hard`) runs it")
    if (cases / "spring_drop.toml").is_file():
        for fn in CHECKS.values():
            yield from fn(cases)
    else:
        yield Check("spring_drop", True,
                    f"not run: no spring_drop.toml in {cases}; `cosim verify SCENE` checks any "
                    f"scene", skipped=True)
    if hard:
        yield from hard_checks(cases)


def run_checks(cases_dir="cases", hard: bool = False):
    """Yield every :class:`Check` in turn; with ``hard``, the hard-case
    matrix after them (:func:`hard_checks`)."""
    cases = Path(cases_dir)
    for fn in CHECKS.values():
        yield from fn(cases)
    if hard:
        yield from hard_checks(cases)
