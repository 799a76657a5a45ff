"""Work-precision studies: the error metrics on series with known answers,
and the bench on a tiny setting (no timing is asserted: speed is the bench's
own output)."""
import csv
import math
import os
import stat
from types import SimpleNamespace

import numpy as np
import pytest

import cosim.studies.bench as bench
from cosim.errors import OutputError
from cosim.scene.load import SceneError
from cosim.studies.bench import (COLUMNS, MAX_SPREAD, BenchRow, cheapest_within, read_csv,
                                 reference, run_bench, write_csv)
from cosim.cli import main
from cosim.studies.metrics import exit_velocity, impact_metrics, relative_errors
from conftest import CASES

# the study measures the energy long steps gain: the run guard is off
SPRING = dict(contact="wall", joint="body/x",
              overrides=['contacts.wall.placement="coupler"', "scheme.accept_unsafe_step=true",
                         "guard.energy_check=false"])


def fake_result(intervals, t, dq, peak=2e-3):
    return SimpleNamespace(
        summary={"contacts": {"C": {"count": len(intervals), "peak_penetration": peak,
                                    "intervals": intervals}}},
        series={"t": np.asarray(t), "dq/robot/arm": np.asarray(dq)})


def test_exit_velocity_interpolates_between_samples():
    t = np.linspace(0.0, 1.0, 11)
    assert exit_velocity(t, 3.0 * t - 1.0, 0.437) == pytest.approx(3.0 * 0.437 - 1.0)
    with pytest.raises(ValueError, match=r"`t_release` = 1.5 s lies outside the samples"):
        exit_velocity(t, t, 1.5)


def test_impact_metrics_and_relative_errors_on_a_known_series():
    t = np.linspace(0.0, 0.2, 201)
    run = impact_metrics(fake_result([[0.10, 0.11], [0.12, 0.1305]], t, -20.0 + 200.0 * t,
                                     peak=1.1e-3), "C", "robot/arm")
    assert run == {"count": 2, "peak": 1.1e-3, "exit_velocity": pytest.approx(6.1)}
    ref = {"count": 3, "peak": 1e-3, "exit_velocity": 6.0}
    err = relative_errors(run, ref)
    assert err["count"] == 1
    assert err["peak"] == pytest.approx(0.1)
    assert err["exit_velocity"] == pytest.approx(0.1 / 6.0)
    # a contact that never released has no exit velocity
    never = impact_metrics(fake_result([], t, t), "C", "robot/arm")
    assert math.isnan(never["exit_velocity"])


def _straddled(impacts, joints=("arm",)):
    """A series sampled every ms whose rate jumps from 1 to -3 at 0.1003 s,
    between two samples, and the run's impact records."""
    t = np.linspace(0.0, 0.2, 201)
    dq = np.where(t < 0.1003, 1.0, -3.0)
    res = fake_result([[0.1003, 0.1003]], t, dq, peak=0.0)
    res.series.update({f"dq/robot/{j}": dq for j in joints if j != "arm"})
    res.summary["impacts"] = impacts
    return res


def test_an_impulse_release_reads_the_rate_the_impact_left_not_across_the_jump():
    """A rigid impact jumps the rates within an instant, between two samples
    of a co-simulation's series: the exit velocity is the impact's recorded
    ``dq_after``, the rate at the touch its ``dq_before``; interpolation
    across the jump (0.7 of the way: -1.8) is neither."""
    from cosim.studies.metrics import impact_regime
    hit = {"time": 0.1003, "contact": "C", "dq_before": {"arm": 1.0}, "dq_after": {"arm": -3.0}}
    res = _straddled([hit])
    assert impact_metrics(res, "C", "robot/arm")["exit_velocity"] == -3.0
    regime = impact_regime(res.summary, res.series, "C", "robot/arm")
    assert (regime["rate_at_touch"], regime["rate_at_release"]) == (1.0, -3.0)
    assert regime["regime"] == "backward"
    # no record of an impact there (another contact's, another instant, or
    # another side's joints): the reading between the samples, as before
    for other in ({**hit, "contact": "D"}, {**hit, "time": 0.05},
                  {**hit, "dq_after": {"x": 0.0}, "dq_before": {"x": 0.0}}):
        got = impact_metrics(_straddled([other]), "C", "robot/arm")["exit_velocity"]
        assert got == pytest.approx(1.0 + 0.3 * (-4.0), rel=1e-9)


