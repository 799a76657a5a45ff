"""The error estimate of every run (cosim.studies.estimate) against true errors."""
import json
import warnings

import pytest

import cosim
from conftest import CASES
from cosim import cli
from cosim.studies.bench_cache import REFERENCE
from cosim.studies.estimate import accuracy_text, estimate_errors
from cosim.studies.metrics import impact_metrics
from cosim.studies.roundoff import perturbed


def _run(name, variant=None, overrides=(), scheme=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(CASES / f"{name}.toml", variant, list(overrides), scheme)
        return scene, cosim.simulate(scene, estimate=False)     # the tests estimate it


def _within(estimate, true, factor=3.0):
    return true / factor <= estimate <= true * factor


def test_spring_drop_exit_velocity_estimate_within_3x_of_the_closed_form():
    # undamped: the mass leaves at +1 m/s exactly; the run's error is the
    # rate read between samples at the release (metrics.exit_velocity)
    scene, res = _run("spring_drop")
    acc = estimate_errors(scene, res)
    e = acc["exit"]["body/x"]
    assert e["reliable"] and acc["reliable"], acc["why"]
    true = abs(e["value"] - 1.0)
    assert true > 1e-6            # a measurable error, not round-off
    assert _within(e["relative_error"], true), (e["relative_error"], true)
    assert acc["order"] == {"contacts": 2.9, "exit": 2.6}
    assert acc["order_hosted"] == {"contacts": 4.6, "exit": 1.8}     # the body's RK4, its samples
    # peak: both runs step the embedded contact alike, the estimate is round-off
    assert acc["contacts"]["wall"]["peak_penetration"]["relative_error"] < 1e-9


def _reference_f100():
    ov = [f"scheme.monolithic.{k}={json.dumps(v)}" for k, v in REFERENCE.items()]
    return impact_metrics(_run("three_mass", "f100", ov, "monolithic")[1], "C", "robot/arm")


@pytest.mark.parametrize("contact_step", [1e-5, 1.8e-5])
def test_three_mass_f100_within_the_asymptotic_range_is_estimated_within_3x(contact_step):
    """At omega h = 0.10 and 0.19 in C the companion (at 3.8x and 2.1x, so
    that its omega h stays below 0.4) gives C's peak error within 1.2x and
    the arm's exit-velocity error within 1.8x of the error against the
    bench's reference (measured)."""
    scene, res = _run("three_mass", "f100", [f"scheme.contact_step={contact_step}"])
    acc = estimate_errors(scene, res)
    assert 2 <= acc["factor"] < 4
    ref, m = _reference_f100(), impact_metrics(res, "C", "robot/arm")
    assert m["count"] == ref["count"] == 9
    for est, q in ((acc["contacts"]["C"]["peak_penetration"], "peak"),
                   (acc["exit"]["robot/arm"], "exit_velocity")):
        true = abs(m[q] / ref[q] - 1.0)
        assert est["reliable"], est
        assert _within(est["relative_error"], true), (q, est["relative_error"], true)


@pytest.mark.parametrize("ulps", [0, 2, -2])
def test_three_mass_f100_at_its_own_step_is_past_the_range_and_says_so(ulps):
    """At the scene's 30 us C sits at omega h = 0.31: even a companion at 2x
    would step it past 0.4, where the errors of neighbouring steps scatter
    (the estimate at 4x was 6x too small); C and the exit rates read at its
    release get no number, and the line says why."""
    scene = perturbed(_run("three_mass", "f100")[0], ulps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cosim.simulate(scene)
    acc = estimate_errors(scene, res)
    c = acc["contacts"]["C"]
    assert c["peak_penetration"]["relative_error"] is None
    assert "past 0.4" in c["peak_penetration"]["why"]
    assert acc["exit"]["robot/arm"]["relative_error"] is None
    assert not acc["reliable"]
    assert "C peak" not in accuracy_text(acc)


@pytest.mark.parametrize("ulps", [0, 1, -2])
def test_counts_that_differ_are_not_reliable_and_print_no_number(ulps):
    # Jacobi at omega h 0.13 in C: the run closes C 9 times, its companion
    # (3x, within the asymptotic range) 10 times, as at every step measured
    # from omega h 0.06 to 0.19
    scene, _ = _run("three_mass", "f100", ['scheme.name="jacobi"',
                                           "scheme.contact_step=1.2e-5"])
    with warnings.catch_warnings():       # Jacobi ignores the scene's `sequence`
        warnings.simplefilter("ignore")
        scene = perturbed(scene, ulps)
        res = cosim.simulate(scene)
    acc = estimate_errors(scene, res)
    c = acc["contacts"]["C"]
    assert not c["count"]["robust"]
    assert not acc["reliable"]
    assert not c["peak_penetration"]["reliable"]
    assert c["peak_penetration"]["relative_error"] is None
    assert c["peak_penetration"]["difference"] > 0     # kept for the curious
    assert all(not e["reliable"] for k, e in acc["exit"].items() if k != "at")
    assert c["count"] == {"value": 9, "companion": 10, "robust": False}
    text = accuracy_text(acc)
    assert text.startswith("accuracy: not reliable (contact C closed 9 times, 10 in the "
                           "companion")
    assert "%" not in text


@pytest.mark.parametrize("name", ["spring_drop", "ground_multicontact"])
def test_companion_costs_at_most_30_percent_of_the_counted_work(name):
    scene, res = _run(name)
    acc = estimate_errors(scene, res)
    assert acc["companion"]["macro_steps"] <= 0.3 * res.n_windows
    assert acc["work_share"]["macro_steps"] <= 0.3
    # the rk4 side that hosts the contacts is coarsened too: its steps shrink alike
    assert acc["work_share"]["integrator_steps"] <= 0.3


def test_a_failed_companion_makes_nothing_reliable(monkeypatch):
    scene, res = _run("spring_drop")
    from cosim.scene import run as run_module

    def broken(*a, **k):
        raise RuntimeError("no")
    monkeypatch.setattr(run_module, "simulate", broken)
    acc = estimate_errors(scene, res)
    assert not acc["reliable"] and acc["companion"]["status"] == "refused"
    assert accuracy_text(acc).startswith("accuracy: not reliable (the companion did not run")


def test_the_monolithic_scheme_gets_no_companion_and_says_so():
    scene, res = _run("spring_drop", scheme="monolithic")
    acc = estimate_errors(scene, res)
    assert acc["companion"]["status"] == "not run" and not acc["reliable"]
    assert acc["contacts"]["wall"]["peak_penetration"]["relative_error"] is None
    assert accuracy_text(acc).startswith("accuracy: not estimated for the monolithic scheme")


def _cli_run(tmp_path, *extra):
    out = tmp_path / "run"
    assert cli.main(["run", str(CASES / "spring_drop.toml"), "--out", str(out), "--quiet",
                     *extra]) == 0
    return json.loads((out / "summary.json").read_text())


def test_run_summary_has_accuracy_and_the_terminal_says_it(tmp_path, capsys):
    s = _cli_run(tmp_path)
    assert s["accuracy"]["reliable"] is True
    assert s["accuracy"]["factor"] == 4
    assert "accuracy (companion at 4x the step" in capsys.readouterr().out


def test_no_estimate_leaves_no_accuracy_key(tmp_path, capsys):
    assert "accuracy" not in _cli_run(tmp_path, "--no-estimate")
    assert "accuracy" not in _cli_run(tmp_path, "--overwrite", "--set", "output.estimate=false")
    assert "accuracy" not in capsys.readouterr().out


def test_exit_rates_are_the_bench_exit_velocity_at_the_last_release():
    from cosim.studies.estimate import exit_rates
    from cosim.studies.metrics import impact_metrics
    scene, res = _run("spring_drop")
    rates, at = exit_rates(res, {"body"})
    assert at == "release of wall at 0.0131416 s"
    # one interpolation, two callers: equal to round-off
    assert rates["body/x"] == pytest.approx(impact_metrics(res, "wall", "body/x")[
        "exit_velocity"], rel=1e-14)


def test_ctrl_c_during_the_companion_keeps_the_run_without_estimate(tmp_path, monkeypatch,
                                                                   capsys):
    from cosim.scene import run as run_module
    from cosim.studies import estimate

    partial = _run("spring_drop")[1]

    def interrupted(scene, *a, **k):       # the companion: stopped by Ctrl-C
        raise run_module.RunInterrupted(partial) from KeyboardInterrupt()
    real = estimate.estimate_errors

    def estimate_errors(scene, res, *a, **k):
        monkeypatch.setattr(run_module, "simulate", interrupted)
        return real(scene, res, *a, **k)
    monkeypatch.setattr(estimate, "estimate_errors", estimate_errors)
    out = tmp_path / "run"
    code = cli.main(["run", str(CASES / "spring_drop.toml"), "--out", str(out), "--quiet"])
    assert code == 130
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "finished" and "accuracy" not in s
    assert "accuracy" not in capsys.readouterr().out


def test_the_companion_coarsens_the_steps_that_set_the_accuracy():
    from cosim.studies.estimate import coarsened
    scene, _ = _run("three_mass", "f100", ["scheme.interface_tolerance=1e-4"])
    comp, changed = coarsened(scene, 4)
    assert comp.scheme_options["macro_step"] == pytest.approx(4 * 2e-3, rel=1e-15)
    assert comp.scheme_options["contact_step"] == pytest.approx(4 * 3e-5, rel=1e-15)
    # extrapolation order 1: the controlled step goes as tol ** (1/3)
    assert comp.scheme_options["interface_tolerance"] == pytest.approx(1e-4 * 4 ** 3,
                                                                       rel=1e-15)
    assert set(changed) == {f"scheme.gauss_seidel.{k}" for k in (
        "macro_step", "contact_step", "interface_tolerance", "approach_horizon")}
    # the window stepped at contact_step before an onset stays the run's
    assert comp.scheme_options["approach_horizon"] == 2e-3
    # the robot's step stays: at 4x it would put contact A past omega h = 0.5
    assert comp.subsystems == scene.subsystems
    spring, _ = _run("spring_drop")
    comp, changed = coarsened(spring, 4)          # omega h = 0.04 at 4x: coarsened
    assert comp.subsystems[0].max_step == pytest.approx(4e-5, rel=1e-15)
    assert "subsystems.body.integrator.max_step" in changed
    with pytest.raises(ValueError, match="`factor` must be a finite number > 1"):
        coarsened(scene, 1)


def test_the_library_run_bench_and_sweep_pay_nothing_for_it(monkeypatch):
    from cosim.studies import estimate
    calls = []
    monkeypatch.setattr(estimate, "estimate_errors", lambda *a, **k: calls.append(a))
    scene, res = _run("spring_drop")
    assert "accuracy" not in res.summary
    from cosim.studies.bench import run_bench
    run_bench(CASES / "spring_drop.toml", schemes=["gauss_seidel"], steps=[1e-4],
              tolerances=(), paper=False, spread=1,
              ref={"count": 1, "peak": 1e-3, "exit_velocity": 1.0, "energy": 0.0,
                   "cpu_time_s": 0.0})
    assert calls == []


def test_a_contact_that_never_closes_writes_no_nan(tmp_path):
    # the wall moved out of reach: the contact never closes in either run
    s = _cli_run(tmp_path, "--set", "subsystems.body.bodies.mass.joint.dq0=1.0")
    wall = s["accuracy"]["contacts"]["wall"]
    assert wall["count"] == {"value": 0, "companion": 0, "robust": True}
    assert wall["t_on"]["value"] is None and not wall["t_on"]["reliable"]
    assert s["accuracy"]["exit"]["at"] == "end of the run"
    assert s["accuracy"]["reliable"] is True     # nothing closed: the counts and rates are
    text = (tmp_path / "run" / "summary.json").read_text()
    assert "NaN" not in text


@pytest.mark.parametrize("ulps", [0, 1, -1])
def test_a_companion_the_guard_stops_makes_nothing_reliable_and_says_why(ulps):
    # spring_drop's wall exchanged with the force held over each 50 us step
    # (extrapolation order 0): the run holds, its companion at 200 us creates
    # energy and the guard stops it
    scene = perturbed(_run("spring_drop", None, [
        'contacts.wall.placement="coupler"', "scheme.accept_unsafe_step=true",
        "scheme.extrapolation_order=0", "scheme.macro_step=5e-5"])[0], ulps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cosim.simulate(scene)
    assert res.success
    acc = estimate_errors(scene, res)
    assert acc["companion"]["status"] == "failed" and not acc["reliable"]
    assert acc["why"][0].startswith("the companion failed: the energy grew")
    assert all(e["relative_error"] is None for c in acc["contacts"].values()
               for k, e in c.items() if k != "count")
    assert "%" not in accuracy_text(acc)


@pytest.mark.parametrize("ulps", [0, 2, -2])
def test_no_companion_runs_where_nothing_it_gives_could_be_read(ulps):
    """three_mass f100 at its own 30 us: C lies past the asymptotic range at
    4x and 2x, A and B are stepped by the robot, which keeps its step: the
    companion would cost 0.5 of the run for nothing, and is not run."""
    from cosim.studies.estimate import BLIND
    scene = perturbed(_run("three_mass", "f100")[0], ulps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cosim.simulate(scene)
    acc = estimate_errors(scene, res)
    assert acc["companion"] == {"status": "not run", "message": BLIND}
    assert acc["work_share"] is None and not acc["reliable"]
    assert all(c["count"]["robust"] is None for c in acc["contacts"].values())
    assert "past 0.4" in acc["contacts"]["C"]["peak_penetration"]["why"]
    assert accuracy_text(acc).startswith("accuracy: not reliable, no companion run (")


def test_the_line_gives_what_was_estimated_and_names_what_was_not():
    """three_mass f10: C and the exit rates are estimated; A and B, which the
    robot's own step resolves at omega h = 0.3 in both runs, are named
    without a number."""
    scene, res = _run("three_mass", "f10")
    acc = estimate_errors(scene, res)
    line = accuracy_text(acc)
    assert "C peak " in line and "exit robot/" in line
    assert "not estimated: A, B (`robot` steps contact A at the same step" in line
    assert "A peak" not in line and "B peak" not in line


def test_the_companion_factor_keeps_exchanged_contacts_within_the_asymptotic_range():
    from cosim.studies.companion import ASYMPTOTIC_OMEGA_H, MIN_FACTOR, fitting_factor
    assert (ASYMPTOTIC_OMEGA_H, MIN_FACTOR) == (0.4, 2.0)
    assert fitting_factor(4, {}) == (4, {})
    assert fitting_factor(4, {"C": 0.05, "D": 0.1}) == (4, {})
    factor, beyond = fitting_factor(4, {"C": 0.05, "D": 0.15})     # 0.4 / 0.15 = 2.67
    assert factor == 2.6 and beyond == {}
    factor, beyond = fitting_factor(4, {"C": 0.05, "D": 0.3})      # 2x would pass 0.4
    assert factor == 4 and beyond == {"D": pytest.approx(1.2, rel=1e-15)}


@pytest.mark.parametrize("ulps", [0, 2, -2])
def test_exit_rates_read_at_another_instant_in_the_companion_are_not_compared(ulps):
    """beam_impact: at 2x its steps (C at omega h 0.19, so a 2x companion)
    the second closing of C lasts to the end of the run, so the companion
    reads the rates at the end, the run at C's release: 7 % apart, not an
    error of the run; no number is given (on copies moved by a few ulps too)."""
    scene = perturbed(_run("beam_impact")[0], ulps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cosim.simulate(scene)
    acc = estimate_errors(scene, res)
    assert acc["factor"] == 2
    assert acc["exit"]["at"].startswith("release of C at ")
    e = acc["exit"]["robot/arm"]
    assert e["relative_error"] is None
    assert e["why"].startswith("the companion reads the exit rates at end of the run")
    assert acc["contacts"]["C"]["peak_penetration"]["reliable"]
