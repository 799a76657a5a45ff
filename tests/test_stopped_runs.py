"""A run that stops early (the guard, a failure, Ctrl-C) ends its summary, its
series and its message at one time, the last sample kept, and its summary
holds what the kept steps did: no contact interval ends before it begins or
after the stop, ``in_touch_time`` is never negative, the peaks are those of
the kept steps.  The command line prints the message once.

A scheme reports a step's switches (and rigid impacts) before the sample at
the step's end, and the guard may refuse that sample: three_mass f1000 under
Jacobi with a contact step of 0.1 ms is stopped on the step in which C first
touches, and C's summary used to read ``intervals [[0.102739, 0.1027]]``,
``in_touch_time -3.9e-05``, peak 0."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import cosim
from conftest import CASES, ROOT
from roundoff import cli_copies
from cosim.core.recorder import Recorder, intervals_until

THREE_MASS = CASES / "three_mass.toml"
#: the guard stops it on the step in which contact C first touches (at 0.1028 s)
JACOBI = ["run", str(THREE_MASS), "--variant", "f1000", "--scheme", "jacobi",
          "--set", "scheme.contact_step=1e-4"]
#: loose tolerances: the guard stops it early (energy growth or chatter at contact A)
MONOLITHIC = ["run", str(THREE_MASS), "--variant", "f100", "--set", "t_end=0.106",
              "--scheme", "monolithic", "--set", "scheme.monolithic.rtol=0.5",
              "--set", "scheme.monolithic.atol=1e-2"]


def run_cli(args, out, kernel=None):
    """``cosim ARGS --out OUT``; ``kernel`` "numpy" or "compiled" sets
    ``COSIM_KERNEL``, None leaves the environment's."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    if kernel is not None:
        env.pop("COSIM_KERNEL", None)
        if kernel == "numpy":
            env["COSIM_KERNEL"] = "numpy"
    return subprocess.run([sys.executable, "-m", "cosim.cli", *args, "--out", str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300, env=env)


def assert_consistent(summary: dict, series) -> None:
    """The invariants of a summary against its own series."""
    t = np.asarray(series["t"])
    t_end = summary["t_end"]
    assert t_end == t[-1], (t_end, t[-1])
    for name, c in summary["contacts"].items():
        iv = c["intervals"]
        assert c["count"] == len(iv), name
        for a, b in iv:
            assert 0.0 <= a <= b <= t_end, (name, a, b, t_end)
        assert all(iv[k][1] <= iv[k + 1][0] for k in range(len(iv) - 1)), (name, iv)
        assert c["in_touch_time"] >= 0.0, (name, c["in_touch_time"])
        assert c["in_touch_time"] == pytest.approx(sum(b - a for a, b in iv), abs=1e-15)
        # the summary's peak is the largest of the peaks the kept samples located
        assert c["peak_penetration"] == np.max(series[f"peak/{name}"]), name
        if not iv:                     # a contact that never closed in a kept step
            assert c["peak_penetration"] == 0.0 and c["impulse"] == 0.0, (name, c)
    for imp in summary["impacts"]:
        assert imp["time"] <= t_end


def assert_stopped_cli(proc, out) -> dict:
    """A stopped run as the command line shows it: exit 1, the message once,
    opening with the stop time that the summary and the series end at."""
    assert proc.returncode == 1, proc.stderr
    s = json.loads((out / "summary.json").read_text())
    with np.load(out / "series.npz") as z:
        assert_consistent(s, z)
    assert s["status"] == "failed"
    message = s["message"]
    assert message.startswith(f"run stopped at t = {s['t_end']:.6g} s"), message
    both = proc.stdout + proc.stderr
    assert both.count(message) == 1, both
    assert both.count("run stopped at") == 1, both
    assert ".." not in both
    assert f"t_end {s['t_end']:.6g} s" in proc.stdout
    period = "" if message.endswith(".") else "."      # one period, never two
    assert proc.stderr.rstrip("\n").endswith(
        f"{message}{period} Its series and summary up to t = {s['t_end']:.6g} s are in {out}")
    # a time the guard tripped at, if the message gives one, is after the stop
    if "the guard tripped at t = " in message:
        tripped = float(message.split("the guard tripped at t = ")[1].split(" s")[0])
        assert tripped > s["t_end"]
    return s


@pytest.mark.parametrize("copy", cli_copies(cosim.load_scene(THREE_MASS, "f1000")))
def test_a_run_the_guard_stops_mid_touch_ends_its_summary_at_the_stop(tmp_path, copy):
    out = tmp_path / "run"
    s = assert_stopped_cli(run_cli(JACOBI + copy, out), out)
    assert "contact `C` created" in s["message"]
    # the stop falls at the step landed just short of C's onset
    assert "the guard tripped at t = 0.102839 s" in s["message"]
    assert s["t_end"] == pytest.approx(0.102739, abs=5e-7)
    # C touched in the step the guard refused: the kept steps end just past its
    # onset, which its host located (landed on, LAND_MARGIN of a contact step,
    # 1e-9 s here), so C's interval is that sliver and its peak a few nm
    c = s["contacts"]["C"]
    assert all(b - a <= 1e-8 and b == s["t_end"] for a, b in c["intervals"]), c["intervals"]
    assert c["in_touch_time"] <= 1e-8 and c["peak_penetration"] <= 1e-7
    assert s["contacts"]["A"]["count"] == 2


@pytest.mark.parametrize("kernel", ["numpy", "compiled"])
def test_a_loose_monolithic_run_says_one_stop_time(tmp_path, kernel):
    """The numpy reference and the compiled kernel stop it at other times
    (chatter or energy growth): the invariants hold for both."""
    out = tmp_path / "run"
    proc = run_cli(MONOLITHIC, out, kernel)
    s = assert_stopped_cli(proc, out)
    assert s["t_end"] < 0.02


# ------------------------------------------------------------ unit tests
@pytest.mark.parametrize("intervals,opened,t_stop,expected", [
    ([[0.0, 0.1]], None, 0.3, [[0.0, 0.1]]),                 # nothing past the stop
    ([[0.0, 0.1]], 0.2, 0.3, [[0.0, 0.1], [0.2, 0.3]]),      # open: ends at the stop
    ([[0.0, 0.1]], 0.3, 0.3, [[0.0, 0.1], [0.3, 0.3]]),      # opened at the stop itself
    ([[0.0, 0.1]], 0.35, 0.3, [[0.0, 0.1]]),                 # opened in a refused step
    ([[0.0, 0.32]], None, 0.3, [[0.0, 0.3]]),                # released in a refused step
    ([[0.0, 0.31], [0.32, 0.33]], 0.34, 0.3, [[0.0, 0.3]]),  # switched on in a refused step
    ([], None, 0.0, []),
])
def test_intervals_end_at_the_stop(intervals, opened, t_stop, expected):
    got = intervals_until(intervals, opened, t_stop)
    assert got == expected
    assert all(a <= b <= t_stop for a, b in got)


def spring_recorder():
    scene = cosim.load_scene(CASES / "spring_drop.toml")
    system, _ = scene.build()
    return system, Recorder(system, "spring_drop", "test", 1.0, auto_edges=False)


def sample(rec, system, t):
    d, dd = system.penetrations(system.outputs())
    f = system.forces(d, dd)
    z = np.zeros(system.n_contacts)
    rec.record(t, d, dd, f, z, z, work=z)


@pytest.mark.parametrize("status", ["failed", "interrupted", "error"])
def test_the_recorder_drops_what_a_step_it_never_kept_reported(status):
    """The recorder as a scheme drives it: switches, an impact and the
    located peak of a step are reported, and the run stops before the step's
    sample is kept.  The summary ends at the last kept sample without them;
    a contact open at the stop is closed there."""
    system, rec = spring_recorder()
    sample(rec, system, 0.0)
    rec.edge(0, 1e-3, True)                     # a kept step: the wall closes
    sample(rec, system, 2e-3)
    rec.edge(0, 2.5e-3, False)                  # the next step: released, closed again,
    rec.edge(0, 2.7e-3, True)                   # an impact; then the run stops
    rec.impacts.append({"time": 2.6e-3, "contact": "wall"})
    res = rec.finish(status, "stopped", 0.0, {})
    s = res.summary
    assert s["t_end"] == 2e-3
    wall = s["contacts"]["wall"]
    assert wall["intervals"] == [[1e-3, 2e-3]] and wall["count"] == 1
    assert wall["in_touch_time"] == pytest.approx(1e-3, rel=1e-12)
    assert s["impacts"] == [] and res.contact_events == (
        {"contact": "wall", "t_on": 1e-3, "t_off": 2e-3},)
    assert_consistent(s, res.series)


def test_a_finished_run_keeps_every_interval():
    """The same recorder with every step kept: nothing is cut."""
    system, rec = spring_recorder()
    sample(rec, system, 0.0)
    rec.edge(0, 1e-3, True)
    rec.edge(0, 1.5e-3, False)
    sample(rec, system, 2e-3)
    s = rec.finish("finished", "", 0.0, {}).summary
    assert s["contacts"]["wall"]["intervals"] == [[1e-3, 1.5e-3]]
    assert math.isclose(s["contacts"]["wall"]["in_touch_time"], 5e-4, rel_tol=1e-12)


def test_a_guard_error_says_the_stop_and_the_trip_time():
    """The run's message opens with the last kept sample; the guard's own
    time follows when it is later."""
    from cosim.core.guard import GuardError
    from cosim.scene.run import stop_message
    exc = GuardError("the energy grew by 7.5 J", 0.1028, "C",
                     "energy growth")
    assert exc.reason == "the energy grew by 7.5 J"
    assert str(exc) == "run stopped at t = 0.1028 s: the energy grew by 7.5 J"
    assert stop_message(exc, 0.1027000000000001) == (
        "run stopped at t = 0.1027 s (the last sample kept; the guard tripped at "
        "t = 0.1028 s): the energy grew by 7.5 J")
    assert stop_message(exc, 0.1028) == "run stopped at t = 0.1028 s: the energy grew by 7.5 J"
    other = cosim.CouplingError("implicit coupling did not converge at t = 0.01 s")
    assert stop_message(other, 0.01) == ("run stopped at t = 0.01 s: implicit coupling did "
                                         "not converge at t = 0.01 s")
