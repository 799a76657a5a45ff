"""Time integrators for linear structural dynamics ``M a + C v + K u = f(t)``.

Over one step ``[t, t + h]`` the load is a polynomial of degree ``p <= 2`` in the
normalised time ``s = (t' - t) / h``: ``f(t + s h) = sum_j F[j] s**j`` with ``F`` of
shape ``(p + 1, n)`` [N].  The state is ``(u, v, a)``: displacement [m], velocity
[m/s] and the acceleration the scheme carries [m/s^2].  Registry
:data:`STRUCTURAL_INTEGRATORS`: ``newmark``, ``hht_alpha``,
``generalized_alpha`` and ``central_difference`` are one algorithm with different
parameters (:mod:`fem.newmark`, with the references); ``exact`` steps a linear model
with modal damping exactly and is the default where it applies (:mod:`fem.exact_modal`).
Their base class is in :mod:`fem.integrator_base`; this module names them all and
holds the registry.
"""
from __future__ import annotations

from .exact_modal import ExactModal
from .integrator_base import (SMALL_DENSE, StructuralIntegrator,  # noqa: F401
                              _dense, generalized_eigh)
from .newmark import CentralDifference, GeneralizedAlpha, HHTAlpha, Newmark

__all__ = ["StructuralIntegrator", "Newmark", "HHTAlpha", "GeneralizedAlpha",
           "CentralDifference", "ExactModal", "STRUCTURAL_INTEGRATORS",
           "get_structural_integrator"]


STRUCTURAL_INTEGRATORS: dict[str, type[StructuralIntegrator]] = {
    cls.name: cls for cls in (Newmark, HHTAlpha, GeneralizedAlpha, CentralDifference,
                              ExactModal)}


def get_structural_integrator(name) -> type[StructuralIntegrator]:
    """Class registered under ``name`` (a StructuralIntegrator subclass passes through).

    Raises
    ------
    ValueError
        For an unknown name; the message lists the valid ones.
    """
    if isinstance(name, type) and issubclass(name, StructuralIntegrator):
        return name
    try:
        return STRUCTURAL_INTEGRATORS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown structural integrator {name!r}; valid names are "
                         f"{sorted(STRUCTURAL_INTEGRATORS)}") from None
