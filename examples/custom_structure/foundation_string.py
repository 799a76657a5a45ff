"""A taut string on an elastic (Winkler) foundation: a structure of one's own,
installed as a package (``pyproject.toml`` beside this file declares it
under the entry point ``cosim.structures``).

``rho A w_tt - T w_ss + k_f w = 0`` on ``0 < s < L``, pinned at both ends.
The model is cosim's own string (P1 elements, consistent mass ``M``) with
the foundation's stiffness added: ``K = T G + (k_f / (rho A)) M``, ``G`` the
string's Laplacian.  Its discrete frequencies are then exactly the string's
shifted, ``omega_n^2 = omega_string,n^2 + k_f / (rho A)``, and the static
deflection under a point load ``P`` at mid-span tends, as the mesh is
refined, to ``P tanh(lambda L / 2) / (2 T lambda)``, ``lambda = sqrt(k_f / T)``.

Each dataclass field is a key of the scene's ``[subsystems.NAME]`` table:
its annotation says what the value is, ``metadata`` its unit, its range and
its meaning.
"""
from dataclasses import dataclass, field
from typing import ClassVar

import fem

__all__ = ["FoundationString"]


def _key(unit: str, doc: str, **check):
    return field(metadata={"unit": unit, "doc": doc, **check})


@dataclass(frozen=True)
class FoundationString(fem.StructureModel):
    """A taut string, both ends pinned, on a foundation of stiffness
    ``foundation_stiffness`` [N/m^2] (force per length per deflection)."""

    length: float = _key("m", "span L", rule=">0")
    tension: float = _key("N", "tension T", rule=">0")
    density: float = _key("kg/m^3", "density rho", rule=">0")
    area: float = _key("m^2", "cross-section area A", rule=">0")
    foundation_stiffness: float = _key("N/m^2", "the foundation's stiffness k_f", rule=">=0")
    elements: int = _key("", "number of linear elements", low=2, high=100_000)
    origin: tuple[float, float] = field(default=(0.0, 0.0),
                                        metadata={"unit": "m", "doc": "the end s = 0"})
    axis: tuple[float, float] = field(default=(1.0, 0.0), metadata={
        "doc": "direction along the string", "nonzero": True})
    direction: tuple[float, float] = field(default=(0.0, 1.0), metadata={
        "doc": "direction of the deflection, across `axis`", "nonzero": True})
    rayleigh: tuple[float, ...] | None = None
    name: ClassVar[str] = "foundation_string"

    def __post_init__(self):       # the loader turns a ValueError into a scene error at the key
        if not self.foundation_stiffness >= 0:
            raise ValueError(f"`foundation_stiffness` must be >= 0 N/m^2, got "
                             f"{self.foundation_stiffness!r}")

    def _string(self):
        return fem.String(length=self.length, tension=self.tension, density=self.density,
                          area=self.area, n_elements=self.elements, origin=self.origin,
                          axis=self.axis, direction=self.direction, rayleigh=self.rayleigh)

    def dof_bound(self) -> int:
        return self.elements + 1

    def assemble(self):
        string = self._string().assemble()
        shift = self.foundation_stiffness / (self.density * self.area)
        return string.with_stiffness(string.stiffness + shift * string.mass)
