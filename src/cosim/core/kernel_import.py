"""Importing a compiled kernel: missing is one thing, built wrong another.

Core's loops and the sides load their compiled modules through
:func:`import_kernel` (re-exported by :mod:`cosim.sides.kernel`, which
chooses between a kernel and its numpy reference).
"""
from __future__ import annotations

import importlib

__all__ = ["import_kernel", "REBUILD"]

#: what rebuilds every kernel, as an error says it
REBUILD = "`pip install .`, or in a source tree `python setup.py build_ext --inplace`"


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
