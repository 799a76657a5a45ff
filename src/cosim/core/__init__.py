"""The coupling core: the subsystem protocol, the coupled system and its
connection modes, the coupling schemes, the ODE integrators of the moving
sides, the pre-flight stability checks, the guard, the recorder and the
result of a run.

It knows subsystems only through :class:`cosim.core.subsystem.Subsystem`;
it imports :mod:`cosim.io` and :mod:`cosim.errors`, never the sides, the
scene loader, the studies or the command line.
"""