def test_a_rigid_impact_s_exit_velocity_agrees_between_co_simulation_and_monolithic():
    """manipulator_wall: the tip's rigid impact at 0.3900003 s lies between
    two of the co-simulation's 1 ms samples; its exit velocity read across
    the jump was the rate before the impact (+0.14 rad/s against -3.53: a
    100 % error at every step, so no co-simulation row of `cosim bench` met
    1 %).  Both schemes integrate the robot by DOP853 at rtol 1e-10 to the
    same event, so they agree far within 1e-6 (1e-11 seen)."""
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    path = CASES / "manipulator_wall.toml"
    ev = {}
    for scheme in ("gauss_seidel", "monolithic"):
        res = simulate(load_scene(path, "mu0", scheme=scheme))
        ev[scheme] = impact_metrics(res, "tip", "robot/q10")["exit_velocity"]
    assert ev["monolithic"] < -3.0
    assert ev["gauss_seidel"] == pytest.approx(ev["monolithic"], rel=1e-6)


def test_bench_rows_and_csv_columns(tmp_path):
    """spring_drop's wall as a coupler contact: the paper's method, one
    monolithic tolerance and two steps of Gauss-Seidel (order 0, held force:
    its errors halve with the step).  The reference is cached."""
    ref, rows = run_bench(CASES / "spring_drop.toml", schemes=["gauss_seidel"],
                          steps=[1e-4, 5e-5], tolerances=(1e-6,), cache_dir=tmp_path / "cache",
                          **SPRING)
    assert ref["count"] == 1 and ref["peak"] == pytest.approx(1e-3, rel=1e-6)
    assert [r.label for r in rows] == ["paper_rk45", "monolithic", "gauss_seidel",
                                       "gauss_seidel"]
    assert all(r.status == "finished" for r in rows)
    gs = [r for r in rows if r.scheme == "gauss_seidel"]
    assert gs[1].err_exit_velocity == pytest.approx(gs[0].err_exit_velocity / 2, rel=0.1)
    assert len(list((tmp_path / "cache").glob("*.json"))) == 1
    again = reference(CASES / "spring_drop.toml", cache_dir=tmp_path / "cache", contact="wall",
                      joint="body/x", overrides=SPRING["overrides"])
    assert again == ref
    write_csv(rows, tmp_path / "bench.csv")
    with open(tmp_path / "bench.csv") as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0]) == COLUMNS
    assert {"scheme", "macro_step", "cpu_time_s", "err_peak", "err_count", "err_exit_velocity",
            "err_energy"} <= set(table[0])
    assert len(table) == 4


