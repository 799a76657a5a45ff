"""Why the strip of tests/test_plane_truncation.py needs 20 times the contact
frequency where "within 1e-4 at 10 times" was asked, measured.

With the static correction, what the dropped modes still miss is their
dynamic answer to the force's onset: a penalty spring switches on with a
kink in the force (its slope jumps from 0 to k v), which rings each dropped
mode by about ``(phi_i . b)^2 k v / omega_i^3``.  Against the penetration
``v / omega_c`` that is a share bounded by ``c_r k`` times the ratio of the
contact frequency to the dropped ones (``c_r k``: the share of the dropped
modes' compliance ``c_r`` in the contact's); measured, it lies well below
that bound.  A static correction cannot remove it (a second-order term,
``omega_c^2 b^T (K^-1 M K^-1 - sum phi phi^T / omega^4) b`` added to
``c_r``, was tried outside the suite: at 10 times it left 2.3e-4 of the
peak's 3.0e-4), and the error's sign and size swing with where the cutoff
falls among the modes.  So on the strip struck through 1e8 N/m (``c_r k`` 0.043 at 10 times) the peak's error at cutoffs
of 8 to 12 times runs from below 1e-6 to 3e-4 (at 10 times: 3.0e-4), while
through 1e7 N/m (``c_r k`` 0.0071) it stays below 1e-4 at every one of them,
as it does through 1e8 N/m at 25 and 28 times, where ``c_r k`` has fallen
below 1e-2 (``benchmarks/plane_truncation.py`` scans the cutoffs).
Each run is the monolithic reference at rtol 1e-11 (only the modes differ).
"""
import warnings

import numpy as np
import pytest

import cosim
from documented import Claim, assert_printed, assert_reproduced
from fem.plane import rectangle
from plane_files import write_msh
from test_plane_truncation import SCENE

MASS = 0.2
PAGE = "docs/structures.md"


def _contact_hz(k: float) -> float:
    return float(np.sqrt(k / MASS) / (2 * np.pi))


