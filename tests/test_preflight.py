"""The pre-flight stability check of explicit coupling."""
import math
import re

import pytest

import cosim
from analytic import held_force_rebound_factor
from conftest import CASES
from documented import ROOT
from cosim.core import preflight
from cosim.studies.roundoff import OFFSETS, nudge
from roundoff import COPIES

M, K = 1.0, 1e6
W = math.sqrt(K / M)


def test_held_force_gain_matches_delay_theory():
    """The model problem's energy gain is the square of exp(pi omega H / 4)."""
    for H in (1e-5, 4e-5, 1e-4):
        gain = preflight.contact_energy_gain(M, K, 0.0, H, 0)
        assert gain == pytest.approx(held_force_rebound_factor(W, H) ** 2, rel=0.01)


def test_largest_safe_step_undamped_held_force():
    """1 % energy per contact: H* = 4 ln(1.01) / (2 pi omega) from the delay model."""
    h = preflight.largest_safe_step(M, K, 0.0, 1e-3, 0, 0.01)
    assert h == pytest.approx(4 * math.log(1.01) / (2 * math.pi * W), rel=0.03)
    assert preflight.is_safe(M, K, 0.0, 0.9 * h, 0, 0.01)
    assert not preflight.is_safe(M, K, 0.0, 1.1 * h, 0, 0.01)


def test_damped_held_force_stable_only_below_2c_over_k():
    """In sustained contact the held force is a delay H/2 that feeds energy at
    the rate omega^2 H / 4 against the dashpot's c / (2 m): stable iff H < 2c/k."""
    c = 20.0                            # zeta = 0.01, omega * 2c/k = 0.04
    h_crit = 2 * c / K
    for H, stable in ((0.9 * h_crit, True), (1.1 * h_crit, False)):
        A = preflight.step_map(M, K, c, H, 0)
        rho = max(abs(__import__("numpy").linalg.eigvals(A)))
        assert (rho <= 1.0) == stable, (H, rho)


@pytest.mark.parametrize("order", [1, 2])
def test_extrapolation_gains_less_than_holding(order):
    H = 2e-5
    held = preflight.contact_energy_gain(M, K, 0.0, H, 0) - 1
    assert abs(preflight.contact_energy_gain(M, K, 0.0, H, order) - 1) < 0.1 * held


def _load(H, scheme="jacobi", extra=()):
    return cosim.load_scene(CASES / "spring_drop.toml", overrides=[
        'contacts.wall.placement="coupler"', f"scheme.macro_step={H}", *extra], scheme=scheme)


def test_refuses_too_large_step_and_names_contact_step_and_limit():
    # energy factor exp(pi omega H / 2) = 1.01  ->  H* = 2 ln(1.01) / (pi omega) = 6.33e-6 s
    with pytest.raises(cosim.UnsafeStepError,
                       match=r"contact `wall`: macro step 0\.0001 s is too large.*largest safe "
                             r"macro step is 6\.3\de-06 s"):
        cosim.simulate(_load(1e-4), estimate=False)


@pytest.mark.parametrize("scheme", ["jacobi", "gauss_seidel"])
def test_accepts_safe_step(scheme):
    res = cosim.simulate(_load(5e-6, scheme, ["t_end=0.014"]), estimate=False)
    assert res.success
    assert res.summary["final_state"]["body"]["x"]["dq"] == pytest.approx(1.0, rel=0.01)


def test_explicit_risk_acceptance_runs_and_gains_energy():
    # the run guard would stop the run (tests/test_hard_cases.py): turned off to see the gain
    res = cosim.simulate(_load(1e-4, extra=["scheme.accept_unsafe_step=true",
                                            "guard.energy_check=false"]), estimate=False)
    assert res.success
    assert res.summary["energy"]["final"] > 1.15 * res.summary["energy"]["initial"]


