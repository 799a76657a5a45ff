"""The `cosim` command line.  The only package that talks to the terminal.

:func:`main` runs the command line in a caller's process; :func:`console`
is the console script (``cosim = "cosim.cli:console"``) and ``python -m
cosim.cli``: :func:`main`, then the process ends cheaper.  The parser is in
:mod:`cosim.cli.parser`, the sub-commands in :mod:`cosim.cli.commands` (``sweep`` in
:mod:`cosim.cli.sweep_command`, ``bench`` in :mod:`cosim.cli.bench_command`), the
environment checked before any command, the progress line and the
escaping of control characters in :mod:`cosim.cli.terminal`, the stop on
SIGTERM and SIGHUP in :mod:`cosim.cli.signals`.
"""
from __future__ import annotations

import gc
import sys
import warnings

from cosim.cli.parser import build_parser
from cosim.cli.signals import _stop_code
from cosim.cli.terminal import _Printable, _quiet_pipes

__all__ = ["main", "console", "build_parser"]


def main(argv=None) -> int:
    stdout, stderr = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _Printable(stdout), _Printable(stderr)
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = stdout, stderr


def console(argv=None) -> int:
    """:func:`main` as the `cosim` command runs it, in a process of its own.

    Once the command is done, every object the process holds is moved out of
    the garbage collector's reach (:func:`gc.freeze`): the interpreter's exit
    then skips its last collections over them, about a tenth of a `cosim run`
    of three_mass (0.25 s of CPU).  Nothing is left to them: every file cosim
    writes is whole and closed when its writer returns (``atomic_write``), and
    the exit handlers run as before.  Not for a process that goes on after
    (the garbage it holds would stay), hence not in :func:`main`.
    """
    one_blas_thread_by_default()
    code = main(argv)
    gc.freeze()
    return code


#: the variables a user sets to choose OpenBLAS's threads (numpy's and scipy's)
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def one_blas_thread_by_default() -> None:
    """Run numpy's and scipy's OpenBLAS on one thread in this process and the
    processes it starts, unless the user chose a count (one of
    :data:`BLAS_THREAD_VARIABLES` is set) or numpy is loaded already.

    cosim's solves work on small matrices (a side's modes, a robot's joints),
    which OpenBLAS runs on one thread anyway; but a threaded OpenBLAS starts
    its threads when numpy loads, and they spin, each on a core, for a while
    before they sleep: in a fresh `cosim run` that spinning overlaps the solve
    and doubles the process's CPU there (docs/performance.md, *First runs*).
    """
    import os
    if "numpy" in sys.modules or any(v in os.environ for v in BLAS_THREAD_VARIABLES):
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"


#: exit status when the reader of our output went away (`cosim run ... | head`): 128 + SIGPIPE
EXIT_BROKEN_PIPE = 141


def _check_environment() -> None:
    """Read each environment variable cosim reads (``COSIM_KERNEL``,
    ``COSIM_DRIVER``, ``COSIM_FMU_UNPACK_LIMIT``), so that a bad value is
    refused before any work; a ValueError names the first bad one."""
    import os

    from cosim.core.schemes.driver import driver_choice
    from cosim.sides.kernel import kernel_choice
    kernel_choice()
    driver_choice()
    if "COSIM_FMU_UNPACK_LIMIT" in os.environ:    # read by the FMU's module: loaded only then
        from cosim.sides.fmu_unpack import unpack_limit
        unpack_limit()


def _main(argv) -> int:
    args = build_parser().parse_args(argv)
    try:                                 # a bad COSIM_* variable is said before anything runs
        _check_environment()
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from cosim.errors import KernelBuildError, OutputError, OutputExistsError, PluginError
    from cosim.scene.load import SceneError
    from cosim.core.schemes import UnsafeStepError

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = lambda msg, *a, **k: print(f"warning: {msg}", file=sys.stderr)
        try:
            try:
                code = args.func(args)
                sys.stdout.flush()             # a closed pipe shows here, not at exit
                return code
            except OutputExistsError as exc:
                print(f"error: {exc.for_command_line()}", file=sys.stderr)
                return 2
            except (SceneError, UnsafeStepError, OutputError, PluginError,
                    KernelBuildError) as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 2
            except (Exception, SystemExit) as exc:     # an installed plug-in's failure
                from cosim.core.plugin_guard import blame
                blamed = blame(exc)
                if blamed is None:
                    raise
                print(f"error: {blamed}", file=sys.stderr)
                return 2
            except KeyboardInterrupt as exc:   # outside a run (a run's own is handled there)
                name = getattr(exc, "signal_name", None)
                print("error: interrupted" + (f" ({name})" if name else ""), file=sys.stderr)
                return _stop_code(exc)
        except BrokenPipeError:
            _quiet_pipes()
            return EXIT_BROKEN_PIPE
