"""The numbers of docs/accuracy.md, "Accuracy on request: validation",
held to the published run of benchmarks/accuracy_validation.py, and one
cheap case of it run again here."""
import json
import math

import pytest

from conftest import ROOT
from documented import flat as _flat, load_script, page_section

SCRIPT = ROOT / "benchmarks" / "accuracy_validation.py"
RUN = ROOT / "benchmarks" / "results" / "accuracy_validation"


@pytest.fixture(scope="module")
def av():
    return load_script(SCRIPT, "accuracy_validation")


@pytest.fixture(scope="module")
def data():
    return json.loads((RUN / "validation.json").read_text())


@pytest.fixture(scope="module")
def section():
    return page_section("docs/accuracy.md", "Accuracy on request: validation")


def test_the_run_covers_every_case_and_its_totals_are_its_own(av, data):
    assert [(c["scene"], c["variant"]) for c in data["cases"]] == \
        [(n, v) for n, v, _ in av.CASES]
    assert data["totals"] == av.totals(data["cases"])
    assert data["accuracy"] == av.ACCURACY == 0.01


def test_the_table_is_the_published_runs(av, data, section):
    assert av.table(data) in section


def test_the_verdicts_follow_from_the_errors(av, data):
    for c in data["cases"]:
        for run in ("default", "request"):
            for p in c[run]["pairs"].values():
                assert p["agrees"] == av.agrees(p["estimated"], p["actual"])
        r = c["request"]
        assert r["met"] == (r["count"] == r["count_ref"] and all(
            r["pairs"][q]["actual"] is not None and r["pairs"][q]["actual"] <= 0.01
            for q in av.QUANTITIES))
        if c["cheapest"] is not None:
            ok = [b for b in c["bench"] if b.get("meets")]
            assert c["cheapest"]["cpu_s"] == min(b["cpu_s"] for b in ok)
            assert math.isclose(c["cpu_ratio"], r["cpu_s"] / c["cheapest"]["cpu_s"])


def test_agreement_is_within_3x_or_both_round_off(av):
    assert av.agrees(0.01, 0.0034) and av.agrees(0.01, 0.029)
    assert not av.agrees(0.01, 0.0032) and not av.agrees(0.01, 0.031)
    assert av.agrees(1e-17, 3e-9) and not av.agrees(1e-17, 2e-8)
    assert av.agrees(None, 0.01) is None and av.agrees(0.01, None) is None


def test_the_totals_the_page_states(data, section):
    t, text = data["totals"], _flat(section)
    assert f"agree within 3x on {t['agree']} of the {t['with_estimate']} pairs" in text
    assert f"{t['without_estimate']} of the {t['pairs']} pairs have no estimate" in text
    assert f"1 % is met on {t['met']} of {t['cases']} scenes" in text
    assert (f"within 1.5x of the cheapest bench row on {t['cpu_within_target']} of "
            f"{t['cases'] - t['no_bench_row']}") in text
    assert f"median {t['cpu_ratio_median']:.2g}x, worst {t['cpu_ratio_max']:.2g}x" in text


def _case(data, scene):
    c, = [c for c in data["cases"] if c["scene"] == scene]
    return c


def test_spring_drop_runs_again_as_published(av, data, tmp_path):
    """spring_drop undamped run here against the published run: the same
    scheme and step, errors within 1e-6 of their value (one contact, no
    train to amplify another machine's round-off), the same verdicts; each
    verdict is held away from its threshold by a margin far above that, so
    a few ulps cannot turn it."""
    pub = _case(data, "spring_drop")
    name, variant, contact = next(c for c in av.CASES if c[0] == "spring_drop")
    now = av.validate_case(name, variant, contact, tmp_path / "cache", repeat=1)
    assert now["reference"]["count"] == pub["reference"]["count"]
    for run in ("default", "request"):
        for q in av.QUANTITIES:
            a, b = now[run]["pairs"][q], pub[run]["pairs"][q]
            assert a["agrees"] == b["agrees"], (run, q)
            for k in ("estimated", "actual"):
                if b[k] is None:
                    assert a[k] is None
                elif b[k] < av.ROUNDOFF:             # round-off itself: its size only
                    assert a[k] < av.ROUNDOFF
                else:
                    assert a[k] == pytest.approx(b[k], rel=1e-6), (run, q, k)
            if b["estimated"] is not None and min(b["estimated"], b["actual"]) >= av.ROUNDOFF:
                r = math.log(b["estimated"] / b["actual"])
                assert abs(abs(r) - math.log(av.AGREE)) > 0.05, (run, q)
    r, p = now["request"], pub["request"]
    assert (r["scheme"], r["step"], r["refined"], r["met"]) == \
        (p["scheme"], p["step"], p["refined"], p["met"])
    assert max(p["pairs"][q]["actual"] for q in av.QUANTITIES) < 0.9 * av.ACCURACY


