"""The numbers of docs/performance.md that a command produces now.

Each is a :class:`documented.Claim`: the text as the page prints it, the
command, the value; the test runs the command (or the part of it that gives
the number) and compares.  Timings, CPU shares and peak memory are not here:
each table of them is one published run, held to that run's files in
``tests/test_performance_runs.py``.  The work-precision study's numbers are
in ``tests/test_work_precision_doc.py``.

Counts (macro steps, iterations, contacts, steps) are discrete outcomes: they
are asserted for the scene and for copies moved by round-off
(``tests/roundoff.py``).
"""
from __future__ import annotations

import importlib.util
import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from documented import ROOT, Claim, assert_printed, assert_reproduced
from roundoff import outcomes

import cosim
from cosim.cli import main
from cosim.scene.load import load_scene

PAGE = "docs/performance.md"
CASES = ROOT / "cases"


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(name, mod)          # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _quiet_scene(path, variant=None, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(path, variant, list(overrides))


def _robust(scene, outcome):
    """``outcome`` of the scene, asserted equal on its four round-off copies."""
    seen = outcomes(scene, outcome)
    assert all(o == seen[0] for o in seen), f"not robust to round-off: {seen}"
    return seen[0]


# --- three_mass f100, the default run ---------------------------------------------------------

THREE_MASS_RUN = "cosim run cases/three_mass.toml --variant f100"


def test_the_default_three_mass_run_takes_268_macro_steps_and_the_chain_279(monkeypatch):
    """The work-precision section and the peers table: 268 macro steps, the
    chain's 279 steps (``_step_impl`` of the structure, counted: in the
    Python loop, which calls it; the compiled loop takes the same steps,
    tests/test_driver.py), 9 contacts of C; on the scene and its round-off
    copies."""
    from cosim.sides.fem import StructureSubsystem
    monkeypatch.setenv("COSIM_DRIVER", "python")
    steps = [0]
    real = StructureSubsystem._step_impl

    def counted(self, *a, **k):
        steps[0] += 1
        return real(self, *a, **k)

    def outcome(res):
        n, steps[0] = steps[0], 0
        return res.summary["macro_steps"], n, res.summary["contacts"]["C"]["count"]
    StructureSubsystem._step_impl = counted
    try:
        macro, chain, count = _robust(_quiet_scene(CASES / "three_mass.toml", "f100"), outcome)
    finally:
        StructureSubsystem._step_impl = real
    for claim, value in ((Claim(PAGE, "The default run (`gauss_seidel` at 30 µs) takes 268 macro "
                                      "steps", THREE_MASS_RUN, 268), macro),
                         (Claim(PAGE, "and the chain 279 steps of its own (C's 9 contacts)",
                                THREE_MASS_RUN, 279), chain),
                         (Claim(PAGE, "and the chain 279 steps of its own (C's 9 contacts)",
                                THREE_MASS_RUN, 9), count),
                         (Claim(PAGE, "| 268 | 9 |", THREE_MASS_RUN, 9), count)):
        assert_printed(claim)
        assert_reproduced(claim, value)


def test_the_peers_cosim_row_errors(tmp_path):
    """The peers table's `cosim run` row: C's peak at the samples and
    interpolated, the exit velocity, against the bench's reference (the
    published one: its own round-off spread is 1e-12, far below the
    printed 0.01 %)."""
    peers = _module("peers_run", ROOT / "benchmarks" / "peers" / "run.py")
    ref = json.loads((ROOT / "benchmarks" / "results" / "work_precision_three_mass_f100"
                      / "reference.json").read_text())
    assert main(["run", str(CASES / "three_mass.toml"), "--variant", "f100", "--quiet",
                 "--out", str(tmp_path / "run")]) == 0
    err = peers.errors(peers.run_dir_metrics(tmp_path / "run"), ref)
    half = 0.005e-2                      # half a unit of the printed 0.01 %
    row = "| 268 | 9 | 0.42 % / 0.12 % | 0.20 % | yes |"
    for value, measured in ((0.42e-2, err["err_peak_steps"]), (0.12e-2, err["err_peak_interp"]),
                            (0.20e-2, err["err_exit_velocity"])):
        claim = Claim(PAGE, row, "python benchmarks/peers/run.py --peers cosim", value, abs=half)
        assert_printed(claim)
        assert_reproduced(claim, measured)
    assert err["meets_1pc"] and err["err_count"] == 0


