"""Hard cases (issue 9, part 1): three_mass at f = 1000 and m_s = 0.01 kg under
every scheme and placement of C, macro steps up to ten times the stability
limit.  Each run stays within its energy bound, is refused before it starts
with the reason, or is stopped by the run guard with a message naming the
contact and the time: never NaN, never silent energy growth.  Each point runs
with its round-off copies (``cosim.studies.roundoff.spread``): that property
must hold for all of them, and a verdict is asserted only where it is robust."""
import math
import re
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES, ROOT
from cosim.core.guard import Guard, GuardError, GuardOptions
from cosim.core.schemes import COUPLING_SCHEMES
from cosim.studies.verify import (HARD_COPIES, HardCase, hard_matrix, reference_step,
                                  robustness, run_hard_case)


def _spring_system():
    scene = cosim.load_scene(CASES / "spring_drop.toml")
    system, _ = scene.build()
    return system


def _zeros(system):
    return np.zeros(system.n_rows), np.zeros(system.n_rows), np.zeros(system.n_rows)


# ------------------------------------------------------------ the guard alone
def test_guard_detects_growth_at_the_right_time_and_names_the_contact():
    """spring_drop holds 0.5 J (the body's kinetic energy): with the default
    bound of 0.1 of it, a coupling that creates 0.01 J per step through the
    wall is stopped at the sixth step, the first above 0.05 J."""
    system = _spring_system()
    guard = Guard(system, GuardOptions())
    d, dd, f = _zeros(system)
    diss = np.zeros(1)
    tripped = None
    for k in range(20):
        created = 0.01 * k
        try:
            guard.check(1e-3 * k, d, dd, f, created, 0.0, diss, work=np.array([created]))
        except GuardError as exc:
            tripped = (k, exc)
            break
    assert guard.scale == pytest.approx(0.5)
    assert tripped is not None and tripped[0] == 6
    exc = tripped[1]
    assert exc.t == pytest.approx(6e-3) and exc.contact == "wall"
    assert exc.cause == "energy growth"
    assert isinstance(exc, cosim.SimulationError)
    assert str(exc).startswith("run stopped at t = 0.006 s: the energy grew by 0.06 J")
    assert "contact `wall` created 0.06 J" in str(exc)


def test_guard_says_when_no_contact_holds_the_energy():
    system = _spring_system()
    guard = Guard(system)
    d, dd, f = _zeros(system)
    guard.check(0.0, d, dd, f, 0.0, 0.0, np.zeros(1), work=np.zeros(1))
    with pytest.raises(GuardError, match=r"t = 0\.002 s.*no contact accounts for it .*"
                                         r"`wall`: 0 J\): the rest was created inside the "
                                         r"subsystems' own integrators") as info:
        guard.check(2e-3, d, dd, f, 0.2, 0.0, np.zeros(1), work=np.zeros(1))
    assert info.value.contact is None


def test_guard_bound_grows_with_the_energy_supplied_and_can_be_turned_off():
    system = _spring_system()
    d, dd, f = _zeros(system)
    guard = Guard(system)
    guard.check(0.0, d, dd, f, 0.0, 0.0, np.zeros(1))
    guard.check(1e-3, d, dd, f, 0.14, 1.0, np.zeros(1))     # bound 0.1 * (0.5 + 1) = 0.15
    with pytest.raises(GuardError):
        guard.check(2e-3, d, dd, f, 0.16, 1.0, np.zeros(1))
    off = Guard(system, GuardOptions(energy_check=False))
    off.check(0.0, d, dd, f, 0.0, 0.0, np.zeros(1))
    off.check(1e-3, d, dd, f, 1e6, 0.0, np.zeros(1))       # any growth passes
    with pytest.raises(GuardError, match="not finite"):   # but never a NaN
        off.check(2e-3, d, dd, f, math.nan, 0.0, np.zeros(1))


