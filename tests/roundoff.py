"""Discrete outcomes under round-off: the shared helper of the tests.

A test that asserts a count, a guard's verdict, chatter or a regime asserts
it for the scene and for copies whose initial state is moved by a few ulps
(:func:`cosim.studies.roundoff.spread`): another CPU's numpy (AVX-512 array
powers differ from a scalar ``**`` by an ulp) or another build must not turn
the verdict.  ``COPIES`` is the scene plus four copies (+1, -1, +2, -2 ulps).
"""
from __future__ import annotations

import warnings

import cosim
from cosim.studies.roundoff import perturbed_overrides, spread

#: the scene and its moved copies that a discrete outcome must hold for
COPIES = 5


def outcomes(scene, outcome, copies: int = COPIES, scheme=None, estimate: bool = False) -> list:
    """``outcome(result)`` of the scene and of each moved copy (the run
    alone: its error estimate, whose companions are runs of their own, only
    with ``estimate``)."""
    out = []
    with warnings.catch_warnings():     # the copies repeat the warnings of the scene's load
        warnings.simplefilter("ignore")
        for s in spread(scene, copies):
            out.append(outcome(cosim.simulate(s, scheme=scheme, estimate=estimate)))
    return out


def assert_robust(scene, outcome, expected=None, copies: int = COPIES, scheme=None):
    """Assert that ``outcome`` is the same (and ``expected``, when given) for
    the scene and its copies moved by round-off; return it."""
    seen = outcomes(scene, outcome, copies, scheme)
    first = seen[0] if expected is None else expected
    assert all(o == first for o in seen), f"not robust to round-off: {seen}"
    return first


def cli_copies(scene, copies: int = COPIES) -> list[list[str]]:
    """The ``--set`` arguments of each copy, for a test that runs the CLI."""
    from cosim.studies.roundoff import OFFSETS
    out = [[]]
    for k in OFFSETS[:copies - 1]:
        args = []
        for o in perturbed_overrides(scene, k):
            args += ["--set", o]
        out.append(args)
    return out