def _pct(x):
    return f"{100 * x:.2g} %"


def test_what_the_page_says_decides_the_misses(data, section):
    text, t = _flat(section), data["totals"]
    assert f"(it is {round(100 * t['agree'] / t['with_estimate'])} % of the estimates given" \
        in text
    assert f"an estimate is given for {t['with_estimate']} of the {t['pairs']} pairs" in text
    # every estimate reads the exit velocity at the strike contact's release, as the bench
    assert all(c[run]["exit_at"].startswith(f"release of {c['contact']} ")
               for c in data["cases"] for run in ("request",))
    f1 = _case_v(data, "f1")
    off = [(max(p["estimated"] / p["actual"], p["actual"] / p["estimated"]), p["actual"])
           for run in ("default", "request") for p in f1[run]["pairs"].values()
           if p["agrees"] is False]
    lo, hi = min(o for o, _ in off), max(o for o, _ in off)
    assert f"On three_mass f1 {len(off)} of 4 pairs lie {lo:.1f}x to {hi:.1f}x off" \
        .lower() in text.lower()
    assert f"{min(a for _, a in off):.0e}" == "2e-06" and f"{max(a for _, a in off):.0e}" \
        == "4e-05" and "at errors of 2e-6 to 4e-5" in text
    g = _case(data, "ground_multicontact")["default"]["pairs"]["exit_velocity"]
    assert f"{g['estimated'] / g['actual']:.0f}" == "13" and "estimated 13x too high" in text
    # within the range the request's estimates on f100 agree as the page says
    f100 = _case_v(data, "f100")["request"]["pairs"]
    assert (_pct(f100["peak"]["estimated"]), _pct(f100["peak"]["actual"])) == \
        ("0.025 %", "0.026 %")
    assert (_pct(f100["exit_velocity"]["estimated"]), _pct(f100["exit_velocity"]["actual"])) \
        == ("0.05 %", "0.041 %")
    assert "0.025 % against 0.026 % on the peak and 0.05 % against 0.041 %" in text


def _case_v(data, variant):
    c, = [c for c in data["cases"] if c["variant"] == variant]
    return c


def test_the_scatter_past_the_range_the_page_quotes(data, section):
    """C's peak error on three_mass f100 at 55, 77 and 110 us (the bench rows
    of the request at 18 us are elsewhere: this reads the published
    reference's peak and runs the three steps)."""
    import warnings
    import cosim
    from conftest import CASES
    from cosim.studies.metrics import impact_metrics
    ref = _case_v(data, "f100")["reference"]
    got = []
    for h in (5.5e-5, 7.7e-5, 1.1e-4):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = cosim.load_scene(CASES / "three_mass.toml", "f100",
                                     [f"scheme.contact_step={h}"])
            m = impact_metrics(cosim.simulate(scene), "C", "robot/arm")
        got.append(f"{100 * (m['peak'] / ref['peak'] - 1):+.2f} %")
    assert got == ["-0.24 %", "+0.38 %", "-0.25 %"]
    assert ("C's peak error is -0.24 % at 55 us, +0.38 % at 77 us, -0.25 % at 110 us"
            in _flat(section))


