import os
from pathlib import Path

import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "cases"

# Hypothesis profiles.  ``ci`` (the default): the examples follow from each
# test's name alone (derandomize), so a failure reproduces from its printout
# on any machine, the printout carries the @reproduce_failure blob, and no
# example database is read or written (CI carries no state between runs).
# ``explore`` (HYPOTHESIS_PROFILE=explore): EXPLORE_FACTOR times the examples,
# drawn at random, to look for new defects; a defect found becomes an
# explicit @example on its test.
CI_EXAMPLES = 100
EXPLORE_FACTOR = 20
settings.register_profile("ci", max_examples=CI_EXAMPLES, derandomize=True, print_blob=True,
                          deadline=None, database=None)
settings.register_profile("explore", max_examples=EXPLORE_FACTOR * CI_EXAMPLES,
                          derandomize=False, print_blob=True, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def examples(n: int) -> int:
    """``n`` examples under the ``ci`` profile, as many times more under a
    profile that asks for more (``explore``): a test's own
    ``settings(max_examples=examples(n))`` scales with the profile instead of
    overriding it."""
    return max(1, n * settings.default.max_examples // CI_EXAMPLES)


@pytest.fixture
def spring_drop():
    return CASES / "spring_drop.toml"


# ------------------------------------------------------------ test FMUs
def load_fmu_build(name: str = "fmu_build"):
    """``examples/fmu/build.py`` as a fresh module (a test may change its copy)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / "fmu" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def fmu_build():
    """``(examples/fmu/build.py as a module, the C compiler)``; the test
    skips without FMPy or a C compiler."""
    pytest.importorskip("fmpy", reason="FMPy is not installed (the `fmi` extra)")
    module = load_fmu_build()
    cc = module.find_compiler()
    if cc is None:
        pytest.skip("no C compiler found ($CC, gcc or cc): the test FMU cannot be built")
    return module, cc


@pytest.fixture(scope="session")
def fmus(fmu_build, tmp_path_factory):
    """``{(fmi_version, state): path}`` of the example arm FMUs, built once."""
    module, cc = fmu_build
    out = tmp_path_factory.mktemp("fmu")
    return {(v, st): module.build_fmu(out, v, st, cc) for v in (2, 3) for st in (True, False)}
