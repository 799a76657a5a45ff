"""Coupling schemes, chosen by name."""
from .base import (CoSimulationScheme, CouplingError, CouplingScheme, UnsafeStepError,
                   extrapolation_coeffs)
from .explicit import GaussSeidel, Jacobi
from .implicit import Implicit
from .monolithic import Monolithic

COUPLING_SCHEMES: dict[str, type[CouplingScheme]] = {
    cls.name: cls for cls in (Monolithic, Jacobi, GaussSeidel, Implicit)}


def get_scheme(name) -> type[CouplingScheme]:
    """Resolve a scheme given by registry name or as a class."""
    if isinstance(name, type) and issubclass(name, CouplingScheme):
        return name
    try:
        return COUPLING_SCHEMES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown coupling scheme {name!r}; valid schemes are "
                         f"{sorted(COUPLING_SCHEMES)}") from None


__all__ = ["COUPLING_SCHEMES", "get_scheme", "CouplingScheme", "CoSimulationScheme",
           "CouplingError", "UnsafeStepError", "extrapolation_coeffs", "Monolithic", "Jacobi",
           "GaussSeidel", "Implicit"]
