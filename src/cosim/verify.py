"""The verification cases: each scene against its analytic or reference answer."""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

from . import analytic
from .run import simulate
from .scene import load_scene

__all__ = ["Check", "run_checks", "CHECKS"]


@dataclass(frozen=True)
class Check:
    name: str
    passed: bool
    detail: str


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


def run_checks(cases_dir="cases"):
    """Yield every :class:`Check` in turn."""
    cases = Path(cases_dir)
    for fn in CHECKS.values():
        yield from fn(cases)
