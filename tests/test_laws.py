"""Penalty laws: never tensile, switch and force agree, dissipation is never negative."""
import numpy as np
import pytest

from couplers import (CONTACT_LAWS, FloresLaw, HertzLaw, HuntCrossleyLaw, KelvinVoigtLaw,
                      LankaraniNikraveshLaw, LinearLaw, RigidLaw, get_contact_law)
from ulps import after_product, assert_within, assert_within_ulps, ulp

# The hysteresis examples clip (1 + chi dd <= 0) inside the sampled |dd| <= 5 m/s.
EXAMPLES = {"linear": LinearLaw(1e6), "kelvin_voigt": KelvinVoigtLaw(1e6, 300.0),
            "rigid": RigidLaw(0.5, 0.2),
            "hertz": HertzLaw(1e9, 1.5),
            "hunt_crossley": HuntCrossleyLaw(1e9, 1.5, 0.5),
            "lankarani_nikravesh": LankaraniNikraveshLaw(1e9, 1.5, 0.8, 1.0),
            "flores": FloresLaw(1e9, 1.5, 0.5, 2.0)}
PENALTY = sorted(k for k, v in CONTACT_LAWS.items() if not v.rigid)


def test_every_registered_law_has_an_example():
    assert set(EXAMPLES) == set(CONTACT_LAWS)


@pytest.fixture(params=PENALTY)
def law(request):
    return EXAMPLES[request.param]


def test_rigid_law_has_no_force_and_switches_at_touch():
    law = EXAMPLES["rigid"]
    d = np.array([-1e-3, 0.0, 1e-3])
    assert np.all(law.force(d, np.ones(3)) == 0) and np.all(law.potential(d) == 0)
    assert list(law.switch(d, np.zeros(3)) > 0) == [False, False, True]
    with pytest.raises(ValueError, match=r"`restitution` must be in \(0, 1\], got 1\.5"):
        RigidLaw(1.5, 0.0)
    with pytest.raises(ValueError, match=r"`friction` must be >= 0"):
        RigidLaw(0.5, -0.1)


def test_force_is_never_tensile_and_agrees_with_switch(law):
    rng = np.random.default_rng(1)
    d = rng.uniform(-1e-3, 1e-3, 2000)
    dd = rng.uniform(-5, 5, 2000)
    f = law.force(d, dd)
    assert np.all(f >= 0)
    assert np.all((f > 0) == (law.switch(d, dd) > 0))
    assert np.all(f[d <= 0] == 0)


def test_dissipation_is_never_negative(law):
    rng = np.random.default_rng(2)
    d = rng.uniform(-1e-3, 1e-3, 2000)
    dd = rng.uniform(-5, 5, 2000)
    p = law.dissipation_rate(law.force(d, dd), d, dd)
    assert np.all(p >= -1e-9)


def test_potential_slope_is_derivative(law):
    d = np.linspace(1e-5, 1e-3, 7)
    eps = 1e-9
    num = (law.potential(d + eps) - law.potential(d - eps)) / (2 * eps)
    assert np.allclose(num, law.potential_slope(d), rtol=1e-5)


def test_kelvin_voigt_dissipates_only_by_its_dashpot_while_active():
    law = EXAMPLES["kelvin_voigt"]
    d, dd = 1e-4, 2.0
    f = law.force(d, dd)
    assert law.dissipation_rate(f, d, dd) == pytest.approx(300.0 * dd ** 2)


@pytest.mark.parametrize("kwargs,match", [
    ({"contact_stiffness": -1e6}, r"`contact_stiffness` must be > 0 N/m, got -1000000\.0"),
    ({"contact_stiffness": 0.0}, r"`contact_stiffness` must be > 0 N/m"),
    ({"contact_stiffness": float("nan")}, r"`contact_stiffness` must be > 0 N/m, got nan"),
    ({"contact_stiffness": 1e6, "contact_damping": -1.0}, r"`contact_damping` must be >= 0"),
])
def test_parameters_are_checked(kwargs, match):
    with pytest.raises(ValueError, match=match):
        KelvinVoigtLaw(**kwargs)