@pytest.mark.parametrize("row", ["d", "dd", "f"])
def test_guard_stops_on_an_injected_nan_and_names_the_contact(row):
    system = _spring_system()
    guard = Guard(system)
    d, dd, f = _zeros(system)
    guard.check(0.0, d, dd, f, 0.0, 0.0, np.zeros(1))
    {"d": d, "dd": dd, "f": f}[row][0] = math.nan
    what = {"d": "penetration", "dd": "penetration rate", "f": "force"}[row]
    with pytest.raises(GuardError, match=rf"run stopped at t = 0\.003 s: the {what} of "
                                         rf"contact `wall` is nan") as info:
        guard.check(3e-3, d, dd, f, 0.0, 0.0, np.zeros(1))
    assert info.value.contact == "wall" and info.value.cause == "non-finite"


def test_guard_blames_a_nan_state_on_the_contact_acting_on_it():
    system = _spring_system()
    guard = Guard(system)
    d, dd, f = _zeros(system)
    guard.check(0.0, d, dd, f, 0.0, 0.0, np.zeros(1))
    body = system.subsystems[system.names.index("body")]
    body.x[-1] = math.inf
    with pytest.raises(GuardError, match=r"state of subsystem `body` is not finite "
                                         r"\(contacts on it: `wall`"):
        guard.check(1e-3, d, dd, f, math.nan, 0.0, np.zeros(1))


def test_guard_options_are_checked():
    with pytest.raises(ValueError, match=r"`energy_growth` must be a finite number > 0"):
        GuardOptions(energy_growth=0.0)
    with pytest.raises(ValueError, match=r"`energy_floor` must be"):
        GuardOptions(energy_floor=-1.0)


@pytest.mark.parametrize("setting,match", [
    ("guard.energy_growth=-0.1", r"`guard.energy_growth` must be > 0"),
    ("guard.energy_check=1", r"`guard.energy_check` must be true or false"),
    ("guard.energy_floor=-1.0", r"`guard.energy_floor` must be >= 0"),
    ("guard.typo=1", r"`guard.typo` is not a known key"),
])
def test_scene_guard_table_is_validated(setting, match):
    with pytest.raises(cosim.SceneError, match=match):
        cosim.load_scene(CASES / "spring_drop.toml", overrides=[setting])


# ------------------------------------------------------- the guard in a run
def test_a_nan_in_a_run_stops_it_with_time_and_contact(monkeypatch):
    """A subsystem whose state turns NaN mid-run: the run ends failed at that
    step, the message names the contact and the time, and the series kept
    are finite."""
    from cosim.core.schemes import sampled
    from cosim.core.schemes.explicit import Jacobi
    original = Jacobi.advance

    def poisoned(self, system, t, h, ratio):
        out = original(self, system, t, h, ratio)
        if t + h > 5e-3:
            system.subsystems[system.names.index("body")].x[-1] = math.nan
        return out

    monkeypatch.setattr(Jacobi, "advance", poisoned)
    monkeypatch.setattr(sampled, "ENABLED", False)      # the loop, which calls `advance`
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(CASES / "spring_drop.toml", overrides=[
            "scheme.macro_step=1e-4"], scheme="jacobi")
    res = cosim.simulate(scene, estimate=False)
    assert res.status == "failed"
    # the stop time is the last sample kept; the step the guard refused is named too
    assert res.message.startswith("run stopped at t = 0.005 s (the last sample kept; the guard "
                                  "tripped at t = 0.0051 s): the penetration rate of "
                                  "contact `wall` is nan"), res.message
    assert all(np.all(np.isfinite(a)) for a in res.series.values())
    assert res.t[-1] == pytest.approx(5e-3)


def test_forced_unsafe_step_is_stopped_not_left_to_grow():
    """spring_drop's wall exchanged by Jacobi at 16 times its safe step: the
    pre-flight check refuses it; forced, the guard stops the run at the
    impact, blaming the wall, where it used to gain 40 % energy silently."""
    def load(*extra):
        return cosim.load_scene(CASES / "spring_drop.toml", overrides=[
            'contacts.wall.placement="coupler"', "scheme.macro_step=1e-4", *extra],
            scheme="jacobi")
    with pytest.raises(cosim.UnsafeStepError, match=r"contact `wall`: macro step 0\.0001 s"):
        cosim.simulate(load(), estimate=False)
    res = cosim.simulate(load("scheme.accept_unsafe_step=true"), estimate=False)
    assert res.status == "failed"
    assert "contact `wall` created" in res.message
    t_stop = float(res.message.split("t = ")[1].split(" s")[0])
    assert 0.01 < t_stop < 0.01 + math.pi * 1e-3        # inside the contact
    created = float(res.message.split("grew by ")[1].split(" J")[0])
    # the samples kept stop before the step that tripped the guard
    assert res.summary["energy"]["max_abs_drift"] < created


