"""What an FMU's model description says, read without running the FMU.

The model description (``modelDescription.xml``) names the FMU's variables,
their value references, causality, variability, start values and units, and
the capabilities of its co-simulation face.  Everything here reads that file
only: nothing loads the FMU's binary, so a description can be inspected
(``cosim info``, the scene loader's checks) before any of the FMU's code is
trusted to run.

:func:`read_fmu_variables` refuses what would make the FMU unsafe or
ambiguous to load: an FMI 1.0 description, a ``modelIdentifier`` that is
not a C identifier (it names the shared library, which must then lie in the
FMU's own ``binaries/PLATFORM`` folder), a variable name declared twice.
:class:`DescribedFMU` is an FMU side made from the description alone, for
``cosim info``: it tells what the description tells and cannot step.
:func:`port_mass_problem` is the rule a port mass keeps, declared or
reported by the FMU.

FMPy parses the file; it is imported only when an FMU is read, and without
it :func:`fmpy_module` raises an ``ImportError`` that names the ``fmi``
extra.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.core.subsystem import Subsystem
from cosim.errors import shown

__all__ = ["FMUVariable", "DescribedFMU", "FMUOutputs", "describe", "fmpy_module",
           "read_fmu_variables", "can_get_set_state", "port_mass_problem", "FMI_EXTRA"]

#: how a user installs what an FMU needs
FMI_EXTRA = 'pip install "cosim[fmi]"'
#: what FMI requires of a ``modelIdentifier``: a C identifier, which makes the
#: shared library's file name ``binaries/PLATFORM/IDENTIFIER.so`` stay in that folder
_C_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def fmpy_module():
    """FMPy, imported on first use.

    Raises
    ------
    ImportError
        Naming the ``fmi`` extra, when FMPy is not installed.
    """
    try:
        import fmpy
    except ImportError:
        raise ImportError(f"an `fmu` subsystem needs FMPy, which is not installed: "
                          f"{FMI_EXTRA}", name="fmpy") from None
    return fmpy


@dataclass(frozen=True)
class FMUVariable:
    """One scalar variable of an FMU's model description."""

    name: str
    value_reference: int
    #: ``parameter``, ``input``, ``output``, ``local``, ``independent``, ...
    causality: str
    variability: str
    #: ``Real`` (FMI 2.0) or ``Float64`` (FMI 3.0), ...
    type: str
    start: object = None
    unit: str | None = None
    description: str | None = None

    @property
    def real(self) -> bool:
        """Whether the variable holds a 64-bit real."""
        return self.type in ("Real", "Float64")


def read_fmu_variables(path) -> tuple[object, dict[str, FMUVariable]]:
    """The model description of the FMU at ``path`` and its variables by name.

    Only ``modelDescription.xml`` is read: nothing of the FMU runs.

    Raises
    ------
    ImportError
        If FMPy is not installed.
    ValueError
        If the file is not an FMU FMPy can read; not a co-simulation FMU of
        FMI 2.0 or 3.0; its ``modelIdentifier`` is not a C identifier (the
        name of its shared library, which must lie in the FMU's own
        ``binaries/PLATFORM`` folder); or it declares a variable name twice.
    """
    fmpy = fmpy_module()
    _check_description_size(path)
    version = _fmi_version(path)
    if version is not None and version.startswith("1."):
        raise ValueError(f"is an FMI {shown(version, limit=20)} FMU; cosim supports "
                         f"co-simulation FMUs of FMI 2.0 and 3.0")
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:            # FMPy raises bare Exception on a broken file
        raise ValueError(f"is not an FMU that FMPy can read ({shown(exc)})") from None
    if md.fmiVersion not in ("2.0", "3.0") and not str(md.fmiVersion).startswith("3."):
        raise ValueError(f"must be an FMI 2.0 or 3.0 FMU, got FMI "
                         f"{shown(md.fmiVersion, limit=20)}")
    if md.coSimulation is None:
        raise ValueError("must be a co-simulation FMU (its model description has no "
                         "`CoSimulation` element; model exchange FMUs are not supported)")
    ident = md.coSimulation.modelIdentifier
    if not isinstance(ident, str) or not _C_IDENTIFIER.fullmatch(ident):
        raise ValueError(f"has a `modelIdentifier` that is not a C identifier (letters, digits "
                         f"and _, not starting with a digit), as FMI requires: got "
                         f"{shown(repr(ident), limit=80)}; it names the FMU's shared library, "
                         f"which must lie in the FMU's own `binaries` folder")
    out = {}
    for v in md.modelVariables:
        if v.name in out:
            raise ValueError(f"declares the variable {shown(repr(v.name), limit=80)} twice; "
                             f"variable names must be unique")
        out[v.name] = FMUVariable(v.name, int(v.valueReference), v.causality, v.variability,
                                  v.type, v.start, getattr(v, "unit", None), v.description)
    return md, out