def _first_contact(tmp_path, k: float, modes: str = ""):
    """(duration, peak force) of the first contact, the kept modes' top
    frequency and ``c_r k`` (zero without the correction)."""
    if not (tmp_path / "strip.msh").exists():
        write_msh(tmp_path / "strip.msh", rectangle(1.0, 0.1, 20, 2), "strip")
    text = SCENE.format(modes=modes).replace("contact_stiffness = 1e8",
                                             f"contact_stiffness = {k!r}")
    # the contact through 1e7 N/m lasts 0.44 ms
    text = text.replace("t_end = 4e-4", "t_end = 1.2e-3")
    path = tmp_path / "strip.toml"
    path.write_text(text)
    scene = cosim.load_scene(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # the mode rule and Flamant's warnings
        system, _ = scene.build()
        c = cosim.simulate(scene, estimate=False).summary["contacts"]["hit"]
    k_run = system.links[0].contact.law.contact_stiffness
    on, off = c["intervals"][0]
    sub = system.subsystems[0]
    return (np.array([off - on, k_run * c["peak_penetration"]]),
            sub.natural_frequencies_hz[-1], k / k_run - 1.0)


def _errors(tmp_path, k, ratios):
    ref, top, _ = _first_contact(tmp_path, k)
    assert top > 50 * _contact_hz(k)                       # all 400 modes of the mesh
    out = {}
    for r in ratios:
        got, top, crk = _first_contact(tmp_path, k, f"modes = {{ cutoff_hz = "
                                                    f"{r * _contact_hz(k)}, "
                                                    f"static_correction = true }}")
        assert r * _contact_hz(k) / 2 < top < r * _contact_hz(k)
        out[r] = (got / ref - 1, crk)
    return out


def test_the_error_at_10_times_swings_with_the_cutoff_when_c_r_k_is_large(tmp_path):
    err = _errors(tmp_path, 1e8, (8, 10, 12, 25, 28))
    # far enough up the modes, c_r k falls below 1e-2 and the error below 1e-4
    for r in (25, 28):
        assert err[r][1] < 1e-2 and np.all(np.abs(err[r][0]) < 1e-4), (r, err[r])
    for r in (8, 10, 12):
        assert err[r][1] > 3e-2
    err = {r: err[r] for r in (8, 10, 12)}
    peak = {r: abs(e[1]) for r, (e, _) in err.items()}
    cmd = "tests/test_plane_truncation_rule.py (k = 1e8 N/m)"
    for printed, value, measured, tol in (
            ("at 10 times: 3.0e-4", 3.0e-4, peak[10], 0.05e-4),
            ("`c_r k` 0.043", 0.043, err[10][1], 5e-4)):
        claim = Claim(PAGE, printed, cmd, value, abs=tol)
        assert_printed(claim)
        assert_reproduced(claim, measured)
    assert peak[10] > 1e-4                                  # the issue's 1e-4 is not met
    assert min(peak[8], peak[12]) < 1e-6                    # its neighbours meet it by far
    assert_printed(Claim(PAGE, "from below 1e-6 to 3e-4", cmd, 3e-4))
    for e, _ in err.values():
        assert np.all(np.abs(e) < 5e-4)                     # the rule's 10 times: 5e-4


def test_a_small_c_r_k_meets_1e_4_at_10_times(tmp_path):
    err = _errors(tmp_path, 1e7, (8, 10, 12))
    assert all(crk < 1e-2 for _, crk in err.values())
    claim = Claim(PAGE, "`c_r k` 0.0071", "tests/test_plane_truncation_rule.py (k = 1e7 N/m)",
                  0.0071, abs=5e-5)
    assert_printed(claim)
    assert_reproduced(claim, err[10][1])
    for e, _ in err.values():
        assert np.all(np.abs(e) < 1e-4), e


def _dropped_share_warnings(tmp_path, k: float, ratio: float):
    """The build's warnings that name the dropped modes' share, and the rule
    ``cosim info`` gives, for the strip through ``k`` kept to ``ratio`` x its
    contact frequency."""
    from cosim.scene.plane_build import mode_rules
    if not (tmp_path / "strip.msh").exists():
        write_msh(tmp_path / "strip.msh", rectangle(1.0, 0.1, 20, 2), "strip")
    modes = f"modes = {{ cutoff_hz = {ratio * _contact_hz(k)!r}, static_correction = true }}"
    path = tmp_path / f"strip_{k:g}_{ratio:g}.toml"
    path.write_text(SCENE.format(modes=modes).replace("contact_stiffness = 1e8",
                                                      f"contact_stiffness = {k!r}"))
    scene = cosim.load_scene(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        system, _ = scene.build()
    said = [str(w.message) for w in caught if "of the contact's compliance" in str(w.message)]
    return said, mode_rules(system, scene)["strip"][0]


@pytest.mark.parametrize("nudge", [1.0, 1.0 + 4e-16, 1.0 - 4e-16])
def test_the_rule_warns_where_the_dropped_modes_hold_over_1e_2(tmp_path, nudge):
    # through 1e8 N/m at 15 x the contact frequency the frequency rule is met
    # (ok) but the dropped modes hold ~3e-2 of the compliance: the run warns and
    # `cosim info` says warn; at 28 x (share 6e-3, the error within 1e-4 above) both are quiet
    said, rule = _dropped_share_warnings(tmp_path, 1e8 * nudge, 15.0)
    assert rule["ratio"] >= 10.0 and rule["dropped_share"] > 1e-2, rule
    assert rule["verdict"] == "warn" and len(said) == 1 and "soften the spring" in said[0]
    said, rule = _dropped_share_warnings(tmp_path, 1e8 * nudge, 28.0)
    assert rule["dropped_share"] < 1e-2 and rule["verdict"] == "ok" and not said, (rule, said)
