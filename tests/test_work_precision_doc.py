"""docs/performance.md's work-precision study, held to the run it came from.

The page's table and figure come from one run of
``python benchmarks/work_precision.py`` (three_mass f100, every row on the
scene and four copies moved by round-off), whose ``bench.csv`` and
``reference.json`` are kept in ``benchmarks/results/``.  These tests hold

- the page to that run: its table is the CSV as formatted, the command on
  the page is the study's, and the numbers its prose draws from the run are
  the CSV's (:class:`documented.Claim`);
- the run to the code as it is now: a fast test re-runs two cheap rows on
  two new copies (+3 and -3 ulps, samples the published run did not
  draw) and finds their errors within the published band; a slow test
  re-runs the whole study, reference included, and checks every row.

The band is best..worst over the published copies (the median lies inside).
A new sample is checked against the band widened by its own width on each
side, and by no less than :data:`FLOOR`: with five copies a sixth draw of the
same distribution falls outside min..max with probability 2/6, so min..max
alone would fail on another machine by design, while a band widened by its
width is left only by a draw as far out again as the spread of five; the
floor is what a relative error is known to at all (the reference's own
spread, measured on two copies of it, is 1.3e-13 of the peak and 2.8e-12 of
the exit velocity, and the widest band among the rows that round-off barely
moves is 7.5e-10, Jacobi's exit velocity at 80 µs).  Timings are not checked:
they are the machine's.
"""
from __future__ import annotations

import importlib.util
import json
import math
import warnings

import pytest

from documented import ROOT, Claim, assert_printed, assert_reproduced

import cosim.studies.bench as bench
from cosim.scene.load import load_scene
from cosim.studies.roundoff import perturbed_overrides

PAGE = "docs/performance.md"
RESULTS = ROOT / "benchmarks" / "results" / "work_precision_three_mass_f100"
SCENE = ROOT / "cases" / "three_mass.toml"
#: the smallest tolerance of a band check (see the module's docstring)
FLOOR = 1e-9
ERRORS = ("err_peak", "err_exit_velocity", "err_energy")

_spec = importlib.util.spec_from_file_location("work_precision",
                                               ROOT / "benchmarks" / "work_precision.py")
wp = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(wp)

ROWS, REF = wp.published(RESULTS)


def _page() -> str:
    return (ROOT / PAGE).read_text(encoding="utf-8")


def test_the_page_table_is_the_published_csv_as_formatted():
    text = _page()
    start = text.index(wp.HEADER.splitlines()[0])
    end = text.index("\n\n", start)
    assert text[start:end] == wp.table(ROWS, REF), (
        "docs/performance.md's work-precision table differs from "
        "`python benchmarks/work_precision.py --table benchmarks/results/"
        "work_precision_three_mass_f100`")


def test_the_published_run_is_the_study_of_the_page():
    """One run of the study: every row of it, each on five copies, and the
    page names the command and the spread."""
    assert [(r.label, r.macro_step if r.scheme != "monolithic" else r.tolerance)
            for r in ROWS if r.label != "paper_rk45"] == (
        [("monolithic", t) for t in (1e-3, 1e-4, 1e-6, 1e-8)]
        + [(s, h) for s in ("gauss_seidel", "jacobi", "implicit")
           for h in (8e-5, 4e-5, 3e-5, 2e-5, 1e-5)])
    assert ROWS[0].label == "paper_rk45"
    assert {r.copies for r in ROWS} == {wp.SPREAD}
    text = " ".join(_page().split())
    assert "python benchmarks/work_precision.py --out runs/work-precision" in text
    assert "# = cosim " + " ".join(wp.ARGS) + " --out runs/work-precision" in text.replace(" \\ # ", " ")