def test_the_quick_peers_window_holds_cs_first_two_contacts():
    """`--quick` "ends every run at 0.106 s (C's first two contacts)": C has
    closed and opened twice by then, on the scene and its copies."""
    claim = Claim(PAGE, "`--quick` ends every run at 0.106 s (C's first two contacts)",
                  "python benchmarks/peers/run.py --quick", 2)
    assert_printed(claim)
    scene = _quiet_scene(CASES / "three_mass.toml", "f100", ["t_end=0.106"])
    c = _robust(scene, lambda r: (r.summary["contacts"]["C"]["count"],
                                  r.summary["contacts"]["C"]["intervals"][-1][1] < 0.106))
    assert c == (2, True)
    assert_reproduced(claim, c[0])


@pytest.mark.slow
def test_the_peers_paper_row_errors(tmp_path):
    """The peers table's paper row: the bench's `paper_rk45`, run by
    `cosim run --scheme monolithic` (about 3 s)."""
    peers = _module("peers_run", ROOT / "benchmarks" / "peers" / "run.py")
    ref = json.loads((ROOT / "benchmarks" / "results" / "work_precision_three_mass_f100"
                      / "reference.json").read_text())
    args = ["run", str(CASES / "three_mass.toml"), "--variant", "f100", "--quiet", "--out",
            str(tmp_path / "paper")] + peers.paper_args()
    assert main(args) == 0
    m = peers.run_dir_metrics(tmp_path / "paper")
    err = peers.errors(m, ref)
    row = "| | 9 | 0.02 % / 0.02 % | 0.06 % | yes |"
    assert m["count"] == 9
    for value, measured in ((0.02e-2, err["err_peak_steps"]), (0.02e-2, err["err_peak_interp"]),
                            (0.06e-2, err["err_exit_velocity"])):
        claim = Claim(PAGE, row, "python benchmarks/peers/run.py --peers paper_rk45", value,
                      abs=0.005e-2)
        assert_printed(claim)
        assert_reproduced(claim, measured)


# --- compiled kernels: what limits the targets ------------------------------------------------

@pytest.mark.parametrize("scene, printed, counter, value", [
    ("ground_multicontact", "ground_multicontact takes 2000 macro steps of 0.1 ms",
     "macro_steps", 2000),
    ("brachiation", "brachiation's implicit scheme iterates 2551 times", "iterations", 2551),
])
def test_the_schemes_counters(scene, printed, counter, value):
    """A shipped scene's macro steps or implicit iterations, for the scene
    and its round-off copies."""
    claim = Claim(PAGE, printed, f"cosim run cases/{scene}.toml", value)
    assert_printed(claim)
    assert_reproduced(claim, _robust(_quiet_scene(CASES / f"{scene}.toml"),
                                     lambda r: r.summary[counter]))


def _modes(scene, name: str) -> int:
    system, _ = scene.build()
    return system.subsystems[system.names.index(name)].n_modes


def test_beam_impact_keeps_28_modes():
    n = _modes(_quiet_scene(CASES / "beam_impact.toml"), "beam")
    for printed in ("its 28-mode beam's closed-form steps",):
        claim = Claim(PAGE, printed, "cosim info cases/beam_impact.toml", 28)
        assert_printed(claim)
        assert_reproduced(claim, n)


# --- start-up ---------------------------------------------------------------------------------

def test_our_modules_imported_by_a_three_mass_run(tmp_path):
    """``python benchmarks/startup.py``'s count of our modules a run imports."""
    startup = _module("startup_bench", ROOT / "benchmarks" / "startup.py")
    times = startup.import_times(str(CASES / "three_mass.toml"), "f100", str(tmp_path / "r"))
    loaded = [m for m in times if startup.group(m) in startup.OURS]
    counts = [len(loaded)] + [sum(startup.group(m) == p for m in loaded) for p in startup.OURS]
    claim = Claim(PAGE, "| 92 (70, 3, 11, 8) |", "python benchmarks/startup.py", 92)
    assert_printed(claim)
    assert counts == [92, 70, 3, 11, 8], counts
    assert_printed(Claim(PAGE, "and the 92 modules themselves", "python benchmarks/startup.py",
                         92))