def test_bench_command_writes_table_csv_and_plot(tmp_path, capsys, monkeypatch):
    pytest.importorskip("matplotlib", reason="the plot needs the `plot` extra")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "bench"
    code = main(["bench", str(CASES / "spring_drop.toml"), "--contact", "wall", "--joint",
                 "body/x", "--schemes", "gauss_seidel", "--steps", "1e-4", "--out", str(out),
                 "--set", 'contacts.wall.placement="coupler"',
                 "--set", "scheme.accept_unsafe_step=true"])
    assert code == 0
    text = capsys.readouterr().out
    assert "paper_rk45" in text and "gauss_seidel" in text and "cores" in text
    assert (out / "bench.csv").stat().st_size > 0
    assert (out / "bench.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _row(scheme, label, cpu, peak, count, exit_v, status="finished", worst=None):
    """A row of three copies whose median errors are given; ``worst`` (peak,
    count, exit velocity) its worst copy's, by default the median's."""
    nan = math.nan
    wp, wc, we = worst or (peak, count, exit_v)
    return BenchRow(scheme, label, nan, nan, cpu, peak, count, exit_v, 0.0, status, 3,
                    3 if status == "finished" else 0, peak, wp, 9, 9 + wc, wc, exit_v, we,
                    0.0, 0.0)


def test_cheapest_within_picks_the_cheapest_accurate_row_of_each_kind():
    nan = math.nan
    row = _row
    rows = [row("monolithic", "paper_rk45", 3.0, 0.002, 0, 0.005),
            row("monolithic", "monolithic", 0.8, 0.001, 0, 0.002),
            row("monolithic", "monolithic", 0.5, 0.02, 0, 0.002),      # peak off by 2 %
            row("gauss_seidel", "gauss_seidel", 0.2, 0.009, 1, 0.001),  # a contact too many
            row("gauss_seidel", "gauss_seidel", 0.3, 0.001, 0, 0.002),
            row("jacobi", "jacobi", 0.1, nan, nan, nan, "refused")]
    best = cheapest_within(rows, 0.01)
    assert best["cosim"].cpu_time_s == 0.3
    assert best["monolithic"].cpu_time_s == 0.8
    assert best["paper_rk45"].cpu_time_s == 3.0
    assert best["ratio_monolithic"] == pytest.approx(0.375)
    assert best["ratio_paper_rk45"] == pytest.approx(0.1)
    none = cheapest_within(rows, 1e-4)
    assert none["cosim"] is None and math.isnan(none["ratio_monolithic"])


def test_cheapest_within_judges_a_row_by_its_worst_copy():
    """A row whose median is within 1 % but one copy is not (its exit
    velocity off by 3 %, or a contact too many) is not chosen: the next
    dearer row whose every copy is within is."""
    rows = [_row("monolithic", "monolithic", 1.2, 4e-5, 0, 1.2e-4, worst=(8.6e-4, 0, 2.95e-2)),
            _row("monolithic", "monolithic", 2.5, 5e-9, 0, 4e-9),
            _row("gauss_seidel", "gauss_seidel", 0.2, 5e-3, 0, 4e-3, worst=(9e-3, 1, 6e-3)),
            _row("gauss_seidel", "gauss_seidel", 0.3, 1e-3, 0, 2e-3, worst=(2e-3, 0, 9.9e-3))]
    best = cheapest_within(rows, 0.01)
    assert best["monolithic"].cpu_time_s == 2.5
    assert best["cosim"].cpu_time_s == 0.3
    assert best["paper_rk45"] is None and math.isnan(best["ratio_paper_rk45"])


def test_bench_spread_reports_median_best_and_worst_of_the_copies(tmp_path):
    """spring_drop's wall under Gauss-Seidel at 1e-4 s and the monolithic
    scheme at rtol 1e-8, each on the scene and two copies moved by +1 and -1
    ulp.  The copies are other runs (the monolithic row's exit velocity
    moves: its best and worst differ), the band is ordered, and the count
    stays 1 in every copy.  With one copy, median, best and worst are that
    run's, and they equal the scene's own copy of the spread run (the same
    computation, run twice: bit identity)."""
    kw = dict(schemes=["gauss_seidel"], steps=[1e-4], tolerances=(1e-8,), paper=False,
              cache_dir=tmp_path / "cache", **SPRING)
    ref, rows = run_bench(CASES / "spring_drop.toml", spread=3, **kw)
    assert [(r.label, r.copies, r.finished, r.status) for r in rows] == [
        ("monolithic", 3, 3, "finished"), ("gauss_seidel", 3, 3, "finished")]
    for r in rows:
        for e in ("err_peak", "err_exit_velocity", "err_energy"):
            best, med, worst = getattr(r, f"{e}_best"), getattr(r, e), getattr(r, f"{e}_worst")
            assert 0 <= best <= med <= worst, (r.label, e, best, med, worst)
        assert (r.count_min, r.count_max, r.err_count, r.err_count_worst) == (1, 1, 0, 0)
    mono = rows[0]
    assert mono.err_exit_velocity_best < mono.err_exit_velocity_worst, mono
    _, one = run_bench(CASES / "spring_drop.toml", spread=1, **kw)
    for r in one:
        assert (r.copies, r.finished) == (1, 1)
        assert r.err_peak_best == r.err_peak == r.err_peak_worst
        assert r.err_exit_velocity_best == r.err_exit_velocity == r.err_exit_velocity_worst
    # the scene's own run is among the spread's three values, bit for bit
    assert one[0].err_exit_velocity in (mono.err_exit_velocity_best, mono.err_exit_velocity,
                                        mono.err_exit_velocity_worst)
    write_csv(rows, tmp_path / "bench.csv")
    # every value round-trips (repr: NaN steps compare unequal to themselves)
    assert [repr(r) for r in read_csv(tmp_path / "bench.csv")] == [repr(r) for r in rows]


def test_a_row_whose_copy_did_not_finish_keeps_its_status_and_nan_errors(tmp_path, monkeypatch):
    """A step the scheme refuses (the energy guard at 1 ms) leaves every
    copy refused; a copy whose run fails (here the second of three, made to
    fail) makes the row ``failed``: NaN errors, the count of copies that
    finished, and no choice of it as within 1 %."""
    over = [o for o in SPRING["overrides"] if "accept_unsafe" not in o and "energy" not in o]
    _, rows = run_bench(CASES / "spring_drop.toml", schemes=["gauss_seidel"], steps=[1e-3],
                        tolerances=(), paper=False, spread=2, cache_dir=tmp_path,
                        contact="wall", joint="body/x", overrides=over)
    (r,) = rows
    assert (r.status, r.copies, r.finished) == ("refused", 2, 0)
    assert all(math.isnan(getattr(r, f)) for f in COLUMNS if f.startswith(("err_", "count_")))

    real, calls = bench.simulate, []

    def second_fails(scene, *a, **k):
        res = real(scene, *a, **k)
        calls.append(scene)
        if len(calls) == 2:
            res = SimpleNamespace(success=False, status="failed", summary=res.summary)
        return res
    monkeypatch.setattr(bench, "simulate", second_fails)
    _, rows = run_bench(CASES / "spring_drop.toml", schemes=["gauss_seidel"], steps=[1e-4],
                        tolerances=(), paper=False, spread=3, cache_dir=tmp_path, **SPRING)
    (r,) = rows
    assert (r.status, r.copies, r.finished) == ("failed", 3, 2)
    assert math.isfinite(r.cpu_time_s)
    assert all(math.isnan(getattr(r, f)) for f in COLUMNS if f.startswith(("err_", "count_")))
    assert cheapest_within(rows)["cosim"] is None


def test_a_step_longer_than_the_run_is_one_step_to_t_end(tmp_path):
    """`cosim bench --steps 1e308`: the scheme clips a step longer than the
    run to one step to t_end (tests/test_long_steps.py), so the row is a real
    run of one 0.02 s coupling step: it finishes, with the large errors of
    that step (the peak 9 times the reference's, the energy 100 times), and is
    never the cheapest within 1 %.  (The scheme once took no step at all and
    the row said `finished` with the errors of t = 0.)"""
    _, rows = run_bench(CASES / "spring_drop.toml", schemes=["gauss_seidel"], steps=[1e308],
                        tolerances=(), paper=False, spread=1, cache_dir=tmp_path, **SPRING)
    (r,) = rows
    assert (r.status, r.count_min, r.count_max) == ("finished", 1.0, 1.0), r
    assert r.err_peak > 1.0 and r.err_energy > 1.0, r
    assert cheapest_within(rows)["cosim"] is None


@pytest.mark.parametrize("value", ["0", "-1", str(MAX_SPREAD + 1), "2.5", "three"])
def test_bench_refuses_a_spread_it_cannot_run(value, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        main(["bench", str(CASES / "spring_drop.toml"), "--spread", value,
              "--out", str(tmp_path / "b")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --spread" in err
    assert (f"must be from 1 to {MAX_SPREAD}" in err) or ("expected a whole number" in err), err
    assert not (tmp_path / "b").exists()


def test_run_bench_refuses_a_spread_before_it_runs(tmp_path):
    for bad in (0, -2, MAX_SPREAD + 1, 2.0, True):
        with pytest.raises(ValueError, match=rf"`spread` must be a whole number of copies from "
                                             rf"1 to {MAX_SPREAD} .*got {bad!r}"):
            run_bench(CASES / "spring_drop.toml", spread=bad, cache_dir=tmp_path, **SPRING)
    # a scene at rest at the origin has nothing to move by round-off
    still = SPRING["overrides"] + ["subsystems.body.bodies.mass.joint.q0=0.0",
                                   "subsystems.body.bodies.mass.joint.dq0=0.0"]
    with pytest.raises(SceneError, match=r"spring_drop.toml: `spread` = 2 needs copies moved "
                                         r"by round-off: the scene gives no nonzero initial"):
        run_bench(CASES / "spring_drop.toml", spread=2, cache_dir=tmp_path, contact="wall",
                  joint="body/x", overrides=still)
    assert not list(tmp_path.iterdir())


def test_bench_command_names_a_scene_with_nothing_to_move(tmp_path, capsys, monkeypatch):
    """The default spread on a scene at rest at the origin: exit 2, the file
    and what to do, nothing run."""
    monkeypatch.chdir(tmp_path)
    code = main(["bench", str(CASES / "spring_drop.toml"), "--contact", "wall", "--joint",
                 "body/x", "--out", str(tmp_path / "b"),
                 "--set", "subsystems.body.bodies.mass.joint.q0=0.0",
                 "--set", "subsystems.body.bodies.mass.joint.dq0=0.0"])
    assert code == 2
    err = capsys.readouterr().err
    assert "spring_drop.toml: `spread` = 3 needs copies moved by round-off" in err
    assert "`--spread 1`" in err
    assert not (tmp_path / "runs").exists()


def test_bench_writes_through_the_checked_writer(tmp_path):
    """bench.csv, reference.json and the reference's cache go whole to their
    place as ordinary files (not mkstemp's 0600); a folder that is a file is
    an OutputError naming the path, and nothing is left beside it."""
    rows = [_row("gauss_seidel", "gauss_seidel", 0.3, 1e-3, 0, 2e-3)]
    write_csv(rows, tmp_path / "bench.csv")
    bench.write_reference({"count": 9, "peak": 1e-3}, tmp_path / "reference.json")
    mask = os.umask(0)
    os.umask(mask)
    for name in ("bench.csv", "reference.json"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o666 & ~mask
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bench.csv", "reference.json"]
    (tmp_path / "file").write_text("")
    with pytest.raises(OutputError, match=r"file: it exists and is not a folder"):
        write_csv(rows, tmp_path / "file" / "bench.csv")
    with pytest.raises(OutputError, match=r"refusing to write '\.\.'"):
        write_csv(rows, tmp_path / "..")