def _in_band(pub: bench.BenchRow, new: bench.BenchRow) -> list[str]:
    """What of ``new`` (a re-run of ``pub``'s row) lies outside ``pub``'s
    band widened by its width (at least :data:`FLOOR`); empty when all is in."""
    out = []
    if pub.finished == pub.copies and new.status != "finished":
        return [f"{pub.label} {pub.macro_step} {pub.tolerance}: every published copy "
                f"finished, the re-run is {new.status} ({new.finished} of {new.copies})"]
    if pub.finished == 0 and new.finished:
        return [f"{pub.label}: no published copy finished, {new.finished} re-run ones did"]
    if pub.status != "finished" or new.status != "finished":
        # a row whose copies did not all finish has no published errors (NaN in the
        # CSV) to hold the re-run to, only its share of finished copies: the re-run's
        # share must lie within the published one widened by one copy either way
        share = new.finished / new.copies
        lo, hi = (pub.finished - 1) / pub.copies, (pub.finished + 1) / pub.copies
        if not lo <= share <= hi:
            out.append(f"{pub.label} {pub.macro_step} {pub.tolerance}: {new.finished} of "
                       f"{new.copies} copies finished, published {pub.finished} of "
                       f"{pub.copies}")
        return out
    for e in ERRORS:
        lo, hi = getattr(pub, f"{e}_best"), getattr(pub, f"{e}_worst")
        tol = max(hi - lo, FLOOR)
        for v in (getattr(new, f"{e}_best"), getattr(new, e), getattr(new, f"{e}_worst")):
            if not lo - tol <= v <= hi + tol:
                out.append(f"{pub.label} {pub.macro_step} {pub.tolerance}: {e} {v:.6g} outside "
                           f"the published {lo:.6g}..{hi:.6g} widened by {tol:.3g}")
    width = pub.count_max - pub.count_min
    if not (pub.count_min - width <= new.count_min and new.count_max <= pub.count_max + width):
        out.append(f"{pub.label} {pub.macro_step}: contacts {new.count_min:.0f}-"
                   f"{new.count_max:.0f}, published {pub.count_min:.0f}-{pub.count_max:.0f}")
    return out


def _pub(label, step=math.nan, tol=math.nan) -> bench.BenchRow:
    for r in ROWS:
        if r.label == label and (r.macro_step == step or r.tolerance == tol):  # NaN != NaN
            return r
    raise LookupError(label)


