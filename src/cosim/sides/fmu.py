"""A Functional Mock-up Unit as a subsystem: a co-simulation FMU stepped through FMPy.

The FMU is a black box that offers only the co-simulation face of the
subsystem protocol: it advances its own state over a macro step
(``doStep``) under the port forces it is given and reports its ports'
positions and velocities as outputs.  Contacts with an FMU side are
therefore exchanged by the coupling scheme (placement ``coupler``) or
hosted by the other side; the FMU never evaluates a contact law itself.

FMI 2.0 and 3.0 co-simulation FMUs are supported.  FMPy is imported only
when an FMU is loaded; without it :func:`fmpy_module` raises an
``ImportError`` that names the ``fmi`` extra.

Rollback (the implicit scheme, macro-step control) goes through the FMU's
own state: ``fmi2GetFMUstate``/``fmi3GetFMUState`` and their setters, which
an FMU offers when its model description says ``canGetAndSetFMUstate``
(FMI 2.0) or ``canGetAndSetFMUState`` (FMI 3.0).

The FMU's native code never runs in this process: the FMU is unpacked
(bounded, once per process, :mod:`cosim.sides.fmu_unpack`) and loaded by a
host process of its own (:mod:`cosim.sides.fmu_host`), which each macro step
reaches in one round trip.  An FMI call that fails, or a host that crashes,
raises :class:`cosim.errors.FMUError` (the run ends ``failed`` with its data
so far); a host that hangs is ended on Ctrl-C or SIGTERM.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from cosim.core.subsystem import StepInput, Subsystem, SubsystemState, hermite_coefficients
from cosim.sides.fmu_description import (FMI_EXTRA, FMUOutputs, FMUVariable, can_get_set_state,
                                         describe, fmpy_module, read_fmu_variables)
from cosim.sides.fmu_unpack import remove_stale_unpacked

__all__ = ["FMUSubsystem", "FMUPort", "FMUVariable", "fmpy_module", "read_fmu_variables",
           "can_get_set_state", "FMI_EXTRA", "remove_stale_unpacked"]

#: int_0^1 s^j ds (j = 0, 1, 2): the mean of a polynomial input over a step
_MEAN = np.array([1.0, 1.0 / 2.0, 1.0 / 3.0, 1.0 / 4.0])


@dataclass(frozen=True)
class FMUPort:
    """A port of an FMU: the names of its variables.

    Attributes
    ----------
    position, velocity : (str, str)
        Output variables of the port's x and y position [m] and velocity [m/s].
    force : (str, str)
        Input variables of the force on the port, x and y [N].
    mass : float or str
        The mass the port presents to a contact [kg], for the pre-flight
        stability check and for choosing the host of a contact: a number, or
        the name of an output variable the FMU reports it in.
    """

    position: tuple[str, str]
    velocity: tuple[str, str]
    force: tuple[str, str]
    mass: float | str


class FMUState(SubsystemState):
    """A snapshot of an FMU subsystem: the base snapshot plus the FMU's own
    state handle (freed when the snapshot is dropped)."""

    __slots__ = ("handle", "__weakref__")


class FMUSubsystem(FMUOutputs, Subsystem):
    """A co-simulation FMU (FMI 2.0 or 3.0) whose ports are named variables.

    Parameters
    ----------
    name : str
    path : path-like
        The ``.fmu`` file.
    ports : dict[str, FMUPort]
        Port name -> its variables.
    parameters : dict[str, float], optional
        Start values set before initialisation (parameters of the FMU).
    coordinates : dict[str, (str, str)], optional
        Named coordinates reported in the results: name -> (output variable
        of the coordinate, output variable of its rate).
    energy : str, optional
        Output variable holding the mechanical energy of the FMU [J], for the
        energy ledger and the run guard.  Without it the FMU counts as
        holding no energy.

    Notes
    -----
    ``x`` holds the outputs read after the last step: the coordinates, their
    rates, the port positions and velocities and the energy.  Over a step
    the port force is a polynomial in time (:class:`StepInput`); an FMI 2.0
    FMU that can interpolate its inputs (``canInterpolateInputs``) receives
    its value and first two derivatives at the step's start
    (``fmi2SetRealInputDerivatives``); any other FMU receives the force's
    mean over the step, held, which hands over the same impulse.  The work a
    force does is taken along the cubic Hermite of the port between its
    positions and velocities at the step's ends.
    """

    capabilities = frozenset({"fmi"})

    def __init__(self, name: str, path, ports: dict, parameters: dict | None = None,
                 coordinates: dict | None = None, energy: str | None = None):
        super().__init__(name, ports.keys())
        fmpy_module()                   # without FMPy: an ImportError naming the extra
        names = describe(self, path, ports, coordinates, energy)
        md = self.model_description
        self.parameters = dict(parameters or {})
        vr = self._vr
        self._force_vr = [vr(n) for p in self.ports.values() for n in p.force]
        self._out_vr = [vr(n) for n in names]
        self._mass_vr = {k: vr(p.mass) for k, p in enumerate(self.ports.values())
                         if isinstance(p.mass, str)}
        self._host = _start_host(self, md)
        self._closer = weakref.finalize(self, self._host.close)
        self.x = np.frombuffer(self._host.outputs0, float).copy()
        self.port_moments = np.zeros((3, self.n_ports), complex)

    # ---------------------------------------------------------------- FMI
    def _vr(self, name: str) -> int:
        try:
            return self.variables[name].value_reference
        except KeyError:
            raise KeyError(f"FMU {self.path.name} of subsystem `{self.name}` has no variable "
                           f"`{name}`") from None

    def close(self) -> None:
        """Terminate the FMU, free its instance and end its host process
        (also done when the subsystem is garbage-collected)."""
        self._closer()

    @property
    def host_cpu_time(self) -> float:
        """CPU time the FMU's host process has spent so far [s] (a run adds
        it to its own, as of the host's last answer)."""
        return self._host.cpu_time

    # ------------------------------------------------------------ protocol
    def _step_impl(self, t, h, inputs):
        u0, du, ddu = self._forces(t, h, inputs)
        pos0, vel0 = self.outputs(t, self.x)
        self.x[:] = np.frombuffer(self._host.step(t, h, np.ascontiguousarray(u0, float),
                                                  du, ddu), float)
        pos1, vel1 = self.outputs(t + h, self.x)
        self.port_moments = _velocity_moments(pos0, vel0, pos1, vel1, h)

    def _forces(self, t, h, inputs):
        """The force on each port at the step's start and its first two time
        derivatives there, (n_ports, 2) each; for an FMU that holds its
        inputs, the mean over the step and zero derivatives."""
        zero = np.zeros((self.n_ports, 2))
        if inputs is None:
            return zero, zero, zero
        if type(inputs) is StepInput:
            c = inputs.coeffs
            if self.interpolates_inputs and c.shape[0] <= 3:
                du = c[1] / h if c.shape[0] > 1 else zero
                ddu = 2.0 * c[2] / (h * h) if c.shape[0] > 2 else zero
                return c[0], du, ddu
            if c.shape[0] <= len(_MEAN):
                return np.tensordot(_MEAN[:c.shape[0]], c, axes=1), zero, zero
        # any other input function: its mean by 3-point Gauss-Legendre
        nodes = 0.5 + 0.5 * np.sqrt(0.6) * np.array([-1.0, 0.0, 1.0])
        weights = np.array([5.0, 8.0, 5.0]) / 18.0
        mean = sum(w * np.asarray(inputs(t + s * h), float) for s, w in zip(nodes, weights))
        return mean, zero, zero

    def derivatives(self, t, x, u):
        raise RuntimeError(f"subsystem `{self.name}` is a co-simulation FMU: it has no "
                           f"model-exchange face, so the monolithic scheme cannot stack it; "
                           f"use `jacobi`, `gauss_seidel` or `implicit`")

    def port_mass(self, port: int) -> float:
        """The mass port ``port`` presents to a contact [kg]: the declared
        number, or the value of the FMU's variable now."""
        m = list(self.ports.values())[port].mass
        if isinstance(m, str):
            m = float(np.frombuffer(self._host.get([self._mass_vr[port]], self.t), float)[0])
        return float(m)

    def port_mobility(self, port, direction):
        m = self.port_mass(port)
        n = np.asarray(direction, float)
        return float(n @ n) / m if m > 0 else float("inf")

    def embed_contact(self, contact, *args, **kwargs):
        raise ValueError(f"contact `{contact.name}`: subsystem `{self.name}` is an FMU, a "
                         f"black box that cannot evaluate a contact law; place the contact in "
                         f"the coupler (`placement = \"coupler\"`) or let the other side host it")

    # ------------------------------------------------------------ rollback
    def get_state(self) -> FMUState:
        if not self.can_get_set_state:
            flag = "canGetAndSetFMUState" if self.fmi_version == 3 else "canGetAndSetFMUstate"
            raise RuntimeError(
                f"subsystem `{self.name}`: FMU {self.path.name} cannot get and set its state "
                f"(`{flag}` is false), so it cannot be rolled back; use the `jacobi` or "
                f"`gauss_seidel` scheme without `contact_step`")
        handle = self._host.get_state(self.t)
        st = FMUState(self.t, self.x.copy(), self.aux.copy(), self.n_steps, self.status,
                      self.peak.copy())
        st.handle = handle
        weakref.finalize(st, self._host.free_state, handle)
        return st

    def set_state(self, state: FMUState) -> None:
        self._host.set_state(state.handle, self.t)
        super().set_state(state)


