"""Linear structural models: the discrete chain, the Euler-Bernoulli beam and
the tensioned cable, the string and the axial rod; their modes and their
time integrators.

Importing this package loads numpy only: the chain, the structures' common
base and the modal tools.  The mesh-based models (:mod:`fem.beam`,
:mod:`fem.rod`) and the time integrators (:mod:`fem.integrators`) are
imported when one of their names is first asked for (``from fem import Beam``
works as before); scipy's submodules load where first used, scikit-fem when a
mesh-based model is assembled and meshio when a field is exported.  A scene
with a chain or without any structure pays for none of them.  Plane elastic
bodies from a mesh file are the subpackage :mod:`fem.plane` (meshio reads
their mesh, scikit-fem assembles them).
"""
from .chain import Chain, ChainStructure
from .linear_structure import LinearStructure, LineStructure
from .modal import DENSE_LIMIT, ModalBasis, modes, natural_frequencies, residual_compliance
from .rank_one import rank_one_eigh
from .response import undamped_envelope, undamped_moments, undamped_response

__all__ = ["Beam", "String", "Section", "rectangular_section", "circular_section", "Chain",
           "ChainStructure", "Rod", "LinearStructure", "LineStructure", "ModalBasis", "modes",
           "natural_frequencies", "StructuralIntegrator", "Newmark", "HHTAlpha",
           "GeneralizedAlpha", "CentralDifference", "ExactModal", "STRUCTURAL_INTEGRATORS",
           "get_structural_integrator", "BEAM_ENDS", "ROD_ENDS", "DENSE_LIMIT",
           "residual_compliance", "undamped_response", "undamped_moments", "undamped_envelope",
           "rank_one_eigh", "StructureModel", "STRUCTURE_MODELS", "BUILT_IN_STRUCTURES"]

#: public name -> the submodule that defines it, imported on first use
_LAZY = {**dict.fromkeys(("Beam", "String", "Section", "rectangular_section",
                          "circular_section", "BEAM_ENDS"), "beam"),
         **dict.fromkeys(("Rod", "ROD_ENDS"), "rod"),
         **dict.fromkeys(("StructureModel", "STRUCTURE_MODELS", "BUILT_IN_STRUCTURES"),
                         "structure_model"),
         **dict.fromkeys(("STRUCTURAL_INTEGRATORS", "StructuralIntegrator", "Newmark",
                          "HHTAlpha", "GeneralizedAlpha", "CentralDifference", "ExactModal",
                          "get_structural_integrator"), "integrators")}


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    # the import statement's machinery, which `python -X importtime` reports
    value = getattr(__import__(f"{__name__}.{_LAZY[name]}", fromlist=[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
