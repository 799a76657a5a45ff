"""The command line at its edges (issue 37, items 6, 7, 8 and part of 11):
a bench whose reference has a zero peak, a folder named like a shipped
scene, options and environment variables checked before any work, scene
names echoed escaped and capped, an empty name, `--accuracy` in ASCII
digits only, a sweep with no finished point."""
import csv
import json
import math

import pytest

from cosim import cli
from cosim.scene.checks import parse_accuracy
from cosim.studies.metrics import relative_errors

COMMANDS = ("run", "info", "bench", "sweep")


def _refuse(word):
    raise ValueError(f"not JSON: {word}")


def _cli(capsys, *argv):
    """Exit status, stdout, stderr of `cosim ARGV` (a parser refusal's
    SystemExit taken as its status)."""
    try:
        code = cli.main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


# ---------------------------------------------------------------- item 6
def test_a_zero_reference_has_no_relative_error():
    ref = {"count": 1, "peak": 0.0, "exit_velocity": -2.0}
    same = relative_errors({"count": 1, "peak": 0.0, "exit_velocity": -1.0}, ref)
    assert same["peak"] == 0.0 and same["exit_velocity"] == pytest.approx(0.5)
    other = relative_errors({"count": 1, "peak": 1e-9, "exit_velocity": -2.0}, ref)
    assert math.isnan(other["peak"]) and other["exit_velocity"] == 0.0


