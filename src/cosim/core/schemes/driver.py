"""Whether a run of an explicit scheme takes the compiled macro loop
(:mod:`cosim.core.schemes._driver`), decided once per run, and why not.

The compiled loop covers Jacobi and Gauss-Seidel over sides whose steps run
in compiled kernels (a multibody side stepped by RK4 in
``cosim.sides._multibody_step``, a structure stepped by
``cosim.sides._structure_step``) and rigid references, with contacts
exchanged as forces under the shipped penalty laws, or hosted by one side
against a moving partner, extrapolation orders 0 to 2 and the macro-step
control with rollback.  Anything else runs the Python loop of
:meth:`cosim.core.schemes.base.CoSimulationScheme.run`, which stays the
reference the compiled loop is tested against; so does
``COSIM_KERNEL=numpy``, and ``COSIM_DRIVER=python`` runs it over the
compiled sides.
"""
from __future__ import annotations

import importlib
import logging
import os

__all__ = ["DRIVER_ENV", "refusal", "compiled_driver", "prepare"]

logger = logging.getLogger(__name__)

#: the environment variable that chooses the macro loop: ``compiled`` (the
#: default: the compiled loop wherever it covers the run) or ``python``
DRIVER_ENV = "COSIM_DRIVER"
_CHOICES = ("compiled", "python")
_missing_said = False


def driver_choice() -> str:
    """``"compiled"`` or ``"python"``, from ``COSIM_DRIVER`` (read at each run).

    Raises
    ------
    ValueError
        For any other value.
    """
    value = os.environ.get(DRIVER_ENV, "compiled").strip().lower() or "compiled"
    if value not in _CHOICES:
        raise ValueError(f"`{DRIVER_ENV}` must be one of {list(_CHOICES)}, got {value!r}")
    return value


def compiled_driver():
    """The compiled loop's module, or None where it was not built (said once)."""
    global _missing_said
    from cosim.core.kernel_import import import_kernel
    try:
        return import_kernel("cosim.core.schemes._driver")
    except ImportError as exc:
        if not _missing_said:
            _missing_said = True
            logger.warning("the compiled macro loop `cosim.core.schemes._driver` is not built "
                           "(%s): using the Python loop, which is slower; reinstall with "
                           "`pip install .`", exc)
        return None


def _side_refusal(sub) -> str | None:
    """Why side ``sub`` cannot be stepped by the compiled loop, or None: a side
    that declares ``compiled_loop`` says why itself
    (:meth:`compiled_loop_refusal`); no other side is."""
    name = f"side `{sub.name}`"
    if "compiled_loop" in sub.capabilities:
        why = sub.compiled_loop_refusal()
        return None if why is None else f"{name} {why}"
    if sub.rigid:
        return f"{name} is a rigid {type(sub).__name__}"
    return f"{name} ({type(sub).__name__}) has no compiled kernel"


def _follow_refusal(system) -> str | None:
    """Why the compiled loop cannot move a following contact's surface point
    (:mod:`cosim.core.schemes._follow`), or None: side b must move its ports
    in compiled code (capability ``compiled_follow``, and a face: a
    structure meshed along a line, its compiled face built)."""
    for ln in system.followers:
        sub = system.subsystems[ln.sub_b]
        if "compiled_follow" not in sub.capabilities or sub.follow_face() is None:
            return (f"contact `{ln.contact.name}` follows a point along side `{sub.name}`, "
                    f"which cannot move its ports in compiled code")
    return None


def advance_replaced(scheme) -> bool:
    """Whether the ``advance`` of ``scheme``'s class is not the explicit
    schemes' own (a test or a user wrapped it): theirs must run, so only the
    Python loop, which calls it, may run the scheme."""
    advance = type(scheme).advance
    return (getattr(advance, "__module__", None), getattr(advance, "__qualname__", None)) != (
        "cosim.core.schemes.explicit", f"{type(scheme).__name__}.advance")


def refusal(scheme, system) -> str | None:
    """Why this run takes the Python loop, or None when it takes the compiled one."""
    if driver_choice() == "python":
        return f"the Python loop was asked for (`{DRIVER_ENV}=python`)"
    if os.environ.get("COSIM_KERNEL", "compiled").strip().lower() == "numpy":
        return "the numpy reference was asked for (`COSIM_KERNEL=numpy`)"
    if not vars(type(scheme)).get("compiled_loop", False):      # Jacobi, Gauss-Seidel
        return f"scheme `{scheme.name}` is not an explicit scheme the compiled loop knows"
    if advance_replaced(scheme):
        return f"the `advance` of scheme `{scheme.name}` is replaced"
    if scheme.interface_tolerance:
        return "`interface_tolerance` (interface error control) is set"
    if scheme.substeps and any(n != 1 for n in scheme.substeps.values()):
        return "`substeps` (multirate) are set"
    if system.connections is not None:
        return "a contact has a grasp or friction connection"
    why = _follow_refusal(system)
    if why is not None:
        return why
    for sub in system.subsystems:
        why = _side_refusal(sub)
        if why is not None:
            return why
    from couplers import laws
    shipped = {getattr(laws, n) for n in laws.__all__ if n.endswith("Law")}
    for ln in system.links:
        if type(ln.contact.law) not in shipped:
            return f"contact `{ln.contact.name}` has a user's law"
    return None


def prepare(scheme, system, recorder) -> None:
    """What a run of the co-simulation ``scheme`` over ``system`` does once
    at its start, done before its solve's clock starts
    (:meth:`cosim.core.schemes.base.CouplingScheme.prepare`): each side that
    declares ``compiled_loop`` builds its compiled kernel (as its first step
    or the loop's question would), and the modules the run takes are loaded:
    the sampled path with the recorder's and guard's blocks where every
    partner is rigid, the compiled loop with its block filler where it takes
    the run.  A process's first run then counts no import and no kernel
    build in its ``cpu_time_s``; the run finds them built and loaded."""
    from cosim.core.schemes import driven_block
    from cosim.core.kernel_import import import_kernel
    for sub in system.subsystems:
        if "compiled_loop" in sub.capabilities:
            sub.compiled_loop_refusal()      # builds the side's kernel, kept for its steps
    blocks = sampled = False
    if not len(system.exchanged):           # all partners rigid: perhaps the sampled path
        sampled = importlib.import_module("cosim.core.schemes.sampled").refusal(
            scheme, system) is None
        blocks = True
    if not sampled and refusal(scheme, system) is None and compiled_driver() is not None:
        if system.followers:                 # the loop moves their points in compiled code
            import_kernel("cosim.core.schemes._follow")
        if driven_block.takes(recorder):
            import_kernel("cosim.core.schemes._driver_block")
            blocks = True
    if blocks:
        importlib.import_module("cosim.core.guard_block")
        importlib.import_module("cosim.core.recorder_block")
