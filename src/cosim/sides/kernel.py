"""Which implementation steps each side: the compiled kernel or the numpy reference.

Each side's step runs in compiled code (Cython, built by ``pip install .``):
:mod:`cosim.sides._multibody_step` for the multibody side, :mod:`cosim.sides._structure_step`
for the structure side.  The numpy modules stay the readable reference and are
what the kernels are tested against (``tests/test_kernel.py``,
``tests/test_kernel_structure.py``).

The environment variable ``COSIM_KERNEL`` chooses: ``compiled`` (the default)
uses the kernel wherever it covers the scene and the reference elsewhere;
``numpy`` uses the reference everywhere.  If the kernel was not built, cosim
says so once (a logged warning) and uses the reference.
"""
from __future__ import annotations

import logging
import os

from cosim.core.kernel_import import REBUILD, import_kernel

__all__ = ["kernel_choice", "compiled_module", "import_kernel", "retired", "KERNEL_ENV",
           "REBUILD"]

logger = logging.getLogger(__name__)

#: the environment variable that chooses the implementation
KERNEL_ENV = "COSIM_KERNEL"
_CHOICES = ("compiled", "numpy")
_missing_said: set[str] = set()


def kernel_choice() -> str:
    """``"compiled"`` or ``"numpy"``, from ``COSIM_KERNEL`` (read at each call,
    so a test or a script may switch between runs).

    Raises
    ------
    ValueError
        For any other value.
    """
    value = os.environ.get(KERNEL_ENV, "compiled").strip().lower() or "compiled"
    if value not in _CHOICES:
        raise ValueError(f"`{KERNEL_ENV}` must be one of {list(_CHOICES)}, got {value!r}")
    return value


def compiled_module(name: str):
    """The compiled kernel module ``cosim.sides.NAME``, or None when the reference is
    chosen or the kernel was not built (said once per module)."""
    if kernel_choice() == "numpy":
        return None
    try:
        return import_kernel(f"{__package__}.{name}")
    except ImportError as exc:
        if name not in _missing_said:
            _missing_said.add(name)
            logger.warning("the compiled kernel `cosim.sides.%s` is not built (%s): using the numpy "
                           "reference, which is slower; reinstall with `pip install .`", name, exc)
        return None


def retired(kernel):
    """None, for a side that drops its compiled ``kernel`` (None or False
    too): a kernel is told (``retire()``), so that the compiled loop that
    steps the side through the kernel's C face asks the side again."""
    if kernel:
        kernel.retire()
    return None