def test_the_counts_and_the_grasp_the_page_names(data, section):
    text = _flat(section)
    f1000 = _case_v(data, "f1000")
    r = f1000["request"]
    assert (r["scheme"], r["step"]) == ("jacobi", 5.8e-6) and "Jacobi at 5.8 us" in text
    assert "closed 9 times, 10 in the companion; at 2x the step too" in r["unchecked"]
    assert all("past 0.4" in q["why"] for q in f1000["default"]["pairs"].values())
    assert f1000["default"]["companion"] == "not run"
    assert "f1000's own run (C at omega h 1.0) gets no companion" in text
    b = _case(data, "brachiation")
    r = b["request"]
    assert r["count"] == b["reference"]["count"] == 3 and not r["met"]
    assert _pct(r["pairs"]["exit_velocity"]["actual"]) == "3.4 %"
    assert r["request_met"] is None and "is a grasp" in r["unchecked"]
    assert "not 1 % on the exit velocity (3.4 %), and it says it is not checked (a grasp)" in text


def test_where_the_cpu_goes(av, data, section):
    text = _flat(section)
    x = [c["choice_over_cheapest"] for c in data["cases"] if c["choice_over_cheapest"]]
    assert f"costs {min(x):.1f} to {max(x):.1f} times the cheapest row" in text
    b = _case(data, "brachiation")["request"]["stages_s"]
    assert f"{b['plan']:.2g} s on brachiation against a run of {b['run']:.2g} s" in text
    share = [c["request"]["stages_s"]["estimate"] / c["request"]["stages_s"]["run"]
             for c in data["cases"] if c["scene"] == "three_mass"]
    assert f"({min(share):.1f} to {max(share):.1f} of the run's CPU on three_mass" in text
    t = data["totals"]
    assert (f"the default run's estimate costs at most 30 % of the run's CPU on "
            f"{t['estimate_within_target']} of {t['cases']} (median "
            f"{t['estimate_share_median']:.2f})") in text
    own = {av.case_label(c): (c["default"]["factor"], av.estimate_share(c["default"]),
                              c["default"]["companion"]) for c in data["cases"]}
    assert f"{own['three_mass f1'][1]:.2f} of the run on f1, {own['three_mass f10'][1]:.2f} " \
        f"on f10, {own['ground_multicontact kA1e6'][1]:.2f} on ground_multicontact, " \
        f"{own['spring_drop undamped'][1]:.1f} on spring_drop" in text
    assert own["beam_impact"][0] == 2 and f"factor is 2 ({own['beam_impact'][1]:.2f})" in text
    blind = [v[1] for v in own.values() if v[2] == "not run"]
    assert f"no companion runs ({min(blind):.2f} to {max(blind):.2f}" in text


def test_the_companions_take_2_24_of_the_runs_macro_steps_on_f10():
    """The finer companion (at 0.71x the steps) takes 1.49 of the run's
    macro steps, the coarser (1.41x) 0.75: the approach to each onset adds
    steps that do not scale (the single 4x companion that docs/performance.md
    describes took 0.27)."""
    import warnings
    import cosim
    from conftest import CASES
    from cosim.studies.estimate import estimate_errors
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(CASES / "three_mass.toml", "f10")
        acc = estimate_errors(scene, cosim.simulate(scene))
    assert f"{acc['work_share']['macro_steps']:.2f}" == "2.24"
    assert [f"{c['work_share']['macro_steps']:.2f}" for c in acc["companions"]] == ["1.49", "0.75"]


def test_on_three_mass_the_cheapest_row_lies_past_the_cap(data, section):
    """What makes 1.5x out of reach there: the cheapest row that meets 1 %
    takes a longer step than the request may (the cap), so the request's run
    costs at least the row's before its companion."""
    rows = [c for c in data["cases"] if c["scene"] == "three_mass"]
    assert len(rows) == 4
    for c in rows:
        assert c["cheapest"]["step"] > c["request"]["step"], c["variant"]
        assert c["cpu_ratio"] > 1.5
    assert "cheapest row's step is longer than the cap (every three_mass variant)" in \
        _flat(section)


def test_the_changelog_quotes_the_published_totals(data):
    t = data["totals"]
    text = _flat((ROOT / "CHANGELOG.md").read_text(encoding="utf-8").split("## 0.12.0")[0])
    assert (f"{t['agree']} of the {t['with_estimate']} estimates given agree within 3x with "
            f"the bench's reference, {t['without_estimate']} of {t['pairs']} pairs get none"
            ) in text
