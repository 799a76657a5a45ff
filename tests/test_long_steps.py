"""A step longer than the run: one step to ``t_end``, never "finished" at t = 0.

A macro step (or contact step) longer than ``t_end`` is clipped to the time
that is left, like the last step of any run.  The loop once judged the step
it was about to take against the macro step alone (``h <= 1e-12 * H``): a
step above 1e12 times ``t_end`` made the whole run a sliver, no step was
taken, and the run reported ``finished`` at t = 0 with exit status 0.
"""
import json
import math

import pytest

import cosim
from conftest import CASES
from cosim import cli
from cosim.scene.load import load_scene
from roundoff import cli_copies

SPRING_DROP = CASES / "spring_drop.toml"
T_END = 0.02            # [s] spring_drop's end time


def _run(tmp_path, capsys, args, name="run"):
    out = tmp_path / name
    code = cli.main(["run", str(SPRING_DROP), *args, "--out", str(out)])
    captured = capsys.readouterr()
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() \
        else None
    return code, summary, captured


@pytest.mark.parametrize("key", ["macro_step", "contact_step"])
@pytest.mark.parametrize("step", [2.1e10, 1e308])
def test_a_step_longer_than_the_run_runs_to_t_end(key, step, tmp_path, capsys):
    """spring_drop's contact is embedded in the body's integrator (RK4 at
    1e-5 s), so one macro step of the whole run resolves it exactly as 200
    do: the mass leaves at +1 m/s (undamped, closed form), once.  A finished
    run with one contact holds for the scene and its round-off copies."""
    copies = cli_copies(load_scene(SPRING_DROP))
    for i, extra in enumerate(copies):
        code, s, cap = _run(tmp_path, capsys, ["--set", f"scheme.{key}={step!r}", *extra],
                            f"run{i}")
        assert code == 0, cap.err
        assert s["status"] == "finished" and s["message"] == ""
        # the last sample is t_end itself: the loop sums no steps when there is one
        assert s["t_end"] == pytest.approx(T_END, rel=1e-12)
        assert s["contacts"]["wall"]["count"] == 1
        # RK4 at omega dt = 0.01 over the contact: the rebound to 1e-9 of 1 m/s
        assert s["final_state"]["body"]["x"]["dq"] == pytest.approx(1.0, abs=1e-9)
        # contact_step is not used here: no contact is exchanged by the scheme
        assert s["macro_steps"] == (1 if key == "macro_step" else 200)
        assert f"t_end {T_END:g} s" in cap.out


@pytest.mark.parametrize("key", ["macro_step", "contact_step"])
@pytest.mark.parametrize("step", [2.1e10, 1e308])
def test_a_step_longer_than_the_run_is_judged_as_the_whole_run(key, step, tmp_path, capsys):
    """With the contact exchanged by the scheme, the pre-flight check judges
    the step actually taken, t_end (a step of 1e308 s once made the check
    overflow and quote a largest safe step of 0 s).  k = 1e6 N/m on 1 kg:
    omega = 1000 rad/s, and 0.02 s is far beyond the safe step."""
    code, s, cap = _run(tmp_path, capsys, ["--set", 'contacts.wall.placement="coupler"',
                                           "--set", f"scheme.{key}={step!r}"])
    assert code == 2 and s is None
    assert cap.err.startswith("error: ") and "Traceback" not in cap.err
    assert f"macro step 0.02 s (the whole run: `scheme.{key}` = {step:.3g} s is longer)" in cap.err
    assert "overflow" not in cap.err and "nan" not in cap.err
    safe = float(cap.err.split("largest safe macro step is ")[1].split(" s")[0])
    assert 0.0 < safe < 1.0 / 1000.0     # below 1/omega: a few per cent of a period


def test_a_controlled_run_with_a_long_free_step_reaches_t_end(tmp_path, capsys):
    """Step control (a contact exchanged, ``contact_step`` set): a macro step
    of 1e308 s in free flight is cut to ``contact_step`` before the contact
    and to the remaining time otherwise; the run ends at t_end with the
    closed-form contact (duration pi / omega = 3.1416 ms, rebound +1 m/s)."""
    code, s, cap = _run(tmp_path, capsys, [
        "--scheme", "implicit", "--set", 'contacts.wall.placement="coupler"',
        "--set", "scheme.macro_step=1e308", "--set", "scheme.contact_step=1e-5"])
    assert code == 0, cap.err
    assert s["status"] == "finished"
    assert s["t_end"] == pytest.approx(T_END, rel=1e-12)
    (t_on, t_off), = s["contacts"]["wall"]["intervals"]
    # implicit coupling at 1e-5 s steps: the contact's times within a step
    assert t_off - t_on == pytest.approx(math.pi / 1000.0, abs=1e-5)
    assert s["final_state"]["body"]["x"]["dq"] == pytest.approx(1.0, abs=1e-4)


def test_a_scheme_that_stops_short_of_t_end_has_not_finished(monkeypatch):
    """Whatever a scheme's loop does, a run whose last sample is short of
    t_end is not reported ``finished``: it is an error of cosim."""
    from cosim.core.schemes.explicit import GaussSeidel

    def stop_at_once(self, system, t_end, recorder):
        d, dd = system.penetrations(system.outputs())
        f = system.forces(d, dd)
        z = 0.0 * f[:system.n_contacts]
        recorder.record(0.0, d, dd, f, z, z)
        return self.counters()

    monkeypatch.setattr(GaussSeidel, "run", stop_at_once)
    res = cosim.simulate(load_scene(SPRING_DROP), estimate=False)
    assert res.status == "error" and not res.success
    assert "returned at t = 0 s, short of t_end = 0.02 s" in res.message
