"""Linear structural models: the discrete chain, the Euler-Bernoulli beam and
the tensioned cable, the string and the axial rod; their modes and their
time integrators.

Importing this package loads numpy and scipy only; scikit-fem is imported
when a mesh-based model (beam, string, rod) is assembled, and meshio when a
field is exported, so a scene with a chain or without any structure pays for
neither.
"""
from .beam import BEAM_ENDS, Beam, Section, String, circular_section, rectangular_section
from .chain import Chain, ChainStructure
from .integrators import (STRUCTURAL_INTEGRATORS, CentralDifference, ExactModal,
                          GeneralizedAlpha, HHTAlpha, Newmark, StructuralIntegrator,
                          get_structural_integrator)
from .rank_one import rank_one_eigh
from .response import undamped_moments, undamped_response
from .modal import DENSE_LIMIT, ModalBasis, modes, natural_frequencies, residual_compliance
from .rod import ROD_ENDS, Rod
from .structures import LinearStructure, LineStructure

__all__ = ["Beam", "String", "Section", "rectangular_section", "circular_section", "Chain",
           "ChainStructure", "Rod", "LinearStructure", "LineStructure", "ModalBasis", "modes",
           "natural_frequencies", "StructuralIntegrator", "Newmark", "HHTAlpha",
           "GeneralizedAlpha", "CentralDifference", "ExactModal", "STRUCTURAL_INTEGRATORS",
           "get_structural_integrator", "BEAM_ENDS", "ROD_ENDS", "DENSE_LIMIT",
           "residual_compliance", "undamped_response", "undamped_moments", "rank_one_eigh"]
