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
