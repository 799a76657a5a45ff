"""What makes a run on request cheaper without changing what it computes:
an assembled structure kept for the next build of the same scene
(:func:`cosim.scene.build.clear_assembled`), and the contact's exact
one-step map in closed form (:func:`cosim.core.preflight._exact_map`)."""
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

import cosim
import fem
from cosim.core import preflight
from cosim.scene import build

CASES = Path(__file__).resolve().parents[1] / "cases"


def _load(name, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", None, list(overrides))


def _structure(system):
    return next(s for s in system.subsystems if "modes" in s.capabilities)


@pytest.fixture
def assemblies(monkeypatch):
    """Counts the beam's assemblies, the kept ones forgotten first."""
    calls = []
    real = fem.Beam.assemble

    def counted(self):
        calls.append(self)
        return real(self)
    monkeypatch.setattr(fem.Beam, "assemble", counted)
    build.clear_assembled()
    yield calls
    build.clear_assembled()


def test_a_scene_built_again_is_assembled_once_and_each_build_has_its_own_arrays(assemblies):
    scene = _load("beam_impact")
    a, _ = scene.build()
    b, _ = _load("beam_impact", ["scheme.macro_step=2e-5"]).build()   # the steps alone differ
    assert len(assemblies) == 1
    sa, sb = _structure(a), _structure(b)
    assert sa.structure is not sb.structure
    assert not np.shares_memory(sa.structure.mass.data, sb.structure.mass.data)
    # the same assembly: the same matrices and modes (copies, so equal bit for bit)
    assert np.array_equal(sa.structure.stiffness.toarray(), sb.structure.stiffness.toarray())
    assert np.array_equal(sa.omega, sb.omega)
    build.clear_assembled()
    _load("beam_impact").build()
    assert len(assemblies) == 2                 # forgotten: assembled again


def test_another_structure_is_assembled_anew(assemblies):
    a, _ = _load("beam_impact").build()
    b, _ = _load("beam_impact", ["subsystems.beam.youngs_modulus=105e9"]).build()
    assert len(assemblies) == 2
    # half the stiffness: every frequency 1/sqrt(2) of the other's (the same mass)
    ratio = _structure(b).omega[:3] / _structure(a).omega[:3]
    assert np.allclose(ratio, 1 / math.sqrt(2), rtol=1e-9)


def test_a_kept_assembly_runs_as_a_fresh_one():
    """The run built on a kept assembly is the run built on a new one: the
    same arrays step the same way (their contact count and peak agree; the
    peak within a few ulps, as two builds of one scene may order sums
    differently)."""
    scene = _load("beam_impact")
    build.clear_assembled()
    fresh = cosim.simulate(scene)
    kept = cosim.simulate(scene)                  # its structure from the one kept
    build.clear_assembled()
    for name, c in fresh.summary["contacts"].items():
        assert kept.summary["contacts"][name]["count"] == c["count"]
        p, q = c["peak_penetration"], kept.summary["contacts"][name]["peak_penetration"]
        assert abs(p - q) <= 8 * np.spacing(abs(p)), name


def test_a_plug_in_model_is_not_kept():
    class Spec:
        type = "beam"
        modes = {}
        model = object()       # not a model of fem: it may assemble anything

    assert build._assembly_key(Spec) is None


@pytest.mark.parametrize("zeta", [0.0, 1e-3, 0.1, 0.7, 1.0 - 1e-9, 1.0, 1.0 + 1e-9, 1.5, 30.0,
                                  1e3])
def test_the_closed_form_exact_map_is_the_matrix_exponential(zeta):
    """Against scipy's Pade expm, within 1e-11 of its largest entry: expm's
    own scaling and squaring loses about that much at ``c H / m`` of 6e4
    (zeta 1e3, omega H 30); the closed form's error there is 2e-17 (checked
    against 40-digit arithmetic when it was written)."""
    for omega in (1e2, 3e5):
        for wh in (1e-8, 1e-4, 0.01, 0.3, 1.0, 3.0, 30.0):
            m = 1.3
            k, c, H = omega * omega * m, 2.0 * zeta * omega * m, wh / omega
            ref = expm(np.array([[0.0, 1.0], [-k / m, -c / m]]) * H)
            got = preflight._exact_map(m, k, c, H)
            assert np.all(np.isfinite(got))
            assert np.max(np.abs(got - ref)) <= 1e-11 * np.max(np.abs(ref)), (omega, wh)
