"""Work-precision studies: the error metrics on series with known answers,
and the bench on a tiny setting (no timing is asserted: speed is the bench's
own output)."""
import csv
import math
from types import SimpleNamespace

import numpy as np
import pytest

from cosim.studies.bench import COLUMNS, BenchRow, cheapest_within, reference, run_bench, write_csv
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


def test_cheapest_within_picks_the_cheapest_accurate_row_of_each_kind():
    nan = math.nan

    def row(scheme, label, cpu, peak, count, exit_v, status="finished"):
        return BenchRow(scheme, label, nan, nan, cpu, peak, count, exit_v, 0.0, status)
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
