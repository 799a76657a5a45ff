"""The paper's findings (Lipinski, sections 6-7; CASES.md sections 4-5), computed
with the monolithic reference.  Nothing in the code knows these numbers."""
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES
from roundoff import assert_robust

THREE_MASS = CASES / "three_mass.toml"
#: C's trains (f >= 4, and the light chains) end by 0.128 s: the round-off copies
#: run to here, half the scene's 0.25 s, and count the same train
T_TRAIN = 0.13


def three_mass(variant, *overrides, scheme="monolithic"):
    with warnings.catch_warnings():     # the co-simulation options are not its
        warnings.simplefilter("ignore")
        return cosim.load_scene(THREE_MASS, variant, list(overrides), scheme=scheme)


def c_contacts(variant, scheme="monolithic"):
    with warnings.catch_warnings():     # the co-simulation options are not its
        warnings.simplefilter("ignore")
        res = cosim.simulate(cosim.load_scene(THREE_MASS, variant, scheme=scheme), estimate=False)
    assert res.success, res.message
    return res


@pytest.mark.parametrize("f,count", [(1, 1), (2, 1), (4, 4), (10, 8), (100, 9)])
def test_contact_count_of_c_grows_with_the_contact_stiffness(f, count):
    """CASES.md section 5: for f >= 4 a train of rebounds and re-contacts (up to
    about 9 at f = 100) inside one in-touch period.  A train's count holds for
    the scene's round-off copies too (four copies, run to the train's end:
    1.3 s each)."""
    c = c_contacts(f"f{f}").summary["contacts"]["C"]
    assert c["count"] == count, c["intervals"]
    if count > 1:
        assert_robust(three_mass(f"f{f}", f"t_end={T_TRAIN}"),
                      lambda r: (r.status, r.summary["contacts"]["C"]["count"]),
                      ("finished", count))


def test_in_touch_period_barely_depends_on_f():
    """The whole in-touch period (first touch to last release) at f = 4, 10 and
    100 stays within 25 % of its mean while the stiffness grows 25-fold."""
    spans = []
    for f in (4, 10, 100):
        iv = c_contacts(f"f{f}").summary["contacts"]["C"]["intervals"]
        spans.append(iv[-1][1] - iv[0][0])
    assert max(spans) / min(spans) < 1.25, spans


def regime(res):
    """backward: one contact; backward+: the arm turns back before C touches
    again (the faster top mass catches it); forward: a train of contacts
    before the arm turns back."""
    iv = res.summary["contacts"]["C"]["intervals"]
    if len(iv) == 1:
        return "backward"
    t, darm = res.series["t"], res.series["dq/robot/arm"]
    i0 = np.searchsorted(t, iv[0][0])
    t_back = t[i0 + np.flatnonzero(darm[i0:] > 0)[0]]
    return "backward+" if t_back <= iv[1][0] else "forward"


@pytest.mark.parametrize("ms,expected", [("ms6.4", "backward"), ("ms1.6", "backward+"),
                                         ("ms0.2", "forward")])
def test_three_regimes_as_the_chain_mass_falls(ms, expected):
    """The regime holds for the scene and its round-off copies (the trains, at
    ms1.6 and ms0.2, run to their end; one contact at ms6.4 is no train)."""
    assert regime(c_contacts(ms)) == expected
    if expected != "backward":
        assert_robust(three_mass(ms, f"t_end={T_TRAIN}"), lambda r: (r.status, regime(r)),
                      ("finished", expected))


@pytest.mark.slow
def test_regime_sweep_is_ordered():
    """The whole sweep: heaviest chains backward, lightest forward, in order."""
    order = {"backward": 0, "backward+": 1, "forward": 2}
    found = [regime(c_contacts(f"ms{m}")) for m in ("6.4", "3.2", "1.6", "0.8", "0.4", "0.2",
                                                     "0.1", "0.05")]
    assert found[0] == "backward" and found[-1] == "forward"
    assert [order[r] for r in found] == sorted(order[r] for r in found), found


def test_ground_multicontact_lifts_off_before_c_strikes():
    """CASES.md section 4: B leaves within 2 ms, A later, both before C strikes;
    the order, and each contact's count (A 4, B 2, C 1), hold for the scene
    and its round-off copies."""
    def lift_off(res):
        c = res.summary["contacts"]
        b_off, a_off = c["B"]["intervals"][0][1], c["A"]["intervals"][0][1]
        return (res.status, b_off < 2e-3, b_off < a_off < c["C"]["intervals"][0][0],
                [c[n]["count"] for n in "ABC"])

    assert_robust(cosim.load_scene(CASES / "ground_multicontact.toml"), lift_off,
                  ("finished", True, True, [4, 2, 1]))


def _exit_rate(res, contact, k_interval):
    """Separation speed (gap rate) at the end of a contact interval, from the
    series by a central difference around the release."""
    t, g = res.series["t"], res.series[f"gap/{contact}"]
    t_off = res.summary["contacts"][contact]["intervals"][k_interval][1]
    i = min(np.searchsorted(t, t_off) + 1, len(t) - 2)
    return (g[i + 1] - g[i - 1]) / (t[i + 1] - t[i - 1])


def test_strike_variant_shows_the_papers_findings():
    """CASES.md section 4, variant strike: C's impact makes A co-impact while B
    separates; C's peak penetration is several times A's; C's exit velocity
    barely depends on A's stiffness while A's depends on it strongly."""
    scenes = {v: cosim.load_scene(CASES / "ground_multicontact_strike.toml", v)
              for v in ("kA1e6", "kA4e6", "kA16e6")}
    runs = {v: cosim.simulate(scene, estimate=False) for v, scene in scenes.items()}

    def co_impact(res):
        """One contact of C, during which A strikes again and B separates."""
        c = res.summary["contacts"]
        if c["C"]["count"] != 1:
            return res.status, c["C"]["count"], None, None
        (c_on, c_off), = c["C"]["intervals"]
        a_again = [iv for iv in c["A"]["intervals"] if c_on < iv[0] < c_off]
        return res.status, 1, bool(a_again), c_on < c["B"]["intervals"][0][1] < c_off

    for v, res in runs.items():
        assert co_impact(res) == ("finished", 1, True, True), v
        c = res.summary["contacts"]
        assert c["C"]["peak_penetration"] > 3 * c["A"]["peak_penetration"]
        # the co-impact holds for the scene's round-off copies (0.1 s a run)
        assert_robust(scenes[v], co_impact, ("finished", 1, True, True))
    v_c = [_exit_rate(r, "C", 0) for r in runs.values()]
    v_a = [_exit_rate(r, "A", 1) for r in runs.values()]
    assert (max(v_c) - min(v_c)) / np.mean(v_c) < 0.05, v_c          # observed 2 %
    assert (max(v_a) - min(v_a)) / np.mean(np.abs(v_a)) > 0.3, v_a
