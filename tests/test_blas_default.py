"""The command line runs numpy's OpenBLAS on one thread unless the user
chose a count: a threaded OpenBLAS's threads spin after numpy loads, and in a
fresh `cosim run` their CPU lands in the solve's (docs/performance.md)."""
import os
import subprocess
import sys

import pytest

from cosim.cli import BLAS_THREAD_VARIABLES

_PROBE = """
import os, sys
from cosim.cli import one_blas_thread_by_default
{before}
one_blas_thread_by_default()
print(os.environ.get("OPENBLAS_NUM_THREADS", "unset"))
"""


def _probe(env_extra: dict, before: str = "") -> str:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    env.update(env_extra)
    out = subprocess.run([sys.executable, "-c", _PROBE.format(before=before)], env=env,
                         capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_one_thread_where_the_user_chose_none():
    assert _probe({}) == "1"


@pytest.mark.parametrize("variable", BLAS_THREAD_VARIABLES)
def test_a_users_count_is_kept(variable):
    assert _probe({variable: "3"}) == ("3" if variable == "OPENBLAS_NUM_THREADS" else "unset")


def test_too_late_once_numpy_is_loaded():
    # the threads exist by then: changing the variable would only mislead
    assert _probe({}, before="import numpy") == "unset"


def test_the_command_line_sets_it_for_its_run(tmp_path):
    # `cosim run` through the console script's path; its child sees one thread
    code = ("import os, sys\nfrom cosim.cli import console\n"
            "rc = console(['info', 'cases/spring_drop.toml'])\n"
            "print('BLAS', os.environ.get('OPENBLAS_NUM_THREADS'))\nsys.exit(rc)\n")
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=root,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "BLAS 1" in out.stdout