#: the largest ``modelDescription.xml`` read [bytes]: FMPy parses it whole in memory
DESCRIPTION_MAX_BYTES = 64 << 20


def _check_description_size(path) -> None:
    """Refuse a model description larger than :data:`DESCRIPTION_MAX_BYTES`
    (by the size the zip declares, before anything is unpacked: a small FMU
    may hold a huge, highly compressed member)."""
    import zipfile
    try:
        with zipfile.ZipFile(path) as z:
            size = z.getinfo("modelDescription.xml").file_size
    except (OSError, KeyError, zipfile.BadZipFile, ValueError):
        return                          # FMPy says what is wrong with the file
    if size > DESCRIPTION_MAX_BYTES:
        raise ValueError(f"holds a modelDescription.xml of {size} bytes, more than the "
                         f"{DESCRIPTION_MAX_BYTES} bytes cosim reads")


def _fmi_version(path) -> str | None:
    """The ``fmiVersion`` attribute of the FMU's model description, read
    from its root element alone (FMPy cannot read an FMI 1.0 description as
    one of a later version); None if it cannot be read, which FMPy then
    reports."""
    import xml.etree.ElementTree as ET
    import zipfile
    try:
        with zipfile.ZipFile(path) as z, z.open("modelDescription.xml") as f:
            for _, element in ET.iterparse(f, events=("start",)):
                return element.get("fmiVersion")
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError, ValueError):
        return None
    return None


def can_get_set_state(md) -> bool:
    """Whether the FMU says it can get and set its state."""
    cs = md.coSimulation
    return bool(getattr(cs, "canGetAndSetFMUstate", False)
                or getattr(cs, "canGetAndSetFMUState", False))


def port_mass_problem(mass) -> str | None:
    """What makes ``mass`` unfit as the mass a port presents to a contact
    [kg] (None when it fits): it must be a finite number > 0, as a numeric
    ``port_mass`` of the scene must, and so large that its inverse (the
    port's mobility) is finite."""
    try:
        m = float(mass)
    except (TypeError, ValueError, OverflowError):
        return f"must be a number, got {shown(mass, limit=80)}"
    if not (math.isfinite(m) and m > 0):
        return f"must be finite and > 0 kg, got {m!r}"
    if not math.isfinite(1.0 / m):
        return f"must be finite and > 0 kg with a finite inverse, got {m!r}"
    return None


def describe(side, path, ports: dict, coordinates: dict | None, energy: str | None) -> list:
    """Give the FMU side ``side`` what its model description tells
    (``path``, ``model_description``, ``variables``, ``fmi_version``,
    ``can_get_set_state``, ``interpolates_inputs``), its ``ports``,
    ``coordinate_names`` and ``energy_variable``, and where its ports lie in
    ``x`` (for :class:`FMUOutputs`); return the names of the
    output variables its state ``x`` holds, in order: the coordinates, their
    rates, the ports' positions and velocities, the energy."""
    side.path = Path(path)
    side.model_description, side.variables = read_fmu_variables(side.path)
    md = side.model_description
    side.fmi_version = 3 if str(md.fmiVersion).startswith("3") else 2
    side.can_get_set_state = can_get_set_state(md)
    side.interpolates_inputs = (side.fmi_version == 2
                                and bool(md.coSimulation.canInterpolateInputs))
    side.ports = dict(ports)
    side.coordinate_names = dict(coordinates or {})
    side.energy_variable = energy
    nq, np_ = len(side.coordinate_names), len(side.ports)
    side._port_slices = (slice(2 * nq, 2 * nq + 2 * np_),
                         slice(2 * nq + 2 * np_, 2 * nq + 4 * np_))
    return ([q for q, _ in side.coordinate_names.values()]
            + [dq for _, dq in side.coordinate_names.values()]
            + [n for p in side.ports.values() for n in p.position]
            + [n for p in side.ports.values() for n in p.velocity]
            + ([energy] if energy else []))


