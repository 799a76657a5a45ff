"""The a-priori error and cost model of accuracy on request
(:mod:`cosim.studies.choose`, which holds the names too): an impact's
relative errors ``e = max(a (omega h) ** p, floor)`` per regime and scheme
(:data:`MODEL`), the monolithic scheme's in its ``rtol``
(:data:`MONOLITHIC_MODEL`), the CPU time per counted step (:data:`COST`), and
the step a requested accuracy allows (:func:`step_for`).  It imports nothing
of cosim: the request's choice and the reach of a contact
(:mod:`cosim.studies.reach`) both read it."""
from __future__ import annotations

import math

__all__ = ["MODEL", "MONOLITHIC_MODEL", "COST", "MONOLITHIC_COST_EXPONENT", "SAFETY",
           "QUANTITIES", "predicted_error", "step_for"]

#: (regime, scheme) -> quantity -> (a, p, floor) of
#: ``e = max(a (omega h) ** p, floor)``, from ``python
#: benchmarks/accuracy_model.py`` (the run in
#: ``benchmarks/results/accuracy_model``: three_mass f1, f10, f100, f1000 and
#: beam_impact for ``exchanged``, spring_drop and ground_multicontact for
#: ``host_rk4``; brachiation was measured and left out, see
#: docs/performance.md), ``a`` and ``floor`` rounded up to two digits.  The
#: ``host_rk4`` regime does not depend on the scheme (key ``None``).
MODEL: dict = {
    ("exchanged", "gauss_seidel"): {"peak": (0.016, 2.23, 0.0),
                                    "exit_velocity": (0.032, 2.46, 0.0)},
    ("exchanged", "implicit"): {"peak": (0.00012, 1.18, 1.1e-05),
                                "exit_velocity": (0.015, 2.45, 0.0028)},
    ("exchanged", "jacobi"): {"peak": (0.12, 2.34, 0.0),
                              "exit_velocity": (0.19, 2.19, 0.00026)},
    ("host_rk4", None): {"peak": (0.012, 4.62, 0.0), "exit_velocity": (0.073, 1.84, 0.0)},
}

#: the monolithic scheme: quantity -> (a, p, floor) of ``e = max(a rtol ** p, floor)``,
#: from the same run (every scene but brachiation); round-off moves its
#: errors at rtol 1e-4 by orders of magnitude, so the bound is loose
MONOLITHIC_MODEL: dict = {"peak": (4.0, 0.918, 0.0), "exit_velocity": (2600.0, 1.22, 0.0)}

#: scheme -> (c0 [s], c1 [s per counted step]) of a run's CPU time
#: ``c0 + c1 * steps`` (steps: :meth:`cosim.Scene.work`), from the same run;
#: the monolithic scheme's at rtol 1e-6 (see :data:`MONOLITHIC_COST_EXPONENT`)
COST: dict = {"gauss_seidel": (0.0019, 8.5e-07), "implicit": (0.11, 5.2e-08),
              "jacobi": (0.018, 6.6e-07), "monolithic": (0.066, 0.00055)}

#: the monolithic CPU time grows as ``rtol ** -MONOLITHIC_COST_EXPONENT``
MONOLITHIC_COST_EXPONENT = 0.125

#: the step chosen meets this fraction of the requested accuracy by the
#: model.  ``a`` already bounds every measured point from above; the margin
#: covers the curve between the measured steps
SAFETY = 0.9

#: the quantities predicted
QUANTITIES = ("peak", "exit_velocity")


def _params(regime: str, scheme: str, model=None) -> dict | None:
    model = MODEL if model is None else model
    return model.get((regime, None if regime == "host_rk4" else scheme))


def _bound(par: tuple, x: float) -> float:
    a, p, floor = par
    return max(a * x ** p, floor)


def predicted_error(regime: str, scheme: str, omega_h: float, model=None) -> dict | None:
    """Each quantity's predicted relative error at ``omega_h`` (``omega h``,
    dimensionless), or None where the model has no such scheme."""
    par = _params(regime, scheme, model)
    if par is None:
        return None
    return {q: _bound(v, omega_h) for q, v in par.items()}


def _largest_x(par: dict, target: float) -> float | None:
    """The largest ``x`` whose every bound in ``par`` is at most ``target``;
    None where a floor lies above it."""
    if any(floor > target for _, _, floor in par.values()):
        return None
    return min((target / a) ** (1.0 / p) for a, p, _ in par.values())


def step_for(regime: str, scheme: str, omega: float, accuracy: float, model=None
             ) -> float | None:
    """The largest step [s] whose every predicted error is at most
    ``SAFETY * accuracy``, rounded down to two significant digits; None
    where the model has no such scheme or its floor lies above that."""
    par = _params(regime, scheme, model)
    x = None if par is None else _largest_x(par, SAFETY * accuracy)
    return None if x is None or not x / omega > 0.0 else _floor2(x / omega)


def _floor2(h: float) -> float:
    """``h`` (finite, > 0) rounded down to two significant digits."""
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"a step must be a finite number > 0, got {h!r}")
    e = math.floor(math.log10(h)) - 1
    return float(f"{math.floor(h / 10.0 ** e * (1 + 1e-12))}e{e}")