def test_registry_lookup():
    assert get_contact_law("linear") is LinearLaw
    assert get_contact_law(KelvinVoigtLaw) is KelvinVoigtLaw
    with pytest.raises(ValueError, match=r"unknown contact law 'hertzz'; valid laws are"):
        get_contact_law("hertzz")


#: laws whose formulas hold a power ``d ** n`` (n != 1), the one operation the
#: scalar and the array paths do not share: Python's ``**`` calls the C
#: library's ``pow``, numpy's array power its own (AVX-512) code
POWERED = sorted(k for k, v in EXAMPLES.items() if getattr(v, "exponent", 1.0) != 1.0)


@pytest.mark.parametrize("name", sorted(CONTACT_LAWS))
def test_scalar_evaluation_is_the_array_formula(name):
    """``evaluate`` and the scalar ``potential``/``potential_slope`` (what
    integrators and the schemes call per step, without array calls) give
    what the array formulas give: the switch bit for bit, the force, power
    and potentials within the ulps the one power they compute differently
    can move them (bit for bit too where the law has no power)."""
    law = EXAMPLES[name]
    rng = np.random.default_rng(7)
    d = np.concatenate([rng.uniform(-1e-3, 1e-3, 300), [0.0, -0.0, 1e-300]])
    dd = rng.uniform(-5.0, 5.0, d.size)
    f_arr, sw_arr = law.force(d, dd), law.switch(d, dd)
    s_arr, v_arr = law.potential_slope(d), law.potential(d)
    p_arr = law.dissipation_rate(f_arr, d, dd)
    for x, y in ((d.tolist(), dd.tolist()), (list(d), list(dd))):   # Python and numpy floats
        f, p, sw = np.array([law.evaluate(a, b) for a, b in zip(x, y)]).T
        s = np.array([law.potential_slope(a) for a in x])
        v = np.array([law.potential(a) for a in x])
        # the switch is +, * and min on both paths, in the same order, each
        # correctly rounded: the same bits on every machine; and the scalar
        # force is on exactly where the array's is
        assert np.array_equal(sw, sw_arr), name
        assert np.array_equal(f > 0, f_arr > 0), name
        if name not in POWERED:
            # no power: the same correctly rounded operations in the same
            # order on both paths (IEEE 754), hence the same bits
            for got, want in ((f, f_arr), (p, p_arr), (s, s_arr), (v, v_arr)):
                assert np.array_equal(got, want), name
            continue
        # Both pows are faithful (the C library's: glibc's and musl's are
        # within 0.54 ulp; numpy's AVX-512 one: measured within 1 ulp of
        # glibc's over 400 000 arguments), so they differ by at most 1 ulp;
        # each later product or quotient by the same number turns n ulps
        # into 2 n + 1 (tests/ulps.py).
        slope = after_product(1)                 # k * d**n
        force = after_product(1, 2)              # (k * d**n) * (1 + chi dd)
        energy = after_product(1, 2)             # (k * d**(n+1)) / (n+1)
        why = "pow within 1 ulp of the other path's, then "
        assert_within_ulps(s, s_arr, slope, why + "one product")
        assert_within_ulps(f, f_arr, force, why + "two products")
        assert_within_ulps(v, v_arr, energy, why + "a product and a quotient")
        # p = (f - slope) dd cancels: its bound is the force's and the
        # slope's ulps carried through the subtraction (which rounds by half
        # an ulp of f - slope on each path) and the product by dd (half an
        # ulp of p on each path)
        big_f = np.maximum(np.abs(f), np.abs(f_arr))
        big_s = np.maximum(np.abs(s), np.abs(s_arr))
        big_diff = np.maximum(np.abs(f - s), np.abs(f_arr - s_arr))
        bound = (np.abs(dd) * (force * ulp(big_f) + slope * ulp(big_s) + ulp(big_diff))
                 + ulp(np.maximum(np.abs(p), np.abs(p_arr))))
        assert_within(p, p_arr, bound, "the force's and the slope's ulps through (f - slope) dd")
