"""Coupling schemes, chosen by name."""
from ..integrators import lookup
from .base import (CoSimulationScheme, CouplingError, CouplingScheme, UnsafeStepError,
                   extrapolation_coeffs)
from .explicit import GaussSeidel, Jacobi
from .implicit import Implicit
from .monolithic import Monolithic

COUPLING_SCHEMES: dict[str, type[CouplingScheme]] = {
    cls.name: cls for cls in (Monolithic, Jacobi, GaussSeidel, Implicit)}


def get_scheme(name) -> type[CouplingScheme]:
    """Resolve a scheme given by registry name or as a class."""
    return lookup(COUPLING_SCHEMES, name, CouplingScheme, "coupling scheme")


__all__ = ["COUPLING_SCHEMES", "get_scheme", "CouplingScheme", "CoSimulationScheme",
           "CouplingError", "UnsafeStepError", "extrapolation_coeffs", "Monolithic", "Jacobi",
           "GaussSeidel", "Implicit"]