def test_written_summary_of_a_stopped_run(tmp_path):
    """`cosim run` of a run the guard stops: exit status 1, the summary is
    written with status failed and the message."""
    import json

    from cosim.cli import main
    code = main(["run", str(CASES / "spring_drop.toml"), "--scheme", "jacobi", "--quiet",
                 "--set", 'contacts.wall.placement="coupler"', "--set", "scheme.macro_step=1e-4",
                 "--set", "scheme.accept_unsafe_step=true", "--out", str(tmp_path / "r")])
    assert code == 1
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert s["status"] == "failed" and s["message"].startswith("run stopped at t = ")


# --------------------------------------------------------------- the matrix
def test_reference_steps_are_the_preflight_limit_or_a_tenth_of_the_contact():
    """Explicit coupler: the pre-flight's largest safe step (`cosim info`
    says 2.873e-06 s for f1000); otherwise a tenth of pi / omega."""
    assert reference_step(CASES, "f1000", "jacobi", "coupler") == pytest.approx(2.873e-6,
                                                                                  rel=2e-3)
    omega = 2 * math.pi * 5273.0
    assert reference_step(CASES, "f1000", "gauss_seidel", "embedded") == pytest.approx(
        0.1 * math.pi / omega, rel=1e-3)
    m = hard_matrix(CASES)
    assert {c.scheme for c in m} == set(COUPLING_SCHEMES)
    assert {c.variant for c in m} == {"f1000", "ms0.01"}
    assert max(c.factor or 0 for c in m) == 10.0


# a few points of the matrix at t_end = 0.125 s (C's train lies in 0.1027-0.121 s), with
# the verdict each gives for the scene and its round-off copies (measured robust over 5
# copies; the test runs 3, as `cosim verify --hard` does)
CI_POINTS = [
    (HardCase("f1000", "gauss_seidel", "embedded", 9.48e-6, 1.0), "bounded"),
    (HardCase("f1000", "gauss_seidel", "coupler", 2.87e-6, 1.0), "bounded"),
    (HardCase("ms0.01", "implicit", "coupler", 7.85e-6, 1.0), "bounded"),
    (HardCase("f1000", "jacobi", "coupler", 2.87e-5, 10.0), "refused"),
    (HardCase("f1000", "jacobi", "coupler", 2.87e-5, 10.0, True), "stopped (energy growth, C)"),
    (HardCase("f1000", "jacobi", "embedded", 9.48e-5, 10.0), "stopped (energy growth, C)"),
]


@pytest.mark.parametrize("case,verdict", CI_POINTS, ids=[c.label for c, _ in CI_POINTS])
def test_hard_case_points(case, verdict):
    """Each point's verdict, with its cause and contact, is the same for the
    scene and its copies moved by round-off, and every copy's outcome is
    allowed (never NaN, never silent growth)."""
    r = run_hard_case(case, CASES, t_end=0.125)
    assert r["ok"], r["detail"]
    assert r["robust"] and r["verdicts"] == [verdict] * HARD_COPIES, robustness(r)
    assert r["outcome"] == verdict.split(" ")[0], r["detail"]
    if r["outcome"] == "stopped":
        assert "contact `C`" in r["detail"]