def test_bench_of_a_rigid_contact_writes_its_table(tmp_path, monkeypatch, capsys):
    """manipulator_wall's contact is rigid: the reference's peak penetration
    is 0, which ended the bench in a ZeroDivisionError with nothing written."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "bench"
    code, text, err = _cli(capsys, "bench", "manipulator_wall", "--schemes", "gauss_seidel",
                           "--steps", "1e-3", "--spread", "1", "--out", str(out))
    assert code == 0, err
    assert "Traceback" not in err
    assert "note: the reference's peak is 0: no relative error" in text
    ref = json.loads((out / "reference.json").read_text(), parse_constant=_refuse)
    assert ref["peak"] == 0.0
    with open(out / "bench.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["label"] for r in rows} >= {"paper_rk45", "monolithic", "gauss_seidel"}
    for r in rows:          # a rigid contact never penetrates: every finished row's is 0 too
        if r["status"] == "finished":
            assert float(r["err_peak"]) == 0.0, r


# ---------------------------------------------------------------- item 7
@pytest.mark.parametrize("command", COMMANDS)
def test_a_folder_named_like_a_shipped_scene_does_not_hide_it(command, tmp_path, monkeypatch,
                                                              capsys):
    monkeypatch.chdir(tmp_path)
    code, _, err = _cli(capsys, "run", "spring_drop", "--out", "spring_drop", "--no-estimate")
    assert code == 0 and (tmp_path / "spring_drop").is_dir(), err
    extra = {"run": ["--no-estimate", "--out", "again"], "info": [],
             "bench": ["--schemes", "gauss_seidel", "--steps", "1e-4", "--spread", "1",
                       "--out", "b"],
             "sweep": ["--workers", "1", "--no-plot", "--out", "s", "--quiet"]}[command]
    code, text, err = _cli(capsys, command, "spring_drop", *extra)
    assert code == 0, err
    assert "regular file" not in err
    assert "spring_drop" in text


def test_a_folder_that_is_no_shipped_name_is_still_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "my_scene").mkdir()
    code, _, err = _cli(capsys, "run", "my_scene")
    assert code == 2 and "my_scene: must be a regular file, got a directory" in err


# ---------------------------------------------------------------- item 8
_ENV = {"COSIM_KERNEL": "bogus", "COSIM_DRIVER": "bogus", "COSIM_FMU_UNPACK_LIMIT": "-3"}


@pytest.mark.parametrize("command", ["run", "bench", "sweep"])
@pytest.mark.parametrize("variable", sorted(_ENV))
def test_a_bad_environment_variable_is_refused_before_any_work(variable, command, tmp_path,
                                                               monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(variable, _ENV[variable])
    code, text, err = _cli(capsys, command, "spring_drop")
    assert code == 2
    assert err.startswith("error: ") and variable in err and "Traceback" not in err
    assert "bug of cosim" not in err and not text
    assert not any(tmp_path.iterdir())          # no run folder, nothing written


@pytest.mark.parametrize("steps", ["0", "nan", "-1e-4", "inf", "1e-4,0", ",", "1_0e-4",
                                   "\u0665e-4"])
def test_bench_refuses_steps_it_cannot_run_before_any_row(steps, tmp_path, monkeypatch,
                                                          capsys):
    monkeypatch.chdir(tmp_path)
    code, text, err = _cli(capsys, "bench", "spring_drop", f"--steps={steps}")
    assert code == 2 and "argument --steps" in err
    assert not text and not any(tmp_path.iterdir())     # no monolithic row ran


@pytest.mark.parametrize("argv, said", [
    (["bench", "spring_drop", "--schemes", "gauss_seidel,bogus"],
     "--schemes: no scheme is named 'bogus'"),
    (["bench", "spring_drop", "--schemes", ","], "argument --schemes"),
    (["bench", "spring_drop", "--set", "t_end=-1"], "`t_end` must be > 0"),
    (["sweep", "spring_drop", "--scheme", "bogus"], "--scheme: no scheme is named 'bogus'"),
    (["sweep", "spring_drop", "--variants", "undamped,bogus"],
     "has no variant 'bogus'; its variants are"),
])
def test_options_are_refused_before_any_work(argv, said, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, text, err = _cli(capsys, *argv)
    assert code == 2 and said in err, err
    assert "reference" not in text and "monolithic" not in text
    assert not any(tmp_path.iterdir())


# ---------------------------------------------------------------- item 11
@pytest.mark.parametrize("command", COMMANDS)
def test_a_scene_name_is_echoed_escaped(command, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, text, err = _cli(capsys, command, "foo\nerror: forged")
    assert code == 2
    assert not any(line.startswith("error: forged") for line in (text + err).splitlines())
    assert "foo\\nerror: forged" in err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("command", COMMANDS)
def test_a_long_scene_name_is_echoed_capped(command, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, text, err = _cli(capsys, command, "a" * 100_000)
    assert code == 2
    assert len(text + err) < 2_000 and "(100000 characters)" in err


@pytest.mark.parametrize("command", COMMANDS)
def test_an_empty_scene_name_is_said_to_be_empty(command, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, _, err = _cli(capsys, command, "")
    assert code == 2
    assert "empty name" in err and "must be a regular file" not in err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("text", ["\u0665%", "1_0%", "\uff11%", "0x1", "nan", "inf%", "1e"])
def test_accuracy_takes_ascii_digits_only(text, capsys):
    with pytest.raises(ValueError, match="must be a relative accuracy"):
        parse_accuracy(text)
    code, _, err = _cli(capsys, "info", "spring_drop", "--accuracy", text)
    assert code == 2 and "argument --accuracy" in err


@pytest.mark.parametrize("text, value", [("1%", 0.01), ("0.5 %", 0.005), (".5%", 0.005),
                                         ("1e-2", 0.01), ("5E-1", 0.5), ("1.%", 0.01)])
def test_accuracy_keeps_the_usual_syntax(text, value):
    assert parse_accuracy(text) == pytest.approx(value, rel=1e-15)


def test_a_sweep_with_no_finished_point_draws_nothing_and_says_why(tmp_path, monkeypatch,
                                                                   capsys):
    pytest.importorskip("matplotlib", reason="the plot needs the `plot` extra")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "s"
    out.mkdir()
    (out / "sweep.png").write_bytes(b"an earlier sweep's figure")
    code, text, err = _cli(capsys, "sweep", "spring_drop", "--set", "t_end=-1,-2",
                           "--workers", "1", "--out", str(out), "--quiet")
    assert code == 1
    assert "0 of 2 point(s) finished" in text
    assert f"no plot: no point finished (their messages are in {out / 'sweep.csv'})" in text
    assert not (out / "sweep.png").exists()          # none drawn, none left to mislead
    assert "warning" not in err              # cosim prints every warning on stderr


def test_plot_sweep_refuses_a_table_with_no_finished_point(tmp_path):
    pytest.importorskip("matplotlib", reason="the plot needs the `plot` extra")
    from cosim.studies.sweep import plot_sweep
    rows = [{"point": "a", "status": "refused", "message": "no"}]
    with pytest.raises(ValueError, match="no point of the sweep finished"):
        plot_sweep(rows, tmp_path / "sweep.png")
    assert not (tmp_path / "sweep.png").exists()


def test_a_folder_named_like_a_shipped_study_does_not_hide_it(tmp_path, monkeypatch):
    from cosim.scene.shipped import find_study, shipped_folder
    monkeypatch.chdir(tmp_path)
    (tmp_path / "fig8_stiffness").mkdir()
    assert find_study("fig8_stiffness") == shipped_folder("studies") / "fig8_stiffness.toml"


@pytest.mark.parametrize("variable", ["COSIM_KERNEL", "COSIM_DRIVER"])
def test_simulate_refuses_a_bad_environment_before_it_writes(variable, tmp_path, monkeypatch):
    import cosim
    from conftest import CASES
    scene = cosim.load_scene(CASES / "spring_drop.toml")
    monkeypatch.setenv(variable, "bogus")
    with pytest.raises(ValueError, match=variable):
        cosim.simulate(scene, out=tmp_path / "run")
    assert not any(tmp_path.iterdir())