class FMUOutputs:
    """What an FMU side's state ``x`` tells (the layout :func:`describe`
    gives it): its named coordinates, its ports' positions and velocities,
    its energy."""

    def coordinates(self):
        nq = len(self.coordinate_names)
        return {name: (i, nq + i) for i, name in enumerate(self.coordinate_names)}

    def outputs(self, t, x):
        sp, sv = self._port_slices       # copies: schemes keep outputs while x moves on
        return x[sp].reshape(-1, 2).copy(), x[sv].reshape(-1, 2).copy()

    def energy(self, x=None):
        if self.energy_variable is None:
            return 0.0
        x = self.x if x is None else x
        return float(x[-1])


class DescribedFMU(FMUOutputs, Subsystem):
    """An FMU side known from its model description alone, standing in for
    :class:`cosim.sides.fmu.FMUSubsystem` where nothing of the FMU may run
    (``cosim info`` without ``--run-fmu``).

    Its outputs (``x``) are the start values the description gives, NaN
    where it gives none; a port's mass is the declared number or the start
    value of the variable named, and unknown (``None``) where that variable
    has no usable start value: the FMU reports it only when it runs.  It
    cannot step.

    Parameters
    ----------
    name, path, ports, coordinates, energy
        As for :class:`cosim.sides.fmu.FMUSubsystem`.
    """

    capabilities = frozenset({"fmi"})

    def __init__(self, name: str, path, ports: dict, coordinates: dict | None = None,
                 energy: str | None = None):
        super().__init__(name, ports.keys())
        names = describe(self, path, ports, coordinates, energy)
        self.x = np.array([self._start(n) for n in names], float)
        self.port_moments = np.zeros((3, self.n_ports), complex)

    def _start(self, name: str) -> float:
        """The start value of variable ``name`` [its unit], NaN without one."""
        v = self.variables.get(name)
        try:
            return float(v.start)
        except (AttributeError, TypeError, ValueError, OverflowError):
            return math.nan

    def port_mass(self, port: int) -> float | None:
        """The mass port ``port`` presents to a contact [kg] as far as the
        description tells: the declared number, or the start value of the
        variable named if it fits :func:`port_mass_problem`; else None."""
        m = list(self.ports.values())[port].mass
        if isinstance(m, str):
            m = self._start(m)
        return None if port_mass_problem(m) is not None else float(m)

    def unknown_port_mass(self, port: int) -> str | None:
        """Why port ``port``'s mass is unknown without running the FMU (a
        phrase for a message), or None when it is known."""
        if self.port_mass(port) is not None:
            return None
        pname, var = list(self.ports.items())[port]
        v = self.variables[var.mass]
        start = ("gives it no start value" if v.start is None
                 else f"gives it the start value {shown(v.start, limit=40)}, which "
                      f"{port_mass_problem(self._start(var.mass))}")
        return (f"the mass of port `{pname}` is FMU {shown(self.path.name, limit=80)}'s "
                f"output `{shown(var.mass, limit=80)}`, which the FMU reports only when it "
                f"runs (its model description {start})")

    def port_mobility(self, port, direction):
        m = self.port_mass(port)
        if m is None:
            return math.nan
        n = np.asarray(direction, float)
        return float(n @ n) / m

    def _step_impl(self, t, h, inputs):
        raise RuntimeError(f"subsystem `{self.name}` is FMU {shown(self.path.name, limit=80)} "
                           f"as its model description tells it: nothing of it runs")

    def derivatives(self, t, x, u):
        self._step_impl(t, 0.0, None)
