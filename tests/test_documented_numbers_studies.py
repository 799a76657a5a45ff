"""The numbers of docs/verification.md, sweeps.md, schemes.md, commands.md and
troubleshooting.md that a command produces, held to what it gives now.

Each number is a :class:`documented.Claim`; ``test_printed`` asserts that the
page still prints it, and the tests below, grouped by the runs they need
(module-scoped fixtures: one run serves many claims), assert that the run
gives it.  The tolerance is half a unit of the last printed digit unless a
comment says otherwise.  A discrete outcome (a count, a regime, a status, a
number of warnings or iterations) is asserted for the scene and for copies of
it whose initial state is moved by a few ulps (``tests/roundoff.py``); where
the copies disagree, the page prints the range over them and the test holds
every copy to it.
"""
from __future__ import annotations

import dataclasses
import json
import math
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES
from documented import ROOT, Claim, assert_printed, assert_reproduced
from roundoff import COPIES
from cosim.studies.roundoff import perturbed_overrides, spread

V = "docs/verification.md"
SW = "docs/sweeps.md"
SC = "docs/schemes.md"
CM = "docs/commands.md"
TR = "docs/troubleshooting.md"
THREE_MASS = CASES / "three_mass.toml"

_NUMBER = re.compile(r"[+\-−]?\d+(?:\.\d+)?(?:e[+\-−]?\d+)?")


def number(text: str) -> tuple[float, float]:
    """The value of a printed number (a Unicode minus is a minus) and half a
    unit of its last digit."""
    m = _NUMBER.fullmatch(text.strip())
    assert m, f"not a number: {text!r}"
    s = text.strip().replace("−", "-")
    mant, _, exp = s.partition("e")
    digits = len(mant.split(".")[1]) if "." in mant else 0
    scale = 10.0 ** int(exp) if exp else 1.0
    return float(s), 0.5 * 10.0 ** -digits * scale


def claim(page: str, printed: str, command: str, text: str | None = None,
          rel: float | None = None, abs_: float | None = None) -> Claim:
    """A claim whose value is ``text`` (by default the last number in
    ``printed``), to half a unit of its last digit (or ``rel``, ``abs_``)."""
    if text is None:
        text = _NUMBER.findall(printed)[-1]
    assert text in printed, (text, printed)
    value, half = number(text)
    if rel is not None:
        return Claim(page, printed, command, value, rel=rel)
    return Claim(page, printed, command, value, abs=half if abs_ is None else abs_)


def row(page: str, prefix: str, cells: list[str], command: str) -> list[Claim]:
    """One claim per cell of a Markdown table row: the printed text runs from
    ``prefix`` up to and including that cell, so that each claim is tied to
    its row and column."""
    out = []
    for i, cell in enumerate(cells):
        text = prefix + " | " + " | ".join(cells[:i + 1]) + " |"
        num = _NUMBER.findall(cell)
        if num:
            out.append(claim(page, text, command, num[0]))
    return out


def simulate(scene, estimate: bool = False):
    """The run alone (its estimate only with ``estimate``: a test of the
    estimate calls :func:`cosim.studies.estimate.estimate_errors`)."""
    with warnings.catch_warnings():      # options the scheme ignores, unsafe steps asked for
        warnings.simplefilter("ignore")
        return cosim.simulate(scene, estimate=estimate)


