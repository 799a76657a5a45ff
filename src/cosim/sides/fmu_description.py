"""What an FMU's model description says, read without running the FMU.

The model description (``modelDescription.xml``) names the FMU's variables,
their value references, causality, variability, start values and units, and
the capabilities of its co-simulation face.  Everything here reads that file
only: nothing loads the FMU's binary, so a description can be inspected
(``cosim info``, the scene loader's checks) before any of the FMU's code is
trusted to run.

FMPy parses the file; it is imported only when an FMU is read, and without
it :func:`fmpy_module` raises an ``ImportError`` that names the ``fmi``
extra.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FMUVariable", "fmpy_module", "read_fmu_variables", "can_get_set_state",
           "FMI_EXTRA"]

#: how a user installs what an FMU needs
FMI_EXTRA = 'pip install "cosim[fmi]"'


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

    Raises
    ------
    ImportError
        If FMPy is not installed.
    ValueError
        If the file is not an FMU FMPy can read, or not a co-simulation FMU
        of FMI 2.0 or 3.0.
    """
    fmpy = fmpy_module()
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:            # FMPy raises bare Exception on a broken file
        raise ValueError(f"is not an FMU that FMPy can read ({exc})") from None
    if md.fmiVersion not in ("2.0", "3.0") and not str(md.fmiVersion).startswith("3."):
        raise ValueError(f"must be an FMI 2.0 or 3.0 FMU, got FMI {md.fmiVersion}")
    if md.coSimulation is None:
        raise ValueError("must be a co-simulation FMU (its model description has no "
                         "`CoSimulation` element; model exchange FMUs are not supported)")
    out = {}
    for v in md.modelVariables:
        out[v.name] = FMUVariable(v.name, int(v.valueReference), v.causality, v.variability,
                                  v.type, v.start, getattr(v, "unit", None), v.description)
    return md, out


def can_get_set_state(md) -> bool:
    """Whether the FMU says it can get and set its state."""
    cs = md.coSimulation
    return bool(getattr(cs, "canGetAndSetFMUstate", False)
                or getattr(cs, "canGetAndSetFMUState", False))
