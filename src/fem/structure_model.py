"""The base of a structure that an installed package brings (entry point
``cosim.structures``), and the registry of structure types by name.

A plug-in structure is a frozen dataclass that subclasses
:class:`StructureModel`.  Its fields are the keys of its scene table, read
by their annotation:

=====================  =========================================
annotation             scene value
=====================  =========================================
``float``              a finite number (``metadata["rule"]``: ``">0"`` or ``">=0"``)
``int``                an integer (``metadata["low"]``, ``metadata["high"]``)
``bool``               true or false
``str``                a string (``metadata["choices"]``: the allowed ones)
``tuple[float, float]`` a 2-vector (``metadata["nonzero"]``: refuse ``[0, 0]``)
``tuple[float, ...]``  a non-empty array of numbers
=====================  =========================================

A field's ``metadata`` may also give ``unit`` and ``doc`` (the key's SI
unit and meaning, for ``cosim`` 's reference of keys and its messages).  A
field with a default is optional in the scene.  The keys every structure
shares (``points``, ``modes``, ``integrator``, ``rayleigh``,
``initial_velocity``, ``static_equilibrium``, ``static_loads``) are read by
cosim itself and are not fields, except ``rayleigh``, which the model
receives when the scene gives it (declare ``rayleigh: tuple[float, ...] |
None = None`` to take it).

The model must have a ``length`` [m] (its points are material coordinates
in ``[0, length]``), say in :meth:`StructureModel.dof_bound` how many
degrees of freedom it will have at most (the scene loader's memory check
runs before anything is assembled), and build a
:class:`fem.LinearStructure` in :meth:`StructureModel.assemble`.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

__all__ = ["StructureModel", "STRUCTURE_MODELS", "BUILT_IN_STRUCTURES"]

#: the built-in structure types (the scene loader reads their keys itself)
BUILT_IN_STRUCTURES = ("chain", "beam", "cable", "string", "rod", "plane")

#: scene ``type`` -> model class; the built-in ones by ``"module:Class"``
#: (read by :mod:`cosim.core.plugins` to refuse a plug-in of the same name;
#: the scene loader builds those itself), a plug-in's by its class
STRUCTURE_MODELS: dict = {"chain": "fem.chain:Chain", "beam": "fem.beam:Beam",
                          "cable": "fem.beam:Beam", "string": "fem.beam:String",
                          "rod": "fem.rod:Rod", "plane": "fem.plane:Plane"}


class StructureModel(ABC):
    """A linear structure of a plug-in package, as its scene table gives it
    (see the module's notes).

    Attributes
    ----------
    name : str
        The scene's ``type``; the entry point's name.
    length : float
        Range of the material coordinate of its points, ``[0, length]`` [m].
    """

    name: ClassVar[str]
    length: float

    @abstractmethod
    def dof_bound(self) -> int:
        """Most degrees of freedom the assembled structure has (before its
        supports remove some): the scene's memory check counts with it."""

    @abstractmethod
    def assemble(self):
        """The assembled structure: a :class:`fem.LinearStructure`."""
