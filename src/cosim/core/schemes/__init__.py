"""Coupling schemes, chosen by name.

The explicit schemes are defined on import; the monolithic and the implicit
scheme when first looked up in :data:`COUPLING_SCHEMES` or imported by name
(``from cosim.core.schemes import Implicit`` works as before).
"""
from cosim.core.ode import lookup
from cosim.core.registry import Registry
from .base import (CoSimulationScheme, CouplingError, CouplingScheme, UnsafeStepError,
                   extrapolation_coeffs)
from .explicit import GaussSeidel, Jacobi

COUPLING_SCHEMES: Registry = Registry({
    "monolithic": f"{__name__}.monolithic:Monolithic", Jacobi.name: Jacobi,
    GaussSeidel.name: GaussSeidel, "implicit": f"{__name__}.implicit:Implicit"},
    group="cosim.schemes")

#: public name -> the submodule that defines it, imported on first use
_LAZY = {"Monolithic": "monolithic", "Implicit": "implicit"}


def get_scheme(name) -> type[CouplingScheme]:
    """Resolve a scheme given by registry name or as a class."""
    return lookup(COUPLING_SCHEMES, name, CouplingScheme, "coupling scheme")


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    # the import statement's machinery, which `python -X importtime` reports
    value = getattr(__import__(f"{__name__}.{_LAZY[name]}", fromlist=[name]), name)
    globals()[name] = value
    return value


__all__ = ["COUPLING_SCHEMES", "get_scheme", "CouplingScheme", "CoSimulationScheme",
           "CouplingError", "UnsafeStepError", "extrapolation_coeffs", "Monolithic", "Jacobi",
           "GaussSeidel", "Implicit"]