def test_cheap_rows_on_new_copies_fall_within_the_published_band():
    """Gauss-Seidel and Jacobi at 30 µs (the first the scene's default), each
    on the copies moved by +3 and -3 ulps, against the published reference.
    The page says round-off does not move the co-simulation rows; the
    monolithic rows, which it moves, are not a fast test's subject: their
    energy errors are heavy-tailed (copies at +-3 ulps of rtol 1e-4 and
    1e-6 leave the five copies' band), which the page says; the slow test
    re-runs them on the published copies."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(SCENE, "f100")
    copies = [perturbed_overrides(scene, k) for k in (3, -3)]
    contact, joint = "C", "robot/arm"
    runs = bench._runs(scene, ["gauss_seidel", "jacobi"], [3e-5], (), paper=False)
    rows = [(_pub(label, step=step, tol=tol), scheme, ov)
            for scheme, label, step, tol, ov in runs]
    problems = []
    for pub, scheme, ov in rows:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            new = bench._row(SCENE, "f100", ov, copies, scheme, pub.label, pub.macro_step,
                             pub.tolerance, REF, contact, joint)
        assert new.copies == 2
        problems += _in_band(pub, new)
    assert not problems, problems


def test_the_band_check_rejects_a_row_outside_its_band():
    """The check can fail: a copy 3 widths above the monolithic row's band,
    a count off a band of width 0, a row that stopped where all had run."""
    from dataclasses import replace
    pub = _pub("monolithic", tol=1e-4)
    w = pub.err_exit_velocity_worst - pub.err_exit_velocity_best
    assert _in_band(pub, pub) == []
    assert _in_band(pub, replace(pub, err_exit_velocity_worst=pub.err_exit_velocity_worst
                                 + 3 * w))
    gs = _pub("gauss_seidel", step=3e-5)
    assert _in_band(gs, replace(gs, count_max=10.0))
    assert _in_band(gs, replace(gs, err_peak=gs.err_peak * (1 + 1e-5)))
    assert _in_band(gs, replace(gs, status="failed", finished=3))
    # a published row where 3 of 5 finished: a re-run where none or all do is outside it
    partial = replace(pub, status="failed", finished=3)
    assert _in_band(partial, replace(pub, status="failed", finished=0))
    assert _in_band(partial, pub)
    assert _in_band(partial, replace(pub, status="failed", finished=2)) == []


@pytest.mark.slow
def test_the_whole_study_reproduces_every_row_within_its_band(tmp_path):
    """The study again, as the page runs it (five copies a row), with its
    reference run afresh: the reference within 1e-9 of the published one
    (its own round-off spread is 3e-12), every row within its band."""
    ref, rows = bench.run_bench(SCENE, "f100", ["gauss_seidel", "jacobi", "implicit"],
                                [8e-5, 4e-5, 3e-5, 2e-5, 1e-5], "C", "robot/arm",
                                spread=wp.SPREAD, cache_dir=tmp_path)
    assert ref["count"] == REF["count"]
    for k in ("peak", "exit_velocity"):
        assert ref[k] == pytest.approx(REF[k], rel=1e-9), k
    assert ref["energy"] == pytest.approx(REF["energy"], abs=1e-12)
    assert [(r.label, repr(r.macro_step), repr(r.tolerance)) for r in rows] == \
        [(r.label, repr(r.macro_step), repr(r.tolerance)) for r in ROWS]
    problems = [p for pub, new in zip(ROWS, rows) for p in _in_band(pub, new)]
    assert not problems, problems


def _worst_of_1pct(r) -> float:
    return max(r.err_peak_worst, r.err_exit_velocity_worst)


def _slope_gauss_seidel() -> float:
    import numpy as np
    gs = [r for r in ROWS if r.label == "gauss_seidel"]
    h = [r.macro_step for r in gs]
    err = [max(r.err_peak, r.err_exit_velocity) for r in gs]
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])


_BENCH = "python benchmarks/work_precision.py"
#: the prose's numbers that the published run gives (half a unit of the
#: printed digit; the table itself is held by the first test), each with the
#: function that reads it from that run
def _cpu(label, step=math.nan, tol=math.nan) -> float:
    return _pub(label, step=step, tol=tol).cpu_time_s


CLAIMS = [
    (Claim(PAGE, "give the same 9 contacts", _BENCH, 9), lambda: REF["count"]),
    (Claim(PAGE, "C's peak error runs from 3.9e-5 (best copy) to 9.1e-4 (worst)", _BENCH,
           3.9e-5, abs=0.05e-5), lambda: _pub("monolithic", tol=1e-4).err_peak_best),
    (Claim(PAGE, "C's peak error runs from 3.9e-5 (best copy) to 9.1e-4 (worst)", _BENCH,
           9.1e-4, abs=0.05e-4), lambda: _pub("monolithic", tol=1e-4).err_peak_worst),
    (Claim(PAGE, "velocity's from 5.2e-4 to **3.0 %** (median 5.4e-4)", _BENCH, 5.2e-4,
           abs=0.05e-4), lambda: _pub("monolithic", tol=1e-4).err_exit_velocity_best),
    (Claim(PAGE, "velocity's from 5.2e-4 to **3.0 %** (median 5.4e-4)", _BENCH, 3.0e-2,
           abs=0.05e-2), lambda: _pub("monolithic", tol=1e-4).err_exit_velocity_worst),
    (Claim(PAGE, "velocity's from 5.2e-4 to **3.0 %** (median 5.4e-4)", _BENCH, 5.4e-4,
           abs=0.05e-4), lambda: _pub("monolithic", tol=1e-4).err_exit_velocity),
    (Claim(PAGE, "At rtol 1e-3 every copy finishes within 1 % (the exit velocity at worst "
                 "5.7e-3), its energy 9.9e-2 off.", _BENCH, 5.7e-3, abs=0.05e-3),
     lambda: (lambda r: r.err_exit_velocity_worst if r.finished == r.copies == wp.SPREAD
              else math.nan)(_pub("monolithic", tol=1e-3))),
    (Claim(PAGE, "its energy 9.9e-2 off", _BENCH, 9.9e-2, abs=0.05e-2),
     lambda: _pub("monolithic", tol=1e-3).err_energy_worst),
    (Claim(PAGE, "same errors on every copy to 1e-9", _BENCH, 0.0, abs=1e-9),
     lambda: max(getattr(r, f"{e}_worst") - getattr(r, f"{e}_best")
                 for r in ROWS if r.scheme != "monolithic" or r.label == "paper_rk45"
                 for e in ERRORS)),
    (Claim(PAGE, "(80 µs is within 1 % here, at 7.7e-3, with little margin)", _BENCH, 7.7e-3,
           abs=0.05e-3), lambda: _worst_of_1pct(_pub("gauss_seidel", step=8e-5))),
    (Claim(PAGE, "falls as h^2.4", _BENCH, 2.4, abs=0.05), _slope_gauss_seidel),
    (Claim(PAGE, "so 10 µs buys 6.1e-5 for 2.1 times the CPU of 30 µs", _BENCH, 6.1e-5,
           abs=0.05e-5), lambda: _worst_of_1pct(_pub("gauss_seidel", step=1e-5))),
    (Claim(PAGE, "so 10 µs buys 6.1e-5 for 2.1 times the CPU of 30 µs", _BENCH, 2.1,
           abs=0.05), lambda: _cpu("gauss_seidel", step=1e-5) / _cpu("gauss_seidel", step=3e-5)),
    (Claim(PAGE, "(1.7e-4 at 40 µs and 5.7e-5 at 20 µs, the energy to 2.5e-5)", _BENCH, 1.7e-4,
           abs=0.05e-4), lambda: _worst_of_1pct(_pub("implicit", step=4e-5))),
    (Claim(PAGE, "(1.7e-4 at 40 µs and 5.7e-5 at 20 µs, the energy to 2.5e-5)", _BENCH, 5.7e-5,
           abs=0.05e-5), lambda: _worst_of_1pct(_pub("implicit", step=2e-5))),
    (Claim(PAGE, "(1.7e-4 at 40 µs and 5.7e-5 at 20 µs, the energy to 2.5e-5)", _BENCH, 2.5e-5,
           abs=0.05e-5),
     lambda: max(_pub("implicit", step=h).err_energy_worst for h in (4e-5, 3e-5, 2e-5))),
    (Claim(PAGE, "rtol 1e-6 to 1e-8 (7.2e-7 and 4.6e-9, the energy to 8.1e-5 and 2.6e-8)",
           _BENCH, 7.2e-7, abs=0.05e-7), lambda: _worst_of_1pct(_pub("monolithic", tol=1e-6))),
    (Claim(PAGE, "rtol 1e-6 to 1e-8 (7.2e-7 and 4.6e-9, the energy to 8.1e-5 and 2.6e-8)",
           _BENCH, 4.6e-9, abs=0.05e-9), lambda: _worst_of_1pct(_pub("monolithic", tol=1e-8))),
    (Claim(PAGE, "rtol 1e-6 to 1e-8 (7.2e-7 and 4.6e-9, the energy to 8.1e-5 and 2.6e-8)",
           _BENCH, 8.1e-5, abs=0.05e-5), lambda: _pub("monolithic", tol=1e-6).err_energy_worst),
    (Claim(PAGE, "rtol 1e-6 to 1e-8 (7.2e-7 and 4.6e-9, the energy to 8.1e-5 and 2.6e-8)",
           _BENCH, 2.6e-8, abs=0.05e-8), lambda: _pub("monolithic", tol=1e-8).err_energy_worst),
    (Claim(PAGE, "costs 1.1 times `implicit` at 40 µs", _BENCH, 1.1, abs=0.05),
     lambda: _cpu("monolithic", tol=1e-6) / _cpu("implicit", step=4e-5)),
    (Claim(PAGE, "adds a contact to the train (10 of 9)", _BENCH, 10),
     lambda: _pub("jacobi", step=4e-5).count_max),
    (Claim(PAGE, "at 80 µs it is 12 % off", _BENCH, 0.12, abs=0.005),
     lambda: _worst_of_1pct(_pub("jacobi", step=8e-5))),
    # the cheapest rows within 1 % and their ratios, from the CSV's unrounded CPU times
    (Claim(PAGE, "**0.24 times the monolithic CPU and 0.09 times the paper's**", _BENCH, 0.24,
           abs=0.005), lambda: (lambda b: b["cosim"].cpu_time_s / b["monolithic"].cpu_time_s)(
               bench.cheapest_within(ROWS))),
    (Claim(PAGE, "**0.24 times the monolithic CPU and 0.09 times the paper's**", _BENCH, 0.09,
           abs=0.005), lambda: (lambda b: b["cosim"].cpu_time_s / b["paper_rk45"].cpu_time_s)(
               bench.cheapest_within(ROWS))),
]


@pytest.mark.parametrize("claim,measure", CLAIMS, ids=[c.id for c, _ in CLAIMS])
def test_the_prose_numbers_are_the_published_runs(claim, measure):
    assert_printed(claim)
    assert_reproduced(claim, float(measure()))


def test_the_rows_within_one_percent_are_those_the_page_names():
    """"Within 1 % on every copy: `paper_rk45`, the monolithic scheme at rtol
    1e-3, 1e-6 and 1e-8, every `gauss_seidel` and `implicit` row, and `jacobi` from
    30 µs down", and the cheapest co-simulation row the page names."""
    assert_printed(Claim(PAGE, "Within 1 % on every copy: `paper_rk45`, the monolithic scheme "
                               "at rtol 1e-3, 1e-6 and 1e-8, every `gauss_seidel` and `implicit` "
                               "row, and `jacobi` from 30 µs down.", _BENCH, 0))
    ok = {(r.label, r.macro_step if r.scheme != "monolithic" else r.tolerance)
          for r in ROWS if bench.within(r, 0.01)}
    assert ok == ({("paper_rk45", 1e-4), ("monolithic", 1e-3), ("monolithic", 1e-6),
                   ("monolithic", 1e-8)}
                  | {(s, h) for s in ("gauss_seidel", "implicit")
                     for h in (8e-5, 4e-5, 3e-5, 2e-5, 1e-5)}
                  | {("jacobi", h) for h in (3e-5, 2e-5, 1e-5)})
    best = bench.cheapest_within(ROWS)
    assert (best["cosim"].label, best["cosim"].macro_step) == ("gauss_seidel", 8e-5)
    assert best["monolithic"].tolerance == 1e-3
    claim = ("`gauss_seidel` at 80 µs, 0.04 s, against the monolithic scheme's 0.18 s (rtol "
             "1e-3) and the paper's 0.44 s")
    for value, measured in ((0.04, best["cosim"].cpu_time_s),
                            (0.18, best["monolithic"].cpu_time_s),
                            (0.44, best["paper_rk45"].cpu_time_s)):
        c = Claim(PAGE, claim, _BENCH, value, abs=0.005)
        assert_printed(c)
        assert_reproduced(c, measured)