def load(path, variant=None, overrides=(), scheme=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(path, variant, list(overrides), scheme)


def moved(scene, copies: int) -> list:
    """The scene and its copies moved by round-off (`spread`), validated
    again without the warnings the scene's own load already gave."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return spread(scene, copies)


def pct(x: float, ref: float) -> float:
    return 100.0 * (x / ref - 1.0)


# ======================================================================
# three_mass f100 against the monolithic reference (verification, schemes,
# sweeps): one reference run, the table's rows each with its copies
# ======================================================================
M3, S2 = "scheme.macro_step=1e-3", "scheme.contact_step=2e-5"
COUPLER = 'contacts.C.placement="coupler"'
F100_ROWS = {
    "shipped": (None, ()),
    "gs": (None, (M3, S2)),
    "jacobi": ("jacobi", (M3, S2)),
    "implicit": ("implicit", (M3, S2)),
    "gs_tol": (None, (M3, "scheme.contact_step=1e-4", "scheme.interface_tolerance=1e-3")),
    "implicit_coupler": ("implicit", (M3, S2, COUPLER)),
    "iqn_coupler": ("implicit", (M3, S2, COUPLER, 'scheme.acceleration="iqn_ils"')),
    "gs_coupler": (None, (M3, S2, COUPLER, "scheme.accept_unsafe_step=true")),
    # the interface error control's sentence: the scene's macro step, 100 us in contact
    "coarse_1e-4": (None, ("scheme.contact_step=1e-4",)),
    "tol_1e-4": (None, ("scheme.contact_step=1e-4", "scheme.interface_tolerance=1e-3")),
}


def _cmd(name):
    scheme, ov = F100_ROWS[name]
    return ("cosim run cases/three_mass.toml --variant f100"
            + (f" --scheme {scheme}" if scheme else "") + "".join(f" --set {o}" for o in ov))


TABLE = "| scheme, placement of C (steps) |"
F100_CLAIMS = [  # (claim, row, quantity)
    *[(c, "shipped", q) for c, q in zip(row(
        SC, "| `gauss_seidel`, hosted by the chain (the scene as shipped: 2 ms, 30 µs)",
        ["9", "−0.12 %", "+0.20 %", "−0.026", "268", "0"], _cmd("shipped")),
        ("count", "peak", "exit", "coupling", "steps", "iterations"))],
    *[(c, "gs", q) for c, q in zip(row(
        SC, "| `gauss_seidel`, hosted by the chain",
        ["9", "−0.03 %", "+0.07 %", "−0.0085", "515", "0"], _cmd("gs")),
        ("count", "peak", "exit", "coupling", "steps", "iterations"))],
    *[(c, "jacobi", q) for c, q in zip(row(
        SC, "| `jacobi`, hosted by the chain",
        ["9", "+0.26 %", "−0.10 %", "+0.061", "521", "0"], _cmd("jacobi")),
        ("count", "peak", "exit", "coupling", "steps", "iterations"))],
    *[(c, "implicit", q) for c, q in zip(row(
        SC, "| `implicit`, hosted by the chain",
        ["9", "+0.00 %", "−0.01 %", "−6.8e-07", "517", "997"], _cmd("implicit")),
        ("count", "peak", "exit", "coupling", "steps", "iterations"))],
    *[(c, "gs_tol", q) for c, q in zip(row(
        SC, "| `gauss_seidel`, hosted, `contact_step = 1e-4`, `interface_tolerance = 1e-3`",
        ["9", "−0.10 %", "+0.20 %", "−0.031", "379", "0"], _cmd("gs_tol")),
        ("count", "peak", "exit", "coupling", "steps", "iterations"))],
    *[(c, "implicit_coupler", q) for c, q in zip(row(
        SC, "| `implicit`, coupler",
        ["11", "−19.1 %", "+8.35 %", "−2.26", "562", "1204"], _cmd("implicit_coupler")),
        ("count", "peak", "exit", "coupling", "steps", "iterations"))],
    *[(c, "gs_coupler", q) for c, q in zip(row(
        SC, "| `gauss_seidel`, coupler (refused by the pre-flight check; forced)",
        ["9", "−2.9 %", "+0.60 %", "−0.387", "567", "0"], _cmd("gs_coupler")),
        ("count", "peak", "exit", "coupling", "steps", "iterations"))],
    # verification.md: the default against the reference, and with 20 us steps
    (claim(V, "reproduces the reference's 9 contacts", _cmd("shipped")), "shipped", "count"),
    (claim(V, "its peak penetration to −0.116 %", _cmd("shipped")), "shipped", "peak"),
    (claim(V, "release) to +0.197 %", _cmd("shipped")), "shipped", "exit"),
    (claim(V, "with `contact_step = 2e-5` these are −0.03 %", _cmd("gs")), "gs", "peak"),
    (claim(V, "with `contact_step = 2e-5` these are −0.03 % and +0.07 %", _cmd("gs")), "gs", "exit"),
    # sweeps.md: the studies' scheme against the reference (magnitudes)
    (claim(SW, "C's peak is within 0.116 %", _cmd("shipped")), "shipped", "|peak|"),
    (claim(SW, "the arm's exit velocity within 0.197 %", _cmd("shipped")), "shipped", "|exit|"),
    # schemes.md: the forced explicit coupler and the same steps hosted
    (claim(SC, "it closes C 9 times, as the reference does", _cmd("gs_coupler"), "9"),
     "gs_coupler", "count"),
    (claim(SC, "it closes C 9 times, as the reference does", _cmd("shipped"), "9"),
     "shipped", "count"),
    (claim(SC, "C's peak is 2.9 % low", _cmd("gs_coupler")), "gs_coupler", "|peak|"),
    (claim(SC, "the coupling takes 0.387 J out", _cmd("gs_coupler")), "gs_coupler",
     "|coupling|"),
    (claim(SC, "the same 20 µs lands within 0.07 %", _cmd("gs")), "gs", "max|error|"),
    # schemes.md: one coupler contact, Aitken and IQN-ILS take the same iterations
    (claim(SC, "`contact_step = 2e-5`: 1204 each", _cmd("implicit_coupler")),
     "implicit_coupler", "iterations"),
    (claim(SC, "`contact_step = 2e-5`: 1204 each", _cmd("iqn_coupler")), "iqn_coupler", "iterations"),
    # schemes.md: interface error control at the scene's macro step
    (claim(SC, "takes C's peak error from 0.5 %", _cmd("coarse_1e-4")), "coarse_1e-4", "|peak|"),
    (claim(SC, "takes C's peak error from 0.5 % to 0.1 %", _cmd("tol_1e-4")), "tol_1e-4", "|peak|"),
    (claim(SC, "exit-velocity error from 0.9 %", _cmd("coarse_1e-4")), "coarse_1e-4", "|exit|"),
    (claim(SC, "exit-velocity error from 0.9 % to 0.2 %", _cmd("tol_1e-4")), "tol_1e-4", "|exit|"),
    (claim(SC, "for 997 iterations over its 517 macro steps", _cmd("implicit"), "997"),
     "implicit", "iterations"),
    (claim(SC, "for 997 iterations over its 517 macro steps", _cmd("implicit")),
     "implicit", "steps"),
    # implicit hosted: "errors below 1e-4, the energy closed to 1e-6 J" are bounds (below)
]


# the implicit row's iterations: the scene and its moved copies take 997 or 998
# (round-off moves one fixed-point iteration over 517 steps), to one
F100_CLAIMS = [(dataclasses.replace(c, abs=1.0) if (name, q) == ("implicit", "iterations")
                else c, name, q) for c, name, q in F100_CLAIMS]


@pytest.fixture(scope="module")
def f100_reference():
    res = simulate(load(THREE_MASS, "f100", scheme="monolithic"))
    assert res.success, res.message
    return res


@pytest.fixture(scope="module")
def f100_rows(f100_reference):
    """Each row of the table, for the scene and its moved copies: C's count,
    peak and exit-velocity errors in %, coupling error [J], macro steps and
    iterations."""
    from cosim.studies.metrics import impact_metrics
    ref = impact_metrics(f100_reference, "C", "robot/arm")
    out = {}
    for name, (scheme, ov) in F100_ROWS.items():
        runs = []
        for scene in moved(load(THREE_MASS, "f100", ov, scheme), COPIES):
            res = simulate(scene)
            assert res.success, (name, res.message)
            m = impact_metrics(res, "C", "robot/arm")
            peak, exit_ = pct(m["peak"], ref["peak"]), pct(m["exit_velocity"], ref["exit_velocity"])
            runs.append({"count": m["count"], "peak": peak, "exit": exit_,
                         "|peak|": abs(peak), "|exit|": abs(exit_),
                         "max|error|": max(abs(peak), abs(exit_)),
                         "coupling": res.summary["contacts"]["C"]["coupling_error"],
                         "|coupling|": abs(res.summary["contacts"]["C"]["coupling_error"]),
                         "steps": res.n_windows, "iterations": res.n_iterations})
        out[name] = runs
    return out


@pytest.mark.parametrize("claim,name,quantity", F100_CLAIMS,
                         ids=[c.id for c, _, _ in F100_CLAIMS])
def test_three_mass_f100_against_the_reference(f100_rows, claim, name, quantity):
    """Every copy gives the printed value: the counts, steps and iterations
    are the same in all of them (measured: so are the other digits)."""
    for run in f100_rows[name]:
        assert_reproduced(claim, run[quantity])


IMPLICIT_BOUNDS = (claim(SC, "errors below 1e-4", _cmd("implicit")),
                   claim(SC, "the energy closed to 1e-6 J", _cmd("implicit")))


def test_implicit_hosted_closes_the_energy(f100_rows):
    """schemes.md: `implicit` with C hosted: "errors below 1e-4, the energy
    closed to 1e-6 J" (bounds; measured 9.7e-5 and 6.8e-7 J)."""
    errors, energy = IMPLICIT_BOUNDS
    for run in f100_rows["implicit"]:
        assert run["max|error|"] / 100 < errors.value, run
        assert abs(run["coupling"]) < energy.value, run


PREFLIGHT_9US = claim(SC, "the explicit coupler refuses any step above 9 µs",
                      "cosim run cases/three_mass.toml --variant f100 --set "
                      "'contacts.C.placement=\"coupler\"' --set scheme.contact_step=2e-5")


def test_the_explicit_coupler_is_refused_above_9_us():
    """schemes.md: "the explicit coupler refuses any step above 9 µs" (the
    pre-flight check's largest safe step, 9.08e-06 s)."""
    c = PREFLIGHT_9US
    with pytest.raises(cosim.UnsafeStepError) as info:
        simulate(load(THREE_MASS, "f100", [COUPLER, S2]))
    safe = float(re.search(r"largest safe macro step is ([0-9.e+-]+) s", str(info.value))[1])
    assert_reproduced(c, safe * 1e6)


# ======================================================================
# verification.md: the paper's findings with the monolithic reference
# ======================================================================
PAPER_F = {"f1": 1, "f2": 1, "f4": 4, "f10": 8, "f100": 9}
PAPER_MS = {"ms6.4": (1, "backward"), "ms3.2": (1, "backward"), "ms1.6": (2, "backward+"),
            "ms0.8": (4, "forward"), "ms0.4": (5, "forward"), "ms0.2": (7, "forward"),
            "ms0.1": (11, "forward"), "ms0.05": (13, "forward")}
MONO = "cosim run cases/three_mass.toml --variant {} --scheme monolithic"
PAPER_CLAIMS = [
    *[(c, v) for c, v in zip(row(V, "| contacts of C", ["1", "1", "4", "8", "9"],
                                 MONO.format("fN")), PAPER_F)],
    (claim(V, "| 6.4, 3.2 | 1 |", MONO.format("ms6.4")), "ms6.4"),
    (claim(V, "| 6.4, 3.2 | 1 |", MONO.format("ms3.2")), "ms3.2"),
    (claim(V, "| 1.6 | 2 |", MONO.format("ms1.6")), "ms1.6"),
    (claim(V, "| 0.8 … 0.05 | 4 … 13 |", MONO.format("ms0.8"), "4"), "ms0.8"),
    (claim(V, "| 0.8 … 0.05 | 4 … 13 |", MONO.format("ms0.05"), "13"), "ms0.05"),
]
REGIME_ROWS = {"backward": "| 6.4, 3.2 | 1 | backward: one contact",
               "backward+": "| 1.6 | 2 | backward+:",
               "forward": "| 0.8 … 0.05 | 4 … 13 | forward:"}


def _paper_run(scene):
    from cosim.studies.metrics import impact_regime
    res = simulate(scene)
    assert res.success, res.message
    iv = res.summary["contacts"]["C"]["intervals"]
    return {"count": res.summary["contacts"]["C"]["count"], "span": iv[-1][1] - iv[0][0],
            "regime": impact_regime(res.summary, res.series, "C", "robot/arm")["regime"]}


@pytest.fixture(scope="module")
def paper(f100_reference):
    """The monolithic reference of each variant, as shipped (f100 is the
    shared reference run)."""
    out = {}
    for v in [*PAPER_F, *PAPER_MS]:
        if v == "f100":
            iv = f100_reference.summary["contacts"]["C"]["intervals"]
            out[v] = {"count": len(iv), "span": iv[-1][1] - iv[0][0]}
        else:
            out[v] = _paper_run(load(THREE_MASS, v, scheme="monolithic"))
    return out


@pytest.mark.parametrize("claim,variant", PAPER_CLAIMS, ids=[c.id + "@" + v for c, v in PAPER_CLAIMS])
def test_contacts_of_c_with_the_monolithic_reference(paper, claim, variant):
    """The scene as shipped; ``test_paper_counts_survive_round_off`` (slow)
    asserts the same for its moved copies, and ``test_fig8`` / ``test_fig11``
    assert the same counts under the default scheme for every copy."""
    assert_reproduced(claim, paper[variant]["count"])


TOUCH_25 = claim(V, "For f ≥ 4 the in-touch period, from first touch to last release, varies by "
                   "less than 25 %", MONO.format("f4, f10, f100"))


def test_regimes_and_in_touch_period_with_the_monolithic_reference(paper):
    """The chain-mass table's regimes, and "for f ≥ 4 the in-touch period
    ... varies by less than 25 %" (a bound; measured 4 %)."""
    for regime, text in REGIME_ROWS.items():
        assert_printed(Claim(V, text, MONO.format("msX"), 0.0))
    for v, (_, regime) in PAPER_MS.items():
        assert paper[v]["regime"] == regime, (v, paper[v])
    c = TOUCH_25
    spans = [paper[v]["span"] for v in ("f4", "f10", "f100")]
    assert 100 * (max(spans) / min(spans) - 1) < c.value, spans


@pytest.mark.slow
def test_paper_counts_survive_round_off():
    """The counts and regimes of the monolithic reference hold for copies
    moved by +-1 ulp (the scene itself: the fast tests above)."""
    for v, count in PAPER_F.items():
        for scene in moved(load(THREE_MASS, v, scheme="monolithic"), 3)[1:]:
            assert _paper_run(scene)["count"] == count, v
    for v, (count, regime) in PAPER_MS.items():
        for scene in moved(load(THREE_MASS, v, scheme="monolithic"), 3)[1:]:
            got = _paper_run(scene)
            assert (got["count"], got["regime"]) == (count, regime), (v, got)


GROUND = [
    (claim(V, "B leaves the ground at 1.87 ms", "cosim run cases/ground_multicontact.toml"),
     lambda c: 1e3 * c["B"]["intervals"][0][1]),
    (claim(V, "and A at 35.7 ms", "cosim run cases/ground_multicontact.toml"),
     lambda c: 1e3 * c["A"]["intervals"][0][1]),
    (claim(V, "C\n  strikes at 0.103 s", "cosim run cases/ground_multicontact.toml"),
     lambda c: c["C"]["intervals"][0][0]),
]


@pytest.mark.parametrize("claim,get", GROUND, ids=[c.id for c, _ in GROUND])
def test_ground_multicontact_lifts_off(claim, get):
    res = simulate(load(CASES / "ground_multicontact.toml"))
    assert_reproduced(claim, get(res.summary["contacts"]))


STRIKE = "python benchmarks/strike_findings.py"
STRIKE_CLAIMS = [
    (claim(V, "C's peak penetration is 5 to 43 times A's", STRIKE, "5"), "kA1e6", "ratio"),
    (claim(V, "C's peak penetration is 5 to 43 times A's", STRIKE, "43"), "kA16e6", "ratio"),
    (claim(V, "C's exit speed is the same to 2.2 %", STRIKE), None, "spread"),
    (claim(V, "(5.93, 5.88, 6.01 m/s)", STRIKE, "5.93"), "kA1e6", "c_exit"),
    (claim(V, "(5.93, 5.88, 6.01 m/s)", STRIKE, "5.88"), "kA4e6", "c_exit"),
    (claim(V, "(5.93, 5.88, 6.01 m/s)", STRIKE, "6.01"), "kA16e6", "c_exit"),
    (claim(V, "A's falls from 0.95 to\n  0.20 m/s", STRIKE, "0.95"), "kA1e6", "a_exit"),
    (claim(V, "A's falls from 0.95 to\n  0.20 m/s", STRIKE, "0.20"), "kA16e6", "a_exit"),
]


@pytest.fixture(scope="module")
def strike():
    """The benchmark the page names, run as a user runs it; its table parsed."""
    p = subprocess.run([sys.executable, "benchmarks/strike_findings.py"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    out = {}
    for line in p.stdout.splitlines():
        f = line.split()
        if f and f[0].startswith("kA"):
            out[f[0]] = {"c_exit": float(f[2]), "a_exit": float(f[3]), "ratio": float(f[4])}
    out[None] = {"spread": float(re.search(r"spread ([0-9.]+) %", p.stdout)[1])}
    return out


@pytest.mark.parametrize("claim,variant,quantity", STRIKE_CLAIMS,
                         ids=[c.id + "@" + str(v) for c, v, _ in STRIKE_CLAIMS])
def test_strike_findings(strike, claim, variant, quantity):
    assert_reproduced(claim, strike[variant][quantity])


# ----------------------------------------------------- closed forms (spring_drop)
@pytest.fixture(scope="module")
def spring_drop_runs():
    return {v: simulate(load(CASES / "spring_drop.toml", v, scheme="monolithic"))
            for v in ("undamped", "kelvin_voigt")}


CLOSED_FORMS = (claim(V, "π√(m/k) = 3.14159 ms", "cosim verify"),
                claim(V, "the rebound is +1 m/s", "cosim verify"),
                claim(V, "e = 0.744079", "cosim verify"),
                claim(V, "against 0.729 for the textbook", "exp(-zeta pi / sqrt(1 - zeta^2))"))


def test_spring_drop_closed_forms(spring_drop_runs):
    """The closed forms to their printed digits, and the monolithic runs that
    `cosim verify` checks against them: contact time and rebound to the
    check's tolerance 1e-6 (relative), which is finer than the printed digits
    of the contact time but not than those of e = 0.744079 (half a unit is
    7e-7 relative); the run's restitution is therefore held to the closed
    form at 1e-6, and the closed form to the printed digits."""
    from analytic import kelvin_voigt_clipped, linear_contact
    tc, v1, e, textbook = CLOSED_FORMS
    zeta = 200.0 / (2 * math.sqrt(1e6 * 1.0))
    assert_reproduced(tc, 1e3 * linear_contact(1.0, 1e6))
    assert_reproduced(e, kelvin_voigt_clipped(1.0, 1e6, 200.0)[1])
    assert_reproduced(textbook, math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2)))
    und = spring_drop_runs["undamped"].summary
    (t_on, t_off), = und["contacts"]["wall"]["intervals"]
    assert_reproduced(tc, 1e3 * (t_off - t_on))
    assert_reproduced(v1, und["final_state"]["body"]["x"]["dq"])
    kv = spring_drop_runs["kelvin_voigt"].summary
    assert kv["final_state"]["body"]["x"]["dq"] / 1.0 == pytest.approx(e.value, rel=1e-6)


VERIFY_TOLERANCES = (claim(V, "For the monolithic scheme (1e-6 relative)", "cosim verify"),
                     claim(V, "the scene's default scheme (1e-5)", "cosim verify"))


def test_cosim_verify_checks_at_the_printed_tolerances():
    """"For the monolithic scheme (1e-6 relative) and the scene's default
    scheme (1e-5), the contact time, the rebound velocity and the energy
    ledger ... are checked": `cosim verify` prints those tolerances, and
    every check passes (exit 0)."""
    mono, default = VERIFY_TOLERANCES
    p = subprocess.run([sys.executable, "-m", "cosim.cli", "verify"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("PASS")]
    assert len(lines) == 12 and "FAIL" not in p.stdout, p.stdout
    for ln in lines:
        tol = float(re.search(r"tol\. ([0-9.e+-]+)\)", ln)[1])
        assert_reproduced(mono if "/monolithic:" in ln else default, tol)


# ----------------------------------------------------- explicit schemes on spring_drop
SPRING_COUPLER = ['contacts.wall.placement="coupler"', "scheme.accept_unsafe_step=true",
                  "guard.energy_check=false"]     # the runs measure a long step's gain


def _drop(scheme, H, order, *extra):
    res = simulate(load(CASES / "spring_drop.toml", None, SPRING_COUPLER + [
        f"scheme.macro_step={H}", f"scheme.extrapolation_order={order}", *extra], scheme))
    assert res.success, res.message
    return res


HELD_FORCE = (claim(V, "the rebound gain matches exp(πωH/4) to 5 %", "tests/test_spring_drop.py",
                    "5"),
              claim(V, "converge at second order, within\n0.25 (ωH)²", "tests/test_spring_drop.py",
                    "0.25"))


def test_held_force_gain_and_the_second_order_envelope():
    """verification.md: with the force held, the rebound gain matches
    exp(πωH/4) to 5 % (a bound: ω = 1000 rad/s, H = 1e-4 and 2.5e-5 s,
    Jacobi and Gauss-Seidel); extrapolation of order 1 and the implicit
    scheme stay within 0.25 (ωH)² in the rebound velocity (H = 1e-4 to
    1.25e-5 s)."""
    from analytic import held_force_rebound_factor
    gain, env = HELD_FORCE
    for scheme in ("jacobi", "gauss_seidel"):
        for H in (1e-4, 2.5e-5):
            v = _drop(scheme, H, 0).summary["final_state"]["body"]["x"]["dq"]
            theory = held_force_rebound_factor(1000.0, H) - 1.0
            assert 100 * abs((v - 1.0) / theory - 1.0) < gain.value, (scheme, H, v, theory)
    for scheme in ("jacobi", "gauss_seidel", "implicit"):
        for H in (1e-4, 5e-5, 2.5e-5, 1.25e-5):
            v = _drop(scheme, H, 1).summary["final_state"]["body"]["x"]["dq"]
            assert abs(v - 1.0) <= env.value * (1000.0 * H) ** 2, (scheme, H, v)


ONSET = Claim(V, "the step controller lands on onsets to 1e-9 s", "tests/test_step_control.py",
              math.sqrt(2 * 0.01 / 2000.0), abs=1e-9)


def test_the_step_controller_lands_on_the_onset():
    """verification.md: "the step controller lands on onsets to 1e-9 s" (a
    bound): a constant 2000 N push from 1 cm, a 5 ms first step, touch-down
    at sqrt(2 x0 / a)."""
    c = ONSET
    res = _drop("implicit", 5e-3, 1, "scheme.contact_step=1.25e-5",
                'subsystems.body.bodies.mass.joint.drive={type="constant", torque=-2000.0}',
                "subsystems.body.bodies.mass.joint.dq0=0.0")
    assert res.n_rejected >= 1
    assert_reproduced(c, res.summary["contacts"]["wall"]["intervals"][0][0])


# ----------------------------------------------------- the two-mass oscillator
TWO_MASS = [  # (row prefix, cells, [(scheme, extrapolation order) per cell])
    ("| `jacobi`", ["1.08", "2.00", "3.0"], [("jacobi", 0), ("jacobi", 1), ("jacobi", 2)]),
    ("| `gauss_seidel`", ["1.07", "2.00", "2.13 (the interpolated force is linear)"],
     [("gauss_seidel", 0), ("gauss_seidel", 1), ("gauss_seidel", 2)]),
    ("| `implicit`", ["2.00 (force linear over the step, whatever the predictor)"],
     [("implicit", 1)]),
]
TWO_MASS_CLAIMS = [(c, case) for prefix, cells, cases in TWO_MASS
                   for c, case in zip(row(V, prefix, cells, "tests/test_two_mass.py"), cases)]


@pytest.fixture(scope="module")
def two_mass_orders(tmp_path_factory):
    """The observed order of the global error over the four steps H (three halvings),
    as tests/test_two_mass.py measures it (the same scene and error norm)."""
    import test_two_mass as tm
    path = tmp_path_factory.mktemp("two_mass") / "two_mass.toml"
    v1, v2 = tm.STARTS["generic"]
    path.write_text(tm.SCENE.format(
        t_end=tm.T_END, m1=tm.MASSES[0], m2=tm.MASSES[1], k1=tm.GROUND_K[0], k2=tm.GROUND_K[1],
        kc=tm.COUPLING_K, preload=tm.PRELOAD, q1=tm.Q0[0], q2=tm.Q0[1], v1=v1, v2=v2))
    q_ex, dq_ex, _ = tm._exact("generic", tm.T_END)
    amp, _ = tm._vibration("generic")
    out = {}
    for _, _, cases in TWO_MASS:
        for scheme, order in cases:
            errs = []
            for H in tm.HS:
                ov = [f"scheme.macro_step={H}", f"scheme.extrapolation_order={order}",
                      "scheme.accept_unsafe_step=true"]
                ov += [f"subsystems.{s}.integrator.max_step={H / tm.SUB_STEPS}"
                       for s in ("left", "right")]
                res = simulate(load(path, None, ov, scheme))
                assert res.success, res.message
                fs = res.summary["final_state"]
                q = np.array([fs["left"]["x"]["q"], fs["right"]["x"]["q"]])
                dq = np.array([fs["left"]["x"]["dq"], fs["right"]["x"]["dq"]])
                errs.append(np.linalg.norm(np.concatenate([q - q_ex, (dq - dq_ex) / tm.W])) / amp)
            out[scheme, order] = float(np.polyfit(np.log(tm.HS), np.log(errs), 1)[0])
    return out


def test_the_two_mass_steps_the_page_names():
    """"four macro steps H from 5 ms to 0.625 ms (three halvings)": the steps
    tests/test_two_mass.py fits the orders over."""
    import test_two_mass as tm
    text = "fitted over four macro steps H from 5 ms to 0.625 ms (three halvings;"
    hs = np.asarray(tm.HS)
    for value, measured in ((4, len(hs)), (5e-3, hs[0]), (0.625e-3, hs[-1]),
                            (3, int(np.sum(np.isclose(hs[:-1] / hs[1:], 2.0, rtol=0,
                                                      atol=1e-12))))):
        claim = Claim(V, text, "pytest tests/test_two_mass.py", value, rel=1e-12)
        assert_printed(claim)
        assert_reproduced(claim, measured)


@pytest.mark.parametrize("claim,case", TWO_MASS_CLAIMS, ids=[c.id for c, _ in TWO_MASS_CLAIMS])
def test_two_mass_orders(two_mass_orders, claim, case):
    assert_reproduced(claim, two_mass_orders[case])


# ======================================================================
# sweeps.md: the two studies, for the scene and its moved copies
# ======================================================================
def _study_points(name):
    from cosim.studies.sweep import load_study
    st = load_study(ROOT / "studies" / f"{name}.toml")
    return st


@pytest.fixture(scope="module")
def studies():
    """Each study's records (``cosim.studies.sweep.sweep``, as `cosim sweep
    --study` runs them), for the scene and for each moved copy: the copy's
    initial state enters as one more key of the grid, with one value.  A
    study is swept when a test first asks for it (``studies[name]``), so
    that a worker of pytest-xdist given the tests of one study alone does
    not sweep the other."""
    return _Studies()


class _Studies(dict):
    def __missing__(self, name):
        self[name] = _study_records(name)
        return self[name]


def _study_records(name):
    """One study's records, for the scene and each moved copy."""
    from cosim.studies.sweep import sweep
    st = _study_points(name)
    base = load(st.scene, st.variants[0])
    copies = []
    for k in (0, 1, -1, 2, -2)[:COPIES]:
        grid = dict(st.grid)
        for o in (perturbed_overrides(base, k) if k else []):
            key, value = o.split("=", 1)
            grid[key] = [float(value)]
        rows = sweep(st.scene, variants=list(st.variants), grid=grid, workers=1,
                     contact="C", joint="robot/arm")
        assert all(r["status"] == "finished" for r in rows), rows
        copies.append(rows)
    return copies


def _by(rows, name):
    """fig8's rows by f (its x value), fig11's by variant."""
    if name == "fig8_stiffness":
        return {round(r["set.contacts.C.law.contact_stiffness"] / 1.6e5): r for r in rows}
    return {r["variant"]: r for r in rows}


def _iv(r):
    iv = r["contacts.C.intervals"]
    return json.loads(iv) if isinstance(iv, str) else iv


FIG8 = "cosim sweep --study fig8_stiffness"
FIG11 = "cosim sweep --study fig11_chain_mass"
FIG8_CLAIMS = [
    (claim(SW, "one long contact (19.8 and 17.5 ms)", FIG8, "19.8"),
     lambda p: 1e3 * p[1]["contacts.C.in_touch_time"]),
    (claim(SW, "one long contact (19.8 and 17.5 ms)", FIG8, "17.5"),
     lambda p: 1e3 * p[2]["contacts.C.in_touch_time"]),
    *[(claim(SW, "contacts begins: 4 at f = 3 and 4, 8 at f = 6 to 20, 9 at f = 40 and 100", FIG8,
             n), (lambda p, f=f: p[f]["contacts.C.count"]))
      for n, fs in (("4", (3, 4)), ("8", (6, 10, 20)), ("9", (40, 100))) for f in fs],
    (claim(SW, "(15 ms at f = 4, 2.7 ms at f = 100)", FIG8, "15"),
     lambda p: 1e3 * p[4]["contacts.C.in_touch_time"]),
    (claim(SW, "(15 ms at f = 4, 2.7 ms at f = 100)", FIG8, "2.7"),
     lambda p: 1e3 * p[100]["contacts.C.in_touch_time"]),
    (claim(SW, "stays between 15.2 and 21.7 ms", FIG8, "15.2"),
     lambda p: 1e3 * min(_iv(r)[-1][1] - _iv(r)[0][0] for r in p.values())),
    (claim(SW, "stays between 15.2 and 21.7 ms", FIG8, "21.7"),
     lambda p: 1e3 * max(_iv(r)[-1][1] - _iv(r)[0][0] for r in p.values())),
]
FIG11_CLAIMS = [
    (claim(SW, "One contact of 2.6-2.8 ms", FIG11, "2.6"),
     lambda p: 1e3 * p["ms3.2"]["contacts.C.in_touch_time"]),
    (claim(SW, "One contact of 2.6-2.8 ms", FIG11, "2.8"),
     lambda p: 1e3 * p["ms6.4"]["contacts.C.in_touch_time"]),
    (claim(SW, "the arm leaves at\n  9.05 and 5.10 rad/s", FIG11, "9.05"),
     lambda p: p["ms6.4"]["impact.rate_at_release"]),
    (claim(SW, "the arm leaves at\n  9.05 and 5.10 rad/s", FIG11, "5.10"),
     lambda p: p["ms3.2"]["impact.rate_at_release"]),
    *[(claim(SW, "against the −14.98 rad/s it came with", FIG11),
       (lambda p, v=v: p[v]["impact.rate_at_touch"])) for v in ("ms6.4", "ms3.2")],
    (claim(SW, "(+0.22 rad/s)", FIG11), lambda p: p["ms1.6"]["impact.rate_at_release"]),
    (claim(SW, "the top mass strikes it again 20 ms later", FIG11),
     lambda p: 1e3 * (_iv(p["ms1.6"])[1][0] - _iv(p["ms1.6"])[0][1])),
    (claim(SW, "coming at −4.7 rad/s (0.8 kg)", FIG11, "−4.7"),
     lambda p: p["ms0.8"]["impact.rate_at_release"]),
    (claim(SW, "−13.9 rad/s (0.05 kg)", FIG11, "−13.9"), lambda p: p["ms0.05"]["impact.rate_at_release"]),
    *[(claim(SW, "strikes 4, 5, 7, 11 and\n  13 times", FIG11, n),
       (lambda p, v=v: p[v]["contacts.C.count"]))
      for n, v in (("4", "ms0.8"), ("5", "ms0.4"), ("7", "ms0.2"), ("11", "ms0.1"), ("13", "ms0.05"))],
]
FIG11_REGIMES = {"ms6.4": "backward", "ms3.2": "backward", "ms1.6": "backward+",
                 **{f"ms{m}": "forward" for m in ("0.8", "0.4", "0.2", "0.1", "0.05")}}


@pytest.mark.parametrize("claim,get", FIG8_CLAIMS, ids=[c.id for c, _ in FIG8_CLAIMS])
def test_fig8(studies, claim, get):
    for rows in studies["fig8_stiffness"]:
        assert_reproduced(claim, get(_by(rows, "fig8_stiffness")))


@pytest.mark.parametrize("claim,get", FIG11_CLAIMS, ids=[c.id for c, _ in FIG11_CLAIMS])
def test_fig11(studies, claim, get):
    for rows in studies["fig11_chain_mass"]:
        assert_reproduced(claim, get(_by(rows, "fig11_chain_mass")))


def test_fig11_regimes(studies):
    for text in ("6.4 and 3.2 kg: **backward**", "1.6 kg: **backward+**",
                 "0.8 kg and below: **forward**"):
        assert_printed(Claim(SW, text, FIG11, 0.0))
    for rows in studies["fig11_chain_mass"]:
        assert {v: r["impact.regime"] for v, r in _by(rows, "fig11_chain_mass").items()} \
            == FIG11_REGIMES


_PLACEMENT_CMD = "cosim sweep cases/three_mass.toml --variants f100 --set ... --out runs/placement"
PLACEMENT = (claim(SW, "the sweep ends with `3 of 4 point(s) finished` and exit\nstatus 1",
                   _PLACEMENT_CMD, "1"),
             claim(SW, "the sweep ends with `3 of 4 point(s) finished`", _PLACEMENT_CMD, "3"),
             claim(SW, "largest safe step, 2.87e-05 s", _PLACEMENT_CMD))


def test_placement_sweep_ends_with_its_refused_point(tmp_path):
    """The page's second command: three points finish and the coupler point
    at 1.6e6 N/m is refused by the pre-flight check (exit status 1), for the
    scene and its moved copies (their initial state as one more `--set`)."""
    from roundoff import cli_copies
    c, n, safe = PLACEMENT
    for i, extra in enumerate(cli_copies(load(THREE_MASS, "f100"))):
        p = subprocess.run(
            [sys.executable, "-m", "cosim.cli", "sweep", str(THREE_MASS), "--variants", "f100",
             "--set", "contacts.C.law.contact_stiffness=1.6e5,1.6e6",
             "--set", 'contacts.C.placement="embedded","coupler"', *extra,
             "--workers", "1", "--no-plot", "--quiet", "--out", str(tmp_path / f"s{i}")],
            capture_output=True, text=True, timeout=300)
        assert_reproduced(c, p.returncode)
        done = re.search(r"(\d+) of 4 point\(s\) finished", p.stdout)
        assert done, p.stdout
        assert_reproduced(n, int(done[1]))
        msg = re.search(r"largest safe macro step is ([0-9.e+-]+) s", p.stdout)
        assert msg, p.stdout
        assert_reproduced(safe, float(msg[1]))


SWEEP_EXIT = (claim(SW, "The exit status is 0 when every point finished", "cosim sweep ..."),
              claim(SW, "and 2 for a malformed command", "cosim sweep ... --scheduler foo"))


def test_sweep_exit_status_when_every_point_finished_or_the_command_is_malformed(tmp_path):
    """"The exit status is 0 when every point finished, 1 when some did not
    ..., and 2 for a malformed command" (1: the placement sweep above)."""
    ok, bad = SWEEP_EXIT
    base = [sys.executable, "-m", "cosim.cli", "sweep", str(THREE_MASS), "--variants", "f100",
            "--workers", "1", "--no-plot", "--quiet"]
    p = subprocess.run(base + ["--out", str(tmp_path / "ok")], capture_output=True, text=True,
                       timeout=300)
    assert_reproduced(ok, p.returncode)
    p = subprocess.run(base + ["--scheduler", "foo", "--out", str(tmp_path / "bad")],
                       capture_output=True, text=True, timeout=300)
    assert_reproduced(bad, p.returncode)
    assert not (tmp_path / "bad").exists()


# ======================================================================
# schemes.md: IQN-ILS, step control, multirate
# ======================================================================
IQN = [
    (claim(SC, "it took 160 iterations for 40 steps", "pytest tests/test_iqn_ils.py", "160"), "iqn_ils", 0),
    (claim(SC, "where Aitken took 268", "pytest tests/test_iqn_ils.py"), "aitken", 0),
    (claim(SC, "and 90 with `reuse = 2`", "pytest tests/test_iqn_ils.py", "90"), "iqn_ils", 2),
]


@pytest.mark.parametrize("claim,acceleration,reuse", IQN, ids=[c.id for c, _, _ in IQN])
def test_iqn_ils_iterations(tmp_path, claim, acceleration, reuse):
    """The bar pressed on two sprung feet of tests/test_iqn_ils.py, 40 steps;
    the iteration counts for the scene and its moved copies."""
    from test_iqn_ils import PRESSED
    path = tmp_path / "press.toml"
    path.write_text(PRESSED)
    ov = [f'scheme.acceleration="{acceleration}"', "scheme.tolerance=1e-8"]
    if acceleration == "iqn_ils":
        ov.append(f"scheme.reuse={reuse}")
    for scene in moved(load(path, None, ov, "implicit"), COPIES):
        res = simulate(scene)
        assert res.success and res.n_windows == 40, res.message
        assert_reproduced(claim, res.n_iterations)


SIXTH = Claim(SC, "with a sixth of\nthe windows", "tests/test_step_control.py", 6.0, abs=0.5)


def test_step_control_takes_a_sixth_of_the_windows():
    """schemes.md: on a coupler-placed spring_drop, step control (1 ms free,
    12.5 µs in contact) "reproduces uniform contact-sized steps, with a
    sixth of the windows" (measured 270 against 1600: 1/5.9)."""
    c = SIXTH
    base = ['contacts.wall.placement="coupler"', "scheme.accept_unsafe_step=true",
            "guard.energy_check=false"]
    fine = simulate(load(CASES / "spring_drop.toml", None, base + ["scheme.macro_step=1.25e-5"],
                         "gauss_seidel"))
    ctrl = simulate(load(CASES / "spring_drop.toml", None,
                         base + ["scheme.macro_step=1e-3", "scheme.contact_step=1.25e-5"],
                         "gauss_seidel"))
    assert ctrl.summary["final_state"]["body"]["x"]["dq"] == pytest.approx(
        fine.summary["final_state"]["body"]["x"]["dq"], rel=1e-9)
    assert_reproduced(c, fine.n_windows / ctrl.n_windows)


MULTIRATE = [
    (claim(SC, "exit-speed error 5.0 times under Gauss-Seidel with the heavy side first",
           "tests/test_multirate.py"), '["heavy", "light"]'),
    (claim(SC, "6.0 times with the\nlight side first", "tests/test_multirate.py"),
     '["light", "heavy"]'),
]


@pytest.mark.parametrize("claim,sequence", MULTIRATE, ids=[c.id for c, _ in MULTIRATE])
def test_multirate_cuts_the_light_sides_error(tmp_path, claim, sequence):
    from test_multirate import EXACT, run
    from test_hosted_contacts import velocities
    one = run(tmp_path, f"scheme.sequence={sequence}", scheme="gauss_seidel")
    four = run(tmp_path, f"scheme.sequence={sequence}", "scheme.substeps={light = 4}",
               scheme="gauss_seidel")
    assert_reproduced(claim, abs(velocities(one)[1] - EXACT) / abs(velocities(four)[1] - EXACT))


# ======================================================================
# verification.md: the hard-case matrix, and growth without the guard
# ======================================================================
# (variant, scheme, placement) -> (step at 1 x ref, cells at 0.5, 1, 2, 5, 10 x ref);
# a cell is B value, B lo–hi (varies with round-off: the range over the copies),
# R (forced cell) or S
MATRIX = {
    ("f1000", "jacobi", "embedded"): ("9.43e-06 s", ["B 0.076", "B 0.35", "B 1.8", "S", "S"]),
    ("f1000", "jacobi", "coupler"): ("2.86e-06 s", ["B 0.00029", "B 0.0023", "R (B 0.019)", "R (B 0.29)", "R (S)"]),
    ("f1000", "gauss_seidel", "embedded"): ("9.43e-06 s", ["B 0", "B 0", "B 0", "B 0.27", "S"]),
    ("f1000", "gauss_seidel", "coupler"): ("2.86e-06 s", ["B 0.01", "B 0.043", "R (B 0.18)", "R (B 1.8)", "R (S)"]),
    ("f1000", "implicit", "embedded"): ("9.43e-06 s", ["B 3.7e-07", "B 1.2e-05", "B 0.00012", "B 0.013", "B 0"]),
    ("f1000", "implicit", "coupler"): ("9.43e-06 s", ["B 0.098", "B 0.23", "B 0.67", "S", "S"]),
    ("ms0.01", "jacobi", "embedded"): ("7.81e-06 s", ["B 0.02", "B 0.09", "B 0.41", "B 3", "S"]),
    ("ms0.01", "jacobi", "coupler"): ("2.36e-06 s", ["B 1.2e-05", "B 0.00013", "R (B 0.0011)", "R (B 0.066)", "R (S)"]),
    ("ms0.01", "gauss_seidel", "embedded"): ("7.81e-06 s", ["B 0", "B 0", "B 0", "B 0.031", "B 1.1"]),
    ("ms0.01", "gauss_seidel", "coupler"): ("2.36e-06 s", ["B 0.058", "B 0.0057", "R (B 0.028)", "R (B 0.13)", "R (S)"]),
    ("ms0.01", "implicit", "embedded"): ("7.81e-06 s", ["B 0", "B 1.4e-06", "B 2.2e-05", "B 0.002", "B 0.035"]),
    ("ms0.01", "implicit", "coupler"): ("7.81e-06 s", ["B 0.00066", "B 0.015", "B 0.33", "S", "S"]),
}
MONOLITHIC_ROWS = {(v, p): claim(V, f"| `{v}` | `monolithic` | {p} | – | B < 1e-07 (no macro step) "
                                    "| | | | |", "cosim verify --hard", "1e-07")
                   for v in ("f1000", "ms0.01") for p in ("embedded", "coupler")}


def _matrix_text(key):
    (v, s, p), (step, cells) = key, MATRIX[key]
    return f"| `{v}` | `{s}` | {p} | {step} | " + " | ".join(cells) + " |"


def _judge(cell: str, runs: list[dict]) -> None:
    """A printed cell against the runs of its point (plain, then forced)."""
    forced = cell.startswith("R (")
    if forced:
        assert all(r["outcome"] == "refused" for r in runs[0]), cell
        inner, got = cell[3:-1], runs[1]
    else:
        inner, got = cell, runs[0]
    outcome = {"B": "bounded", "S": "stopped"}[inner[0]]
    assert all(r["outcome"] == outcome and r["ok"] for r in got), (cell, got)
    if inner == "B 0":      # the energy never rose above its initial value
        assert all(r["created"] <= 0.0 for r in got), (cell, got)
    elif outcome == "bounded":
        lo_hi = inner[2:].split("–")
        (lo, h_lo), (hi, h_hi) = number(lo_hi[0]), number(lo_hi[-1])
        for r in got:       # every copy within the printed value or range
            assert lo - h_lo <= r["created"] <= hi + h_hi, (cell, [x["created"] for x in got])


def _hard_runs(keys, copies):
    """{(variant, scheme, placement, factor): [plain runs, forced runs]} over
    the scene and its moved copies."""
    from cosim.studies.verify import HardCase, hard_matrix, run_hard_case
    cases = [c for c in hard_matrix(CASES) if (c.variant, c.scheme, c.placement) in keys]
    out = {}
    for case in cases:
        runs = []
        for k in (0, 1, -1, 2, -2, 3, -3)[:copies]:
            extra = perturbed_overrides(load(THREE_MASS, case.variant), k) if k else []

            class Moved(HardCase):     # the case's overrides plus the copy's initial state
                def overrides(self, t_end=None, _extra=tuple(extra)):
                    return super().overrides(t_end) + list(_extra)
            moved = Moved(case.variant, case.scheme, case.placement, case.step, case.factor,
                          case.forced)
            runs.append(run_hard_case(moved, CASES))
        slot = out.setdefault((case.variant, case.scheme, case.placement, case.factor), [[], []])
        slot[int(case.forced)] = runs
    return out


#: each row of the matrix as printed; its number is the step at 1 x ref
MATRIX_ROWS = {key: claim(V, _matrix_text(key), "cosim verify --hard", step.split()[0])
               for key, (step, _) in MATRIX.items()}
MATRIX_BOUND_CHECKS = (claim(V, "of a 4.51 J bound", "cosim verify --hard"),
                       claim(V, "All 88 checks passed", "cosim verify --hard"))


def test_hard_matrix_reference_steps_bound_and_checks():
    """The matrix's cheap numbers: its reference step per row (the printed
    step at 1 x ref), the 4.51 J bound, and the 88 checks of `cosim verify
    --hard` (the spring_drop checks and the matrix's points)."""
    from cosim.studies.verify import CHECKS, hard_matrix, reference_step, run_hard_case
    for key, c in MATRIX_ROWS.items():
        ref = reference_step(CASES, *key)
        assert_reproduced(c, float(f"{ref * (1 - 5e-3):.3g}"))
    bound, checks = MATRIX_BOUND_CHECKS
    r = run_hard_case(hard_matrix(CASES, factors=(1.0,), variants=("f1000",),
                                  schemes=("implicit",), placements=("embedded",))[0], CASES)
    assert_reproduced(bound, r["bound"])
    n_spring = sum(len(fn(CASES)) for fn in CHECKS.values())
    assert_reproduced(checks, n_spring + len(hard_matrix(CASES)))


@pytest.mark.parametrize("key", [k for k in MATRIX if k[0] == "f1000"],
                         ids=lambda k: "/".join(k))
def test_hard_matrix_f1000_rows(key):
    """The f1000 rows for the scene as shipped (about 8 s of CPU in all);
    ``test_hard_matrix_survives_round_off`` (slow) runs every row, the
    monolithic reference and ms0.01 included, for the scene and four moved
    copies."""
    runs = _hard_runs({key}, 1)
    for fac, cell in zip((0.5, 1.0, 2.0, 5.0, 10.0), MATRIX[key][1]):
        _judge(cell, runs[(*key, fac)])


@pytest.mark.slow
def test_hard_matrix_survives_round_off():
    """Every cell of the matrix, the monolithic rows included, for the scene
    and four moved copies (about 5 min of CPU): the outcome is the same in
    all, and each bounded run's created energy lies within the printed value
    or, where the copies disagree (ms0.01 with C exchanged), the printed
    range.  Then the page's summary of the largest bounded steps.  The fast
    tests above cover the steps, the bound and the f1000 rows."""
    runs = _hard_runs(set(MATRIX) | {(v, "monolithic", p) for v in ("f1000", "ms0.01")
                                     for p in ("embedded", "coupler")}, COPIES)
    for key, (_, cells) in MATRIX.items():
        for fac, cell in zip((0.5, 1.0, 2.0, 5.0, 10.0), cells):
            _judge(cell, runs[(*key, fac)])
    for v in ("f1000", "ms0.01"):
        for p in ("embedded", "coupler"):
            bound = MONOLITHIC_ROWS[v, p].value      # a bound: round-off of the reference
            got = runs[(v, "monolithic", p, None)][0]
            assert all(r["outcome"] == "bounded" and r["created"] < bound for r in got), got

    def largest(v, s, p):
        ok = [f for f in (0.5, 1.0, 2.0, 5.0, 10.0)
              if all(r["outcome"] == "bounded" for r in runs[(v, s, p, f)][0])]
        return max(ok)

    def largest_forced(v, s):
        return max(f for f in (2.0, 5.0, 10.0)
                   if all(r["outcome"] == "bounded" for r in runs[(v, s, "coupler", f)][1]))
    assert (largest("f1000", "jacobi", "embedded"), largest("ms0.01", "jacobi", "embedded")) == (2, 5)
    assert (largest("f1000", "gauss_seidel", "embedded"),
            largest("ms0.01", "gauss_seidel", "embedded")) == (5, 10)
    assert largest("f1000", "implicit", "embedded") == largest("ms0.01", "implicit", "embedded") == 10
    for v in ("f1000", "ms0.01"):
        for s in ("jacobi", "gauss_seidel"):
            assert largest(v, s, "coupler") == 1
            assert largest_forced(v, s) == 5
    assert (largest("f1000", "implicit", "coupler"), largest("ms0.01", "implicit", "coupler")) == (2, 2)


GROWTH = [
    (claim(V, "Jacobi at\n  100 µs in contact gains 245 J on f1000",
           "cosim run cases/three_mass.toml --variant f1000 --scheme jacobi --set "
           "scheme.contact_step=1e-4 --set guard.energy_check=false", "245", abs_=0.5),
     "jacobi", "1e-4"),
    (claim(V, "and at 1 ms more than 1e90 J", "... --scheme jacobi --set scheme.contact_step=1e-3 ...",
           "1e90"),                        # a lower bound: it diverges
     "jacobi", "1e-3"),
    (claim(V, "Gauss-Seidel at 100 µs\n  gains 19 J",
           "... --scheme gauss_seidel --set scheme.contact_step=1e-4 ...", abs_=0.5),
     "gauss_seidel", "1e-4"),
]


GROWTH_OF = claim(V, "gains 245 J on f1000 (of 45 J)", GROWTH[0][0].command, "45")


@pytest.mark.parametrize("claim,scheme,step", GROWTH, ids=[c.id for c, _, _ in GROWTH])
def test_growth_without_the_guard(claim, scheme, step):
    """The energy created (the summary's largest drift; nothing dissipates)
    for the scene and its moved copies; the "(of 45 J)" is the initial energy."""
    claim_of = GROWTH_OF
    scene = load(THREE_MASS, "f1000", [f"scheme.contact_step={step}", "guard.energy_check=false"],
                 scheme)
    for s in moved(scene, COPIES):
        res = simulate(s)
        assert res.success, res.message
        e = res.summary["energy"]
        assert e["dissipated"] == 0.0
        if claim.printed.startswith("and at 1 ms more than"):     # a bound: it diverges
            assert e["max_abs_drift"] > claim.value, e
        else:
            assert_reproduced(claim, e["max_abs_drift"])
        assert_reproduced(claim_of, e["initial"])


# ======================================================================
# troubleshooting.md
# ======================================================================
_DRIFT_CMD = ("cosim run cases/three_mass.toml --variant f1000 --scheme jacobi --set "
              "scheme.contact_step=2.5e-5")
DRIFTING = (claim(TR, "creates 3.4 J of 45.1 J and warns twice", _DRIFT_CMD, "3.4"),
            claim(TR, "creates 3.4 J of 45.1 J and warns twice", _DRIFT_CMD, "45.1"))


def test_a_drifting_run_warns_twice():
    """"creates 3.4 J of 45.1 J and warns twice", for the scene and its
    moved copies."""
    created, scale = DRIFTING
    for s in moved(load(THREE_MASS, "f1000", ["scheme.contact_step=2.5e-5"], scheme="jacobi"),
                   COPIES):
        res = simulate(s)
        assert res.status == "finished"
        assert_reproduced(created, res.summary["energy"]["max_abs_drift"])
        assert_reproduced(scale, res.summary["energy"]["initial"])
        assert [w["kind"] for w in res.summary["warnings"]] == ["energy", "coupling_error"]


GUARD_CMD = ("cosim run cases/three_mass.toml --variant f1000 --scheme jacobi --set "
             "scheme.contact_step=1e-3")
GUARD = [
    claim(TR, "run stopped at t = 0.103 s", GUARD_CMD),
    claim(TR, "the guard tripped at t = 0.104 s", GUARD_CMD),
    claim(TR, "the energy grew by 10.71 J", GUARD_CMD),
    claim(TR, "(bound 4.511 J", GUARD_CMD),
    claim(TR, "of the energy scale 45.11 J", GUARD_CMD),
    claim(TR, "created 10.71 J of it", GUARD_CMD),
]
_GUARD_RE = [r"run stopped at t = ([0-9.e+-]+) s", r"the guard tripped at t = ([0-9.e+-]+) s",
             r"the energy grew by ([0-9.e+-]+) J",
             r"\(bound ([0-9.e+-]+) J", r"of the energy scale ([0-9.e+-]+) J",
             r"created ([0-9.e+-]+) J of it"]


GUARD_CONTACT_TIME = claim(TR, "(1 ms steps in contact, against C's contact time of 92 µs "
                               "at its first touch)", "cosim info cases/three_mass.toml --variant f1000 --json")


def test_the_guards_example_message(tmp_path):
    """The command prints the message the page shows and exits 1; its moved
    copies stop with the same numbers."""
    tc = GUARD_CONTACT_TIME
    info = subprocess.run([sys.executable, "-m", "cosim.cli", "info", str(THREE_MASS), "--variant",
                           "f1000", "--json"], capture_output=True, text=True, timeout=120)
    assert_reproduced(tc, 1e6 * json.loads(info.stdout)["contacts"]["C"]["contact_time_s"])
    p = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(THREE_MASS), "--variant",
                        "f1000", "--scheme", "jacobi", "--set", "scheme.contact_step=1e-3",
                        "--quiet", "--out", str(tmp_path / "run")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 1, p.stderr
    out = " ".join((p.stdout + p.stderr).split())
    for c, pattern in zip(GUARD, _GUARD_RE):
        assert_reproduced(c, float(re.search(pattern, out)[1]))
    for s in moved(load(THREE_MASS, "f1000", ["scheme.contact_step=1e-3"], "jacobi"),
                    COPIES)[1:]:
        res = simulate(s)
        assert res.status == "failed" and "contact `C`" in res.message
        for c, pattern in zip(GUARD, _GUARD_RE):
            assert_reproduced(c, float(re.search(pattern, res.message)[1]))


_SAMPLING_CMD = "cosim info cases/three_mass.toml --set contacts.C.law.contact_stiffness=1e11"
SAMPLING = (claim(TR, "C closes for 3.68e-06 s", _SAMPLING_CMD),
            claim(TR, "between samples 3e-05 s apart", _SAMPLING_CMD),
            claim(TR, "0.123 samples per contact", _SAMPLING_CMD),
            claim(CM, "with a `sampling_note` naming the key to change when that is fewer than 4",
                  "cosim info SCENE --json"))


def test_the_sampling_note():
    """`cosim info` with C's spring at 1e11 N/m: the contact time, the
    sampling interval and the samples per contact the page quotes, and the
    note itself (exit 0)."""
    tc, dt, n, four = SAMPLING
    p = subprocess.run([sys.executable, "-m", "cosim.cli", "info", str(THREE_MASS), "--set",
                        "contacts.C.law.contact_stiffness=1e11", "--json"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    info = json.loads(p.stdout)["contacts"]["C"]
    assert_reproduced(tc, info["contact_time_s"])
    assert_reproduced(dt, info["sampling_interval_s"])
    assert_reproduced(n, info["samples_per_contact"])
    assert "too coarse to draw it" in info["sampling_note"]
    assert "`scheme.contact_step`" in info["sampling_note"]
    # commands.md: the note comes "when that is fewer than 4"
    from cosim.scene.info import SAMPLES_TO_DRAW
    assert_reproduced(four, SAMPLES_TO_DRAW)
    # every contact of f100, from the function `cosim info` prints, without
    # the runs that confirm the explicit schemes' steps: they set
    # max_macro_step_* alone, not the sampling, and took most of the time
    from cosim.scene.info import scene_info
    info = scene_info(load(THREE_MASS, "f100"), confirm_steps=0)
    for c in info["contacts"].values():     # A, B: 2.4, 2.9; C: 10
        assert bool(c.get("sampling_note")) == (c["samples_per_contact"] < 4), c


GUARD_DEFAULTS = [(claim(TR, f"| `{key}` | {text} |", f"cosim.load_scene(...).guard.{key}",
                         text.split()[0]), key)
                  for key, text in (("energy_growth", "0.1"), ("energy_floor", "1e-3 J"),
                                    ("energy_warning", "0.01"), ("coupling_warning", "0.01"))]
LIMITS = [
    (claim(TR, "more than 20 000 elements", "cosim.scene.load.MAX_ELEMENTS", "20"),
     lambda loader, tomlread: loader.MAX_ELEMENTS / 1000),
    (claim(TR, "more than 1e9 integrator steps before it starts", "cosim.scene.load.MAX_STEPS"),
     lambda loader, tomlread: loader.MAX_STEPS),
    (claim(TR, "| `max_steps` | 1e9 |", "cosim.scene.load.MAX_STEPS"),
     lambda loader, tomlread: loader.MAX_STEPS),
    (claim(TR, "A count above 1e8 runs", "cosim.scene.work.WARN_STEPS"),
     lambda loader, tomlread: _work().WARN_STEPS),
    (claim(TR, "`interface_tolerance` below 2.22e-16",
           "cosim.core.schemes.base.MIN_RELATIVE_TOLERANCE", "2.22e-16"),
     lambda loader, tomlread: _schemes_base().MIN_RELATIVE_TOLERANCE),
    *[(claim(TR, "(2.51, 3.31, 6.39)", "cosim.core.preflight.EXPLICIT_STABILITY", text),
       lambda loader, tomlread, m=method: _preflight().EXPLICIT_STABILITY[m])
      for method, text in (("RK23", "2.51"), ("RK45", "3.31"), ("DOP853", "6.39"))],
    (claim(TR, "estimated memory passes 4 GiB", "cosim.scene.load.MAX_MEMORY"),
     lambda loader, tomlread: loader.MAX_MEMORY / 2**30),
    (claim(TR, "`must hold at most 67108864 bytes`", "cosim.io.tomlread.MAX_BYTES"),
     lambda loader, tomlread: tomlread.MAX_BYTES),
    (claim(TR, "`must nest at most 32 levels", "cosim.io.tomlread.MAX_DEPTH"),
     lambda loader, tomlread: tomlread.MAX_DEPTH),
    (claim(TR, "`must hold at most 10000 keys", "cosim.io.tomlread.MAX_KEYS"),
     lambda loader, tomlread: tomlread.MAX_KEYS),
]


def _work():
    from cosim.scene import work
    return work


def _schemes_base():
    from cosim.core.schemes import base
    return base


def _preflight():
    from cosim.core import preflight
    return preflight


def test_the_guards_defaults_and_the_loaders_limits():
    """The defaults a loaded scene's guard gets (`cosim.load_scene`), and the
    limits the page quotes by name."""
    from cosim.io import tomlread
    from cosim.scene import load as loader
    g = load(CASES / "spring_drop.toml").guard
    for c, key in GUARD_DEFAULTS:
        assert_reproduced(c, getattr(g, key))
    for c, value in LIMITS:
        assert_reproduced(c, value(loader, tomlread))


CONNECT = claim(TR, "does not answer within 10 s", "cosim sweep --scheduler tcp://...")


def test_the_scheduler_connect_timeout():
    from cosim.studies.sweep import CONNECT_TIMEOUT_S
    assert_reproduced(CONNECT, CONNECT_TIMEOUT_S)


# ======================================================================
# commands.md: the summary's keys and the located peak
# ======================================================================
def _section(page: str, start: str, end: str) -> str:
    text = (ROOT / page).read_text(encoding="utf-8")
    return text[text.index(start):text.index(end)]


def test_the_summary_keys_are_the_pages(tmp_path):
    """Every key the page lists is in a real summary.json (a run with a
    connection and a rigid impact is not needed: the keys are always there),
    and every key there is on the page."""
    res = simulate(load(THREE_MASS, "f100"))        # `accuracy` has its own paragraph
    cosim.write_outputs(res, tmp_path / "run", load(THREE_MASS, "f100"))
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    text = _section(CM, "`summary.json` has", "`accuracy` (left out")
    named = set(re.findall(r"(?<!\})`([a-z_]+)`", text))      # not a {doc}`page`
    if "`final_state.SUBSYSTEM.JOINT.{q,dq}`" in text:
        named.add("final_state")
    if "`contacts.NAME`" in text:
        named.add("contacts")
    top = set(s) | set(s["energy"]) | set(s["contacts"]["C"])
    # the names the paragraph gives beside the keys: a warning's fields and the plausibility
    # kinds (each a `_warning("KIND", ...)` of cosim.scene.plausible), and the strict JSON's
    # note of a value not finite, written as null
    from pathlib import Path

    from cosim.io.strict_json import NOTE_KEY
    from cosim.scene import plausible
    kinds = set(re.findall(r'_warning\(\s*"([a-z_]+)"', Path(plausible.__file__).read_text()))
    assert kinds == {"static_deflection", "frequency", "section", "contact_gap"}, kinds
    named -= kinds | {"kind", "key", NOTE_KEY, "null"}
    assert top <= named, f"not on the page: {sorted(top - named)}"
    assert named <= top, f"on the page, not in summary.json: {sorted(named - top)}"
    assert "`contacts.NAME`" in text and "`final_state.SUBSYSTEM.JOINT.{q,dq}`" in text
    joint = s["final_state"]["robot"]["arm"]
    assert set(joint) == {"q", "dq"}
    series = _section(CM, "`series.npz` holds", "A contact's `peak_penetration`")
    kinds = {re.sub(r"/.*", "/", k) if "/" in k and not k.startswith("energy/") else k
             for k in res.series}
    listed = {re.sub(r"/.*", "/", k) if "/" in k and not k.startswith("energy/") else k
              for k in re.findall(r"`([a-z]+(?:/[A-Za-z/]+)?)`", series)}
    assert kinds == listed, (sorted(kinds), sorted(listed))


def test_the_accuracy_keys_are_on_the_page():
    """Every key of a run's error estimate (summary key `accuracy`, which
    `cosim run` adds) is named in the page's paragraph on it."""
    from cosim.studies.estimate import estimate_errors
    scene = load(THREE_MASS, "f10")             # a companion runs (f100's C lies past 0.4)
    acc = estimate_errors(scene, simulate(scene))
    text = _section(CM, "`accuracy` (left out", "`series.npz` holds")
    named = set(re.findall(r"`([a-z_]+)[`.]", text))             # `contacts.NAME` too
    keys = set(acc) | set(acc["companion"]) | set(acc["work_share"]) | set(acc["exit"])
    keys |= set(acc["order"]) | set(acc["order_prior"]) | set(acc["companions"][0])
    keys |= {k for e in acc["exit"].values() if isinstance(e, dict) for k in e}
    keys |= set(acc["contacts"]["C"]) | set(acc["contacts"]["C"]["count"])
    keys |= set(acc["contacts"]["C"]["peak_penetration"])
    keys = {k for k in keys if "/" not in k}                 # SUBSYSTEM/JOINT, not a key
    assert keys <= named, f"not on the page: {sorted(keys - named)}"


LOCATED_PEAK = Claim(CM, "spring_drop at macro steps from\n0.1 ms to 5 ms gives v0 sqrt(m/k) to 1e-6",
                     "cosim run cases/spring_drop.toml --set scheme.macro_step=H", 1e-3, rel=1e-6)


@pytest.mark.parametrize("macro_step", [1e-4, 2e-3, 5e-3])
def test_the_located_peak_at_any_macro_step(macro_step):
    """"spring_drop at macro steps from 0.1 ms to 5 ms gives v0 sqrt(m/k) to
    1e-6" (a bound, relative; v0 = 1 m/s, m = 1 kg, k = 1e6 N/m)."""
    c = LOCATED_PEAK
    res = simulate(load(CASES / "spring_drop.toml", None, [f"scheme.macro_step={macro_step}"]))
    assert_reproduced(c, res.summary["contacts"]["wall"]["peak_penetration"])


# ======================================================================
def _every_claim() -> list[Claim]:
    """Every claim of this module: those in its upper-case tables (lists,
    tuples and dicts, nested), once each."""
    seen: dict = {}

    def walk(x):
        if isinstance(x, Claim):
            seen.setdefault((x.page, x.printed, x.value), x)
        elif isinstance(x, (list, tuple)):
            for y in x:
                walk(y)
        elif isinstance(x, dict):
            for y in x.values():
                walk(y)
    for name, value in list(globals().items()):
        if name.isupper():
            walk(value)
    return list(seen.values())


ALL = _every_claim()


@pytest.mark.parametrize("claim", ALL, ids=[c.id for c in ALL])
def test_printed(claim):
    assert_printed(claim)