def test_a_verdict_that_differs_among_copies_is_said_so():
    """The check's detail says `robust` or lists the copies' verdicts, on one line."""
    from cosim.studies.verify import hard_checks

    assert robustness({"robust": True, "verdicts": ["bounded"] * 3}) == "robust"
    assert robustness({"robust": False, "verdicts": ["bounded", "stopped (chatter, A)",
                                                     "bounded"]}) == \
        "not robust (verdicts: bounded; stopped (chatter, A); bounded)"
    (check,) = hard_checks(CASES, 0.125, [CI_POINTS[3][0]])
    assert check.passed and check.detail.startswith("refused by the pre-flight check")
    assert check.detail.endswith("; robust") and "\n" not in check.detail


def test_verify_hard_prints_one_line_per_check(monkeypatch, capsys):
    """`cosim verify --hard`: a PASS or FAIL line per check and nothing else,
    nothing on stderr (no log line, no bare message); a stopped run shows the
    guard's own figures (the energy created at the sample it refused, and its
    bound: created above the bound, as a stop needs), a refused one the
    pre-flight check's largest safe step."""
    from cosim import cli
    from cosim.studies import verify

    points = [CI_POINTS[3][0], CI_POINTS[4][0]]        # refused; forced, then stopped
    monkeypatch.setattr(verify, "hard_matrix", lambda cases: points)
    assert cli.main(["verify", "--cases", str(CASES), "--hard"]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    lines = out.splitlines()
    assert lines[-1] == "all checks passed" and len(lines) == len(verify.CHECKS) * 3 + 3
    assert all(re.fullmatch(r"PASS  \S[^:]*: \S.*", ln) for ln in lines[:-1]), lines
    refused, stopped = lines[-3:-1]
    safe = reference_step(CASES, "f1000", "jacobi", "coupler")
    assert refused == (f"PASS  {points[0].label}: refused by the pre-flight check (largest "
                       f"safe step {safe:.3g} s); robust")
    m = re.fullmatch(rf"PASS  {re.escape(points[1].label)}: stopped by the guard at "
                     r"t = (\S+) s \(energy growth, C\): created (\S+) J, bound (\S+) J; robust",
                     stopped)
    assert m, stopped
    t, created, bound = map(float, m.groups())
    assert created > bound and 0.1 < t < 0.125


def test_the_verification_page_shows_three_lines_as_printed():
    """docs/verification.md quotes three lines of `cosim verify --hard`: these
    points of the matrix print them."""
    from cosim.studies.verify import hard_checks

    page = (ROOT / "docs" / "verification.md").read_text(encoding="utf-8")
    shown = page.split("Each check is one\nline; three of them:\n\n```text\n")[1].split("```")[0]
    matrix = hard_matrix(CASES, factors=(1.0, 10.0), variants=("f1000",), schemes=("jacobi",),
                         placements=("coupler",))
    lines = [f"{'PASS' if c.passed else 'FAIL'}  {c.name}: {c.detail}"
             for c in hard_checks(CASES, None, matrix)]
    assert lines == shown.strip().splitlines()


def test_hard_line_of_a_bounded_and_a_failed_point():
    from cosim.studies.verify import hard_line

    r = {"ok": True, "outcome": "bounded", "detail": "created 0.272 J of 4.51 J allowed",
         "verdicts": ["bounded"] * 3, "robust": True, "created": 0.2723, "bound": 4.5111}
    assert hard_line(r) == "bounded: created 0.272 J, bound 4.51 J; robust"
    r = {**r, "ok": False, "outcome": "stopped", "detail": "a copy: stopped: run stopped\nat t",
         "verdicts": ["bounded", "stopped (failed, no contact)", "bounded"], "robust": False}
    assert hard_line(r) == ("stopped, not robust (verdicts: bounded; stopped (failed, no "
                            "contact); bounded): a copy: stopped: run stopped at t")


@pytest.mark.slow
@pytest.mark.parametrize("case", hard_matrix(CASES), ids=lambda c: c.label)
def test_hard_case_matrix(case):
    """The whole matrix at the scene's t_end (also `cosim verify --hard`): every
    copy of every point ends within its bound, refused, or stopped by the guard
    naming the contact; the verdict itself is asserted only where it is robust
    (`cosim verify --hard` says which)."""
    r = run_hard_case(case, CASES)
    assert r["ok"], f"{r['outcome']}, {robustness(r)}: {r['detail']}"
