"""Ctrl-C and SIGTERM during a long block of the sampled path
(:mod:`cosim.core.schemes.sampled`) stop the run within a fraction of a
second and keep what was computed, as they do in the macro loop.

The block here is spring_drop's free flight (100 macro steps up to the touch
at 10 ms) under ``max_step = 2e-10``: each macro step takes 500 000 RK4
steps, so the kernel's one call over the block runs for tens of seconds.
The kernel looks at the signals within its steps; the run keeps the whole
macro steps taken before the signal (its folder holds the series and the
summary, ``status`` interrupted) and exits 128 + the signal."""
import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import CASES
from ulps import ulp

SPRING_DROP = CASES / "spring_drop.toml"
#: the scene's macro step [s], its height above the wall [m] and speed towards it [m/s]
H, Q0, V0 = 1e-4, 0.01, -1.0
#: the RK4 step asked [s]: 500 000 of them a macro step
MAX_STEP = 2e-10
#: a generous bound on the wait from the signal to the exit [s]: the kernel
#: looks at the signals every 4096 RK4 steps (well under a millisecond here),
#: then the run writes its files; without that look it ends its block first
#: (tens of seconds on this scene, minutes under max_step = 1e-10)
EXIT_WITHIN = 5.0


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_stops_a_long_sampled_block_at_once_and_keeps_its_steps(tmp_path, sig, code):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "run", str(SPRING_DROP),
                             "--set", f"subsystems.body.integrator.max_step={MAX_STEP!r}",
                             "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tmp_path)
    try:
        spool = out / ".series.npz.spool"
        deadline = time.monotonic() + 120
        while not spool.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert spool.exists(), "the run never started"
        time.sleep(2.5)                       # into the block: a few macro steps taken
        assert proc.poll() is None, proc.communicate()
        sent = time.monotonic()
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=120)
        waited = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert waited < EXIT_WITHIN, f"{waited:.1f} s from the signal to the exit"
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr
    name = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM"
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "interrupted"
    assert s["message"].startswith(f"interrupted ({name}) at t = ")
    assert "status interrupted" in stdout
    assert sorted(p.name for p in out.iterdir()) == ["scene.toml", "series.npz", "summary.json"]
    with np.load(out / "series.npz") as npz:
        t, q, dq = npz["t"], npz["q/body/x"], npz["dq/body/x"]
        assert all(len(npz[k]) == len(t) for k in npz.files)
    # the macro steps taken before the signal, whole: one sample at each
    # end, the last one the summary's, all before the touch (the block's end)
    assert len(t) >= 2 and t[-1] < 0.01 - H
    assert s["t_end"] == pytest.approx(t[-1])
    assert np.allclose(np.diff(t), H, rtol=1e-9, atol=0)
    # free flight: the kept states are the computed ones.  RK4 is exact on it
    # but for round-off: each of its RK4 steps (MAX_STEP apart) rounds q by at
    # most half an ulp, and its increment by less, so after k macro steps q
    # is within k H / MAX_STEP ulps of Q0 + V0 t; no force moves dq
    steps = np.rint(t / H) * (H / MAX_STEP)
    assert np.all(np.abs(q - (Q0 + V0 * t)) <= steps * ulp(Q0)), q - (Q0 + V0 * t)
    assert np.all(dq == V0)