def _velocity_moments(pos0, vel0, pos1, vel1, h) -> np.ndarray:
    """``int v(t) s^j dt`` over the step (j = 0, 1, 2; (3, n_ports) complex
    [m]) of the cubic Hermite through the ports' end positions and
    velocities: ``int_0^1 x'(s) s^j ds`` with ``x'(s) = c1 + 2 c2 s + 3 c3 s^2``."""
    c = lambda a: a[:, 0] + 1j * a[:, 1]          # noqa: E731
    _, c1, c2, c3 = hermite_coefficients(c(pos0), c(vel0), c(pos1), c(vel1), h)
    j = np.arange(3)[:, None]
    return c1 / (j + 1) + 2 * c2 / (j + 2) + 3 * c3 / (j + 3)


def _start_host(sub: FMUSubsystem, md):
    """The host process of ``sub``'s FMU, its instance initialised and its
    first outputs read (``host.outputs0``).

    Raises
    ------
    RuntimeError
        Naming the subsystem and the FMU: it cannot be unpacked, its library
        is not in its ``binaries`` folder, or it fails (or crashes) while
        loaded, instantiated or initialised.
    """
    from fmpy import platform, platform_tuple, sharedLibraryExtension
    from cosim.errors import shown
    from cosim.sides.fmu_client import FMUHost
    from cosim.sides.fmu_unpack import unpacked

    label = shown(sub.path.name, limit=120)
    head = f"subsystem `{sub.name}`: FMU {label}"
    try:
        folder = unpacked(sub.path)
    except (ValueError, OSError) as exc:
        raise RuntimeError(f"{head} cannot be unpacked: {exc}") from None
    identifier = md.coSimulation.modelIdentifier
    binaries = (folder / "binaries").resolve()
    library = (binaries / (platform_tuple if sub.fmi_version == 3 else platform)
               / f"{identifier}{sharedLibraryExtension}")
    if not library.resolve().is_relative_to(binaries):
        raise RuntimeError(f"{head}: its `modelIdentifier` {shown(identifier, 80)!r} names a "
                           f"library outside its `binaries` folder")
    host = FMUHost(label, sub.name, sub.fmi_version, len(sub._force_vr), len(sub._out_vr),
                   sub.interpolates_inputs)
    config = {"fmi_version": sub.fmi_version, "unzipped": str(folder),
              "library": str(library), "model_identifier": identifier,
              "token": md.instantiationToken if sub.fmi_version == 3 else md.guid,
              "instance": sub.name, "output_vrs": sub._out_vr, "force_vrs": sub._force_vr,
              "interpolates_inputs": sub.interpolates_inputs,
              "parameter_vrs": [sub._vr(k) for k in sub.parameters],
              "parameter_values": [float(v) for v in sub.parameters.values()]}
    try:
        host.outputs0 = host.start(config)
    except BaseException as exc:
        host.close()
        if isinstance(exc, RuntimeError):
            raise RuntimeError(f"{head} could not be instantiated and initialised: "
                               f"{exc}") from None
        raise
    return host