@pytest.mark.slow
def test_two_copies_of_the_reference_agree_far_below_any_rows_error():
    """The reference stays one run: on the scene and a copy moved by 1 ulp it
    gives the same count, and peak and exit velocity within 1e-11 of each
    other (1.3e-13 and 2.8e-12 measured), below the smallest row error of the
    published run by orders of magnitude."""
    from cosim.scene.run import simulate
    assert_printed(Claim(PAGE, "differ by less than 1e-11 in C's peak and the exit velocity",
                         "bench.reference on two copies", 1e-11))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(SCENE, "f100", [], "monolithic")
        out = []
        for k in (0, 1):
            ov = bench._monolithic(bench.REFERENCE) + perturbed_overrides(scene, k)
            res = simulate(load_scene(SCENE, "f100", ov, "monolithic"))
            out.append(bench._metrics(res, "C", "robot/arm"))
    a, b = out
    assert a["count"] == b["count"] == REF["count"]
    spread = [abs(a[k] - b[k]) / abs(a[k]) for k in ("peak", "exit_velocity")]
    assert max(spread) < 1e-11, spread
    smallest = min(min(r.err_peak_best, r.err_exit_velocity_best) for r in ROWS
                   if r.status == "finished")
    assert smallest > 100 * max(spread), (smallest, spread)
