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

import importlib
import logging
import os

__all__ = ["kernel_choice", "compiled_module", "import_kernel", "retired", "KERNEL_ENV",
           "REBUILD"]

logger = logging.getLogger(__name__)

#: the environment variable that chooses the implementation
KERNEL_ENV = "COSIM_KERNEL"
_CHOICES = ("compiled", "numpy")
_missing_said: set[str] = set()
#: what rebuilds every kernel, as an error says it
REBUILD = "`pip install .`, or in a source tree `python setup.py build_ext --inplace`"


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


def import_kernel(name: str):
    """Import the compiled module ``name`` (its full dotted name).

    Raises
    ------
    ImportError
        Where it was not built (a caller falls back to the reference, and
        says so).
    cosim.errors.KernelBuildError
        Where it was built but does not fit the modules it was built with:
        Cython checks at import that each type it shares with another kernel
        (or with numpy) has the size it was compiled against, and raises
        ValueError ("size changed, may indicate binary incompatibility") when
        one of them was rebuilt from changed declarations without the other.
        That is a broken build, not a missing one: running on the reference
        would hide it (a test comparing the kernel with the reference would
        compare the reference with itself), so the run stops and says what
        rebuilds it.
    """
    try:
        return importlib.import_module(name)
    except ValueError as exc:
        from cosim.errors import KernelBuildError
        raise KernelBuildError(
            f"the compiled kernel `{name}` was built but does not fit the modules it was "
            f"built with ({exc}): a kernel was rebuilt from changed declarations (.pxd) "
            f"without its partners; rebuild every kernel: {REBUILD}") from None


def retired(kernel):
    """None, for a side that drops its compiled ``kernel`` (None or False
    too): a kernel is told (``retire()``), so that the compiled loop that
    steps the side through the kernel's C face asks the side again."""
    if kernel:
        kernel.retire()
    return None