def test_implicit_and_embedded_need_no_check():
    assert cosim.simulate(_load(1e-4, "implicit"), estimate=False).success
    scene = cosim.load_scene(CASES / "spring_drop.toml", overrides=["scheme.macro_step=1e-3"],
                             scheme="jacobi")
    assert cosim.simulate(scene, estimate=False).success       # the wall's contact is embedded


# ------------------------------------------------- the refusal's advice works
def _refusal(scene) -> str:
    system, sch = scene.build()
    with pytest.raises(cosim.UnsafeStepError) as info:
        sch.preflight(system, scene.t_end)
    return str(info.value)


def _passes(scene) -> bool:
    system, sch = scene.build()
    try:
        sch.preflight(system, scene.t_end)
    except cosim.UnsafeStepError:
        return False
    return True


def _advised(msg: str, key: str) -> float:
    m = re.search(rf"Set `scheme\.{key}` to ([0-9.e+-]+) s or less", msg)
    assert m, msg
    return float(m[1])


BEAM_C = ["contacts.C.placement=\"coupler\""]    # the scheme, not the beam, steps contact C


def test_a_refused_contact_step_is_named_and_its_advice_passes():
    """beam_impact with contact C in the coupler: its 5e-5 s `contact_step` is
    refused, the refusal names `scheme.contact_step` (not the macro step, whose
    lowering would be refused the same) and the value it advises passes the
    check, as printed and nudged a few ulps."""
    scene = cosim.load_scene(CASES / "beam_impact.toml", overrides=BEAM_C)
    msg = _refusal(scene)
    assert "the step is `scheme.contact_step`" in msg and "scheme.macro_step" not in msg, msg
    h = _advised(msg, "contact_step")
    assert 0 < h < 5e-5
    page = (ROOT / "docs" / "troubleshooting.md").read_text(encoding="utf-8")
    quoted = re.search(r"`(Set `scheme\.contact_step` to [0-9.e+-]+ s or less)`", page)[1]
    assert quoted in msg            # the page quotes this refusal's advice
    for k in (0,) + OFFSETS[:COPIES - 1]:
        assert _passes(cosim.load_scene(CASES / "beam_impact.toml", overrides=BEAM_C + [
            f"scheme.contact_step={nudge(h, k)!r}"]))
    # following the old advice (a smaller macro step) is refused all the same
    assert not _passes(cosim.load_scene(CASES / "beam_impact.toml",
                                        overrides=BEAM_C + ["scheme.macro_step=1e-4"]))


@pytest.mark.parametrize("key", ["macro_step", "contact_step"])
def test_a_refused_macro_step_advises_a_step_that_passes(key):
    """spring_drop at 1e-4 s: the advised value, set as the macro step or as
    the contact step, passes; just above the largest safe step does not."""
    msg = _refusal(_load(1e-4))
    assert "the step is `scheme.macro_step`" in msg, msg
    h = _advised(msg, "macro_step")
    assert "or `scheme.contact_step` to it" in msg
    hmax = float(re.search(r"largest safe macro step is ([0-9.e+-]+) s", msg)[1])
    assert h <= hmax
    for k in (0,) + OFFSETS[:COPIES - 1]:
        assert _passes(_load(1e-4, extra=[f"scheme.{key}={nudge(h, k)!r}"]))
    assert not _passes(_load(1e-4, extra=[f"scheme.{key}={1.05 * hmax!r}"]))


def test_the_advised_step_holds_for_every_contact():
    """Two contacts of different stiffness: the advice is the smaller safe step."""
    problems = [(M, K, 0.0, 0, 0.01, False), (M, 100 * K, 0.0, 0, 0.01, False)]
    h = preflight.advised_step(problems, 1e-4)
    assert all(preflight.is_safe(*p[:3], h, *p[3:]) for p in problems)
    assert h < preflight.largest_safe_step(M, K, 0.0, 1e-4, 0, 0.01)
    assert h == float(f"{h:.2g}")                # exactly what the message prints
