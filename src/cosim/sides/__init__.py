"""The sides: adapters that make each model package a subsystem.

- :mod:`cosim.sides.multibody`: a :mod:`multibody` tree as a subsystem;
- :mod:`cosim.sides.fem`: a :mod:`fem` structure as a subsystem;
- :mod:`cosim.sides.kernel`: the choice between the compiled step kernels
  (``_multibody_step``, ``_structure_step``) and the numpy reference.

They implement :mod:`cosim.core`'s protocol and import nothing above it.
"""