_DATACLASSES = """
import contextlib, dataclasses, io, sys, warnings
warnings.simplefilter("ignore")
from cosim.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    assert main(["run", sys.argv[1], "--variant", "f100", "--out", sys.argv[2], "--quiet"]) == 0
from couplers.law_base import ContactLaw
from cosim.core.ode import TimeStepper
made = {v for name, mod in list(sys.modules.items())
        if name.split(".")[0] in ("cosim", "multibody", "fem", "couplers") and mod is not None
        for v in vars(mod).values()
        if isinstance(v, type) and v.__module__ == name and dataclasses.is_dataclass(v)
        and v.__dataclass_params__.frozen and "__init__" in v.__dict__}
print(len(made), sum(issubclass(v, (ContactLaw, TimeStepper)) for v in made))
"""


def test_the_frozen_dataclasses_a_three_mass_run_creates(tmp_path):
    """"the 30 frozen dataclasses the run needs (9 of them laws and
    integrators)": the classes of our modules, imported by the run in a
    fresh process, that are frozen dataclasses with methods of their own
    (a class that reuses its base's generates none)."""
    import subprocess
    proc = subprocess.run([sys.executable, "-c", _DATACLASSES, str(CASES / "three_mass.toml"),
                           str(tmp_path / "r")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    made, laws = map(int, proc.stdout.split())
    claim = Claim(PAGE, "the 30 frozen dataclasses the run needs (9 of them laws and "
                        "integrators;", "python benchmarks/startup.py", 30)
    assert_printed(claim)
    assert_reproduced(claim, made)
    assert laws == 9


# --- memory: what a run writes ----------------------------------------------------------------

def _streamed(tmp_path, t_end: float) -> tuple[int, float, int]:
    import zipfile
    out = tmp_path / f"run{t_end:g}"
    assert main(["run", str(CASES / "beam_impact.toml"), "--set", f"t_end={t_end}", "--quiet",
                 "--no-estimate", "--out", str(out)]) == 0
    with zipfile.ZipFile(out / "series.npz") as zf:
        size = sum(i.file_size for i in zf.infolist())
    with np.load(out / "series.npz") as z:
        return len(z["t"]), size / 2**20, len(z.files) - 1


def _check_memory(tmp_path, t_end):
    """The published memory run's samples and series size (the page's table
    is that run's, ``tests/test_performance_runs.py``) are what a run writes
    now."""
    data = json.loads((ROOT / "benchmarks" / "results" / "memory" / "memory.json").read_text())
    rows = [r for r in data["rows"] if r["t_end"] == t_end]
    assert len(rows) == 3
    n, size, series = _streamed(tmp_path, t_end)
    for r in rows:
        claim = Claim(PAGE, f"| {r['samples']} |", "python benchmarks/memory.py", r["samples"])
        assert_printed(claim)
        assert_reproduced(claim, n)
        if r["series_mib"] is not None:
            assert size == pytest.approx(r["series_mib"], abs=0.05)
    return series


def test_a_one_second_beam_impact_run_writes_its_samples(tmp_path):
    series = _check_memory(tmp_path, 1.0)
    claim = Claim(PAGE, "one copy of the 147 series of 8 bytes", "python benchmarks/memory.py",
                  147)
    assert_printed(claim)
    assert_reproduced(claim, series)


@pytest.mark.slow
def test_a_ten_second_beam_impact_run_writes_its_samples(tmp_path):
    _check_memory(tmp_path, 10.0)


# --- how cost grows with size -----------------------------------------------------------------

@pytest.fixture(scope="module")
def size_scaling():
    return _module("size_scaling", ROOT / "benchmarks" / "size_scaling.py")


def _size_scene(ss, series, n):
    robot = {j: {"q": 0.0, "dq": 0.0} for j in ss.JOINTS}
    path = ss.CASES / ("three_mass.toml" if series == "chain" else "beam_impact.toml")
    return _quiet_scene(path, "f100" if series == "chain" else None,
                        ss.overrides(series, n, robot, 0.01))


def test_kept_modes_of_the_size_series(size_scaling):
    """The table's "kept modes" of `beam_modal` (16 … 1024 elements: 25 …
    29, 29 from 64 elements on) and of the chain (every mode: 3 … 300)."""
    ss = size_scaling
    modal = [_modes(_size_scene(ss, "beam_modal", n), "beam") for n in ss.SIZES["beam_modal"]]
    assert_printed(Claim(PAGE, "| `beam_modal` | 16 … 1024 elements | 25 … 29 |",
                         "python benchmarks/size_scaling.py", 25))
    assert_printed(Claim(PAGE, "From 64 elements on, the 20 kHz cutoff keeps 29 modes",
                         "python benchmarks/size_scaling.py", 29))
    assert (modal[0], max(modal)) == (25, 29), modal
    assert modal[ss.SIZES["beam_modal"].index(64):] == [29] * 5, modal
    assert_printed(Claim(PAGE, "| `chain` | 3 … 300 masses | 3 … 300 |",
                         "python benchmarks/size_scaling.py", 3))
    assert [_modes(_size_scene(ss, "chain", n), "chain") for n in (3, 300)] == [3, 300]
    assert _modes(_size_scene(ss, "beam_full", 16), "beam") == 32    # every mode: 2 per element


def test_c_strikes_a_longer_chain_eight_times(size_scaling):
    """"C's train has 9 contacts on 3 or 6 masses and 8 from 12 masses on",
    on the benchmark's window; at 6 and 12 masses (either side of the
    change) also with the robot's start moved by +-1 ulp."""
    from cosim.studies.roundoff import nudge
    ss = size_scaling
    assert_printed(Claim(PAGE, "C's train has 9 contacts on 3 or 6 masses and 8 from 12 masses "
                               "on", "python benchmarks/size_scaling.py", 9))
    robot = ss.robot_state("chain")
    counts = {n: ss.run_point("chain", n, robot).contacts_C for n in ss.SIZES["chain"]}
    assert counts == {n: 9 if n <= 6 else 8 for n in ss.SIZES["chain"]}, counts
    for ulps in (1, -1):
        moved = {j: {k: nudge(v, ulps) for k, v in s.items()} for j, s in robot.items()}
        assert [ss.run_point("chain", n, moved).contacts_C for n in (6, 12)] == [9, 8]


def test_the_full_beam_at_1024_elements_keeps_2048_modes(size_scaling):
    """"2048 modes at 1024 elements, ω_max = 7.9·10⁸ rad/s": the build of
    `beam_full` at 1024 elements (a dense eigen-solve of 2048 DOFs, a few
    seconds)."""
    system, _ = _size_scene(size_scaling, "beam_full", 1024).build()
    beam = system.subsystems[system.names.index("beam")]
    text = "(`beam_full`: 2048 modes at 1024 elements, ω_max = 7.9·10⁸ rad/s)"
    for claim, value in ((Claim(PAGE, text, "python benchmarks/size_scaling.py", 2048),
                          beam.n_modes),
                         (Claim(PAGE, text, "python benchmarks/size_scaling.py", 7.9e8,
                                abs=0.05e8), float(np.max(beam.omega)))):
        assert_printed(claim)
        assert_reproduced(claim, value)


_PEAKS = ("C's peak penetration at 256 elements is 3.12621 mm with the 20 kHz cutoff (the same "
          "to six digits from 128 to 1024 elements) and 3.12581 mm with every mode (the same at "
          "128 elements), 0.013 % apart.")


def _peak_claims(series: str, peaks) -> None:
    value = 3.12621e-3 if series == "beam_modal" else 3.12581e-3
    for p in peaks:
        claim = Claim(PAGE, _PEAKS, "python benchmarks/size_scaling.py", value, abs=0.000005e-3)
        assert_printed(claim)
        assert_reproduced(claim, p)


def test_cs_peak_on_the_beam_from_128_elements(size_scaling):
    """C's peak with the 20 kHz cutoff at 128 to 1024 elements and with
    every mode at 128 (a few seconds; 256 with every mode is the slow test
    below)."""
    ss = size_scaling
    robot = ss.robot_state("beam_full")
    _peak_claims("beam_modal", [ss.run_point("beam_modal", n, robot).peak_C
                                for n in (128, 256, 512, 1024)])
    _peak_claims("beam_full", [ss.run_point("beam_full", 128, robot).peak_C])


@pytest.mark.slow
def test_cs_peak_on_the_beam_at_256_elements_with_and_without_reduction(size_scaling):
    """C's peak at 256 elements, 20 kHz cutoff and every mode, and how far
    apart they are ("0.013 % apart"); about a minute of CPU."""
    ss = size_scaling
    robot = ss.robot_state("beam_full")
    modal, full = (ss.run_point(s, 256, robot).peak_C for s in ("beam_modal", "beam_full"))
    _peak_claims("beam_modal", [modal])
    _peak_claims("beam_full", [full])
    apart = Claim(PAGE, _PEAKS, "python benchmarks/size_scaling.py", 0.013e-2, abs=0.0005e-2)
    assert_reproduced(apart, abs(modal - full) / full)


@pytest.mark.slow
def test_the_full_beam_at_1024_elements_solves_its_contact_basis_147_times(size_scaling):
    """`beam_full` at 1024 elements: the contact basis solved 147 times, once
    per step in contact.  Long: the full beam's runs grow as elements^1.6 or
    faster (this one ran past 25 minutes of CPU on a 2-core machine
    and was not seen to finish there)."""
    import cosim.sides.fem_closed_form as fcf
    ss = size_scaling
    robot = ss.robot_state("beam_full")
    real, calls = fcf.rank_one_eigh, [0]

    def counted(*a, **k):
        calls[0] += 1
        return real(*a, **k)
    fcf.rank_one_eigh = counted
    try:
        ss.run_point("beam_full", 1024, robot)
    finally:
        fcf.rank_one_eigh = real
    claim = Claim(PAGE, "147 times at 1024 elements", "python benchmarks/size_scaling.py", 147)
    assert_printed(claim)
    assert_reproduced(claim, calls[0])


def test_cs_contact_time_on_three_mass_f100():
    """"keep its step in contact at 30 µs or below, a tenth of the contact
    time (0.3 ms here)": C's contact time at its first touch, as `cosim info`
    gives it: the function the command prints (``scene_info``) without the
    runs that confirm the explicit schemes' steps (``confirm_steps=0``),
    which set ``max_macro_step_*`` alone and took nearly all of its CPU."""
    from cosim.scene.info import scene_info
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        info = scene_info(load_scene(CASES / "three_mass.toml", "f100"), confirm_steps=0)
    claim = Claim(PAGE, "at 30 µs or below, a tenth of the contact time (0.3 ms here)",
                  "cosim info cases/three_mass.toml --variant f100", 0.3e-3, abs=0.05e-3)
    assert_printed(claim)
    assert_reproduced(claim, info["contacts"]["C"]["contact_time_s"])


def test_the_bench_settings_the_page_names():
    """The reference and the paper's method as `cosim bench` runs them."""
    import cosim.studies.bench as bench
    for printed, value, measured in (
            ("monolithic DOP853, rtol 1e-11", 1e-11, bench.REFERENCE["rtol"]),
            ("RK45, max step 1e-4 s, rtol 1e-4, atol\n1e-6", 1e-4, bench.PAPER_RK45["max_step"]),
            ("RK45, max step 1e-4 s, rtol 1e-4, atol\n1e-6", 1e-4, bench.PAPER_RK45["rtol"]),
            ("RK45, max step 1e-4 s, rtol 1e-4, atol\n1e-6", 1e-6, bench.PAPER_RK45["atol"])):
        claim = Claim(PAGE, printed, "cosim bench", value, rel=1e-12)
        assert_printed(claim)
        assert_reproduced(claim, measured)
    assert bench.REFERENCE["method"] == "DOP853" and bench.PAPER_RK45["method"] == "RK45"


_SCIPY = """
import sys, warnings
warnings.simplefilter("ignore")
import cosim
scene = cosim.load_scene(sys.argv[1], "f100", overrides=sys.argv[2:], scheme="monolithic")
before = "scipy.integrate" in sys.modules
cosim.simulate(scene)
print(before, "scipy.integrate" in sys.modules)
"""


def test_the_paper_rows_first_run_imports_no_scipy():
    """"the paper's RK45 now being cosim's own pair, which imports no
    scipy": in a fresh process the paper row's scene (RK45), loaded and then
    run, has not imported ``scipy.integrate``."""
    import subprocess
    import cosim.studies.bench as bench
    assert_printed(Claim(PAGE, "the paper's RK45 now being cosim's own pair, which imports no "
                               "scipy", "python benchmarks/peers/run.py", 0))
    proc = subprocess.run([sys.executable, "-c", _SCIPY, str(CASES / "three_mass.toml"),
                           *bench._monolithic(bench.PAPER_RK45)], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == ["False", "False"], proc.stdout
